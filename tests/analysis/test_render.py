"""analysis.render: the one Markdown writer, the one booktabs writer, escaping, cell formatting, figure saving."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.render import (fmt_cell, frame_cells, latex_table, markdown_table, md_cell, pyplot, save_figure,
                             tex_breakable, tex_cell, tex_escape, write_table)


# ---------------------------------------------------------------------------------------------- cells
@pytest.mark.parametrize("x, digits, missing, expected", [
    (0.12345, 3, "", "0.123"),
    (np.float64(2.0), 2, "", "2.00"),
    (np.int64(7), 3, "", "7"),          # integers stay integers, whatever the digits
    (3, 2, "", "3"),
    (True, 3, "", "yes"),
    (np.bool_(False), 3, "", "no"),
    (None, 3, "–", "–"),
    (float("nan"), 3, "", ""),
    (float("inf"), 3, "-", "-"),        # non-finite counts as missing
    (pd.NA, 3, "?", "?"),
    ("PU1", 3, "", "PU1"),
])
def test_fmt_cell(x, digits, missing, expected):
    assert fmt_cell(x, digits, missing) == expected


def test_frame_cells_keeps_column_order_and_formats_per_type():
    df = pd.DataFrame({"item": ["a", "b"], "r": [0.5, np.nan], "n": [3, 4], "ok": [True, False]})
    header, rows = frame_cells(df, digits=2)
    assert header == ["item", "r", "n", "ok"]
    assert rows == [["a", "0.50", "3", "yes"], ["b", "", "4", "no"]]


def test_frame_cells_print_whole_numbers_as_integers():
    """Counts held as floats (a pivot of counts, a count column with a missing value read back from CSV) print as
    integers (APA), in every writer that starts from the frame; a column with any fraction keeps its decimals."""
    df = pd.DataFrame({"red_stops": [5.0, 4.0, np.nan], "share": [0.5, 1.0, 2.0], "n": [3, 4, 5]})
    header, rows = frame_cells(df, digits=3)
    assert [r[0] for r in rows] == ["5", "4", ""] and [r[1] for r in rows] == ["0.500", "1.000", "2.000"]


# ---------------------------------------------------------------------------------------------- LaTeX
def test_tex_escape_is_one_pass():
    # a backslash becomes \textbackslash{} whose braces must not be escaped again
    assert tex_escape("a\\b") == r"a\textbackslash{}b"
    assert tex_escape("50% & {x}_1 #2 $3 ~ ^") == r"50\% \& \{x\}\_1 \#2 \$3 \textasciitilde{} \^{}"


def test_tex_escape_symbols():
    assert tex_escape("λ, Cα, β, ΔR²") == r"$\lambda$, C$\alpha$, $\beta$, $\Delta$R$^2$"
    assert tex_escape("PEoU3† 0.1 – 0.2, PU -> BI") == r"PEoU3$^\dagger$ 0.1 -- 0.2, PU $\rightarrow$ BI"
    assert tex_escape("≈ 0.5 ± 0.1 × 2 − 1") == r"$\approx$ 0.5 $\pm$ 0.1 $\times$ 2 $-$ 1"


def test_tex_breakable_paths_and_identifiers():
    """A file path or an identifier in a note may break after / and _; units and ratios stay whole."""
    assert tex_breakable(tex_escape("(data/reference/README.md),")) == \
        r"(data/\allowbreak reference/\allowbreak README.md),"
    assert tex_breakable(tex_escape("m/s, 1/40, Wh/km")) == "m/s, 1/40, Wh/km"
    assert tex_breakable(tex_escape("see docs/sweep.md")) == r"see docs/\allowbreak sweep.md"
    assert tex_breakable(tex_escape("per_participant")) == r"per\_\allowbreak participant"


def test_tex_cell_bold_and_stars():
    assert tex_cell("**0.707**") == r"\textbf{0.707}"
    assert tex_cell("**Perceived Usefulness (PU)**") == r"\textbf{Perceived Usefulness (PU)}"
    assert tex_cell("0.517**") == "0.517**"      # a significance mark stays a mark
    assert tex_cell("****") == "****"


def test_latex_table_structure():
    tex = latex_table(["Item", "λ"], [["PU1", "0.800"], ["x_y", "**0.9**"]], title="Loadings (%)",
                      notes=["Note. N = 40.", "* p < .05"], label="tab:l", align="lc")
    assert tex.splitlines() == [
        r"\begin{table}[tbp]", r"\centering\small", r"\begin{threeparttable}", r"\caption{Loadings (\%)}",
        r"\label{tab:l}", r"\begin{tabular}{lS[table-format=1.3, print-zero-integer=false]}", r"\toprule",
        r"Item & {$\lambda$} \\",
        r"\midrule", r"PU1 & .800 \\", r"x\_y & {\textbf{0.9}} \\", r"\bottomrule", r"\end{tabular}",
        r"\begin{tablenotes}[flushleft]\footnotesize\raggedright", r"\item \textit{Note.} N = 40.",
        r"\item * p < .05",
        r"\end{tablenotes}", r"\end{threeparttable}", r"\end{table}"]
    assert r"\begin{tabular}{lll}" in latex_table(["a", "b", "c"], [])  # no numbers: text, set left
    with pytest.raises(ValueError):
        latex_table(["a", "b"], [], align="l")


def test_latex_numeric_columns_align_on_the_decimal_point_as_written():
    tex = latex_table(["x", "r", "b", "n"], [["a", ".41**", "-1.50", "12"], ["b", "−.07", "0.25", "–"]])
    # no leading zero where the column has none (APA: values bounded by 1); the marks' room kept; a dash as text
    assert "S[table-format=-1.2, print-zero-integer=false, table-space-text-post={**}]" in tex
    assert "S[table-format=-1.2]S[table-format=2]" in tex
    assert r"a & .41{**} & -1.50 & 12 \\" in tex and r"b & -.07 & 0.25 & {--} \\" in tex


def _label_table(columns: int, label: str = "Perceived usefulness of the advice", rows: int = 4):
    header = ["Construct", *[f"Statistic number {j}" for j in range(1, columns)]]
    return header, [[f"{label} {i}", *[f"{0.1 * i + j:.3f}" for j in range(1, columns)]] for i in range(rows)]


def test_latex_table_goes_where_it_fits():
    assert latex_table(*_label_table(2)).startswith(r"\begin{table}[tbp]")
    assert latex_table(*_label_table(6)).startswith(r"\begin{table*}[tbp]")
    assert latex_table(*_label_table(10)).startswith(r"\begin{sidewaystable*}[p]")
    # wider than a landscape page at \small: landscape pages at \footnotesize (with less space between columns)
    dense = latex_table(*_label_table(12))
    assert dense.startswith("\\begin{landscape}\n\\begingroup\\footnotesize") and dense.count(r"\begin{longtable}") == 1
    # wider than a landscape page even so: in column groups that each repeat
    # the row labels and fit the page (no shrinking to an unreadable size)
    wide = latex_table(*_label_table(30), title="Wide")
    assert wide.startswith("\\begin{landscape}\n\\begingroup\\footnotesize") and "adjustbox" not in wide
    parts = wide.count(r"\begin{longtable}")
    assert parts > 1 and wide.count(r"\addtocounter{table}{-1}") == parts - 1
    assert wide.count("Perceived usefulness of the advice 3 &") == parts
    # taller than a page: a longtable, the header repeated on every page, the notes after the last row
    tall = latex_table(*_label_table(4, rows=120), title="Tall", notes=["Note. N = 40."], label="tab:tall")
    assert tall.startswith("\\begingroup\\small") and tall.count(r"\begin{longtable}") == 1
    assert r"\caption{Tall}\label{tab:tall}\\" in tall and r"\caption*{Table \thetable{} (continued)}\\" in tall
    assert tall.index(r"\endhead") < tall.index(r"\textit{Note.} N = 40.") < tall.index(r"\endlastfoot") < \
        tall.index("Perceived usefulness of the advice 0 &")
    # a long label wraps (p column) rather than pushing the table out of its column
    header, rows = _label_table(3, label="A label long enough to need more than one line in one column of a page")
    narrow = latex_table(header, rows)
    assert narrow.startswith(r"\begin{table}[tbp]") and r"p{" in narrow


def test_latex_tables_fit_a_two_column_article(tmp_path):
    """Compiled in a two-column article, none of the tables is wider than its room (0 overfull boxes) or taller
    than its page (a float that is, "Float too large", runs off the page)."""
    from tests.latex_fit import compile_tables, misfits, overfull, pdflatex

    if pdflatex() is None:
        return
    tables = [latex_table(*_label_table(n), title=f"{n} columns", notes=["Note. A note long enough to wrap " * 3])
              for n in (2, 4, 6, 9, 12, 30)]
    tables.append(latex_table(*_label_table(6, rows=120), title="Tall", notes=["Note. A note (data/a/b/README.md)."]))
    header, rows = _label_table(3, label="A label long enough to need more than one line in one column of a page")
    tables.append(latex_table(header, rows, title="wrapped"))
    tables.append(latex_table(["Item", "β", "p"], [["PU → BI", ".41**", "< .001"], ["SN → BI", "−.07", ".512"]],
                              notes=["Note. ** p < .01."]))
    log = compile_tables(tables, tmp_path)
    assert misfits(log) == {"overfull": 0, "float too large": 0, "output loop": 0}, overfull(log)


# ---------------------------------------------------------------------------------------------- Markdown
def test_markdown_table_default():
    md = markdown_table(["a", "c"], [["1", "x|y"]], title="T", notes=["n1", "n2"])
    assert md == "### T\n\n| a | c |\n|---|---|\n| 1 | x\\|y |\n\n_n1_\n_n2_\n"


def test_markdown_table_options():
    md = markdown_table(["Style", "n", "mean"], [["all", "5", "1.00"]], title="KPIs", notes=["** p < .01", "last"],
                        align="lrc", title_style="bold", notes_style="plain")
    assert md == ("**KPIs**\n\n| Style | n | M |\n|---|---:|:---:|\n| all | 5 | 1.00 |\n\n"
                  "** p < .01  \nlast\n")
    with pytest.raises(ValueError):
        markdown_table(["a", "b"], [], align="l")


def test_md_cell_never_splits_a_row():
    assert md_cell("a|b\nc") == "a\\|b c"
    md = markdown_table(["x"], [["p|q"], ["r\ns"]])
    assert {ln.replace("\\|", "").count("|") for ln in md.splitlines() if ln.startswith("|")} == {2}


def test_write_table(tmp_path):
    df = pd.DataFrame({"stage": ["enrolled", "excluded"], "n": [40, 2], "share": [1.0, 0.05]})
    paths = write_table(df, tmp_path / "t", "flow", "Participant flow", digits=2)
    assert [p.name for p in paths] == ["flow.csv", "flow.md", "flow.tex"]
    assert pd.read_csv(paths[0]).equals(df)
    assert "| excluded | 2 | 0.05 |" in paths[1].read_text()
    assert r"excluded & 2 & 0.05 \\" in paths[2].read_text() and r"\label{tab:flow}" in paths[2].read_text()


# ---------------------------------------------------------------------------------------------- figures
def test_save_figure_png_svg_pdf_reproducible(tmp_path):
    def draw(out):
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot([0, 1, 2], [0, 1, 4])
        ax.set_title("Title with text")
        return save_figure(fig, out, "f")

    a, b = draw(tmp_path / "a"), draw(tmp_path / "b")
    assert [p.suffix for p in a] == [".png", ".svg", ".pdf"]
    for x, y in zip(a, b):
        assert x.read_bytes() == y.read_bytes(), x.name
    pdf = a[2].read_bytes()
    assert b"CreationDate" not in pdf and b"pedas-study" in pdf
    # fonts embedded as TrueType (Type 42 -> /TrueType or /CIDFontType2), never as Type 3
    assert b"/Type3" not in pdf and (b"/TrueType" in pdf or b"/CIDFontType2" in pdf)
    svg = a[1].read_text()
    assert svg.startswith("<?xml") and "<dc:date>" not in svg and "pedas-study" in svg
    assert pyplot().get_fignums() == []      # closed after saving

"""analysis.render: the one Markdown writer, the one booktabs writer, escaping, cell formatting, figure saving."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.render import (fmt_cell, frame_cells, latex_table, markdown_table, md_cell, pyplot, save_figure,
                             tex_cell, tex_escape, write_table)


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


# ---------------------------------------------------------------------------------------------- LaTeX
def test_tex_escape_is_one_pass():
    # a backslash becomes \textbackslash{} whose braces must not be escaped again
    assert tex_escape("a\\b") == r"a\textbackslash{}b"
    assert tex_escape("50% & {x}_1 #2 $3 ~ ^") == r"50\% \& \{x\}\_1 \#2 \$3 \textasciitilde{} \^{}"


def test_tex_escape_symbols():
    assert tex_escape("λ, Cα, β, ΔR²") == r"$\lambda$, C$\alpha$, $\beta$, $\Delta$R$^2$"
    assert tex_escape("PEoU3† 0.1 – 0.2, PU -> BI") == r"PEoU3$^\dagger$ 0.1 -- 0.2, PU $\rightarrow$ BI"
    assert tex_escape("≈ 0.5 ± 0.1 × 2 − 1") == r"$\approx$ 0.5 $\pm$ 0.1 $\times$ 2 $-$ 1"


def test_tex_cell_bold_and_stars():
    assert tex_cell("**0.707**") == r"\textbf{0.707}"
    assert tex_cell("**Perceived Usefulness (PU)**") == r"\textbf{Perceived Usefulness (PU)}"
    assert tex_cell("0.517**") == "0.517**"      # a significance mark stays a mark
    assert tex_cell("****") == "****"


def test_latex_table_structure():
    tex = latex_table(["Item", "λ"], [["PU1", "0.800"], ["x_y", "**0.9**"]], title="Loadings (%)",
                      notes=["N = 40.", "* p < .05"], label="tab:l", align="lc")
    assert tex.splitlines() == [
        r"\begin{table}[t]", r"\centering", r"\caption{Loadings (\%)}", r"\label{tab:l}",
        r"\begin{tabular}{lc}", r"\toprule", r"Item & $\lambda$ \\", r"\midrule",
        r"PU1 & .800 \\", r"x\_y & \textbf{0.9} \\", r"\bottomrule", r"\end{tabular}",
        r"\par\smallskip\footnotesize N = 40. \\ * p < .05", r"\end{table}"]
    assert latex_table(["a", "b", "c"], [])[:200].count(r"\begin{tabular}{lrr}") == 1  # default alignment


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
def test_save_figure_png_pdf_reproducible(tmp_path):
    def draw(out):
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot([0, 1, 2], [0, 1, 4])
        return save_figure(fig, out, "f")

    a, b = draw(tmp_path / "a"), draw(tmp_path / "b")
    assert [p.suffix for p in a] == [".png", ".pdf"]
    for x, y in zip(a, b):
        assert x.read_bytes() == y.read_bytes()
    pdf = a[1].read_bytes()
    assert b"CreationDate" not in pdf and b"pedas-study" in pdf
    assert pyplot().get_fignums() == []      # closed after saving

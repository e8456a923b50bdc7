"""The manuscript outputs of a report folder (analysis.report.manuscript, analysis.report.word): the numbered tables and
figures in reading order as Word (APA style, A4) and LaTeX, from exhibits.json or, without it, from index.html."""
from __future__ import annotations

import io

import pytest

from analysis.render import markdown_table, parse_markdown_table, pyplot, save_figure
from analysis.report.exhibits import Exhibit, write_exhibits
from analysis.report.manuscript import exhibits_from_document, latex_files, manuscript_files, report_exhibits
from analysis.report.word import column_widths, results_docx


def _table(out, stem: str, columns: int = 3, rows: int = 3, title: str = "T") -> dict:
    header = ["Construct", *[f"c{j}" for j in range(1, columns)]]
    cells = [[f"**PU{i}**" if i == 0 else f"PU{i}", *[f"{-0.1 * i + j / 10:.3f}" for j in range(1, columns)]]
             for i in range(rows)]
    (out / "tables").mkdir(parents=True, exist_ok=True)
    (out / "tables" / f"{stem}.md").write_text(markdown_table(header, cells, title, ["a note"]), encoding="utf-8")
    return {"md": f"tables/{stem}.md"}


def _figure(out, stem: str, width: float = 3) -> dict:
    fig, ax = pyplot().subplots(figsize=(width, 2))
    ax.plot([0, 1], [0, 1])
    save_figure(fig, out / "figures", stem)
    return {ext: f"figures/{stem}.{ext}" for ext in ("png", "svg", "pdf")}


@pytest.fixture
def report(tmp_path):
    """A report folder with two main-text tables, a figure and a wide appendix table, listed in exhibits.json."""
    out = tmp_path / "rep"
    ex = [Exhibit("table", "Table 1", "main", "Sample", "flow", "Participant flow", "Note. N = 40.",
                  _table(out, "flow")),
          Exhibit("figure", "Figure 1", "main", "Drives", "savings", "Energy savings by section",
                  "Note. One dot per participant.", _figure(out, "savings")),
          Exhibit("table", "Table 2", "main", "Drives", "bands", "Reproduction bands", "", _table(out, "bands", 4)),
          Exhibit("table", "Table A1", "appendix", "Drives", "per_participant", "KPIs per participant",
                  "Note. One row per participant.", _table(out, "per_participant", columns=14, rows=30))]
    write_exhibits(out, ex)
    return out, ex


def _paragraphs(doc) -> list[str]:
    return [p.text for p in doc.paragraphs if p.text]


def test_docx_numbered_tables_and_figures_in_reading_order_apa_a4(report):
    import docx

    out, ex = report
    data = results_docx(out, ex, "A study")
    assert results_docx(out, ex, "A study") == data  # the same exhibits, the same bytes
    doc = docx.Document(io.BytesIO(data))
    texts = _paragraphs(doc)
    order = [t for t in texts if t.split(" ")[0] in ("Table", "Figure") and t.split(" ")[-1][-1:].isdigit()]
    assert order == ["Table 1", "Figure 1", "Table 2", "Table A1"]
    # label in bold, title in italics on the next line, the note with "Note." in italics
    i = texts.index("Table 1")
    assert texts[i + 1] == "Participant flow" and texts[i + 2] == "Note. N = 40."
    label = next(p for p in doc.paragraphs if p.text == "Table 1")
    title = next(p for p in doc.paragraphs if p.text == "Participant flow")
    note = next(p for p in doc.paragraphs if p.text == "Note. N = 40.")
    assert label.runs[0].bold and title.runs[0].italic and note.runs[0].italic and note.runs[0].text == "Note."
    assert texts.index("Appendix") > texts.index("Table 2") and texts.index("Appendix") < texts.index("Table A1")
    assert len(doc.tables) == 3 and len(doc.inline_shapes) == 1
    # cells as printed, bold kept
    t = doc.tables[0]
    assert [c.text for c in t.rows[0].cells] == ["Construct", "c1", "c2"]
    assert t.rows[1].cells[0].paragraphs[0].runs[0].bold and t.rows[2].cells[1].text == "0.000"
    # horizontal rules only: above and below the header, below the last row
    xml = t._tbl.xml
    assert xml.count("<w:top ") == 3 and xml.count("<w:bottom ") == 6 and "<w:left " not in xml \
        and "<w:insideV" not in xml
    # A4 portrait, the 14-column appendix table on a landscape page of its own
    first, *rest = doc.sections
    assert round(first.page_width.cm, 1) == 21.0 and round(first.page_height.cm, 1) == 29.7
    assert [round(s.page_width.cm, 1) for s in rest] == [29.7]


def test_column_widths_fit_the_page_and_wrap_the_widest_first():
    header = ["Label", "β", "p"]
    rows = [["A label long enough to need several lines in a narrow table " * 2, "0.123", ".001"]]
    natural = column_widths(header, rows, 10_000)
    narrow = column_widths(header, rows, 200)
    assert narrow[1:] == natural[1:]              # the numbers keep their width
    assert sum(narrow) == pytest.approx(200, abs=0.5) and narrow[0] < natural[0]


def test_latex_results_in_order_with_appendix_numbers(report):
    out, ex = report
    files = latex_files(out, ex)
    body = files["results.tex"].decode()
    assert body.index(r"\input{tables/flow}") < body.index("figures/savings") < body.index(r"\input{tables/bands}") \
        < body.index(r"\appendix") < body.index(r"\input{tables/per_participant}")
    assert r"\renewcommand{\thetable}{A\arabic{table}}" in body
    # the appendix on one-column pages: its long and wide tables are longtables, which two columns cannot hold
    assert body.index(r"\onecolumn") < body.index(r"\appendix")
    assert files["figures/savings.pdf"] == (out / "figures" / "savings.pdf").read_bytes()
    flow = files["tables/flow.tex"].decode()
    assert r"\caption{Participant flow}" in flow and r"\item \textit{Note.} N = 40." in flow
    # 14 columns: wider than a landscape page at \small, on landscape pages at \footnotesize
    assert files["tables/per_participant.tex"].decode().startswith("\\begin{landscape}\n\\begingroup\\footnotesize")


def _compile_example(out, ex, work) -> str:
    """results.tex with its preamble and figures, as shipped (latex/example.tex), compiled; the log."""
    from tests.latex_fit import compile_tex

    for rel, data in latex_files(out, ex).items():
        (work / rel).parent.mkdir(parents=True, exist_ok=True)
        (work / rel).write_bytes(data)
    return compile_tex(work, "example")


def test_latex_results_compile_in_a_two_column_article(report, tmp_path):
    """The shipped example compiles, nothing overfull."""
    from tests.latex_fit import misfits, pdflatex

    if pdflatex() is None:
        return
    out, ex = report
    assert misfits(_compile_example(out, ex, tmp_path / "latex")) == {"overfull": 0, "float too large": 0,
                                                                       "output loop": 0}


@pytest.fixture
def long_report(tmp_path):
    """A report shaped like the paper study's: figures narrow and wide in both parts, a main-text table taller than
    a page; in the appendix a table of 120 rows, one of 36 columns (wider than a landscape page), figures after them;
    notes with a file path in a table one column wide."""
    out = tmp_path / "long"
    path_note = "Note. Data: reconstructed answers fitted to the published tables (data/reference/README.md), " \
                "not the original participants' answers."
    ex = [Exhibit("table", "Table 1", "main", "Sample", "flow", "Participant flow", path_note, _table(out, "flow", 2)),
          *[Exhibit("figure", f"Figure {k}", "main", "Drives", f"main{k}", f"Figure {k} of the results", "",
                    _figure(out, f"main{k}", 3 if k % 2 else 6)) for k in range(1, 4)],
          Exhibit("table", "Table 2", "main", "Drives", "tall", "A main-text table taller than a page", "",
                  _table(out, "tall", 3, rows=70)),
          *[Exhibit("figure", f"Figure {k}", "main", "Drives", f"main{k}", f"Figure {k} of the results", "",
                    _figure(out, f"main{k}", 3 if k % 2 else 6)) for k in range(4, 7)],
          Exhibit("table", "Table A1", "appendix", "Drives", "per_drive", "KPIs per drive",
                  "Note. One row per drive.", _table(out, "per_drive", columns=8, rows=120)),
          Exhibit("table", "Table A2", "appendix", "Drives", "per_participant", "KPIs per participant",
                  path_note, _table(out, "per_participant", columns=36, rows=34)),
          *[Exhibit("figure", f"Figure A{k}", "appendix", "Simulation core", f"core{k}", f"Core figure {k}", "",
                    _figure(out, f"core{k}", 6)) for k in range(1, 9)],
          Exhibit("table", "Table A3", "appendix", "Reproduction", "audit", "Audit", path_note,
                  _table(out, "audit", columns=3, rows=10))]
    write_exhibits(out, ex)
    return out, ex


def test_latex_results_with_long_and_wide_appendix_tables_compile(long_report, tmp_path):
    """A table taller than a page and one wider than a landscape page, with figures before and after them: the
    example compiles (a float taller than the page jammed the float queue: "Output loop"), no float runs off its
    page ("Float too large"), nothing is wider than its room (a note's file path breaks at its slashes)."""
    from tests.latex_fit import misfits, overfull, pdflatex

    out, ex = long_report
    files = latex_files(out, ex)
    assert r"\begin{longtable}" in files["tables/per_drive.tex"].decode()
    assert files["tables/per_participant.tex"].decode().count(r"\begin{longtable}") > 1   # column groups
    body = files["results.tex"].decode()   # two columns around a main-text longtable, one for the appendix
    assert "\\onecolumn\n\\input{tables/tall}\n\\twocolumn\n" in body
    assert "\\clearpage\n\\input{tables/per_drive}\n" in body and body.count(r"\onecolumn") == 2
    if pdflatex() is None:
        return
    log = _compile_example(out, ex, tmp_path / "latex")
    assert misfits(log) == {"overfull": 0, "float too large": 0, "output loop": 0}, overfull(log)


def test_without_exhibits_json_the_document_order_is_used(report):
    out, ex = report
    (out / "exhibits.json").unlink()
    assert report_exhibits(out) == ([], "none")
    (out / "index.html").write_text(
        "<h1>A study</h1><h2 id=\"s\">Sample</h2><section id=\"tab-flow\">...</section>"
        "<h2>Drives</h2><figure id=\"fig-savings\"><img src=\"figures/savings.png\" alt=\"x\">"
        "<figcaption><strong>savings</strong>: Energy savings. · <a href=\"figures/savings.pdf\">pdf</a>"
        "</figcaption></figure><section id=\"tab-per_participant\">...</section>", encoding="utf-8")
    found, source = report_exhibits(out)
    assert source == "index.html"
    assert [(e.label, e.part, e.section, e.stem) for e in found] == [
        ("Table 1", "main", "Sample", "flow"), ("Figure 1", "main", "Drives", "savings"),
        ("Table A1", "appendix", "Drives", "per_participant")]   # 30 rows: an appendix table
    assert found[1].title == "Energy savings." and set(found[1].files) == {"png", "svg", "pdf"}
    assert found[0].title == "T" and found[0].note == "a note"
    assert found == exhibits_from_document(out)
    files = manuscript_files(out)
    assert "from the tables and figures of index.html" in files["README.md"].decode()
    assert {"results.docx", "latex/results.tex", "latex/preamble.tex", "latex/example.tex"} <= set(files)


def test_parse_markdown_table_round_trip():
    md = markdown_table(["a", "b|c"], [["1", "x|y"], ["**B**", ""]], "Title", ["n1", "n2"], title_style="bold",
                        notes_style="plain")
    assert parse_markdown_table(md) == ("Title", ["a", "b|c"], [["1", "x|y"], ["**B**", ""]], ["n1", "n2"])
    with pytest.raises(ValueError):
        parse_markdown_table("no table")

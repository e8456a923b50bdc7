"""The results as a Word document (python-docx): the numbered tables and figures of the results document in reading
order, main text then appendix, APA 7 style (docs/report.md, "Manuscript outputs").

Each table: "Table 1" in bold, its title in italics on the next line, the table with horizontal rules only (above
and below the header, below the last row), the note below ("Note." in italics). Each figure the same with the
picture in place of the table. A4 pages, 2.54 cm margins, Times New Roman; tables wider than nine columns on a
landscape page of their own. The same exhibits give the same bytes (fixed dates, sorted zip entries).
"""
from __future__ import annotations

import io
import re
import zipfile
from datetime import datetime
from pathlib import Path

from analysis.report.exhibits import Exhibit

_EPOCH = (1980, 1, 1, 0, 0, 0)
A4_CM = (21.0, 29.7)
MARGIN_CM = 2.54
LANDSCAPE_COLUMNS = 9  # a table with more columns than this gets a landscape page
# so does a table whose row labels would get less than this share of their width on a portrait page: they would wrap
# to a word a line (the hierarchical regression table's "Step 2: Dependent Variable - ATT"); a wrapped text column
# further right (a note, an explanation) reads well and stays portrait
LABEL_SHARE = 0.6
FIGURE_MAX_CM = 16.0   # the text width of an A4 page with 2.54 cm margins
_NUMERIC = re.compile(r"^[-−+]?(\d+\.?\d*|\.\d+)[*†‡]{0,3}$|^[<>≤≥] ?[-−]?(\d+\.?\d*|\.\d+)$")


def normalise_docx(data: bytes) -> bytes:
    """A DOCX (itself a zip) rewritten with sorted entries and fixed dates, so it is byte-identical per input."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name in sorted(src.namelist()):
            z.writestr(zipfile.ZipInfo(name, _EPOCH), src.read(name), zipfile.ZIP_DEFLATED)
    return out.getvalue()


def _rule(cell, edge: str) -> None:
    """A single black rule on one edge of a table cell."""
    from docx.oxml import OxmlElement
    from docx.oxml.ns import qn

    pr = cell._tc.get_or_add_tcPr()
    borders = pr.first_child_found_in("w:tcBorders")
    if borders is None:
        borders = OxmlElement("w:tcBorders")
        pr.append(borders)
    el = OxmlElement(f"w:{edge}")
    for k, v in (("val", "single"), ("sz", "6"), ("space", "0"), ("color", "000000")):
        el.set(qn(f"w:{k}"), v)
    borders.append(el)


def _repeat_header(row) -> None:
    """The header row repeats on every page a long table runs over."""
    from docx.oxml import OxmlElement
    from docx.oxml.ns import qn

    el = OxmlElement("w:tblHeader")
    el.set(qn("w:val"), "true")
    row._tr.get_or_add_trPr().append(el)


_BREAKS = str.maketrans({";": ";\u200b", "_": "_\u200b"})  # a zero-width space: where a long identifier may wrap


def _runs(paragraph, text: str) -> None:
    """`text` into a table cell's paragraph, Markdown `**bold**` as bold, breakable after ; and _."""
    bold = len(text) > 4 and text.startswith("**") and text.endswith("**")
    paragraph.add_run((text[2:-2] if bold else text).translate(_BREAKS)).bold = bold or None


def _note(doc, note: str) -> None:
    if not note:
        return
    p = doc.add_paragraph(style="Exhibit note")
    text = note[len("Note."):].lstrip() if note.startswith("Note.") else note
    p.add_run("Note.").italic = True
    p.add_run(" " + text)


def _label(doc, ex: Exhibit) -> None:
    doc.add_paragraph(style="Exhibit label").add_run(ex.label).bold = True
    doc.add_paragraph(style="Exhibit title").add_run(ex.title).italic = True


def _cell_width(text: str) -> float:
    """The width (pt) of a cell's text in Word: the LaTeX estimate (\\small, about 9 pt) scaled to the cells' 10 pt
    with 8 % to spare, plus Word's cell margins (0.19 cm on each side) and a little more."""
    from analysis.render import text_width_pt

    return 1.2 * text_width_pt(text) + 14.0


def natural_widths(header: list[str], rows: list[list[str]]) -> list[float]:
    """Each column's width (pt) with no cell wrapped (header words may wrap)."""
    return [max([_cell_width(r[j]) for r in rows] + [max(map(_cell_width, str(h).split() or [""]))])
            for j, h in enumerate(header)]


def column_widths(header: list[str], rows: list[list[str]], room_pt: float) -> list[float]:
    """Column widths (pt) of a table in `room_pt`: each column as wide as its widest cell (header words may wrap);
    when they do not fit, the widest columns wrap first (water-filling), none below its longest word."""
    width = _cell_width
    natural = natural_widths(header, rows)
    least = [max(width(w) for c in [h, *(r[j] for r in rows)] for w in re.split(r"\s+|(?<=[;_])", str(c)))
             for j, h in enumerate(header)]
    if sum(natural) <= room_pt:
        return natural
    lo, hi = 0.0, max(natural)
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if sum(min(n, max(m, mid)) for n, m in zip(natural, least)) <= room_pt else (lo, mid)
    return [min(n, max(m, lo)) for n, m in zip(natural, least)]


def _table(doc, header: list[str], rows: list[list[str]], room_pt: float) -> None:
    from docx.enum.text import WD_ALIGN_PARAGRAPH
    from docx.shared import Pt

    t = doc.add_table(rows=len(rows) + 1, cols=len(header))
    t.autofit = False
    widths = [Pt(w) for w in column_widths(header, rows, room_pt)]
    for col, w in zip(t.columns, widths):
        col.width = w
    cells = [r.cells for r in t.rows]  # once: cell look-ups by index walk the whole table
    for row_cells in cells:
        for cell, w in zip(row_cells, widths):
            cell.width = w  # Word reads the cells' widths, LibreOffice the grid's
    # the style by its id: python-docx's `paragraph.style = ...` scans every style of the document to see whether the
    # one given is the default, which made these look-ups most of the document's time (the same XML either way)
    cell_style = doc.styles["Exhibit cell"].style_id
    numeric = [j > 0 and all(_NUMERIC.match(r[j].strip().strip("*")) or r[j].strip() in ("", "–", "—")
                             for r in rows) for j in range(len(header))]
    for j, (cell, h) in enumerate(zip(cells[0], header)):
        p = cell.paragraphs[0]
        p._p.style = cell_style
        _runs(p, h)
        p.alignment = WD_ALIGN_PARAGRAPH.CENTER if j else WD_ALIGN_PARAGRAPH.LEFT
        _rule(cell, "top")
        _rule(cell, "bottom")
    _repeat_header(t.rows[0])
    for row_cells, row in zip(cells[1:], rows):
        for j, (cell, v) in enumerate(zip(row_cells, row)):
            p = cell.paragraphs[0]
            p._p.style = cell_style
            _runs(p, v)
            if numeric[j]:
                p.alignment = WD_ALIGN_PARAGRAPH.CENTER
    for cell in cells[-1]:
        _rule(cell, "bottom")


def _styles(doc) -> None:
    from docx.enum.style import WD_STYLE_TYPE
    from docx.shared import Pt

    normal = doc.styles["Normal"]
    normal.font.name, normal.font.size = "Times New Roman", Pt(12)
    from docx.oxml.ns import qn

    for name, size in (("Title", 16), ("Heading 1", 14), ("Heading 2", 12)):  # APA: bold, in the body's font
        st = doc.styles[name]
        st.font.name, st.font.size, st.font.bold, st.font.color.rgb = "Times New Roman", Pt(size), True, None
        fonts = st.element.rPr.rFonts
        for theme in ("w:asciiTheme", "w:hAnsiTheme", "w:eastAsiaTheme", "w:cstheme"):
            fonts.attrib.pop(qn(theme), None)  # a theme font would win over the name
    for name, size, before, after, keep in (("Exhibit label", 12, 12, 0, True), ("Exhibit title", 12, 0, 6, True),
                                            ("Exhibit note", 10, 4, 12, False), ("Exhibit cell", 10, 0, 0, False)):
        st = doc.styles.add_style(name, WD_STYLE_TYPE.PARAGRAPH)
        st.base_style = normal
        st.font.size = Pt(size)
        pf = st.paragraph_format
        pf.space_before, pf.space_after, pf.keep_with_next = Pt(before), Pt(after), keep


def _room_pt(landscape: bool) -> float:
    """The text width (pt) of an A4 page with the margins, portrait or landscape."""
    return (A4_CM[1 if landscape else 0] - 2 * MARGIN_CM) / 2.54 * 72.0


def _page(section, landscape: bool) -> None:
    from docx.enum.section import WD_ORIENT
    from docx.shared import Cm

    w, h = A4_CM if not landscape else A4_CM[::-1]
    section.orientation = WD_ORIENT.LANDSCAPE if landscape else WD_ORIENT.PORTRAIT
    section.page_width, section.page_height = Cm(w), Cm(h)
    section.left_margin = section.right_margin = section.top_margin = section.bottom_margin = Cm(MARGIN_CM)


def results_docx(out: Path, exhibits: list[Exhibit], title: str = "Results") -> bytes:
    """The exhibits of the report folder `out` as one DOCX: `title`, then each section's tables and figures in
    order (section names as headings), the appendix after its own heading."""
    import docx
    from docx.enum.section import WD_SECTION
    from docx.shared import Cm

    from analysis.render import parse_markdown_table

    out = Path(out)
    doc = docx.Document()
    # fixed document dates: the same exhibits give the same bytes
    doc.core_properties.created = doc.core_properties.modified = datetime(2000, 1, 1)
    doc.core_properties.author = doc.core_properties.last_modified_by = ""
    doc.core_properties.title = title
    _styles(doc)
    _page(doc.sections[0], landscape=False)
    doc.add_heading(title, level=0)
    part, section, landscape = "", "", False
    for ex in sorted(exhibits, key=lambda e: e.part == "appendix"):  # main text first (a stable sort)
        if ex.part != part:
            part = ex.part
            doc.add_heading("Appendix" if part == "appendix" else "Results", level=1)
            section = ""
        if ex.section and ex.section != section:
            section = ex.section
            doc.add_heading(section, level=2)
        if ex.kind == "table" and "md" in ex.files and (out / ex.files["md"]).exists():
            _, header, rows, _ = parse_markdown_table((out / ex.files["md"]).read_text(encoding="utf-8"))
            wide = (len(header) > LANDSCAPE_COLUMNS or column_widths(header, rows, _room_pt(landscape=False))[0]
                    < LABEL_SHARE * natural_widths(header, rows)[0])
            if wide != landscape:
                landscape = wide
                _page(doc.add_section(WD_SECTION.NEW_PAGE), landscape)
            _label(doc, ex)
            _table(doc, header, rows, _room_pt(wide))
            _note(doc, ex.note)
        elif ex.kind == "figure" and "png" in ex.files and (out / ex.files["png"]).exists():
            if landscape:
                landscape = False
                _page(doc.add_section(WD_SECTION.NEW_PAGE), landscape)
            _label(doc, ex)
            png = out / ex.files["png"]
            with open(png, "rb") as f:
                width_cm = int.from_bytes(f.read(24)[16:20], "big") / 150.0 * 2.54  # drawn at 150 dpi
            doc.add_picture(str(png), width=Cm(min(FIGURE_MAX_CM, width_cm)))
            doc.paragraphs[-1].paragraph_format.keep_with_next = bool(ex.note)
            _note(doc, ex.note)
    buf = io.BytesIO()
    doc.save(buf)
    return normalise_docx(buf.getvalue())

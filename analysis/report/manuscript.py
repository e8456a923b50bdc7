"""The report's numbered tables and figures as a manuscript's results: a Word document (`results.docx`) and LaTeX
(`latex/`), both in the reading order of the results document (docs/report.md, "Manuscript outputs").

The exhibits come from ``exhibits.json`` beside the document (:mod:`analysis.report.exhibits`). A report folder
without that list (one written before the document numbered its exhibits) gets one read from its ``index.html``
(:func:`exhibits_from_document`): every table and figure in the document's order, numbered in that order.
"""
from __future__ import annotations

import html
import re
from pathlib import Path

from analysis.render import parse_markdown_table
from analysis.report.exhibits import Exhibit, read_exhibits

MANUSCRIPT_DIR = "manuscript"
# sections of the document whose tables and figures are an appendix's in a list read from index.html
_APPENDIX_SECTIONS = {"Simulation core", "Reproduction", "Steps and files"}
_APPENDIX_ROWS, _APPENDIX_COLUMNS = 25, 9  # a table longer or wider than this is an appendix table there


# ---------------------------------------------------------------------------------------------- the exhibits
def _figure_files(out: Path, src: str) -> dict[str, str]:
    stem = Path(src).with_suffix("")
    return {ext: f"{stem.as_posix()}.{ext}" for ext in ("png", "svg", "pdf") if (out / f"{stem}.{ext}").exists()}


def exhibits_from_document(out: Path) -> list[Exhibit]:
    """The tables and figures of the report document `out/index.html` in its order, numbered in that order (Table 1,
    Figure 1 ...; Table A1 ... for the appendix: the simulation core, reproduction and files sections and tables of
    more than 25 rows or 9 columns), titles and notes from the tables' Markdown and the figures' captions."""
    out = Path(out)
    doc = (out / "index.html").read_text(encoding="utf-8")
    token = re.compile(r"<h2[^>]*>(?P<h>.*?)</h2>|<section id=\"tab-(?P<t>[^\"]+)\"|"
                       r"<figure[^>]*><img src=\"(?P<src>[^\"]+)\"[^>]*>\s*<figcaption>(?P<cap>.*?)</figcaption>", re.S)
    section, found = "", []
    for m in token.finditer(doc):
        if m.group("h") is not None:
            section = html.unescape(re.sub("<[^>]+>", "", m.group("h"))).strip()
        elif m.group("t") is not None:
            stem = html.unescape(m.group("t"))
            md = out / "tables" / f"{stem}.md"
            if not md.exists():
                continue
            title, header, rows, notes = parse_markdown_table(md.read_text(encoding="utf-8"))
            big = len(rows) > _APPENDIX_ROWS or len(header) > _APPENDIX_COLUMNS
            files = {ext: f"tables/{stem}.{ext}" for ext in ("md", "tex", "csv") if (out / "tables" /
                                                                                     f"{stem}.{ext}").exists()}
            found.append(("table", "appendix" if big or section in _APPENDIX_SECTIONS else "main", section, stem,
                          title or stem.replace("_", " "), " ".join(notes), files))
        else:
            src = html.unescape(m.group("src"))
            cap = html.unescape(re.sub("<[^>]+>", "", m.group("cap")))
            stem = Path(src).stem
            cap = cap.split(": ", 1)[1] if cap.startswith(f"{stem}: ") else cap
            cap = cap.split(" · pdf")[0].strip()
            found.append(("figure", "appendix" if section in _APPENDIX_SECTIONS else "main", section, stem, cap, "",
                          _figure_files(out, src)))
    counts: dict[tuple[str, str], int] = {}
    exhibits = []
    for kind, part, section, stem, title, note, files in sorted(found, key=lambda f: f[1] == "appendix"):
        n = counts[(kind, part)] = counts.get((kind, part), 0) + 1
        label = f"{kind.capitalize()} {'A' if part == 'appendix' else ''}{n}"
        exhibits.append(Exhibit(kind, label, part, section, stem, title, note, files))
    return exhibits


def report_exhibits(out: Path) -> tuple[list[Exhibit], str]:
    """The exhibits of a report folder and where they came from: ``exhibits.json`` (the document's own list) or,
    where it is absent, the list read from ``index.html`` (:func:`exhibits_from_document`)."""
    listed = read_exhibits(out)
    if listed:
        return listed, "exhibits.json"
    if (Path(out) / "index.html").exists():
        return exhibits_from_document(out), "index.html"
    return [], "none"


def exhibit_cells(out: Path, ex: Exhibit) -> tuple[list[str], list[list[str]]]:
    """Header and cells of a table exhibit as printed (from its Markdown)."""
    _, header, rows, _ = parse_markdown_table((Path(out) / ex.files["md"]).read_text(encoding="utf-8"))
    return header, rows


# ---------------------------------------------------------------------------------------------- LaTeX
PREAMBLE = r"""% the packages and settings the tables and figures of results.tex need
\usepackage[T1]{fontenc}
\usepackage{graphicx}
\usepackage[export]{adjustbox}  % max width/height of a figure: drawn size, shrunk to the line if wider
\usepackage{booktabs,threeparttable,longtable,array,makecell,rotating,pdflscape}
\usepackage{siunitx}
\sisetup{group-digits=false, table-align-text-after=false}
\extrafloats{200}  % results.tex is floats only: more than LaTeX's 18 may wait at once
"""
EXAMPLE = r"""\documentclass[twocolumn]{article}
\input{preamble}
\begin{document}
\input{results}
\end{document}
"""
#: a figure wider than this (inches, as drawn) spans both columns of a two-column article
WIDE_FIGURE_IN = 4.5


def _note(ex: Exhibit) -> list[str]:
    if not ex.note:
        return []
    return [ex.note if ex.note.startswith("Note.") else f"Note. {ex.note}"]


def latex_table_of(out: Path, ex: Exhibit) -> str:
    """A table exhibit as LaTeX (:func:`analysis.render.latex_table`) with its number's title and note."""
    from analysis.render import latex_table

    header, rows = exhibit_cells(out, ex)
    return latex_table(header, rows, ex.title, _note(ex), label=f"tab:{ex.stem}",
                       align="l" + "r" * (len(header) - 1))


def _figure_inches(path: Path) -> float:
    """Width of a PNG as drawn, in inches (at the 150 dpi :func:`analysis.render.save_figure` writes)."""
    with open(path, "rb") as f:
        head = f.read(24)
    return int.from_bytes(head[16:20], "big") / 150.0


def latex_figure_of(out: Path, ex: Exhibit) -> str:
    """A figure exhibit as LaTeX: `figure` (or `figure*` when drawn wider than :data:`WIDE_FIGURE_IN`) with the
    figure's PDF at its drawn size, shrunk to the line (and 80 % of the page's height) if larger, caption and note."""
    from analysis.render import tex_text

    png = Path(out) / ex.files["png"] if "png" in ex.files else None
    env = "figure*" if png is not None and png.exists() and _figure_inches(png) > WIDE_FIGURE_IN else "figure"
    return "\n".join([rf"\begin{{{env}}}[tbp]", r"\centering",
                      rf"\includegraphics[max width=\linewidth,max height=0.8\textheight]{{figures/{ex.stem}}}",
                      rf"\caption{{{tex_text(ex.title)}}}", rf"\label{{fig:{ex.stem}}}",
                      *([r"\par\smallskip\footnotesize\raggedright " + tex_text(_note(ex)[0]).replace(
                          "Note.", r"\textit{Note.}", 1)] if ex.note else []),
                      rf"\end{{{env}}}"]) + "\n"


def latex_files(out: Path, exhibits: list[Exhibit]) -> dict[str, bytes]:
    """The LaTeX of the results, by path under ``latex/``: ``tables/<stem>.tex`` per table, ``figures/<stem>.pdf``
    per figure, ``results.tex`` (the exhibits in reading order to ``\\input`` into a manuscript: the main text in
    the document's two columns, a table that breaks across pages on one-column pages of its own; then the appendix,
    on one-column pages, with A-numbers), ``preamble.tex`` (the packages they need) and ``example.tex`` (both in a
    two-column article)."""
    from analysis.render import tex_escape

    out = Path(out)
    files: dict[str, bytes] = {}
    body, part, section = [], "", ""
    for ex in sorted(exhibits, key=lambda e: e.part == "appendix"):  # main text first (a stable sort)
        if ex.part != part:
            part = ex.part
            if part == "appendix":
                # one column: long tables (longtable) need it, and an appendix of tables reads as one
                body += [r"\onecolumn", r"\appendix", r"\section*{Appendix}",
                         r"\setcounter{table}{0}\setcounter{figure}{0}",
                         r"\renewcommand{\thetable}{A\arabic{table}}\renewcommand{\thefigure}{A\arabic{figure}}"]
            section = ""
        if ex.section != section:
            section = ex.section
            body.append(rf"\subsection*{{{tex_escape(section)}}}")
        if ex.kind == "table":
            tex = latex_table_of(out, ex)
            files[f"tables/{ex.stem}.tex"] = tex.encode()
            put = rf"\input{{tables/{ex.stem}}}"
            if r"\begin{longtable}" not in tex:
                body.append(put)
            elif part == "appendix":  # after the floats before it, which come first in reading order
                body += [r"\clearpage", put]
            else:  # a longtable cannot be set in two columns
                body += [r"\onecolumn", put, r"\twocolumn"]
        else:
            if "pdf" in ex.files and (out / ex.files["pdf"]).exists():
                files[f"figures/{ex.stem}.pdf"] = (out / ex.files["pdf"]).read_bytes()
            body.append(latex_figure_of(out, ex).rstrip("\n"))
    files["results.tex"] = ("\n".join(body) + "\n").encode()
    files["preamble.tex"] = PREAMBLE.encode()
    files["example.tex"] = EXAMPLE.encode()
    return files


# ---------------------------------------------------------------------------------------------- both
def study_title(out: Path) -> str:
    """The study's title as the document shows it (its first heading), "Results" without one."""
    doc = Path(out) / "index.html"
    m = re.search(r"<h1[^>]*>(.*?)</h1>", doc.read_text(encoding="utf-8"), re.S) if doc.exists() else None
    return html.unescape(re.sub("<[^>]+>", "", m.group(1))).strip() if m else "Results"


def manuscript_files(out: Path) -> dict[str, bytes]:
    """The manuscript outputs of a report folder, by path under ``manuscript/``: ``results.docx`` and
    ``latex/...`` (:func:`latex_files`), and ``README.md`` saying where the exhibits came from."""
    from analysis.report.word import results_docx

    exhibits, source = report_exhibits(out)
    if not exhibits:
        return {}
    files = {"results.docx": results_docx(out, exhibits, study_title(out))}
    files.update({f"latex/{k}": v for k, v in latex_files(out, exhibits).items()})
    tables = sum(e.kind == "table" for e in exhibits)
    how = ("the results document's numbered list (exhibits.json)" if source == "exhibits.json" else
           "the tables and figures of index.html in its order, numbered in that order (the report has no "
           "exhibits.json)")
    files["README.md"] = (f"# Manuscript outputs\n\n{tables} tables and {len(exhibits) - tables} figures, from {how}."
                          "\n\n- `results.docx`: main text and appendix, numbered tables (title, note) and figures "
                          "(caption), A4, APA style.\n- `latex/results.tex`: the same in LaTeX to `\\input` into "
                          "a manuscript (the appendix on one-column pages: its long tables break across pages); "
                          "`latex/preamble.tex`: the packages it needs; `latex/example.tex`: both in a two-column "
                          "article.\n").encode()
    return files


def write_manuscript(out: Path) -> list[Path]:
    """Write :func:`manuscript_files` into ``<out>/manuscript/`` (replacing what was there); the paths written."""
    import shutil

    target = Path(out) / MANUSCRIPT_DIR
    files = manuscript_files(out)
    if target.exists():
        shutil.rmtree(target)
    paths = []
    for rel, data in sorted(files.items()):
        p = target / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
        paths.append(p)
    return paths

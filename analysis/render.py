"""Rendering shared by every analysis output: tables as Markdown / LaTeX booktabs, figures as PNG + SVG + PDF.

One Markdown table writer (:func:`markdown_table`), one booktabs writer (:func:`latex_table`), one LaTeX escape
(:func:`tex_escape`) and one cell formatter (:func:`fmt_cell`). Table modules build header and string cells in
their own (paper-shaped) layout and hand them to these writers.
"""
from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from numbers import Integral, Real
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from analysis import apa

# metadata without a creation date or tool version keeps an unchanged figure byte-identical between runs
PDF_METADATA = {"Creator": "pedas-study", "Producer": None, "CreationDate": None}
PNG_METADATA = {"Software": None}
SVG_METADATA = {"Creator": "pedas-study", "Date": None}
#: the formats every figure is written in: PNG for screens, SVG and PDF (vector) for a manuscript
FIGURE_FORMATS = ("png", "svg", "pdf")
# read when a figure is saved: TrueType (Type 42) fonts embedded in the PDF, as journals require (the default Type 3
# fonts are bitmaps to some checkers); a fixed salt for the ids of the SVG (random per process otherwise)
SAVE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42, "svg.hashsalt": "pedas-study", "svg.fonttype": "path"}


def pyplot():
    """`matplotlib.pyplot` on the non-interactive Agg backend, imported on first use (keeps CLI start-up light)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def bare_figure(figsize: tuple[float, float]):
    """A matplotlib Figure on the Agg canvas without pyplot, for a figure that is only saved: pyplot's import (its
    backend and figure-manager machinery) is a third of matplotlib's start-up. :func:`save_figure` writes it as it
    writes a pyplot figure, to the same bytes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, out_dir: str | Path, stem: str, dpi: int = 150) -> list[Path]:
    """Write a matplotlib figure as `<stem>.png`, `<stem>.svg` and `<stem>.pdf` into `out_dir` (PDF fonts embedded
    as TrueType, no dates in any of them: the same figure gives the same bytes); close it; return the three paths."""
    import matplotlib

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{stem}.{ext}" for ext in FIGURE_FORMATS]
    metadata = {"png": PNG_METADATA, "svg": SVG_METADATA, "pdf": PDF_METADATA}
    with matplotlib.rc_context(SAVE_RC):
        for path, ext in zip(paths, FIGURE_FORMATS):
            fig.savefig(path, dpi=dpi, bbox_inches="tight", metadata=metadata[ext])
    plt = sys.modules.get("matplotlib.pyplot")  # a figure of pyplot's is closed there; a bare one has nothing to close
    if plt is not None:
        plt.close(fig)
    return paths


# ---------------------------------------------------------------------------------------------- cells
def fmt_cell(x, digits: int = 3, missing: str = "") -> str:
    """One table cell as text: floats to `digits` decimals, integers as integers, booleans as yes/no,
    None / NaN / infinite as `missing`, anything else as `str(x)`.

    Examples
    --------
    >>> from analysis.render import fmt_cell
    >>> fmt_cell(0.12345), fmt_cell(3), fmt_cell(True), fmt_cell(float("nan")), fmt_cell("PU1")
    ('0.123', '3', 'yes', '', 'PU1')
    >>> fmt_cell(-0.25), fmt_cell(-0.0004)  # a true minus sign; a value that rounds to zero has none
    ('−0.250', '0.000')
    """
    if x is None or x is pd.NA or x is pd.NaT:
        return missing
    if isinstance(x, str):
        return x
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, Integral):
        return str(int(x))
    if isinstance(x, Real):
        return apa.num(x, digits) if math.isfinite(x) else missing
    return str(x)


def whole_numbers(col: pd.Series) -> bool:
    """Whether a float column holds whole numbers only (at least one): counts that a frame or a CSV read back holds
    as floats (a count column with a missing value, a pivot of counts). APA prints integer-valued quantities as
    integers.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.render import whole_numbers
    >>> whole_numbers(pd.Series([7.0, None, 0.0])), whole_numbers(pd.Series([7.0, 0.5])), whole_numbers(pd.Series([7]))
    (True, False, False)
    """
    if not pd.api.types.is_float_dtype(col):
        return False
    finite = col[np.isfinite(col)]
    return len(finite) > 0 and bool((finite == np.round(finite)).all())


def frame_cells(df: pd.DataFrame, digits: int = 3) -> tuple[list[str], list[list[str]]]:
    """Header and string cells of a tidy frame (floats to `digits` decimals, a float column of whole numbers as
    integers (:func:`whole_numbers`), missing as empty); a pair of lower and upper confidence limits
    (``ci_low``/``ci_high`` ...) becomes one ``[LL, UL]`` column in the lower one's place."""
    pairs = {low: (high, head) for low, high, head in apa.ci_columns(df.columns)}
    highs = {high for high, _ in pairs.values()}
    header, cols = [], []
    for c in df.columns:
        if c in highs:
            continue
        if c in pairs:
            high, head = pairs[c]
            header.append(head)
            cols.append([("" if fmt_cell(lo) == "" else apa.ci(lo, hi, digits))
                         for lo, hi in zip(df[c], df[high])])
        else:
            header.append(str(c))
            whole = whole_numbers(df[c])
            cols.append([fmt_cell(int(x) if whole and math.isfinite(x) else x, digits) for x in df[c]])
    return header, [list(r) for r in zip(*cols)] if cols else []


# ---------------------------------------------------------------------------------------------- Markdown
_MD_ALIGN = {"l": "---", "r": "---:", "c": ":---:"}


def md_cell(x) -> str:
    r"""A Markdown table cell: `|` escaped and line breaks flattened, so that a cell never splits the row.

    Examples
    --------
    >>> from analysis.render import md_cell
    >>> print(md_cell("a|b\nc"))
    a\|b c
    """
    return str(x).replace("|", r"\|").replace("\r", " ").replace("\n", " ")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "",
                   notes: Sequence[str] = (), align: str | None = None, title_style: str = "heading",
                   notes_style: str = "italic") -> str:
    """A GitHub-flavoured Markdown table with an optional title above and notes below.

    `align`: one letter l/r/c per column (as in LaTeX), default unaligned. `title_style`: "heading" (`### title`)
    or "bold" (`**title**`, the paper-table look). `notes_style`: "italic" (one `_note_` line each) or "plain"
    (verbatim, hard line breaks between notes; for notes that contain `*` marks).

    Examples
    --------
    >>> from analysis.render import markdown_table
    >>> print(markdown_table(["Item", "λ"], [["PU1", "0.737"], ["ATT1", "0.410*"]], "Loadings",
    ...                      ["* omitted item"], title_style="bold", notes_style="plain"), end="")
    **Loadings**
    <BLANKLINE>
    | Item | λ |
    |---|---|
    | PU1 | .737 |
    | ATT1 | .410* |
    <BLANKLINE>
    * omitted item
    """
    if align is not None and len(align) != len(header):
        raise ValueError(f"align {align!r} has {len(align)} letters for {len(header)} columns")
    header, rows = apa.table_cells(header, rows)
    out = []
    if title:
        out += [f"**{title}**" if title_style == "bold" else f"### {title}", ""]
    out.append("| " + " | ".join(md_cell(h) for h in header) + " |")
    out.append("|" + "|".join(_MD_ALIGN[a] for a in align or "l" * len(header)) + "|")
    out += ["| " + " | ".join(md_cell(c) for c in r) + " |" for r in rows]
    if notes:
        if notes_style == "plain":
            out += [""] + [f"{n}  " for n in notes[:-1]] + [notes[-1]]
        else:
            out += [""] + [f"_{n}_" for n in notes]
    return "\n".join(out) + "\n"


def parse_markdown_table(text: str) -> tuple[str, list[str], list[list[str]], list[str]]:
    r"""(title, header, rows, notes) of a table written by :func:`analysis.render.markdown_table`: the title line
    above (`**title**` or `### title`), the first pipe table, the lines below it as notes (`_note_` unwrapped);
    escaped pipes restored.

    Examples
    --------
    >>> from analysis.render import parse_markdown_table
    >>> parse_markdown_table("**T**\n\n| a | b |\n|---|---:|\n| 1 | x\\|y |\n\n_n1_\n* p < .05  \n")
    ('T', ['a', 'b'], [['1', 'x|y']], ['n1', '* p < .05'])
    """
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.startswith("|")), None)
    if first is None:
        raise ValueError("no Markdown table in the text")
    last = first
    while last + 1 < len(lines) and lines[last + 1].startswith("|"):
        last += 1
    title = next((ln.strip() for ln in lines[:first] if ln.strip()), "")
    title = title[2:-2] if title.startswith("**") and title.endswith("**") else title.lstrip("#").strip()

    def cells(line: str) -> list[str]:
        parts = re.split(r"(?<!\\)\|", line.strip())[1:-1]
        return [p.strip().replace("\\|", "|") for p in parts]

    header = cells(lines[first])
    rows = [cells(ln) for ln in lines[first + 2:last + 1]]
    notes = []
    for ln in lines[last + 1:]:
        ln = ln.strip()
        if ln:
            notes.append(ln[1:-1] if len(ln) > 2 and ln[0] == ln[-1] == "_" else ln)
    return title, header, rows, notes


# ---------------------------------------------------------------------------------------------- LaTeX
_TEX_SPECIALS = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                 "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\^{}"}
_TEX_SPECIALS_RE = re.compile("|".join(re.escape(k) for k in _TEX_SPECIALS))
# symbols the tables print, as LaTeX that compiles without a Unicode font set-up
TEX_SYMBOLS = {"λ": r"$\lambda$", "α": r"$\alpha$", "β": r"$\beta$", "Δ": r"$\Delta$", "Σ": r"$\Sigma$",
               "²": r"$^2$", "¹": r"$^1$", "⁻": r"$^-$", "†": r"$^\dagger$", "‡": r"$^\ddagger$", "–": "--",
               "->": r"$\rightarrow$",
               "√": r"$\surd$", "·": r"$\cdot$", "≈": r"$\approx$", "±": r"$\pm$", "≤": r"$\leq$", "≥": r"$\geq$",
               "×": r"$\times$", "−": r"$-$", "ω": r"$\omega$", "χ": r"$\chi$", "η": r"$\eta$",
               "ε": r"$\varepsilon$", "³": r"$^3$"}


def tex_escape(s: str) -> str:
    r"""Plain text -> LaTeX: special characters escaped (in one pass), then the symbols of :data:`TEX_SYMBOLS`.

    Examples
    --------
    >>> from analysis.render import tex_escape
    >>> print(tex_escape("R² & β_1 (50%)"))
    R$^2$ \& $\beta$\_1 (50\%)
    """
    s = _TEX_SPECIALS_RE.sub(lambda m: _TEX_SPECIALS[m.group(0)], str(s))
    for k, v in TEX_SYMBOLS.items():
        s = s.replace(k, v)
    return s


def tex_cell(c) -> str:
    """A cell for LaTeX: Markdown `**bold**` -> `\\textbf{...}`, everything else escaped by :func:`tex_escape`."""
    c = str(c)
    if len(c) > 4 and c.startswith("**") and c.endswith("**"):
        return rf"\textbf{{{tex_escape(c[2:-2])}}}"
    return tex_escape(c)


# ---------------------------------------------------------------------------------------------- LaTeX layout
#: the page of a two-column article (10 pt, `\documentclass[twocolumn]{article}`), the strictest common journal
#: layout, in TeX points: one column, both columns (`table*`), a landscape page (`sidewaystable*`)
COLUMN_PT, TEXT_PT, PAGE_PT = 229.5, 469.0, 550.0
#: the packages a table of :func:`latex_table` needs in the preamble
LATEX_PACKAGES = ("booktabs", "threeparttable", "siunitx", "array", "makecell", "rotating", "adjustbox")
_TAB_SEP_PT = 12.0  # 2 \tabcolsep
_WRAP_MIN_PT = 80.0  # a wrapped text column keeps at least this (or its widest cell), so that labels stay readable
# character widths at \small (T1 Computer Modern, measured with pdflatex), in points; any other character (λ, β, †,
# the minus sign) counts 5.5; bold text is 15 % wider. 3 % on top, so that an estimate errs towards wrapping
_CHAR_PT = {ch: pt for chars, pt in (("il!',.:;[]`|", 2.5), ("fj- ", 3.0), ("rstI()", 3.5), ("cez", 4.0),
                                     ("0123456789ago\"$*/?\\^{}", 4.5), ("bdhknpquvxyJS", 5.0), ("FLZ~", 6.0),
                                     ("wBCEPT", 6.5), ("ADHKNOQRUVXY&+<=>@_", 7.0), ("mG#%", 7.5), ("MW", 8.5))
            for ch in chars}
_BREAK_RE = re.compile(r"(?<=[;_])")  # where a wrapped cell may also break: after ; and _
_NUMBER_RE = re.compile(r"^(?P<sign>[-−+]?)(?P<int>\d*)(?:\.(?P<dec>\d+))?(?P<post>[*†‡]{0,3})$")


def text_width_pt(s: str) -> float:
    """Estimated width of a cell's text at \\small, in points (`**bold**` as bold)."""
    bold = len(s) > 4 and s.startswith("**") and s.endswith("**")
    return 1.03 * (1.15 if bold else 1.0) * sum(_CHAR_PT.get(ch, 5.5) for ch in (s[2:-2] if bold else s))


def _plain(cell: str) -> str:
    c = str(cell)
    return c[2:-2] if len(c) > 4 and c.startswith("**") and c.endswith("**") else c


def _number(cell: str):
    m = _NUMBER_RE.match(cell.strip())
    return m if m and (m.group("int") or m.group("dec")) else None


def _two_lines(header: str) -> tuple[str, ...]:
    """A header broken at the space nearest its middle (one line when it has no space)."""
    words = header.split(" ")
    if len(words) < 2:
        return (header,)
    cut = min(range(1, len(words)), key=lambda k: abs(len(" ".join(words[:k])) - len(" ".join(words[k:]))))
    return " ".join(words[:cut]), " ".join(words[cut:])


@dataclass(frozen=True)
class _Column:
    numeric: bool
    letter: str          # l / c / r for a text column
    natural: float       # width on one line, header unbroken (pt, with the column separation)
    narrow: float        # the least width: header on two lines, text wrapped at its longest word
    fmt: str = ""        # siunitx table-format of a numeric column
    zero: bool = True    # whether numbers below 1 keep their leading zero as written
    post: str = ""       # the longest run of marks after a number (*, †), space kept for it


def _column(header: str, cells: list[str], letter: str) -> _Column:
    widths = [text_width_pt(c.strip()) for c in cells]
    cells = [_plain(c).strip() for c in cells]
    filled = [c for c in cells if c not in ("", "–", "—", "-")]
    nums = [_number(c) for c in filled]
    head_one = text_width_pt(header)
    head_two = max(text_width_pt(x) for x in _two_lines(header))
    if filled and all(nums) and letter != "l":
        ints = max(len(m.group("int")) or 1 for m in nums)
        decs = max(len(m.group("dec") or "") for m in nums)
        signed = any(m.group("sign") in ("-", "−") for m in nums)
        post = max(len(m.group("post")) for m in nums)  # a dagger is narrower than a digit: counted as one
        body = text_width_pt("0" * (ints + decs + (1 if decs else 0) + (1 if signed else 0) + post))
        zero = not any(m.group("int") == "" for m in nums)
        fmt = f"{'-' if signed else ''}{ints}.{decs}" if decs else f"{'-' if signed else ''}{ints}"
        marks = max((m.group("post") for m in nums), key=len)
        return _Column(True, "S", max(head_one, body) + _TAB_SEP_PT, max(head_two, body) + _TAB_SEP_PT, fmt, zero,
                       marks)
    body = max(widths, default=0.0)
    word = max((text_width_pt(w) for c in [*cells, header] for w in _BREAK_RE.sub(" ", c).split()), default=0.0)
    # text reads from the left (APA); a column asked to be centred stays so
    return _Column(False, "l" if letter == "r" else letter, max(head_one, body) + _TAB_SEP_PT,
                   max(min(body, _WRAP_MIN_PT), word, min(head_two, head_one)) + _TAB_SEP_PT)


@dataclass(frozen=True)
class TableLayout:
    """Where a table goes and how wide its columns are: env "table" (one column), "table*" (both columns) or
    "sidewaystable*" (a landscape page); `widths`: pt per column (None: the column's natural width); `scaled`: the
    table is wider than a landscape page even wrapped and is shrunk to fit it; `split_header`: headers on two
    lines."""

    env: str
    widths: tuple[float | None, ...]
    scaled: bool = False
    split_header: bool = False


def table_layout(columns: Sequence[_Column]) -> TableLayout:
    """The narrowest place a table fits in (one column, both columns, a landscape page), wrapping its widest text
    columns (water-filling: the widest first, down to their longest word) and breaking long headers when needed."""
    natural = sum(c.natural for c in columns)
    for env, room in (("table", COLUMN_PT), ("table*", TEXT_PT), ("sidewaystable*", PAGE_PT)):
        if natural <= room:
            return TableLayout(env, (None,) * len(columns))
        if sum(c.narrow for c in columns) > room:
            continue
        fixed = sum(c.narrow for c in columns if c.numeric)
        text = [c for c in columns if not c.numeric]
        if not text:  # numbers only: their headers on two lines are what makes the table fit
            return TableLayout(env, (None,) * len(columns), split_header=True)
        lo, hi = 0.0, max(c.natural for c in text)  # the cap on text widths: largest with the table in the room
        for _ in range(40):
            mid = (lo + hi) / 2
            if fixed + sum(min(c.natural, max(c.narrow, mid)) for c in text) <= room:
                lo = mid
            else:
                hi = mid
        widths = tuple(None if c.numeric else min(c.natural, max(c.narrow, lo)) for c in columns)
        return TableLayout(env, widths, split_header=True)
    return TableLayout("sidewaystable*", tuple(None if c.numeric else c.narrow for c in columns), scaled=True,
                       split_header=True)


def _colspec(col: _Column, width: float | None) -> str:
    if col.numeric:
        zero = "" if col.zero else ", print-zero-integer=false"
        post = f", table-space-text-post={{{tex_escape(col.post)}}}" if col.post else ""
        return f"S[table-format={col.fmt}{zero}{post}]"
    if width is not None and width < col.natural - 0.01:
        return rf">{{\raggedright\arraybackslash}}p{{{width - _TAB_SEP_PT:.1f}pt}}"
    return col.letter


def _tex_header(h: str, col: _Column, split: bool) -> str:
    lines = _two_lines(h) if split else (h,)
    body = tex_cell(lines[0]) if len(lines) == 1 else r"\makecell[b]{" + r" \\ ".join(map(tex_cell, lines)) + "}"
    return "{" + body + "}" if col.numeric else body


def _tex_number(cell: str) -> str:
    c = _plain(cell).strip()
    m = _number(c)
    if m is None:
        return "{" + tex_cell(cell) + "}" if c else ""
    num = m.group("sign").replace("−", "-") + (m.group("int") or "") + (f".{m.group('dec')}" if m.group("dec")
                                                                           else "")
    if str(cell).startswith("**"):  # a bold number stands as text: siunitx would drop its weight
        return "{" + tex_cell(cell) + "}"
    post = tex_escape(m.group("post")) if m.group("post") else ""
    return num + (f"{{{post}}}" if post else "")


def latex_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "", notes: Sequence[str] = (),
                label: str = "", align: str | None = None) -> str:
    r"""A table for a journal: `threeparttable` with the caption above, booktabs rules, the notes left-aligned
    below (a first note "Note. ..." with "Note." in italics); numeric columns as `siunitx` S columns aligned on the
    decimal point (a leading zero printed as written: none where the column has none, APA); the smallest place it
    fits in (:func:`table_layout`): `table` in one column of a two-column article, `table*` across both, or
    `sidewaystable*` on a landscape page, wrapping wide text columns; a table too wide even for that is shrunk
    (`adjustbox`). `align` (l/c/r per column, default l then r) keeps a column given as `l` as text; a text column
    given as `r` is set left. Needs the
    packages of :data:`LATEX_PACKAGES`.

    Examples
    --------
    >>> from analysis.render import latex_table
    >>> print(latex_table(["Item", "λ"], [["**PU**", ""], ["PU1", ".737"]], "Loadings"), end="")
    \begin{table}[tbp]
    \centering\small
    \begin{threeparttable}
    \caption{Loadings}
    \begin{tabular}{lS[table-format=1.3, print-zero-integer=false]}
    \toprule
    Item & {$\lambda$} \\
    \midrule
    \textbf{PU} &  \\
    PU1 & .737 \\
    \bottomrule
    \end{tabular}
    \end{threeparttable}
    \end{table}
    """
    align = align or "l" + "r" * (len(header) - 1)
    header, rows = apa.table_cells(header, rows)
    if len(align) != len(header):
        raise ValueError(f"align {align!r} has {len(align)} letters for {len(header)} columns")
    columns = [_column(str(h), [str(r[j]) for r in rows], align[j]) for j, h in enumerate(header)]
    lay = table_layout(columns)
    out = [rf"\begin{{{lay.env}}}[{'p' if lay.env.startswith('sideways') else 'tbp'}]", r"\centering\small"]
    # shrunk as a whole: threeparttable measures its tabular, which it cannot do inside a box of its own
    out += [r"\begin{adjustbox}{max width=\linewidth}"] if lay.scaled else []
    out.append(r"\begin{threeparttable}")
    if title:
        out.append(rf"\caption{{{tex_escape(title)}}}")
    if label:
        out.append(rf"\label{{{label}}}")
    spec = "".join(_colspec(c, w) for c, w in zip(columns, lay.widths))
    out += [rf"\begin{{tabular}}{{{spec}}}", r"\toprule",
            " & ".join(_tex_header(str(h), c, lay.split_header) for h, c in zip(header, columns)) + r" \\",
            r"\midrule"]
    wrapped = [w is not None and w < c.natural - 0.01 for c, w in zip(columns, lay.widths)]

    def text(x, wrap: bool) -> str:
        return tex_cell(x).replace(";", r";\allowbreak ").replace(r"\_", r"\_\allowbreak ") if wrap else tex_cell(x)

    out += [" & ".join(_tex_number(x) if c.numeric else text(x, w) for x, c, w in zip(r, columns, wrapped))
            + r" \\" for r in rows]
    out += [r"\bottomrule", r"\end{tabular}"]
    if notes:
        items = [tex_escape(n) for n in notes]
        if items[0].startswith("Note."):
            items[0] = r"\textit{Note.}" + items[0][len("Note."):]
        out += [r"\begin{tablenotes}[flushleft]\footnotesize", *(rf"\item {n}" for n in items), r"\end{tablenotes}"]
    out += [r"\end{threeparttable}", *([r"\end{adjustbox}"] if lay.scaled else []), rf"\end{{{lay.env}}}"]
    return "\n".join(out) + "\n"


def write_table(df: pd.DataFrame, out_dir: str | Path, stem: str, title: str = "", notes: Sequence[str] = (),
                digits: int = 3) -> list[Path]:
    """Write a tidy frame as `<stem>.csv` (full precision), `.md` and `.tex` (booktabs); return the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    header, rows = frame_cells(df, digits)
    paths = [out / f"{stem}.csv", out / f"{stem}.md", out / f"{stem}.tex"]
    df.to_csv(paths[0], index=False)
    paths[1].write_text(markdown_table(header, rows, title, notes), encoding="utf-8")
    paths[2].write_text(latex_table(header, rows, title, notes, label=f"tab:{stem}"), encoding="utf-8")
    return paths

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


_PATH_RE = re.compile(r"\S*/\S*")
_EXTENSION_RE = re.compile(r"\.[A-Za-z]\w*[^\w]*$")


def tex_breakable(tex: str) -> str:
    r"""Escaped LaTeX text with places to break a line where it has no space: after each ``/`` of a file path (a
    word with two slashes or ending in a file name's extension; ``m/s`` stays whole) and after each ``\_`` of an
    identifier. For running text in a narrow measure: notes, captions, wrapped cells.

    Examples
    --------
    >>> from analysis.render import tex_breakable, tex_escape
    >>> print(tex_breakable(tex_escape("see (data/reference/README.md), in m/s, per_participant")))
    see (data/\allowbreak reference/\allowbreak README.md), in m/s, per\_\allowbreak participant
    """
    def path(m: re.Match) -> str:
        word = m.group(0)
        return word.replace("/", "/\\allowbreak ") if word.count("/") > 1 or _EXTENSION_RE.search(word) else word

    return _PATH_RE.sub(path, tex).replace(r"\_", "\\_\\allowbreak ")


def tex_text(s: str) -> str:
    """Plain running text (a caption, a note) as LaTeX: :func:`tex_escape`, then :func:`tex_breakable`."""
    return tex_breakable(tex_escape(s))


# ---------------------------------------------------------------------------------------------- LaTeX layout
#: the page of a two-column article (10 pt, `\documentclass[twocolumn]{article}`, US letter), the strictest common
#: journal layout, in TeX points: one column, both columns (`table*`; also the line of the one-column pages a
#: `longtable` needs) and the text height (the most a float may take; the line of a landscape page, whose height
#: is the text width)
COLUMN_PT, TEXT_PT, PAGE_PT = 229.5, 469.0, 550.0
#: the packages a table of :func:`latex_table` needs in the preamble
LATEX_PACKAGES = ("booktabs", "threeparttable", "longtable", "siunitx", "array", "makecell", "rotating",
                  "pdflscape")


@dataclass(frozen=True)
class TableStyle:
    """How densely a table is set: font size, its character widths relative to \\small (\\footnotesize digits are
    0.919 of \\small's, measured with pdflatex), baseline skip (pt), the space between columns (2 \\tabcolsep, pt)
    and the least width of a wrapped text column (pt; its longest word in any case)."""

    size: str
    scale: float
    skip: float
    sep: float
    wrap_min: float


#: the styles a table is tried in, loosest first: the body text's \small, \footnotesize, \footnotesize with half
#: the space between columns and text columns down to their longest word
SMALL = TableStyle("small", 1.0, 11.0, 12.0, 80.0)
FOOTNOTE = TableStyle("footnotesize", 0.92, 9.5, 12.0, 80.0 * 0.92)
TIGHT = TableStyle("footnotesize", 0.92, 9.5, 6.0, 0.0)
#: the share of a page a float may take by the estimate of its height (:func:`table_height`, within 0-6 % above
#: the typeset height of the paper study's 37 float tables); a taller table is set as a `longtable`, which breaks
#: across pages (a float cannot: it would run off the page or jam the float queue)
_FLOAT_SHARE = 0.93
_RULES_PT = 8.0  # booktabs' three rules with the space around them
_CAPTION_SKIP_PT = 10.0  # \abovecaptionskip
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


def _lines(text: str, width: float, scale: float = 1.0) -> int:
    """Lines a text takes in a measure `width` pt wide (at `scale` times \\small), broken greedily at its spaces and
    after ; and _."""
    space = text_width_pt(" ") * scale
    lines, used = 1, 0.0
    for word in _BREAK_RE.sub(" ", _plain(text)).split():
        w = text_width_pt(word) * scale
        if used and used + space + w > width:
            lines, used = lines + 1, w
        else:
            used += (space if used else 0.0) + w
    return lines


@dataclass(frozen=True)
class _Column:
    numeric: bool
    letter: str          # l / c / r for a text column
    natural: float       # width on one line, header unbroken (pt, with the column separation)
    narrow: float        # the least width: header on two lines, text wrapped at its longest word
    fmt: str = ""        # siunitx table-format of a numeric column
    zero: bool = True    # whether numbers below 1 keep their leading zero as written
    post: str = ""       # the longest run of marks after a number (*, †), space kept for it
    sep: float = SMALL.sep  # the space between columns counted in the widths


def _column(header: str, cells: list[str], letter: str, style: TableStyle = SMALL) -> _Column:
    scale, sep = style.scale, style.sep
    widths = [text_width_pt(c.strip()) * scale for c in cells]
    cells = [_plain(c).strip() for c in cells]
    filled = [c for c in cells if c not in ("", "–", "—", "-")]
    nums = [_number(c) for c in filled]
    head_one = text_width_pt(header) * scale
    head_two = max(text_width_pt(x) for x in _two_lines(header)) * scale
    if filled and all(nums) and letter != "l":
        ints = max(len(m.group("int")) or 1 for m in nums)
        decs = max(len(m.group("dec") or "") for m in nums)
        signed = any(m.group("sign") in ("-", "−") for m in nums)
        post = max(len(m.group("post")) for m in nums)  # a dagger is narrower than a digit: counted as one
        body = text_width_pt("0" * (ints + decs + (1 if decs else 0) + (1 if signed else 0) + post)) * scale
        zero = not any(m.group("int") == "" for m in nums)
        fmt = f"{'-' if signed else ''}{ints}.{decs}" if decs else f"{'-' if signed else ''}{ints}"
        marks = max((m.group("post") for m in nums), key=len)
        return _Column(True, "S", max(head_one, body) + sep, max(head_two, body) + sep, fmt, zero, marks, sep)
    body = max(widths, default=0.0)
    word = max((text_width_pt(w) * scale for c in [*cells, header] for w in _BREAK_RE.sub(" ", c).split()),
               default=0.0)
    # text reads from the left (APA); a column asked to be centred stays so
    return _Column(False, "l" if letter == "r" else letter, max(head_one, body) + sep,
                   max(min(body, style.wrap_min), word, min(head_two, head_one)) + sep, sep=sep)


#: a part of a table: its columns (indices), their widths (pt; None: the column's natural width) and whether the
#: headers are on two lines
Part = tuple[tuple[int, ...], tuple[float | None, ...], bool]


@dataclass(frozen=True)
class TableLayout:
    """How a table is set. `env`: a float, "table" (one column), "table*" (both columns) or "sidewaystable*" (a
    landscape page), or "longtable" (breaks across pages, one-column pages; `landscape`: on landscape pages).
    `columns`: every column in `style`; `parts`: the column groups set one after the other (one part with every
    column, unless the table is wider than a landscape page even wrapped)."""

    env: str
    columns: tuple[_Column, ...]
    parts: tuple[Part, ...]
    landscape: bool = False
    style: TableStyle = SMALL


def _fit(columns: Sequence[_Column], room: float) -> tuple[tuple[float | None, ...], bool] | None:
    """Column widths (None: natural) and whether the headers go on two lines, for the table to fit `room` pt,
    wrapping its widest text columns (water-filling: the widest first, down to their longest word); None when it
    does not fit even so."""
    if sum(c.natural for c in columns) <= room:
        return (None,) * len(columns), False
    if sum(c.narrow for c in columns) > room:
        return None
    fixed = sum(c.narrow for c in columns if c.numeric)
    text = [c for c in columns if not c.numeric]
    if not text:  # numbers only: their headers on two lines are what makes the table fit
        return (None,) * len(columns), True
    lo, hi = 0.0, max(c.natural for c in text)  # the cap on text widths: largest with the table in the room
    for _ in range(40):
        mid = (lo + hi) / 2
        if fixed + sum(min(c.natural, max(c.narrow, mid)) for c in text) <= room:
            lo = mid
        else:
            hi = mid
    return tuple(None if c.numeric else min(c.natural, max(c.narrow, lo)) for c in columns), True


def _wrapped(col: _Column, width: float | None) -> bool:
    return width is not None and not col.numeric and width < col.natural - 0.01


def table_width(columns: Sequence[_Column], widths: Sequence[float | None]) -> float:
    """Estimated width of a table (pt) with these column widths."""
    return sum(c.natural if w is None else w for c, w in zip(columns, widths))


def table_height(columns: Sequence[_Column], widths: Sequence[float | None], split: bool, header: Sequence[str],
                 rows: Sequence[Sequence[str]], title: str = "", notes: Sequence[str] = (), style: TableStyle = SMALL
                 ) -> float:
    """Estimated height of a table (pt): the caption ("Table A10: " and the title, wrapped to the table's width),
    the header (one or two lines), each row as many lines as its most wrapped cell, the rules, the notes at
    \\footnotesize."""
    width = table_width(columns, widths)
    lines = 2 if split and any(" " in str(h) for h in header) else 1
    lines += sum(max([1] + [_lines(str(x), w - c.sep, style.scale) for x, c, w in zip(r, columns, widths)
                            if _wrapped(c, w)]) for r in rows)
    caption = _lines(f"Table A10: {title}", width, style.scale) * style.skip + _CAPTION_SKIP_PT if title else 0.0
    note = sum(_lines(n, width, FOOTNOTE.scale) for n in notes) * FOOTNOTE.skip
    return lines * style.skip + caption + note + _RULES_PT


def _parts(columns: Sequence[_Column], room: float) -> tuple[Part, ...]:
    """A table too wide for `room` even wrapped, as column groups that fit it: its leading text columns (the row
    labels) in each, the others in order, as few groups as fit and of about equal count."""
    keys = []
    for j, c in enumerate(columns[:-1]):
        if c.numeric:
            break
        keys.append(j)
    if not keys or _fit([columns[k] for k in keys], room / 2) is None:
        keys = [0]
    rest = [j for j in range(len(columns)) if j not in keys]

    def fit(group):
        return _fit([columns[j] for j in (*keys, *group)], room)

    greedy: list[list[int]] = [[]]
    for j in rest:
        if greedy[-1] and fit([*greedy[-1], j]) is None:
            greedy.append([])
        greedy[-1].append(j)
    k = len(greedy)
    even = [rest[i * len(rest) // k:(i + 1) * len(rest) // k] for i in range(k)]
    groups = even if all(fit(g) is not None for g in even) else greedy
    parts = []
    for g in groups:
        idx = (*keys, *g)
        # a column wider than the room on its own: as narrow as it gets
        widths, split = fit(g) or (tuple(columns[j].narrow for j in idx), True)
        parts.append((idx, widths, split))
    return tuple(parts)


def table_layout(header: Sequence[str], rows: Sequence[Sequence[str]], align: str | None = None, title: str = "",
                 notes: Sequence[str] = ()) -> TableLayout:
    """Where a table goes: the narrowest float it fits in (one column, both columns, a landscape page), wrapping its
    widest text columns and breaking long headers when needed, if it is no taller than 93 % of that page
    (:func:`table_height`); otherwise a `longtable` (one-column pages) at the text width, else on landscape pages
    (:data:`SMALL`), else on landscape pages in :data:`FOOTNOTE`, then :data:`TIGHT`, else in column groups
    (:func:`_parts`) on landscape pages in :data:`TIGHT`."""
    align = align or "l" + "r" * (len(header) - 1)

    def columns(style: TableStyle) -> tuple[_Column, ...]:
        return tuple(_column(str(h), [str(r[j]) for r in rows], align[j], style) for j, h in enumerate(header))

    small, every = columns(SMALL), tuple(range(len(header)))
    for env, room, height in (("table", COLUMN_PT, PAGE_PT), ("table*", TEXT_PT, PAGE_PT),
                              ("sidewaystable*", PAGE_PT, TEXT_PT)):
        fit = _fit(small, room)
        if fit is None:
            continue
        if table_height(small, *fit, header, rows, title, notes) <= _FLOAT_SHARE * height:
            return TableLayout(env, small, ((every, *fit),))
        break  # too tall for a page: a longtable (a wider place is no taller)
    for style, landscape in ((SMALL, False), (SMALL, True), (FOOTNOTE, True), (TIGHT, True)):
        cols = small if style == SMALL else columns(style)
        fit = _fit(cols, PAGE_PT if landscape else TEXT_PT)
        if fit is not None:
            return TableLayout("longtable", cols, ((every, *fit),), landscape, style)
    return TableLayout("longtable", cols, _parts(cols, PAGE_PT), True, TIGHT)


def _colspec(col: _Column, width: float | None) -> str:
    if col.numeric:
        zero = "" if col.zero else ", print-zero-integer=false"
        post = f", table-space-text-post={{{tex_escape(col.post)}}}" if col.post else ""
        return f"S[table-format={col.fmt}{zero}{post}]"
    if _wrapped(col, width):
        return rf">{{\raggedright\arraybackslash}}p{{{width - col.sep:.1f}pt}}"
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


def _tex_cell(x, col: _Column, width: float | None) -> str:
    if col.numeric:
        return _tex_number(x)
    return tex_breakable(tex_cell(x)).replace(";", r";\allowbreak ") if _wrapped(col, width) else tex_cell(x)


def _tabular(lay: TableLayout, part: Part, header: Sequence[str], rows: Sequence[Sequence[str]]
             ) -> tuple[str, str, list[str]]:
    """Column specification, header row and body rows of one part of a table."""
    idx, widths, split = part
    cols = [lay.columns[j] for j in idx]
    spec = "".join(_colspec(c, w) for c, w in zip(cols, widths))
    head = " & ".join(_tex_header(str(header[j]), c, split) for j, c in zip(idx, cols)) + r" \\"
    body = [" & ".join(_tex_cell(r[j], c, w) for j, c, w in zip(idx, cols, widths)) + r" \\" for r in rows]
    return spec, head, body


def _tex_notes(notes: Sequence[str]) -> list[str]:
    items = [tex_text(n) for n in notes]
    if items and items[0].startswith("Note."):
        items[0] = r"\textit{Note.}" + items[0][len("Note."):]
    return items


def _longtable(lay: TableLayout, header, rows, title: str, notes: Sequence[str], label: str) -> list[str]:
    r"""A `longtable` per part (one number: the later parts step the counter back), the caption above, the header
    repeated on each page (`\endhead`, "Table A1 (continued)" above it), the notes below the last row, as wide as
    the table and never widening it (a zero-width box)."""
    room = PAGE_PT if lay.landscape else TEXT_PT
    out = [r"\begin{landscape}"] if lay.landscape else []
    out.append(rf"\begingroup\{lay.style.size}" + (rf"\setlength{{\tabcolsep}}{{{lay.style.sep / 2:g}pt}}"
                                                     if lay.style.sep != SMALL.sep else ""))
    for k, part in enumerate(lay.parts):
        spec, head, body = _tabular(lay, part, header, rows)
        width = min(room, table_width([lay.columns[j] for j in part[0]], part[1]))
        cont = [r"\caption*{Table \thetable{} (continued)}\\"] if title else []
        mark = rf"\label{{{label}}}" if label and not k else ""   # the number is the first part's
        first = [rf"\caption{{{tex_text(title)}}}{mark}\\"] if title and not k else cont
        last = [r"\bottomrule"]
        if notes and k == len(lay.parts) - 1:
            text = r"\par ".join(_tex_notes(notes))
            last += [rf"\multicolumn{{{len(part[0])}}}{{@{{}}l@{{}}}}{{\rule{{0pt}}{{2.5ex}}\makebox[0pt][l]"
                     rf"{{\parbox[t]{{{width:.1f}pt}}{{\footnotesize\raggedright {text}}}}}}}\\"]
        out += ([r"\addtocounter{table}{-1}"] if k else []) + [
            rf"\setlength{{\LTcapwidth}}{{{width:.1f}pt}}", rf"\begin{{longtable}}{{{spec}}}",
            *first, r"\toprule", ("" if title else mark) + head, r"\midrule", r"\endfirsthead",
            *cont, r"\toprule", head, r"\midrule", r"\endhead",
            r"\bottomrule", r"\endfoot", *last, r"\endlastfoot", *body, r"\end{longtable}"]
    out.append(r"\endgroup")
    return out + ([r"\end{landscape}"] if lay.landscape else [])


def latex_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "", notes: Sequence[str] = (),
                label: str = "", align: str | None = None) -> str:
    r"""A table for a journal, placed by :func:`table_layout`. A float that fits a page: `threeparttable` with the
    caption above, booktabs rules, the notes left-aligned below (a first note "Note. ..." with "Note." in italics),
    as `table` in one column of a two-column article, `table*` across both or `sidewaystable*` on a landscape page,
    wrapping wide text columns. A table taller than a page or wider than a landscape page: a `longtable` (one-column
    pages only; on landscape pages when it is wider than the text) with the header repeated on each page and the
    notes after the last row; a table wider than a landscape page even at \footnotesize in column groups, each
    with the row labels. Numeric columns as `siunitx` S columns aligned on the decimal point (a leading zero printed
    as written: none where the column has none, APA). `align` (l/c/r per column, default l then r) keeps a column
    given as `l` as text; a text column given as `r` is set left. Needs the packages of :data:`LATEX_PACKAGES`.

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
    rows = [[str(x) for x in r] for r in rows]
    lay = table_layout(header, rows, align, title, notes)
    if lay.env == "longtable":
        return "\n".join(_longtable(lay, header, rows, title, notes, label)) + "\n"
    spec, head, body = _tabular(lay, lay.parts[0], header, rows)
    out = [rf"\begin{{{lay.env}}}[{'p' if lay.env.startswith('sideways') else 'tbp'}]", r"\centering\small",
           r"\begin{threeparttable}"]
    if title:
        out.append(rf"\caption{{{tex_text(title)}}}")
    if label:
        out.append(rf"\label{{{label}}}")
    out += [rf"\begin{{tabular}}{{{spec}}}", r"\toprule", head, r"\midrule", *body, r"\bottomrule", r"\end{tabular}"]
    if notes:
        out += [r"\begin{tablenotes}[flushleft]\footnotesize\raggedright",
                *(rf"\item {n}" for n in _tex_notes(notes)), r"\end{tablenotes}"]
    out += [r"\end{threeparttable}", rf"\end{{{lay.env}}}"]
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

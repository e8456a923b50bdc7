"""Rendering shared by every analysis output: tables as Markdown / LaTeX booktabs, figures as PNG + PDF.

One Markdown table writer (:func:`markdown_table`), one booktabs writer (:func:`latex_table`), one LaTeX escape
(:func:`tex_escape`) and one cell formatter (:func:`fmt_cell`). Table modules build header and string cells in
their own (paper-shaped) layout and hand them to these writers.
"""
from __future__ import annotations

import math
import re
import sys
from numbers import Integral, Real
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from analysis import apa

# PDF metadata without a creation date keeps an unchanged figure byte-identical between runs
PDF_METADATA = {"Creator": "pedas-study", "Producer": None, "CreationDate": None}
PNG_METADATA = {"Software": None}


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
    """Write a matplotlib figure as `<stem>.png` and `<stem>.pdf` into `out_dir`; close it; return both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{stem}.png", out / f"{stem}.pdf"]
    fig.savefig(paths[0], dpi=dpi, bbox_inches="tight", metadata=PNG_METADATA)
    fig.savefig(paths[1], bbox_inches="tight", metadata=PDF_METADATA)
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


def frame_cells(df: pd.DataFrame, digits: int = 3) -> tuple[list[str], list[list[str]]]:
    """Header and string cells of a tidy frame (floats to `digits` decimals, missing as empty); a pair of lower and
    upper confidence limits (``ci_low``/``ci_high`` ...) becomes one ``[LL, UL]`` column in the lower one's place."""
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
            cols.append([fmt_cell(x, digits) for x in df[c]])
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
               "ε": r"$\varepsilon$"}


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


def latex_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "", notes: Sequence[str] = (),
                label: str = "", align: str | None = None) -> str:
    r"""A booktabs `table` environment: caption, label, toprule/midrule/bottomrule, the notes in one footnote-size
    paragraph below (one line each). `align` defaults to a left text column and right-aligned numbers.

    Examples
    --------
    >>> from analysis.render import latex_table
    >>> print(latex_table(["Item", "λ"], [["**PU**", ""], ["PU1", "0.737"]], "Loadings"), end="")
    \begin{table}[t]
    \centering
    \caption{Loadings}
    \begin{tabular}{lr}
    \toprule
    Item & $\lambda$ \\
    \midrule
    \textbf{PU} &  \\
    PU1 & .737 \\
    \bottomrule
    \end{tabular}
    \end{table}
    """
    align = align or "l" + "r" * (len(header) - 1)
    header, rows = apa.table_cells(header, rows)
    out = [r"\begin{table}[t]", r"\centering"]
    if title:
        out.append(rf"\caption{{{tex_escape(title)}}}")
    if label:
        out.append(rf"\label{{{label}}}")
    out += [rf"\begin{{tabular}}{{{align}}}", r"\toprule",
            " & ".join(tex_cell(h) for h in header) + r" \\", r"\midrule"]
    out += [" & ".join(tex_cell(c) for c in r) + r" \\" for r in rows]
    out += [r"\bottomrule", r"\end{tabular}"]
    if notes:
        out.append(r"\par\smallskip\footnotesize " + r" \\ ".join(tex_escape(n) for n in notes))
    out.append(r"\end{table}")
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

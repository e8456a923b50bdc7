"""Rendering shared by every analysis output: tables as Markdown / LaTeX booktabs, figures as PNG + PDF."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import pandas as pd

# PDF metadata without a creation date keeps an unchanged figure byte-identical between runs
PDF_METADATA = {"Creator": "pedas-study", "Producer": None, "CreationDate": None}
PNG_METADATA = {"Software": None}


def save_figure(fig, out_dir: str | Path, stem: str, dpi: int = 150) -> list[Path]:
    """Write a matplotlib figure as `<stem>.png` and `<stem>.pdf` into `out_dir`; close it; return both paths."""
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{stem}.png", out / f"{stem}.pdf"]
    fig.savefig(paths[0], dpi=dpi, bbox_inches="tight", metadata=PNG_METADATA)
    fig.savefig(paths[1], bbox_inches="tight", metadata=PDF_METADATA)
    plt.close(fig)
    return paths


def tex_escape(s: str) -> str:
    """Escape LaTeX special characters of a plain-text cell."""
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("$", r"\$"), ("#", r"\#"),
                 ("_", r"\_"), ("{", r"\{"), ("}", r"\}"), ("~", r"\textasciitilde{}"), ("^", r"\^{}")):
        s = s.replace(a, b)
    return s


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "",
                   notes: Sequence[str] = ()) -> str:
    """A GitHub-flavoured Markdown table with an optional `### title` and notes below."""
    out = [f"### {title}", ""] if title else []
    out.append("| " + " | ".join(header) + " |")
    out.append("|" + "|".join("---" for _ in header) + "|")
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    if notes:
        out += [""] + [f"_{n}_" for n in notes]
    return "\n".join(out) + "\n"


def latex_table(header: Sequence[str], rows: Sequence[Sequence[str]], title: str = "", notes: Sequence[str] = (),
                label: str = "", align: str | None = None) -> str:
    """A booktabs `table` environment (caption, label, toprule/midrule/bottomrule, notes as a footnote line)."""
    align = align or "l" + "r" * (len(header) - 1)
    out = [r"\begin{table}[t]", r"\centering"]
    if title:
        out.append(rf"\caption{{{tex_escape(title)}}}")
    if label:
        out.append(rf"\label{{{label}}}")
    out += [rf"\begin{{tabular}}{{{align}}}", r"\toprule",
            " & ".join(tex_escape(str(h)) for h in header) + r" \\", r"\midrule"]
    out += [" & ".join(tex_escape(str(c)) for c in r) + r" \\" for r in rows]
    out.append(r"\bottomrule")
    out.append(r"\end{tabular}")
    for n in notes:
        out.append(rf"\par\footnotesize {tex_escape(n)}")
    out.append(r"\end{table}")
    return "\n".join(out) + "\n"


def _cell(x, digits: int) -> str:
    if x is None or (isinstance(x, float) and pd.isna(x)):
        return ""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return str(x)


def frame_cells(df: pd.DataFrame, digits: int = 3) -> tuple[list[str], list[list[str]]]:
    """Header and string cells of a tidy frame (floats to `digits` decimals, missing as empty)."""
    return [str(c) for c in df.columns], [[_cell(x, digits) for x in row] for row in df.itertuples(index=False)]


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

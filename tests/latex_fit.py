"""Compile LaTeX tables the way a journal would place them and count what does not fit: every table in one
`\\documentclass[twocolumn]{article}` (a `table` in one column, `table*` across both, `sidewaystable*` on a
landscape page, a `longtable` on one-column pages) with the preamble the manuscript outputs ship
(analysis.report.manuscript.PREAMBLE)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path


def pdflatex() -> str | None:
    """The pdflatex to use; None outside CI when it is not installed (CI installs it: .ci/run)."""
    found = shutil.which("pdflatex")
    assert found or not os.environ.get("CI"), "CI compiles the LaTeX tables: .ci/run installs pdflatex"
    return found


def compile_tex(work: Path, name: str) -> str:
    """Run pdflatex on `work/<name>.tex` (asserts success: exit 0, no character lost to a missing glyph); the log."""
    p = subprocess.run([pdflatex(), "-interaction=nonstopmode", "-halt-on-error", f"{name}.tex"], cwd=work,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout[-3000:]
    log = (work / f"{name}.log").read_text(errors="replace")
    assert "Missing character" not in log, [ln for ln in log.splitlines() if "Missing character" in ln][:5]
    return log


def compile_tables(tables: list[str], work: Path, name: str = "tables") -> str:
    """Compile `tables` (LaTeX tables, one page each; a longtable on one-column pages) in a two-column article;
    the log (asserts success)."""
    from analysis.report.manuscript import PREAMBLE

    work.mkdir(parents=True, exist_ok=True)
    body = "\n\\clearpage\n".join(f"\\onecolumn\n{t}\\twocolumn" if "\\begin{longtable}" in t else t for t in tables)
    (work / f"{name}.tex").write_text("\\documentclass[twocolumn]{article}\n" + PREAMBLE +
                                      "\\begin{document}\n" + body + "\n\\end{document}\n", encoding="utf-8")
    return compile_tex(work, name)


def overfull(log: str) -> list[str]:
    """The "Overfull \\hbox" lines of a LaTeX log (a line of text or a table wider than its room)."""
    return re.findall(r"^Overfull \\hbox.*$", log, re.M)


def misfits(log: str) -> dict[str, int]:
    """What of a document does not fit its page, from its LaTeX log: overfull lines or tables ("Overfull \\hbox"),
    floats taller than the page ("Float too large") and a float queue that never empties ("Output loop")."""
    return {"overfull": len(overfull(log)), "float too large": log.count("Float too large"),
            "output loop": log.count("Output loop")}

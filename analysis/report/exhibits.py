"""The results document's numbered exhibits: every table and figure in reading order, as one list.

The document (HTML, Markdown) numbers its tables and figures (Table 1, Figure 1 in the main text; Table A1, Figure A1
in the appendix); the Word and LaTeX outputs and the bundle take the same numbers, titles and notes from this list,
written beside the document as ``exhibits.json`` (docs/report.md).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

EXHIBITS_FILE = "exhibits.json"


@dataclass(frozen=True)
class Exhibit:
    """One numbered table or figure of the results document.

    kind: "table" or "figure"; label: "Table 1", "Figure A2"; part: "main" or "appendix"; section: the heading it
    stands under; stem: its file stem; title: the APA title; note: the note printed under it ("" for none);
    files: format -> path relative to the report folder (tables: md, tex, csv; figures: png, svg, pdf).
    """

    kind: str
    label: str
    part: str
    section: str
    stem: str
    title: str
    note: str = ""
    files: dict[str, str] = field(default_factory=dict)


def write_exhibits(out: Path, exhibits: list[Exhibit]) -> Path:
    """Write the exhibits in reading order to ``<out>/exhibits.json``; return its path."""
    path = Path(out) / EXHIBITS_FILE
    path.write_text(json.dumps([asdict(e) for e in exhibits], indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return path


def read_exhibits(out: Path) -> list[Exhibit]:
    """The exhibits a report folder lists, in reading order ([] where the folder has no list)."""
    path = Path(out) / EXHIBITS_FILE
    if not path.is_file():
        return []
    return [Exhibit(**e) for e in json.loads(path.read_text(encoding="utf-8"))]

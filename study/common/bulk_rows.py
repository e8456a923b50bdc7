"""Bulk files: a CSV with one row per participant or per event, read as text with each row's line in the file, and
the refusal of a whole file that names every bad row (``participant import``, ``session advance --from``).

A bulk command is all or nothing: each row goes through the checks of the single command, and if any row is bad
nothing is stored and :class:`BadRows` names each bad row by its line (the header is line 1), participant id and
reason.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Sequence

from study.common.errors import UserError, shown
from study.common.input_size import check_size

if TYPE_CHECKING:  # pandas only for the DataFrame of read_rows: a bulk command reads its file without it
    import pandas as pd


@dataclass(frozen=True)
class BadRow:
    """One row of a bulk file that a check refused (or that was not checked, see :class:`BadRows`)."""

    line: int                 # line in the file, the header being line 1 (0: not a line of a file)
    participant_id: str
    reason: str

    def __str__(self) -> str:
        where = f"line {self.line}: " if self.line else ""   # 0: a row of no file (a folder's file)
        return f"{where}{self.participant_id or '(no id)'}: {self.reason}"


class BadRows(UserError):
    """A bulk file refused as a whole. The message is one line, ``FILE: N bad row(s)``; :meth:`lines` names each bad
    row (and each row left unchecked because an earlier row of the same participant is bad) in file order."""

    def __init__(self, source: str, rows: Iterable[BadRow], unchecked: Iterable[BadRow] = ()) -> None:
        self.source = source
        self.rows = list(rows)
        self.unchecked = list(unchecked)
        super().__init__(f"{source}: {len(self.rows)} bad row(s)")

    def lines(self) -> list[str]:
        """One line per bad or unchecked row, ordered by line."""
        return [str(r) for r in sorted(self.rows + self.unchecked, key=lambda r: r.line)]


def cell(value: Any) -> str | None:
    """A cell of a bulk frame as stripped text; None when empty or missing (NaN, None)."""
    if value is None or (isinstance(value, float) and value != value):
        return None
    text = str(value).strip()
    return text or None


@dataclass(frozen=True)
class BulkRows:
    """The rows of a bulk CSV as text, without pandas: the header's column names and, per row, its line in the file
    with {column: stripped text} ('' when empty). :func:`import_roster <study.people.participants.import_roster>` and
    :func:`apply_events <study.people.protocol.apply_events>` take it as they take the DataFrame of :func:`read_rows`."""

    columns: list[str]
    rows: list[tuple[int, dict[str, str]]]

    def __len__(self) -> int:
        return len(self.rows)


def records(frame: "pd.DataFrame | BulkRows") -> tuple[list[str], list[tuple[Any, dict[str, Any]]]]:
    """(column names, [(row label, {column: cell})]) of a bulk frame: a :class:`BulkRows` as it is, a DataFrame by
    its columns and ``iterrows()`` (the label is its index: the line in the file for :func:`read_rows`)."""
    if isinstance(frame, BulkRows):
        return list(frame.columns), frame.rows
    return list(frame.columns), [(line, row.to_dict()) for line, row in frame.iterrows()]


def read_rows(path: str | Path) -> pd.DataFrame:
    """The rows of a bulk CSV as text (:func:`read_table`) in a DataFrame: one column per header name (stripped),
    every cell stripped text ('' when empty), indexed by the row's line in the file (``line``)."""
    import pandas as pd

    table = read_table(path)
    return pd.DataFrame([[r[c] for c in table.columns] for _, r in table.rows], columns=table.columns,
                        dtype=object, index=pd.Index([line for line, _ in table.rows], name="line"))


def csv_text(path: Path, missing: str, reason_prefix: str = "") -> str:
    """The text of the CSV file `path`: UTF-8 (a BOM is accepted) without NUL bytes, at most
    :data:`study.common.input_size.MAX_INPUT_BYTES`. Refused (UserError, one line): `missing` when `path` is not a
    file; else the file's name and the reason (after `reason_prefix`)."""
    if not path.is_file():
        raise UserError(missing)
    check_size(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise UserError(f"{shown(path)}: {reason_prefix}not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if "\x00" in text:
        raise UserError(f"{shown(path)}: {reason_prefix}contains NUL bytes (binary file?)")
    return text


def read_table(path: str | Path, ignore: Sequence[str] = ()) -> BulkRows:
    """The rows of a bulk CSV as text: one column per header name (stripped), every cell stripped text ('' when
    empty), each row with its line in the file (the header is line 1, blank lines are skipped). The columns named
    in `ignore` (``--ignore-columns``: a lab's own bookkeeping beside the declared columns) are left out; a name
    the header lacks is refused.

    Refused (UserError, one line): a missing file, text that is not UTF-8 (a BOM is accepted), malformed CSV, an
    empty or duplicate column name, no rows. Rows with more or fewer fields than the header -> :class:`BadRows`.
    """
    path = Path(path)
    text = csv_text(path, f"{path} not found (or not a file)")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    rows: list[tuple[int, list[str]]] = []
    end = 0
    try:
        for fields in reader:
            start, end = end + 1, reader.line_num  # a quoted field may span lines: name the row's first line
            if any(c.strip() for c in fields):
                rows.append((start, [c.strip() for c in fields]))
    except csv.Error as exc:
        raise UserError(f"{shown(path)}: malformed CSV at line {reader.line_num}: {exc}") from None
    if not rows:
        raise UserError(f"{shown(path)}: empty file (expected a header row, then one row per line)")
    header = rows[0][1]
    if "" in header:
        raise UserError(f"{shown(path)}: column {header.index('') + 1} of the header has no name")
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:
        raise UserError(f"{shown(path)}: duplicate column(s) {', '.join(dup)}")
    body = rows[1:]
    if not body:
        raise UserError(f"{shown(path)}: no rows below the header")
    malformed = [BadRow(line, fields[0], f"{len(fields)} fields, the header has {len(header)}")
                 for line, fields in body if len(fields) != len(header)]
    if malformed:
        raise BadRows(shown(path), malformed)
    kept = without_ignored(path, header, ignore)
    return BulkRows([header[k] for k in kept], [(line, {header[k]: fields[k] for k in kept}) for line, fields in body])


def without_ignored(path: Path, header: Sequence[str], ignore: Sequence[str]) -> list[int]:
    """The positions of `header`'s columns that are not in `ignore`; UserError when `ignore` names a column the
    header lacks (a misspelt name would otherwise leave the column it meant in place)."""
    absent = [c for c in ignore if c not in header]
    if absent:
        raise UserError(f"{shown(path)}: --ignore-columns names no column of the file: {', '.join(absent)} "
                        f"(the columns are {', '.join(header)})")
    return [k for k, c in enumerate(header) if c not in ignore]


def check_columns(frame: "pd.DataFrame | BulkRows", source: str, required: Sequence[str],
                  optional: Sequence[str]) -> None:
    """UserError naming the declared columns when `frame` has a column that is neither `required` nor `optional`,
    or lacks a `required` one."""
    declared = list(required) + [c for c in optional if c not in required]
    unknown = [c for c in frame.columns if c not in declared]
    if unknown:
        raise UserError(f"{source}: unknown column(s) {', '.join(map(str, unknown))}; the columns are "
                        f"{', '.join(declared)} (--ignore-columns {','.join(map(str, unknown))} leaves them out)")
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise UserError(f"{source}: column(s) {', '.join(missing)} missing; the columns are {', '.join(declared)}")

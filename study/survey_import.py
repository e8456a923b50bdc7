"""`survey import FILE [--entry 1|2]`: a wide survey CSV (docs/contracts.md) into the store, all or nothing.

Format: ``participant_id`` then one column per item id of the study's instrument (every required item that does
not fill a participant attribute must have a column; the others are optional), raw answers as ticked
(reverse-scored items not reversed), empty cell = missing (stored as NULL). Without ``--entry`` the file is a
single electronic entry (e.g. an export of another survey tool, or ``survey final``) and is final as imported; its
attribute items (the codebook's ``attribute`` column) fill the participants' attributes. ``--entry 1`` /
``--entry 2`` are the two rounds of a double data entry of paper forms, compared by the discrepancy report; they
carry no attribute items.

Checks before anything is written: the file is well-formed CSV (every row as many fields as the header),
every column is a known item, every required item has a column, participant ids match the study's pattern, are
known to the store and not repeated, every answer is an integer within its item's range (or a declared choice),
attribute values fit their declaration and the study's checks, and no participant already has answers for that
round. Any problem -> UserError naming the first problem (line and item) and how many more.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

from study.errors import UserError
from study.instrument import Instrument
from study.survey import attribute_items, attribute_value, instrument_of, response_items, save_entry, submission


@dataclass(frozen=True)
class ImportResult:
    participants: int     # rows imported
    answers: int          # non-missing answers
    missing: int          # empty cells stored as NULL (items of the instrument absent from the file included)
    entry_round: int
    double_entry: bool


def read_survey_csv(path: str | Path, ins: Instrument, study, double_entry: bool = False
                    ) -> list[tuple[int, str, dict]]:
    """Parse and validate a wide survey CSV for instrument `ins` of `study` (a StudyDefinition); returns
    [(line number, participant_id, {item: raw str})].

    Checks the structure, the ids against the study's pattern and every value against the codebook (not the
    store); `double_entry` refuses attribute items. Raises UserError.
    """
    path = Path(path)
    if not path.is_file():
        raise UserError(f"survey file {path} not found")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path.name}: malformed CSV: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if "\x00" in text:
        raise UserError(f"{path.name}: malformed CSV: contains NUL bytes (binary file?)")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    try:
        rows = [(reader.line_num, r) for r in reader]
    except csv.Error as exc:
        raise UserError(f"{path.name}: malformed CSV at line {reader.line_num}: {exc}") from None
    rows = [(n, r) for n, r in rows if any(c.strip() for c in r)]  # blank lines carry nothing
    if not rows:
        raise UserError(f"{path.name}: empty file (expected a header participant_id,"
                        f"{','.join(response_items(ins)[:2])},...)")
    header = [c.strip() for c in rows[0][1]]
    if header[0] != "participant_id":
        raise UserError(f"{path.name}: malformed CSV: the first column must be participant_id, not {header[0]!r}")
    items = header[1:]
    dup = sorted({c for c in items if items.count(c) > 1})
    if dup:
        raise UserError(f"{path.name}: duplicate column(s) {', '.join(dup)}")
    responses = response_items(ins)
    filled = attribute_items(ins)
    unknown = [c for c in items if c not in ins.items.index]
    if unknown:
        raise UserError(f"{path.name}: unknown item column(s) {', '.join(unknown)} for instrument {ins.name}")
    attr_cols = [c for c in items if c in filled]
    if double_entry and attr_cols:
        raise UserError(f"{path.name}: column(s) {', '.join(attr_cols)} fill participant attributes, which a double "
                        f"entry does not compare; record them on the participant record (pedas-study participant "
                        f"add ID --attr NAME=VALUE) or import the file as a single entry")
    required = [i for i in ins.required_items if i in responses and i not in items]
    if required:
        raise UserError(f"{path.name}: required item column(s) missing: {', '.join(required)}")

    problems: list[str] = []
    seen: dict[str, int] = {}
    out = []
    for line, row in rows[1:]:
        if len(row) != len(header):
            problems.append(f"line {line}: malformed CSV: {len(row)} fields, header has {len(header)}")
            continue
        pid = row[0].strip()
        try:
            study.validate_id(pid)
        except UserError as exc:
            problems.append(f"line {line}: {exc}")
            continue
        if pid in seen:
            problems.append(f"line {line}: duplicate participant {pid} (also on line {seen[pid]})")
            continue
        seen[pid] = line
        answers = {}
        for item, raw in zip(items, row[1:]):
            try:
                a = ins.parse(item, raw)
                if item in filled:
                    attribute_value(ins, item, a, study.attribute(filled[item]))
            except (ValueError, UserError) as exc:
                problems.append(f"line {line}, {exc}")
            answers[item] = raw
        out.append((line, pid, answers))
    _raise_first(path, problems)
    if not out:
        raise UserError(f"{path.name}: no participant rows")
    return out


def _raise_first(path: Path, problems: list[str]) -> None:
    if problems:
        more = f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})" if len(problems) > 1 else ""
        raise UserError(f"{path.name}: {problems[0]}{more}; nothing imported")


def import_survey(st, path: str | Path, entry: int | None = None,
                  instrument: str | None = None) -> ImportResult:
    """Import a wide survey CSV in ONE transaction for `instrument` (None = the study's; see the module docstring
    for the checks)."""
    from study.studies import definition

    if entry not in (None, 1, 2):
        raise UserError(f"--entry must be 1 or 2, not {entry}")
    ins = instrument_of(st, instrument)
    instrument = ins.name
    path = Path(path)
    entry_round = entry or 1
    double = entry is not None
    rows = read_survey_csv(path, ins, definition(st), double_entry=double)
    known = set(st.df("SELECT participant_id FROM participants")["participant_id"])
    problems = []
    for line, pid, _ in rows:
        if pid not in known:
            problems.append(f"line {line}: unknown participant {pid} (add it first: pedas-study participant add {pid})")
            continue
        this = submission(st, pid, entry_round, instrument)
        first = submission(st, pid, 1, instrument)
        if this is not None:
            problems.append(f"line {line}: {pid} already has {'entry round %d' % entry_round if double else 'answers'}"
                            f" ({this['source']} by {this['submitted_by']})")
        elif first is not None and not first["double_entry"]:
            problems.append(f"line {line}: {pid} already has final answers from a single {first['source']} entry")
        elif entry_round == 2 and first is None:
            problems.append(f"line {line}: {pid} has no entry round 1 yet; import round 1 first")
    _raise_first(path, problems)
    n_items = len(response_items(ins))
    filled = attribute_items(ins)
    answers = 0
    with st.transaction():
        for line, pid, raw in rows:
            try:
                save_entry(st, pid, entry_round, raw, instrument=instrument, double_entry=double, source="import")
            except UserError as exc:
                raise UserError(f"{path.name}: line {line}: {exc}; nothing imported") from None
            answers += sum(1 for item, v in raw.items() if v.strip() and item not in filled)
    return ImportResult(participants=len(rows), answers=answers, missing=len(rows) * n_items - answers,
                        entry_round=entry_round, double_entry=double)

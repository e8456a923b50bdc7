"""`survey import FILE [--entry 1|2] [--occasion PHASE]`: a survey CSV (docs/contracts.md) into the store, all or
nothing.

Two layouts:

* **wide**: ``participant_id`` then one column per item id of the instrument (every required item that does not
  fill a participant attribute must have a column; the others are optional);
* **long**: ``participant_id``, ``item_id``, ``value`` (one answer a row; an item without a row is missing).

Either may carry an ``occasion`` column (the questionnaire phase, e.g. ``survey_after_visual``) or a ``condition``
column (the condition the occasion rates, e.g. ``visual``: the instrument's occasion that rates it), so that one
file holds a participant's answers of several occasions, one row (wide) or one row per item (long) each. Without
such a column the whole file is one occasion: ``--occasion``, or the instrument's only one. Raw answers as ticked
(reverse-scored items not reversed), empty cell = missing (stored as NULL). Without ``--entry`` the file is a
single electronic entry (e.g. an export of another survey tool, or ``survey final``) and is final as imported; its
attribute items (the codebook's ``attribute`` column) fill the participants' attributes. ``--entry 1`` /
``--entry 2`` are the two rounds of a double data entry of paper forms, compared by the discrepancy report; they
carry no attribute items.

Checks before anything is written: the file is well-formed CSV (every row as many fields as the header),
every column is a known item (or one of the layout's columns), every required item has a column (wide), participant
ids match the study's pattern, are known to the store and not repeated for one occasion, every occasion or
condition is one of the instrument's, every answer is an integer within its item's range (or a declared choice),
attribute values fit their declaration and the study's checks, and no participant already has answers for that
round of that occasion. Any problem -> UserError naming the first problem (line and item) and how many more.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from study.common.bulk_rows import csv_text, without_ignored
from study.common.errors import UserError, shown
from study.folder.instrument import Instrument
from study.survey.answers import (
    attribute_items,
    attribute_value,
    instrument_of,
    response_items,
    save_entry,
    submission,
    target,
)

#: the columns that say which occasion a row answers (at most one of them per file)
WHICH = ("occasion", "condition")
#: the columns of the long layout besides participant_id and WHICH
LONG = ("item_id", "value")


@dataclass(frozen=True)
class ImportResult:
    participants: int     # distinct participants
    questionnaires: int   # rows imported (participant and occasion)
    answers: int          # non-missing answers
    missing: int          # empty cells stored as NULL (items of the instrument absent from the file included)
    entry_round: int
    double_entry: bool
    occasions: tuple[str, ...] = ()   # the occasions the file answered, in the order first met


@dataclass(frozen=True)
class SurveyRow:
    """One participant's answers to one occasion in a file: the line it starts on, the id, the value of the file's
    occasion or condition column (None without one) and {item: raw text}."""

    line: int
    participant_id: str
    which: str | None
    answers: dict


def _read_text(path: Path, ignore: Sequence[str] = ()) -> list[tuple[int, list[str]]]:
    """(line, fields) of the file's non-blank rows, the columns named in `ignore` left out."""
    text = csv_text(path, f"survey file {path} not found", "malformed CSV: ")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    try:
        rows = [(reader.line_num, r) for r in reader]
    except csv.Error as exc:
        raise UserError(f"{shown(path)}: malformed CSV at line {reader.line_num}: {exc}") from None
    rows = [(n, r) for n, r in rows if any(c.strip() for c in r)]  # blank lines carry nothing
    if not ignore or not rows:
        return rows
    header = [c.strip() for c in rows[0][1]]
    kept = without_ignored(path, header, ignore)
    # a row with more or fewer fields than the header keeps its count (refused below as malformed)
    return [(n, [r[k] for k in kept] if len(r) == len(header) else r[:len(r) - len(ignore)]) for n, r in rows]


def read_survey_rows(path: str | Path, ins: Instrument, study, double_entry: bool = False,
                     ignore: Sequence[str] = ()) -> list[SurveyRow]:
    """Parse and validate a survey CSV (wide or long, with or without an occasion/condition column) for instrument
    `ins` of `study` (a StudyDefinition). Checks the structure, the ids against the study's pattern and every value
    against the codebook (not the store, nor the occasions); `double_entry` refuses attribute items; the columns
    named in `ignore` are left out. Raises UserError."""
    path = Path(path)
    rows = _read_text(path, ignore)
    if not rows:
        raise UserError(f"{shown(path)}: empty file (expected a header participant_id,"
                        f"{','.join(response_items(ins)[:2])},...)")
    header = [c.strip() for c in rows[0][1]]
    if header[0] != "participant_id":
        raise UserError(f"{shown(path)}: malformed CSV: the first column must be participant_id, not {header[0]!r}")
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:
        raise UserError(f"{shown(path)}: duplicate column(s) {', '.join(dup)}")
    which = [c for c in header if c in WHICH and c not in ins.items.index]
    if len(which) > 1:
        raise UserError(f"{shown(path)}: give either an occasion or a condition column, not both")
    wcol = header.index(which[0]) if which else None
    long = all(c in header and c not in ins.items.index for c in LONG)
    items = [c for k, c in enumerate(header[1:], start=1) if k != wcol]
    if long:
        extra = [c for c in items if c not in LONG]
        if extra:
            raise UserError(f"{shown(path)}: a long survey file has the columns participant_id, [occasion or "
                            f"condition,] item_id, value; not {', '.join(extra)}")
        return _long_rows(path, rows, header, wcol, ins, study, double_entry)
    responses = response_items(ins)
    filled = attribute_items(ins)
    unknown = [c for c in items if c not in ins.items.index]
    if unknown:
        raise UserError(f"{shown(path)}: unknown item column(s) {', '.join(unknown)} for instrument {ins.name}")
    attr_cols = [c for c in items if c in filled]
    if double_entry and attr_cols:
        raise UserError(f"{shown(path)}: column(s) {', '.join(attr_cols)} fill participant attributes, which a double "
                        f"entry does not compare; record them on the participant record (pedas-study participant "
                        f"add ID --attr NAME=VALUE) or import the file as a single entry")
    required = [i for i in ins.required_items if i in responses and i not in items]
    if required:
        raise UserError(f"{shown(path)}: required item column(s) missing: {', '.join(required)}")

    problems: list[str] = []
    seen: dict[tuple, int] = {}
    out = []
    for line, row in rows[1:]:
        if len(row) != len(header):
            problems.append(f"line {line}: malformed CSV: {len(row)} fields, header has {len(header)}")
            continue
        pid = row[0].strip()
        occ = row[wcol].strip() if wcol is not None else None
        if not _check_id(study, pid, occ, which, line, seen, problems):
            continue
        answers = {}
        for item, raw in zip(items, [c for k, c in enumerate(row[1:], start=1) if k != wcol]):
            _check_value(ins, study, filled, item, raw, line, problems)
            answers[item] = raw
        out.append(SurveyRow(line, pid, occ, answers))
    _raise_first(path, problems)
    if not out:
        raise UserError(f"{shown(path)}: no participant rows")
    return out


def _check_id(study, pid: str, occ: str | None, which: list[str], line: int, seen: dict, problems: list) -> bool:
    try:
        study.validate_id(pid)
    except UserError as exc:
        problems.append(f"line {line}: {exc}")
        return False
    if occ is not None and not occ:
        problems.append(f"line {line}: {pid}: empty {which[0]}")
        return False
    if (pid, occ) in seen:
        at = f" at {which[0]} {occ}" if occ is not None else ""
        problems.append(f"line {line}: duplicate participant {pid}{at} (also on line {seen[(pid, occ)]})")
        return False
    seen[(pid, occ)] = line
    return True


def _check_value(ins: Instrument, study, filled: dict, item: str, raw: str, line: int, problems: list) -> None:
    try:
        a = ins.parse(item, raw)
        if item in filled:
            attribute_value(ins, item, a, study.attribute(filled[item]))
    except (ValueError, UserError) as exc:
        problems.append(f"line {line}, {exc}")


def _long_rows(path: Path, rows, header, wcol, ins: Instrument, study, double_entry: bool) -> list[SurveyRow]:
    """The rows of a long file (participant_id, [occasion|condition,] item_id, value), one SurveyRow per
    participant and occasion (its first line)."""
    filled = attribute_items(ins)
    ci, cv = header.index("item_id"), header.index("value")
    problems: list[str] = []
    groups: dict[tuple, SurveyRow] = {}
    seen_item: dict[tuple, int] = {}
    for line, row in rows[1:]:
        if len(row) != len(header):
            problems.append(f"line {line}: malformed CSV: {len(row)} fields, header has {len(header)}")
            continue
        pid, item, raw = row[0].strip(), row[ci].strip(), row[cv]
        occ = row[wcol].strip() if wcol is not None else None
        key = (pid, occ)
        if key not in groups:
            if not _check_id(study, pid, occ, [header[wcol]] if wcol is not None else [], line, {}, problems):
                continue
            groups[key] = SurveyRow(line, pid, occ, {})
        if item not in ins.items.index:
            problems.append(f"line {line}: unknown item {item!r} for instrument {ins.name}")
            continue
        if double_entry and item in filled:
            problems.append(f"line {line}: {item} fills the participant attribute {filled[item]}, which a double "
                            f"entry does not compare")
            continue
        if (pid, occ, item) in seen_item:
            problems.append(f"line {line}: {pid} {item} given twice (also on line {seen_item[(pid, occ, item)]})")
            continue
        seen_item[(pid, occ, item)] = line
        _check_value(ins, study, filled, item, raw, line, problems)
        groups[key].answers[item] = raw
    _raise_first(path, problems)
    if not groups:
        raise UserError(f"{shown(path)}: no participant rows")
    return list(groups.values())


def read_survey_csv(path: str | Path, ins: Instrument, study, double_entry: bool = False
                    ) -> list[tuple[int, str, dict]]:
    """[(line number, participant_id, {item: raw str})] of a wide or long survey CSV without an occasion column
    (:func:`read_survey_rows`)."""
    return [(r.line, r.participant_id, r.answers) for r in read_survey_rows(path, ins, study, double_entry)]


def _raise_first(path: Path, problems: list[str]) -> None:
    if problems:
        more = f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''})" if len(problems) > 1 else ""
        raise UserError(f"{shown(path)}: {problems[0]}{more}; nothing imported")


def _file_column(path: Path, ignore: Sequence[str] = ()) -> tuple[str | None, str | None]:
    """(which column names the occasion: 'occasion' | 'condition' | None, its value on the first data row)."""
    rows = _read_text(path, ignore)
    if len(rows) < 2:
        return None, None
    header = [c.strip() for c in rows[0][1]]
    for col in WHICH:
        if col in header:
            k = header.index(col)
            return col, rows[1][1][k].strip() if k < len(rows[1][1]) else None
    return None, None


def _instrument_for(st, path: Path, instrument: str | None, occasion: str | None,
                    ignore: Sequence[str] = ()) -> str | None:
    """The instrument a file answers when --instrument is not given: that of --occasion, or of the occasion (or
    the occasion rating the condition) on its first data row; None = the study's."""
    from study.folder.occasions import study_occasions
    from study.store.studies import definition

    if instrument is not None:
        return instrument
    all_occ = study_occasions(definition(st))
    if occasion is not None:
        return next((o.instrument for o in all_occ if o.name == occasion), None)
    col, first = _file_column(path, ignore)
    if col == "occasion":
        return next((o.instrument for o in all_occ if o.name == first), None)
    if col == "condition":
        found = sorted({o.instrument for o in all_occ if o.rates == first})
        if len(found) > 1:
            raise UserError(f"{shown(path)}: condition {first} is rated by several instruments ({', '.join(found)}): "
                            f"name one with --instrument")
        return found[0] if found else None
    return None


def _occasion_map(st, ins: Instrument, path: Path, rows: list[SurveyRow], occasion: str | None,
                  ignore: Sequence[str] = ()) -> list[str]:
    """The occasion of each row: the file's occasion column, the occasion rating its condition column, or the one
    occasion of the whole file (:func:`study.survey.answers.target`)."""
    from study.survey.answers import occasions

    occ = occasions(st, ins.name)
    names = [o.name for o in occ]
    col, _ = _file_column(path, ignore)
    if col is None:
        try:
            return [target(st, ins.name, occasion)[1]] * len(rows)
        except UserError as exc:
            raise UserError(f"{shown(path)}: {exc} or an occasion or condition column in the file") from None
    if occasion is not None:
        raise UserError(f"{shown(path)}: the file names its occasions in its {col} column; drop --occasion")
    by_condition: dict[str, list[str]] = {}
    for o in occ:
        if o.rates:
            by_condition.setdefault(o.rates, []).append(o.name)
    out, problems = [], []
    for r in rows:
        if col == "occasion":
            if r.which not in names:
                problems.append(f"line {r.line}: {r.participant_id}: {r.which!r} is not an occasion of instrument "
                                f"{ins.name} ({', '.join(names)})")
            out.append(r.which)
        else:
            match = by_condition.get(r.which, [])
            if len(match) != 1:
                problems.append(f"line {r.line}: {r.participant_id}: condition {r.which!r} is rated by "
                                + (f"several occasions of {ins.name} ({', '.join(match)}); use an occasion column"
                                   if match else f"no occasion of instrument {ins.name} (rated: "
                                   f"{', '.join(sorted(by_condition)) or 'none'})"))
            out.append(match[0] if match else None)
    _raise_first(path, problems)
    return out


def import_survey(st, path: str | Path, entry: int | None = None, instrument: str | None = None,
                  occasion: str | None = None, ignore_columns: Sequence[str] = ()) -> ImportResult:
    """Import a survey CSV in ONE transaction for `instrument` (None = the instrument of `occasion` or of the file's
    occasions, else the study's) and `occasion` (a file without an occasion column; None = the instrument's only
    one). `ignore_columns`: columns of the file to leave out. See the module docstring for the layouts and
    checks."""
    from study.store.studies import definition

    if entry not in (None, 1, 2):
        raise UserError(f"--entry must be 1 or 2, not {entry}")
    if instrument is not None:
        instrument_of(st, instrument)  # an unknown instrument is named before the file is read
    path = Path(path)
    if not path.is_file():
        raise UserError(f"survey file {path} not found")
    ignore = tuple(ignore_columns)
    ins = instrument_of(st, _instrument_for(st, path, instrument, occasion, ignore))
    instrument = ins.name
    entry_round = entry or 1
    double = entry is not None
    if _file_column(path, ignore)[0] is None:   # one occasion for the whole file: named before its rows are read
        _occasion_map(st, ins, path, [], occasion)
    rows = read_survey_rows(path, ins, definition(st), double_entry=double, ignore=ignore)
    occ = _occasion_map(st, ins, path, rows, occasion, ignore)
    several = len(set(occ)) > 1 or _file_column(path, ignore)[0] is not None
    known = set(st.df("SELECT participant_id FROM participants")["participant_id"])
    problems = []
    for r, o in zip(rows, occ):
        line, pid = r.line, r.participant_id
        at = f" at {o}" if several else ""
        if pid not in known:
            problems.append(f"line {line}: unknown participant {pid} (add it first: pedas-study participant add {pid})")
            continue
        this = submission(st, pid, entry_round, instrument, o)
        first = submission(st, pid, 1, instrument, o)
        if this is not None:
            problems.append(f"line {line}: {pid} already has {'entry round %d' % entry_round if double else 'answers'}"
                            f"{at} ({this['source']} by {this['submitted_by']})")
        elif first is not None and not first["double_entry"]:
            problems.append(f"line {line}: {pid} already has final answers{at} from a single {first['source']} "
                            f"entry")
        elif entry_round == 2 and first is None:
            problems.append(f"line {line}: {pid} has no entry round 1{at} yet; import round 1 first")
    _raise_first(path, problems)
    n_items = len(response_items(ins))
    filled = attribute_items(ins)
    answers = 0
    with st.transaction():
        for r, o in zip(rows, occ):
            try:
                save_entry(st, r.participant_id, entry_round, r.answers, instrument=instrument, double_entry=double,
                           source="import", occasion=o)
            except UserError as exc:
                raise UserError(f"{shown(path)}: line {r.line}: {exc}; nothing imported") from None
            answers += sum(1 for item, v in r.answers.items() if v.strip() and item not in filled)
    return ImportResult(participants=len({r.participant_id for r in rows}), questionnaires=len(rows),
                        answers=answers, missing=len(rows) * n_items - answers,
                        entry_round=entry_round, double_entry=double, occasions=tuple(dict.fromkeys(occ)))

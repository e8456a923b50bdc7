"""Survey answers in the study store: participant links, web drafts, atomic submission, double data entry of
paper forms, the discrepancy report, resolution, and the final answers the analysis reads.

Entry rounds (the `responses.entry_round` column):

* a **single electronic entry** (the participant's own web form, or ``survey import FILE`` of an electronic
  export) is round 1 and is final as entered;
* a **paper form** is typed in twice by two people (rounds 1 and 2, ``double_entry``); an item is final when the
  two entries agree, otherwise when a resolution has been recorded after checking the paper form.

:func:`final_responses` applies exactly this rule (resolution > agreed double entry; single entry as is) and
leaves out participants whose answers are not final yet (second entry missing or a discrepancy unresolved).

The instrument is the store's study's (:func:`instrument_of`; an earlier stored version by name). Items with an
`attribute` in the codebook fill participant attributes instead of `responses` (:func:`_fill_attributes`).

Occasions (:mod:`study.folder.occasions`): answers are keyed by participant, instrument, occasion (the questionnaire phase
answered in), item and entry round; every function takes ``occasion`` (:func:`target`: by default the instrument's
only occasion). A study with one occasion behaves, and writes its files, as before occasions.

Missing answers are NULL, never 0. Every write of research data goes through the audited Store API; web drafts
are not research data until submitted and are not audited. The caller serialises access to a Store shared
between threads (the web app holds a lock around every call).
"""
from __future__ import annotations

import hashlib
import json
import re
import secrets
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

import pandas as pd

from study.common.errors import UserError, check_name
from study.common.times import when
from study.folder.instrument import Answer, Instrument
from study.store import audit_trail
from study.store.audit_trail import utcnow

WEB_ENTERED_BY = "participant"  # `responses.entered_by` of answers the participant gave on the web form
_TOKEN = re.compile(r"^[A-Za-z0-9_-]{43}$")  # secrets.token_urlsafe(32)


class SubmittedError(UserError):
    """The survey has been submitted; it is read-only now."""


class LinkError(UserError):
    """A participant link that cannot be used; `status` is the HTTP status the web form answers with."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class Link:
    """What a valid participant link grants: one participant's survey of one instrument on one occasion."""

    participant_id: str
    instrument: str
    submitted: bool
    occasion: str | None = None


# ---------------------------------------------------------------------------------------------- instruments
def instrument_of(st, name: str | None = None) -> Instrument:
    """The store's instrument `name` (None = the study's current one; a name without its version, e.g.
    ``post_drive``, is the study's current version of it).

    An instrument an earlier stored version of the study declared (e.g. ``..._v1`` after ``[instrument] version``
    became 2) is found in that version's stored files: answers stay tied to the version they were given on.
    Unknown name -> UserError listing the study's instruments.
    """
    from study.folder.definition import StudyError, from_files
    from study.folder.occasions import instrument_named
    from study.store.studies import definition

    study = definition(st)
    check_name("instrument", name, study.instruments)
    if name is not None and name not in study.instruments:   # the name without its version: the current one
        name = instrument_named(study, name) or name
    if name is None or name in study.instruments:
        return study.instrument(name)
    cache = st.__dict__.setdefault("_earlier_instruments", {})
    if name not in cache:
        for files in st.df("SELECT files FROM study_definitions ORDER BY version DESC")["files"]:
            try:
                old = from_files(json.loads(files))
            except StudyError:  # an old version the current checks no longer accept: its codebook is not offered
                continue
            if name in old.instruments:
                cache[name] = old.instruments[name]
                break
    return cache[name] if name in cache else study.instrument(name)


def attribute_items(ins: Instrument) -> dict[str, str]:
    """{item_id: participant attribute} of the items whose answer fills a participant attribute (the codebook's
    optional `attribute` column), in questionnaire order."""
    if "attribute" not in ins.items.columns:
        return {}
    col = ins.items["attribute"].fillna("").astype(str).str.strip()
    return {item: name for item, name in col.items() if name}


def response_items(ins: Instrument) -> list[str]:
    """Items whose answers go to `responses` (every item that does not fill a participant attribute), in order."""
    filled = attribute_items(ins)
    return [i for i in ins.items.index if i not in filled]


def _study(st):
    from study.store.studies import definition

    return definition(st)


@contextmanager
def acting_as(st, actor: str) -> Iterator[None]:
    """Record `actor` in the audit log for the writes inside the block (the caller holds the store's lock)."""
    old = st.actor
    st.actor = actor
    try:
        yield
    finally:
        st.actor = old


def participant_exists(st, participant_id: str) -> bool:
    return bool(st.one("SELECT count(*) FROM participants WHERE participant_id = ?", [participant_id]))


def _require_participant(st, participant_id: str) -> None:
    _study(st).validate_id(participant_id)
    if not participant_exists(st, participant_id):
        raise UserError(f"unknown participant {participant_id} (add it first: pedas-study participant add "
                        f"{participant_id})")


def parse_answers(ins: Instrument, answers: Mapping[str, Any], items: list[str] | None = None) -> dict[str, Answer]:
    """Validate raw answers {item_id: raw}; unknown items and bad values raise UserError (one line).

    `items` limits which items are accepted (default: every item of the instrument).
    """
    allowed = set(ins.items.index if items is None else items)
    out: dict[str, Answer] = {}
    for item, raw in answers.items():
        if item not in allowed:
            if item in ins.items.index and item in attribute_items(ins):
                raise UserError(f"item {item} fills the participant attribute {attribute_items(ins)[item]}: record "
                                f"it on the participant (pedas-study participant add ID --attr NAME=VALUE)")
            raise UserError(f"unknown item {item!r} for instrument {ins.name}")
        try:
            out[item] = ins.parse(item, raw)
        except ValueError as exc:
            raise UserError(str(exc)) from None
    return out


def _rows_to_answers(df: pd.DataFrame) -> dict[str, Answer]:
    out = {}
    for r in df.itertuples(index=False):
        value = None if pd.isna(r.value) else int(r.value)
        text = None if r.text is None or pd.isna(r.text) else str(r.text)
        out[r.item_id] = Answer(value=value, text=text)
    return out


# ---------------------------------------------------------------------------------------------- attributes
def attribute_value(ins: Instrument, item: str, answer: Answer, attribute) -> Any:
    """The typed value of participant `attribute` (a study.folder.definition.Attribute) that an answer to `item` gives.

    A choice attribute takes the k-th of its choices for code k; a numeric attribute takes the number as is; a
    text attribute takes the text of a free-text item or the label of a choice. Missing -> None; a value the
    attribute refuses -> UserError naming the item.
    """
    if answer.missing:
        return None
    try:
        if attribute.type == "choice":
            code = answer.value
            if code is None or not 1 <= code <= len(attribute.choices):
                raise UserError(f"code {code} has no {attribute.name} ({'|'.join(attribute.choices)})")
            return attribute.parse(attribute.choices[code - 1])
        if attribute.type == "text":
            raw = answer.text if answer.text is not None else ins.choices(item).get(answer.value, answer.value)
            return attribute.parse(str(raw))
        return attribute.parse(answer.value if answer.value is not None else answer.text)
    except UserError as exc:
        raise UserError(f"{item}: {exc}") from None


def item_answer(ins: Instrument, item: str, attribute, value: Any) -> Any:
    """The answer to `item` that gives the stored attribute `value` (the inverse of :func:`attribute_value`):
    the choice code for a choice attribute or label, the number as is, the text of a free-text item; None when
    missing or not expressible as an answer to `item`."""
    if value is None or (not isinstance(value, str) and pd.isna(value)):
        return None
    if attribute.type == "choice":
        return attribute.choices.index(value) + 1 if value in attribute.choices else None
    kind = ins.items.loc[item, "response_type"]
    if kind == "text":
        return str(value)
    if attribute.type == "text":
        codes = {label: code for code, label in ins.choices(item).items()}
        if value in codes:
            return codes[value]
        return int(value) if re.fullmatch(r"[+-]?\d+", str(value)) else None
    num = float(value)
    return int(num) if num.is_integer() else num


def _stored_text(value: Any) -> str:
    """An attribute value as `participant_attributes.value` keeps it (as study.people.participants writes it: floats in
    their shortest exact form, so they read back as the same number)."""
    return repr(value) if isinstance(value, float) else str(value)


def _fill_attributes(st, ins: Instrument, participant_id: str, answers: Mapping[str, Answer]) -> dict[str, Any]:
    """Write the participant attributes that the answered attribute items give (audited; an answer replaces a
    value recorded earlier, as the participant's own statement on the form). The values are checked first with
    the attribute declarations, the study's required attributes and its checks, together with the attributes
    already stored; any problem -> UserError and nothing is written. Returns {attribute: typed value} written."""
    from study.folder.attributes import typed_attributes
    from study.people.participants import participant_attributes

    study = _study(st)
    given: dict[str, Any] = {}
    for item, name in attribute_items(ins).items():
        a = answers.get(item)
        if a is None or a.missing:
            continue
        given[name] = attribute_value(ins, item, a, study.attribute(name))
    if not given:
        return {}
    row = participant_attributes(st, [participant_id])
    stored = {} if row.empty else {k: (None if (not isinstance(v, str) and pd.isna(v)) else v)
                                   for k, v in row.iloc[0].drop("participant_id").items()}
    typed_attributes(study, {**stored, **given})
    with st.transaction():
        for name, value in given.items():
            key = {"participant_id": participant_id, "attribute": name}
            if stored.get(name) is None:
                st.insert("participant_attributes", {**key, "value": _stored_text(value)})
            elif stored[name] != value:
                st.update("participant_attributes", key, {"value": _stored_text(value)})
    return given


# ---------------------------------------------------------------------------------------------- occasions
def occasions(st, instrument: str | None = None) -> tuple:
    """The occasions (:class:`study.folder.occasions.Occasion`) on which `instrument` (None = the study's) is answered."""
    from study.folder.occasions import occasions_of

    return occasions_of(_study(st), instrument_of(st, instrument).name)


def several_occasions(st) -> bool:
    """True when the store's study has more than one questionnaire occasion (files then carry an occasion column)."""
    from study.folder.occasions import several

    return several(_study(st))


def target(st, instrument: str | None = None, occasion: str | None = None,
           participant_id: str | None = None) -> tuple[Instrument, str]:
    """(instrument, occasion) of one questionnaire: `occasion` names a questionnaire phase (its instrument is the
    default for `instrument`); without one, the instrument's only occasion, else the questionnaire phase
    `participant_id` is in. An occasion the instrument is not answered on, or an instrument answered on several
    occasions without a way to choose -> UserError listing them."""
    from study.folder.occasions import base_name, study_occasions

    study = _study(st)
    if instrument is None and occasion is not None:
        match = [o for o in study_occasions(study) if o.name == occasion]
        if match:
            instrument = match[0].instrument
    ins = instrument_of(st, instrument)
    mine = [o.name for o in study_occasions(study) if base_name(o.instrument) == base_name(ins.name)]
    if not mine:
        raise UserError(f"instrument {ins.name} is answered in no questionnaire phase of study {study.study_id}")
    if occasion is not None:
        if occasion not in mine:
            raise UserError(f"unknown occasion {occasion!r} for instrument {ins.name} (its questionnaire phases: "
                            f"{', '.join(mine)})")
        return ins, occasion
    if len(mine) == 1:
        return ins, mine[0]
    if participant_id is not None:
        current = st.one("SELECT phase FROM phase_events WHERE participant_id = ? AND outcome = 'in_progress'",
                         [participant_id])
        if current in mine:
            return ins, current
    raise UserError(f"instrument {ins.name} is answered on {len(mine)} occasions ({', '.join(mine)}): "
                    f"name one with --occasion")


def _occasion_of_rates(st, ins: Instrument) -> dict[str, str | None]:
    """occasion -> the condition it rates, for the occasions of `ins`."""
    return {o.name: o.rates for o in occasions(st, ins.name)}


# ---------------------------------------------------------------------------------------------- links
def hash_token(token: str) -> str:
    """SHA-256 hex of a link token (the store keeps only this)."""
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def issue_link(st, participant_id: str, instrument: str | None = None, occasion: str | None = None) -> str:
    """A new one-participant link token (URL-safe, 256 bits) for one questionnaire (:func:`target`: an occasion,
    by default the instrument's only one or the questionnaire phase the participant is in); earlier links of the
    participant for the same questionnaire are revoked (links of other occasions stay).

    Refused for unknown participants and for participants whose answers of that occasion are already stored.
    """
    _require_participant(st, participant_id)
    ins, occasion = target(st, instrument, occasion, participant_id)
    instrument = ins.name
    sub = submission(st, participant_id, 1, instrument, occasion)
    if sub is not None:
        raise UserError(f"{participant_id} already has survey answers{_at(st, occasion)} ({sub['source']}, "
                        f"{when(sub['submitted_at'])} UTC); no new link issued")
    token = secrets.token_urlsafe(32)
    now = utcnow()
    with st.transaction():
        _revoke_active(st, participant_id, instrument, occasion, now)
        st.insert("survey_tokens", {"token_hash": hash_token(token), "participant_id": participant_id,
                                    "instrument": instrument, "issued_at": now, "issued_by": st.actor,
                                    "occasion": occasion})
    return token


def _at(st, occasion: str) -> str:
    """' at <occasion>' in messages of a study with several occasions, '' otherwise (its messages stay as they were)."""
    return f" at {occasion}" if several_occasions(st) else ""


def revoke_links(st, participant_id: str, instrument: str | None = None, occasion: str | None = None) -> int:
    """Revoke every active link of a participant for one questionnaire (:func:`target`); how many were revoked.
    UserError when the participant is unknown or has no active link."""
    _require_participant(st, participant_id)
    ins, occasion = target(st, instrument, occasion, participant_id)
    with st.transaction():
        n = _revoke_active(st, participant_id, ins.name, occasion, utcnow())
        if not n:
            raise UserError(f"{participant_id} has no active survey link{_at(st, occasion)}")
    return n


def _revoke_active(st, participant_id: str, instrument: str, occasion: str, now) -> int:
    active = st.con.execute("SELECT token_hash FROM survey_tokens WHERE participant_id = ? AND instrument = ? "
                            "AND occasion = ? AND revoked_at IS NULL", [participant_id, instrument, occasion]
                            ).fetchall()
    for (h,) in active:
        st.update("survey_tokens", {"token_hash": h}, {"revoked_at": now})
    return len(active)


def resolve_token(st, token: str) -> Link:
    """The link a token grants, or LinkError: 404 malformed/unknown, 403 replaced by a newer link."""
    if not isinstance(token, str) or not _TOKEN.match(token):
        raise LinkError("This survey link is not valid. Please check the address or ask the researcher for a "
                        "new link.", 404)
    row = st.con.execute("SELECT participant_id, instrument, revoked_at, occasion FROM survey_tokens "
                         "WHERE token_hash = ?", [hash_token(token)]).fetchone()
    if row is None:
        raise LinkError("This survey link is not valid. Please check the address or ask the researcher for a "
                        "new link.", 404)
    pid, instrument, revoked, occasion = row
    if revoked is not None:
        raise LinkError("This survey link has been replaced by a newer one. Please ask the researcher.", 403)
    return Link(pid, instrument, submission(st, pid, 1, instrument, occasion) is not None, occasion)


# ---------------------------------------------------------------------------------------------- web drafts
def save_draft(st, participant_id: str, answers: Mapping[str, Any],
               instrument: str | None = None, occasion: str | None = None) -> dict[str, Answer]:
    """Keep the given answers of a participant's unsubmitted web survey of one occasion (upsert per item; ''
    clears one).

    All answers are validated first against the codebook (item known, value within scale_min..scale_max, a
    declared choice, text not too long) and an attribute item's value against its participant attribute; one
    bad answer stores none of them. Refused after submission.
    """
    ins, occasion = target(st, instrument, occasion)
    instrument = ins.name
    parsed = parse_answers(ins, answers)
    study = _study(st)
    for item, name in attribute_items(ins).items():
        if item in parsed:
            attribute_value(ins, item, parsed[item], study.attribute(name))
    if submission(st, participant_id, 1, instrument, occasion) is not None:
        raise SubmittedError("This survey has been submitted and can no longer be changed.")
    now = utcnow()
    with st.transaction():
        for item, a in parsed.items():
            st.con.execute(
                "INSERT INTO survey_drafts (participant_id, instrument, item_id, value, text, saved_at, occasion) "
                "VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT (participant_id, instrument, occasion, item_id) "
                "DO UPDATE SET value = excluded.value, text = excluded.text, saved_at = excluded.saved_at",
                [participant_id, instrument, item, a.value, a.text, now, occasion])
    return parsed


def draft(st, participant_id: str, instrument: str | None = None, occasion: str | None = None) -> dict[str, Answer]:
    """The participant's saved, unsubmitted web answers of one occasion {item_id: Answer}."""
    ins, occasion = target(st, instrument, occasion)
    return _rows_to_answers(st.df("SELECT item_id, value, text FROM survey_drafts WHERE participant_id = ? "
                                  "AND instrument = ? AND occasion = ?", [participant_id, ins.name, occasion]))


def missing_required(ins: Instrument, answers: Mapping[str, Answer]) -> list[str]:
    """Required items without an answer, in questionnaire order."""
    return [i for i in ins.required_items if i not in answers or answers[i].missing]


def submit_web(st, participant_id: str, instrument: str | None = None, occasion: str | None = None) -> int:
    """Submit a participant's web survey of one occasion atomically; returns the number of `responses` rows written.

    Required items must be answered. In one transaction: the attribute items' answers fill the participant's
    attributes (:func:`_fill_attributes`: checked with the study's declarations and checks), one `responses` row
    per other item (NULL where unanswered) is written as entry round 1 by ``participant``, the submission is
    recorded as a single (final) entry and the draft is deleted. Any refusal leaves the store unchanged.
    """
    ins, occasion = target(st, instrument, occasion)
    instrument = ins.name
    answers = draft(st, participant_id, instrument, occasion)
    if submission(st, participant_id, 1, instrument, occasion) is not None:
        raise SubmittedError("This survey has already been submitted.")
    missing = missing_required(ins, answers)
    if missing:
        raise UserError(f"please answer every question before submitting ({len(missing)} unanswered: "
                        f"{', '.join(missing)})")
    now = utcnow()
    with st.transaction():
        _fill_attributes(st, ins, participant_id, answers)
        n = _write_round(st, ins, participant_id, 1, answers, WEB_ENTERED_BY, now, occasion)
        st.insert("survey_submissions", {"participant_id": participant_id, "instrument": instrument,
                                         "entry_round": 1, "source": "web", "double_entry": False,
                                         "submitted_by": WEB_ENTERED_BY, "submitted_at": now, "occasion": occasion})
        st.con.execute("DELETE FROM survey_drafts WHERE participant_id = ? AND instrument = ? AND occasion = ?",
                       [participant_id, instrument, occasion])
    return n


def _write_round(st, ins: Instrument, participant_id: str, entry_round: int, answers: Mapping[str, Answer],
                 entered_by: str, now, occasion: str) -> int:
    """Insert or update (audited) one row per response item of one entry round; returns rows touched."""
    existing = _rows_to_answers(st.df(
        "SELECT item_id, value, text FROM responses WHERE participant_id = ? AND instrument = ? AND occasion = ? "
        "AND entry_round = ?", [participant_id, ins.name, occasion, entry_round]))
    n = 0
    new_rows = []
    for item in response_items(ins):
        a = answers.get(item, Answer())
        key = {"participant_id": participant_id, "instrument": ins.name, "item_id": item, "entry_round": entry_round,
               "occasion": occasion}
        if item not in existing:
            new_rows.append({**key, "value": a.value, "text": a.text, "entered_by": entered_by, "entered_at": now})
            n += 1
        elif existing[item] != a:
            st.update("responses", key, {"value": a.value, "text": a.text, "entered_by": entered_by,
                                         "entered_at": now})
            n += 1
    insert_audited(st, "responses", new_rows)
    return n


def insert_audited(st, table: str, rows: list[dict]) -> None:
    """Insert many rows with one audit_log row each, in the format of :meth:`Store.insert` (key, new row).

    The bulk path of ``Store.insert_df`` plus the audit rows in one statement (about 2x faster than one audited
    ``INSERT ... RETURNING`` per answer, same audit trail). Every column is given, so the stored row is `rows`.
    """
    if not rows:
        return
    cols = st.columns(table)
    df = pd.DataFrame(rows, columns=[c for c in cols if c in rows[0]]).astype(object)
    df = df.where(df.notna(), None)
    keys = st.key_columns(table) or list(df.columns)
    at = utcnow()
    log = pd.DataFrame({
        "at": [at] * len(rows), "actor": [st.actor] * len(rows), "action": ["insert"] * len(rows),
        "table_name": [table] * len(rows),
        "row_key": [audit_trail.to_json({k: r[k] for k in keys}) for r in rows],
        "old": pd.Series([None] * len(rows), dtype=object),
        "new": [audit_trail.to_json({c: r.get(c) for c in df.columns}) for r in rows]})
    with st.transaction():
        st.insert_df(table, df)
        st.insert_df("audit_log", log)


# ---------------------------------------------------------------------------------------------- data entry
def submission(st, participant_id: str, entry_round: int, instrument: str | None = None,
               occasion: str | None = None) -> dict | None:
    """The survey_submissions row of one entry round of one occasion, or None."""
    ins, occasion = target(st, instrument, occasion)
    rows = st.dicts("SELECT * FROM survey_submissions WHERE participant_id = ? AND instrument = ? "
                    "AND occasion = ? AND entry_round = ?", [participant_id, ins.name, occasion, entry_round])
    return rows[0] if rows else None


def entry_answers(st, participant_id: str, entry_round: int,
                  instrument: str | None = None, occasion: str | None = None) -> dict[str, Answer]:
    """The stored answers of one entry round of one occasion {item_id: Answer} (empty when not entered)."""
    ins, occasion = target(st, instrument, occasion)
    return _rows_to_answers(st.df(
        "SELECT item_id, value, text FROM responses WHERE participant_id = ? AND instrument = ? AND occasion = ? "
        "AND entry_round = ?", [participant_id, ins.name, occasion, entry_round]))


def save_entry(st, participant_id: str, entry_round: int, answers: Mapping[str, Any], *,
               instrument: str | None = None, double_entry: bool = True, source: str = "entry",
               replace: bool = False, occasion: str | None = None) -> int:
    """Store one complete entry round of a participant's survey of one occasion (items not given are stored as
    missing).

    `double_entry=True` (paper forms): round 1 and round 2 are typed in by two people and compared;
    `double_entry=False` (only round 1): a single electronic entry, final as is. `replace=True` lets a
    researcher correct an existing double-entry round (each changed item audited). Returns rows written.

    Attribute items (the codebook's `attribute` column) fill the participant's attributes: accepted in a single
    entry (final as entered, :func:`_fill_attributes`), refused in a double entry (two typists' values are not
    compared for attributes; record them on the participant).
    """
    ins, occasion = target(st, instrument, occasion)
    instrument = ins.name
    if entry_round not in (1, 2):
        raise UserError(f"entry round must be 1 or 2, not {entry_round}")
    _require_participant(st, participant_id)
    parsed = parse_answers(ins, answers, None if not double_entry else response_items(ins))
    first = submission(st, participant_id, 1, instrument, occasion)
    this = submission(st, participant_id, entry_round, instrument, occasion)
    at = _at(st, occasion)
    if first is not None and not first["double_entry"]:
        raise UserError(f"{participant_id} already has final survey answers{at} from a single {first['source']} "
                        f"entry")
    if entry_round == 2:
        if not double_entry:
            raise UserError("a second entry round is always part of a double entry")
        if first is None:
            raise UserError(f"{participant_id}: enter round 1 before round 2{at}")
    elif not double_entry and (first is not None or submission(st, participant_id, 2, instrument, occasion)
                               is not None):
        raise UserError(f"{participant_id} already has double-entry answers{at}; a single entry cannot replace them")
    if this is not None and not replace:
        raise UserError(f"{participant_id} already has entry round {entry_round}{at} "
                        f"(by {this['submitted_by']}, {when(this['submitted_at'])} UTC)")
    now = utcnow()
    with st.transaction():
        if not double_entry:
            _fill_attributes(st, ins, participant_id, parsed)
        n = _write_round(st, ins, participant_id, entry_round, parsed, st.actor, now, occasion)
        if this is None:
            st.insert("survey_submissions", {"participant_id": participant_id, "instrument": instrument,
                                             "entry_round": entry_round, "source": source,
                                             "double_entry": double_entry, "submitted_by": st.actor,
                                             "submitted_at": now, "occasion": occasion})
    return n


# ---------------------------------------------------------------------------------------------- discrepancies
def _chosen(st, instrument: str | None, occasion: str | None) -> tuple[Instrument, list[str], bool]:
    """(instrument, the occasions a listing covers, whether it shows an occasion column): one named occasion, or
    every occasion of the instrument (the column only when it has several)."""
    if occasion is not None:
        ins, occasion = target(st, instrument, occasion)
        return ins, [occasion], False
    ins = instrument_of(st, instrument)
    names = [o.name for o in occasions(st, ins.name)]
    if not names:
        raise UserError(f"instrument {ins.name} is answered in no questionnaire phase")
    return ins, names, len(names) > 1


def discrepancies(st, instrument: str | None = None, occasion: str | None = None) -> pd.DataFrame:
    """Every item where the two entries of a double data entry differ.

    Columns: participant_id, item_id, value_1, text_1, value_2, text_2, entered_by_1, entered_by_2,
    resolved (bool), resolved_value, resolved_text, resolved_by; `occasion` after participant_id when the
    instrument is answered on several occasions and none is named. Missing vs. a value counts as a difference.
    """
    ins, names, show = _chosen(st, instrument, occasion)
    df = st.df("""
        SELECT r1.participant_id, r1.occasion, r1.item_id, r1.value AS value_1, r1.text AS text_1,
               r2.value AS value_2, r2.text AS text_2, r1.entered_by AS entered_by_1, r2.entered_by AS entered_by_2,
               res.participant_id IS NOT NULL AS resolved, res.value AS resolved_value, res.text AS resolved_text,
               res.resolved_by, it.position, list_position(?, r1.occasion) AS occ_pos
        FROM responses r1
        JOIN responses r2 ON r2.participant_id = r1.participant_id AND r2.instrument = r1.instrument
                         AND r2.occasion = r1.occasion AND r2.item_id = r1.item_id AND r2.entry_round = 2
        LEFT JOIN survey_resolutions res ON res.participant_id = r1.participant_id
                         AND res.instrument = r1.instrument AND res.occasion = r1.occasion
                         AND res.item_id = r1.item_id
        LEFT JOIN items it ON it.instrument = r1.instrument AND it.item_id = r1.item_id
        WHERE r1.instrument = ? AND list_contains(?, r1.occasion) AND r1.entry_round = 1
          AND (r1.value IS DISTINCT FROM r2.value OR r1.text IS DISTINCT FROM r2.text)
        ORDER BY r1.participant_id, occ_pos, it.position, r1.item_id""", [names, ins.name, names])
    df = df.drop(columns=["position", "occ_pos"] + ([] if show else ["occasion"]))
    for c in ("value_1", "value_2", "resolved_value"):
        df[c] = df[c].astype("Int64")
    df["resolved"] = df["resolved"].astype(bool)
    return df.reset_index(drop=True)


def resolve(st, participant_id: str, item_id: str, raw: Any, note: str | None = None,
            instrument: str | None = None, occasion: str | None = None) -> Answer:
    """Record the final value of a double-entry discrepancy of one occasion (audited); '' / None = missing on the
    form.

    Only items listed by :func:`discrepancies` can be resolved; resolving again replaces the value. An unknown
    participant is said as such (not as "no discrepancy").
    """
    if not participant_exists(st, participant_id):
        raise UserError(f"unknown participant {participant_id}")
    ins, occasion = target(st, instrument, occasion)
    instrument = ins.name
    parsed = parse_answers(ins, {item_id: raw}, response_items(ins))[item_id]
    d = discrepancies(st, instrument, occasion)
    if not ((d["participant_id"] == participant_id) & (d["item_id"] == item_id)).any():
        raise UserError(f"{participant_id} {item_id}: no discrepancy between the two entries to resolve"
                        f"{_at(st, occasion)}")
    key = {"participant_id": participant_id, "instrument": instrument, "item_id": item_id, "occasion": occasion}
    values = {"value": parsed.value, "text": parsed.text, "note": note or None, "resolved_by": st.actor,
              "resolved_at": utcnow()}
    with st.transaction():
        if st.one("SELECT count(*) FROM survey_resolutions WHERE participant_id = ? AND instrument = ? "
                  "AND occasion = ? AND item_id = ?", [participant_id, instrument, occasion, item_id]):
            st.update("survey_resolutions", key, values)
        else:
            st.insert("survey_resolutions", {**key, **values})
    return parsed


# ---------------------------------------------------------------------------------------------- final answers
def _final_long(st, instrument: str, occasion: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(final answers of one occasion long: participant_id, item_id, value, text, basis; per-participant status)."""
    key = ["participant_id", "item_id"]
    resp = st.df("SELECT participant_id, item_id, entry_round, value, text FROM responses WHERE instrument = ? "
                 "AND occasion = ?", [instrument, occasion])
    subs = st.df("SELECT participant_id, double_entry FROM survey_submissions WHERE instrument = ? "
                 "AND occasion = ? AND entry_round = 1", [instrument, occasion])
    res = st.df("SELECT participant_id, item_id, value AS value_r, text AS text_r, true AS has_res "
                "FROM survey_resolutions WHERE instrument = ? AND occasion = ?", [instrument, occasion])
    r1 = resp[resp["entry_round"] == 1].drop(columns="entry_round")
    r2 = resp[resp["entry_round"] == 2].drop(columns="entry_round")
    m = r1.merge(r2, on=key, how="outer", suffixes=("_1", "_2"), indicator="present")
    m = m.merge(res, on=key, how="left")
    m["has_res"] = m["has_res"].astype("boolean").fillna(False).astype(bool)
    m["same"] = (m["present"] == "both") & _eq(m["value_1"], m["value_2"]) & _eq(m["text_1"], m["text_2"])
    pids = sorted(set(resp["participant_id"]))
    has1, has2 = set(r1["participant_id"]), set(r2["participant_id"])
    flagged = set(subs.loc[subs["double_entry"].astype(bool), "participant_id"])
    double = {p for p in pids if p in flagged or p in has2}
    m["double"] = m["participant_id"].isin(double)
    m["disc"] = m["double"] & ~m["same"]
    m["open"] = m["disc"] & ~m["has_res"]
    per = m.groupby("participant_id").agg(discrepancies=("disc", "sum"), unresolved=("open", "sum"))
    status = []
    for p in pids:
        basis = ("single" if p not in double else "awaiting_second_entry" if p not in has1 or p not in has2
                 else "unresolved" if per.loc[p, "unresolved"] else "double_entry_final")
        status.append({"participant_id": p, "basis": basis,
                       "discrepancies": int(per.loc[p, "discrepancies"]) if basis != "awaiting_second_entry" else 0,
                       "unresolved": int(per.loc[p, "unresolved"]) if basis != "awaiting_second_entry" else 0,
                       "final": basis in ("single", "double_entry_final")})
    status = pd.DataFrame(status, columns=["participant_id", "basis", "discrepancies", "unresolved", "final"])
    final_pids = set(status.loc[status["final"], "participant_id"])
    f = m[m["participant_id"].isin(final_pids)].copy()
    single = ~f["double"]
    f = f[single | f["has_res"] | f["same"]]
    use_res = f["has_res"] & f["double"]            # resolution wins over the entries (double entry only)
    f["value"] = f["value_1"].where(~use_res, f["value_r"])
    f["text"] = f["text_1"].where(~use_res, f["text_r"])
    f["basis"] = "agreed"
    f.loc[~f["double"], "basis"] = "single"
    f.loc[use_res, "basis"] = "resolved"
    long = f[["participant_id", "item_id", "value", "text", "basis"]].reset_index(drop=True)
    return long, status


def _eq(a: pd.Series, b: pd.Series) -> pd.Series:
    """Element-wise equality where missing == missing."""
    both_na = a.isna() & b.isna()
    eq = (a == b)
    if hasattr(eq, "fillna"):
        eq = eq.astype("boolean").fillna(False).astype(bool)
    return both_na | eq


def final_responses(st, instrument: str | None = None, occasion: str | None = None) -> pd.DataFrame:
    """The final survey answers, wide, in the survey CSV format of docs/contracts.md.

    Columns: participant_id, then every item of the instrument in codebook order: numeric items (scaled, number,
    choice) as float (NaN = missing; raw answers as ticked, reverse-scored items NOT reversed), free-text items
    as str or None. An item that fills a participant attribute shows the participant's stored attribute as that
    item's answer (:func:`item_answer`: the choice code, the number). One row per participant whose answers are
    final: a single electronic entry as is; a double entry where per item the two entries agree or a resolution
    was recorded (resolution wins). Participants still awaiting their second entry or with unresolved
    discrepancies are left out (see :func:`survey_status`). Exclusions are not applied here.

    Occasions: `occasion` names one (the rows of that questionnaire phase, the columns above). Without one, an
    instrument answered on one occasion gives that occasion's rows (the file of a study without occasions, as it
    always was); one answered on several gives one row per participant and occasion (final there), ordered by
    participant and the occasions' order in the protocol, with ``occasion`` after participant_id and, when an
    occasion rates a condition, ``condition`` (the rated condition, empty for an occasion that rates none).
    """
    ins, names, show = _chosen(st, instrument, occasion)
    frames = []
    for name in names:
        df = _final_wide(st, ins, name)
        if show:
            df.insert(1, "occasion", pd.Series([name] * len(df), dtype=object))
        frames.append(df)
    out = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    if show:
        rates = _occasion_of_rates(st, ins)
        if any(rates.values()):
            out.insert(2, "condition", pd.Series([rates.get(o) for o in out["occasion"]], dtype=object))
        order = {n: k for k, n in enumerate(names)}
        out = out.assign(_o=out["occasion"].map(order)).sort_values(["participant_id", "_o"], kind="stable")
        out = out.drop(columns="_o").reset_index(drop=True)
    out.attrs["instrument"] = ins.name
    return out


def _final_wide(st, ins: Instrument, occasion: str) -> pd.DataFrame:
    """The final answers of one occasion, one row per participant (:func:`final_responses`' columns)."""
    from study.people.participants import participant_attributes

    long, _ = _final_long(st, ins.name, occasion)
    pids = sorted(long["participant_id"].unique())
    values = long.pivot(index="participant_id", columns="item_id", values="value").reindex(index=pids)
    texts = long.pivot(index="participant_id", columns="item_id", values="text").reindex(index=pids)
    filled = attribute_items(ins)
    study = _study(st)
    attrs = participant_attributes(st, pids).set_index("participant_id").reindex(pids) if filled else None
    out = pd.DataFrame({"participant_id": pd.Series(pids, dtype=object)})
    for item in ins.items.index:
        is_text = ins.items.loc[item, "response_type"] == "text"
        if item in filled:
            name = filled[item]
            try:
                attribute = study.attribute(name)
            except UserError:  # an attribute the study no longer declares: nothing to show
                col = [None] * len(pids)
            else:
                col = [item_answer(ins, item, attribute, v) for v in (attrs[name] if name in attrs else
                                                                      [None] * len(pids))]
        else:
            src = texts if is_text else values
            col = src[item].tolist() if item in src else [None] * len(pids)
        if is_text:
            out[item] = pd.Series([None if (v is None or (isinstance(v, float) and v != v) or v is pd.NA)
                                   else str(v) for v in col], dtype=object)
        else:
            out[item] = pd.to_numeric(pd.Series(col, dtype=object), errors="coerce").astype("float64").to_numpy()
    return out


STATUS_COLUMNS = ["participant_id", "link", "draft_items", "entry_1", "entry_2", "basis", "discrepancies",
                  "unresolved", "final"]


def survey_status(st, instrument: str | None = None, occasion: str | None = None) -> pd.DataFrame:
    """One row per participant: link (none|issued|revoked), draft_items, entry_1/entry_2 (source or ''),
    basis (none|single|awaiting_second_entry|unresolved|double_entry_final), discrepancies, unresolved, final.
    For an instrument answered on several occasions and no `occasion` named: one row per participant and occasion,
    with ``occasion`` after participant_id."""
    ins, names, show = _chosen(st, instrument, occasion)
    frames = [_status_of(st, ins.name, name) for name in names]
    if not show:
        return frames[0]
    for name, df in zip(names, frames):
        df.insert(1, "occasion", name)
    order = {n: k for k, n in enumerate(names)}
    out = pd.concat(frames, ignore_index=True)
    out = out.assign(_o=out["occasion"].map(order)).sort_values(["participant_id", "_o"], kind="stable")
    return out.drop(columns="_o").reset_index(drop=True)


def _status_of(st, instrument: str, occasion: str) -> pd.DataFrame:
    parts = st.df("SELECT participant_id FROM participants ORDER BY participant_id")
    links = st.df("SELECT participant_id, bool_or(revoked_at IS NULL) AS active FROM survey_tokens "
                  "WHERE instrument = ? AND occasion = ? GROUP BY participant_id", [instrument, occasion]
                  ).set_index("participant_id")["active"]
    drafts = st.df("SELECT participant_id, count(*) AS n FROM survey_drafts WHERE instrument = ? AND occasion = ? "
                   "GROUP BY participant_id", [instrument, occasion]).set_index("participant_id")["n"]
    subs = st.df("SELECT participant_id, entry_round, source FROM survey_submissions WHERE instrument = ? "
                 "AND occasion = ?", [instrument, occasion])
    _, status = _final_long(st, instrument, occasion)
    status = status.set_index("participant_id")
    rows = []
    for pid in parts["participant_id"]:
        s = subs[subs["participant_id"] == pid]
        src = {int(r.entry_round): r.source for r in s.itertuples()}
        st_row = status.loc[pid] if pid in status.index else None
        rows.append({
            "participant_id": pid,
            "link": "none" if pid not in links.index else ("issued" if links[pid] else "revoked"),
            "draft_items": int(drafts.get(pid, 0)),
            "entry_1": src.get(1, ""), "entry_2": src.get(2, ""),
            "basis": "none" if st_row is None else st_row["basis"],
            "discrepancies": 0 if st_row is None else int(st_row["discrepancies"]),
            "unresolved": 0 if st_row is None else int(st_row["unresolved"]),
            "final": False if st_row is None else bool(st_row["final"]),
        })
    return pd.DataFrame(rows, columns=STATUS_COLUMNS)

"""Recording a participant's way through the study protocol.

A protocol is a JSON file of a study folder (declared in its ``study.toml``, docs/study_folder.md) with an ordered
list of ``phases``; the file as data (:class:`Protocol`, :func:`parse_protocol`) is :mod:`study.folder.protocol_file`. The
store's protocols come from its stored study: :func:`load_protocol`.

Semantics of the phase log (table ``phase_events``, one row per phase a participant entered):

* :func:`advance` starts the next phase. The phase must be exactly the one after the last recorded phase
  (the first phase for a new participant); anything else is refused as out of order. A phase still in
  progress is completed at the moment the next one starts.
* :func:`abort` ends the phase in progress with outcome ``aborted`` and a reason (e.g. motion sickness).
  The participant may still advance afterwards (a technical issue in one drive need not stop the survey)
  unless excluded with scope ``all``: such a participant's protocol is closed.
* :func:`complete` ends the phase in progress with outcome ``completed`` without starting another (the end of
  the last phase, or a stop after an aborted drive).

:func:`apply_events` applies a file of such events (one row each, in file order) in one transaction, all or nothing.
"""
from __future__ import annotations

from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from study.common.errors import UserError, check_choice
from study.common.times import when
from study.folder.protocol_file import Protocol
from study.people.orders import ensure_order, participant_protocol
from study.store.audit_trail import not_in_future, utcnow
from study.store.studies import definition

if TYPE_CHECKING:  # pandas for the DataFrames of status and apply_events: walking the protocol needs none
    import pandas as pd

    from study.common.bulk_rows import BulkRows


def load_protocol(st, name: str | None = None) -> Protocol:
    """A protocol of the store's study (`name` None = its default protocol); unknown name -> UserError."""
    return definition(st).protocol(name)


def protocol_of(st, participant_id: str) -> Protocol:
    """The protocol a registered participant follows (a multi-order protocol in the participant's order); unknown
    participant -> UserError."""
    return participant_protocol(st, participant_id)


_EVENTS = "SELECT * FROM phase_events WHERE participant_id = ? ORDER BY seq"


def _events(st, participant_id: str) -> pd.DataFrame:
    return st.df(_EVENTS, [participant_id])


def _event_rows(st, participant_id: str) -> list[dict[str, Any]]:
    """The participant's phase_events rows by seq, as dicts of Python values (what the writing steps read)."""
    return st.dicts(_EVENTS, [participant_id])


def _when(at: datetime | str | None) -> datetime:
    if at is None:
        return utcnow()
    if isinstance(at, str):
        try:
            at = datetime.fromisoformat(at)
        except ValueError:
            raise UserError(f"bad time {at!r} (use ISO 8601, e.g. 2026-05-04T09:30)") from None
    if at.tzinfo is not None:  # the store keeps UTC without zone
        at = at.astimezone(timezone.utc).replace(tzinfo=None)
    return not_in_future(at)  # a time not yet come would block the participant's next step


def _closed_by_exclusion(st, participant_id: str) -> str | None:
    return st.one("SELECT reason FROM exclusions WHERE participant_id = ? AND scope = 'all'", [participant_id])


def _end_current(st, participant_id: str, ev: list[dict[str, Any]], outcome: str, at: datetime,
                 note: str | None) -> str | None:
    cur = [e for e in ev if e["outcome"] == "in_progress"]
    if not cur:
        return None
    row = cur[-1]
    if at < row["started_at"]:
        raise UserError(f"end time {when(at, seconds=True)} is before the start of {row['phase']} "
                        f"({when(row['started_at'], seconds=True)})")
    values: dict[str, Any] = {"ended_at": at, "outcome": outcome}
    if note:
        old = row["note"] if isinstance(row["note"], str) else ""
        values["note"] = f"{old}; {note}" if old else note
    st.update("phase_events", {"participant_id": participant_id, "phase": row["phase"]}, values)
    return str(row["phase"])


def advance(st, participant_id: str, phase: str, note: str | None = None,
            at: datetime | str | None = None) -> dict[str, Any]:
    """Start `phase` for a participant, completing the phase in progress. Refuses unknown and out-of-order phases.

    Returns {"started": phase, "completed": previous phase or None}.
    """
    when = _when(at)
    with st.transaction():  # the order assignment too: a refused step leaves the store as it was
        reason = _closed_by_exclusion(st, participant_id)
        if reason:
            raise UserError(f"{participant_id} is excluded from all analyses ({reason}); the protocol is closed")
        ensure_order(st, participant_id)  # multi-order protocols: balanced assignment before the first phase
        proto = protocol_of(st, participant_id)
        idx = proto.index(phase)
        ev = _event_rows(st, participant_id)
        done = [e["phase"] for e in ev]
        if phase in done:
            raise UserError(f"{participant_id} already started {phase}")
        expected = proto.phases[len(done)] if len(done) < len(proto.phases) else None
        if phase != expected:
            raise UserError(f"phase out of order: {participant_id} is at "
                            f"{done[-1] if done else 'the start'}, next is {expected}, not {phase}")
        prev = _end_current(st, participant_id, ev, "completed", when, None)
        if ev and when < max(e["started_at"] for e in ev):
            raise UserError(f"start time {when(when, seconds=True)} is before the previous phase started")
        st.insert("phase_events", {"participant_id": participant_id, "phase": phase, "seq": idx + 1,
                                   "started_at": when, "outcome": "in_progress", "note": note})
    return {"started": phase, "completed": prev}


def abort(st, participant_id: str, reason: str, at: datetime | str | None = None) -> str:
    """End the phase in progress with outcome 'aborted' and `reason` as note; returns the phase name."""
    protocol_of(st, participant_id)
    if not reason or not reason.strip():
        raise UserError("an abort needs a reason")
    with st.transaction():
        phase = _end_current(st, participant_id, _event_rows(st, participant_id), "aborted", _when(at),
                             reason.strip())
        if phase is None:
            raise UserError(f"{participant_id} has no phase in progress to abort")
    return phase


def complete(st, participant_id: str, note: str | None = None, at: datetime | str | None = None) -> str:
    """End the phase in progress with outcome 'completed' without starting another; returns the phase name."""
    protocol_of(st, participant_id)
    with st.transaction():
        phase = _end_current(st, participant_id, _event_rows(st, participant_id), "completed", _when(at), note)
        if phase is None:
            raise UserError(f"{participant_id} has no phase in progress to complete")
    return phase


def status(st, participant_id: str) -> pd.DataFrame:
    """One row per protocol phase: phase, seq, planned_minutes, started_at, ended_at, minutes, outcome, note.

    Phases not yet entered have outcome 'pending' (or 'skipped' when a later phase was entered, which the
    refusal of out-of-order steps normally prevents).
    """
    import pandas as pd

    proto = protocol_of(st, participant_id)
    ev = _events(st, participant_id).set_index("phase")
    rows = []
    last_seq = int(ev["seq"].max()) if len(ev) else 0
    for i, p in enumerate(proto.steps, start=1):
        if p.name in ev.index:
            e = ev.loc[p.name]
            minutes = ((e["ended_at"] - e["started_at"]).total_seconds() / 60.0) if pd.notna(e["ended_at"]) else None
            rows.append({"phase": p.name, "seq": i, "planned_minutes": p.planned_minutes,
                         "started_at": e["started_at"], "ended_at": e["ended_at"], "minutes": minutes,
                         "outcome": e["outcome"], "note": e["note"] if isinstance(e["note"], str) else None})
        else:
            rows.append({"phase": p.name, "seq": i, "planned_minutes": p.planned_minutes, "started_at": None,
                         "ended_at": None, "minutes": None, "outcome": "skipped" if i < last_seq else "pending",
                         "note": None})
    return pd.DataFrame(rows)


#: the actions of an events file (:func:`apply_events`), each the single command of that name
ACTIONS = ("advance", "complete", "abort")
#: the columns of an events file: participant_id and phase are required
EVENT_COLUMNS = ("participant_id", "phase", "action", "at", "note", "reason")


def _in_progress(st, participant_id: str) -> str | None:
    return st.one("SELECT phase FROM phase_events WHERE participant_id = ? AND outcome = 'in_progress' "
                  "ORDER BY seq DESC LIMIT 1", [participant_id])


def _apply_one(st, pid: str, action: str, phase: str | None, at: str | None, note: str | None,
               reason: str | None) -> dict[str, Any]:
    """One row of an events file through the single-event function of its action."""
    if not pid:
        raise UserError("participant_id is empty")
    check_choice("action", action, ACTIONS)
    if reason is not None and action != "abort":
        raise UserError(f"a reason goes with action abort, not {action} (use note)")
    if action == "advance":
        if phase is None:
            raise UserError("advance needs a phase")
        r = advance(st, pid, phase, note=note, at=at)
        return {"phase": r["started"], "completed": r["completed"]}
    if note is not None and action == "abort":
        raise UserError("abort takes a reason, not a note")
    current = _in_progress(st, pid) if phase is not None else None
    if phase is not None and current is not None and current != phase:
        raise UserError(f"{pid} is in {current}, not {phase}: {action} ends the phase in progress")
    if action == "abort":
        return {"phase": abort(st, pid, reason or "", at=at), "completed": None}
    return {"phase": complete(st, pid, note=note, at=at), "completed": None}


def _usable(st) -> bool:
    """False when a refused statement aborted the store's transaction (only a rollback is possible then)."""
    import duckdb

    try:
        st.con.execute("SELECT 1")
        return True
    except duckdb.Error:
        return False


def apply_events(st, frame: "pd.DataFrame | BulkRows", source: str = "events") -> pd.DataFrame:
    """Apply many phase events in file order in one transaction: what `session advance`, `session complete` and
    `session abort` do one at a time, all or nothing.

    `frame`: columns ``participant_id``, ``phase`` and optionally ``action`` (advance | complete | abort; empty =
    advance), ``at`` (ISO 8601 as ``--at``; empty = now), ``note`` (advance, complete) and ``reason`` (abort,
    required there); its index names the row in messages (:func:`study.common.bulk_rows.read_rows` sets it to the line in
    the file; a :class:`study.common.bulk_rows.BulkRows` is taken the same way, its lines naming the rows). ``phase`` is
    the phase to start for advance; for complete and abort it may be empty, and when given it must be the phase in
    progress. Each row gets the checks of its single command (protocol order, times not
    going backwards nor in the future, exclusions, ...) against the store as the earlier rows left it, so one file
    can walk a participant through several phases. After a bad row, the same participant's later rows are not
    checked (each would fail for the first one). Any bad row -> :class:`study.common.bulk_rows.BadRows` naming each bad
    and each unchecked row; nothing is stored then. Another column -> UserError naming the columns.

    Returns one row per event: line (the frame's index), participant_id, action, phase (started for advance,
    ended for complete and abort), completed (the phase an advance completed, else None).
    """
    import pandas as pd

    done = apply_event_rows(st, frame, source)
    cols = ["line", "participant_id", "action", "phase", "completed"]
    # object columns: `completed` keeps None (not NaN) where an event completed nothing
    return pd.DataFrame({c: pd.Series([d[c] for d in done], dtype=None if c == "line" else object) for c in cols})


def apply_event_rows(st, frame: "pd.DataFrame | BulkRows", source: str = "events") -> list[dict[str, Any]]:
    """:func:`apply_events` without pandas: the applied events as dicts with the same keys, in file order."""
    from study.common.bulk_rows import BadRow, BadRows, cell, check_columns, records

    check_columns(frame, source, EVENT_COLUMNS[:2], EVENT_COLUMNS[2:])
    columns, rows = records(frame)
    bad: list[BadRow] = []
    unchecked: list[BadRow] = []
    failed: dict[str, Any] = {}   # participant -> line of their first bad row
    done = []
    with st.transaction():
        for line, row in rows:
            get = {c: cell(row[c]) if c in columns else None for c in EVENT_COLUMNS}
            pid, action = get["participant_id"] or "", get["action"] or "advance"
            if not _usable(st):
                unchecked.append(BadRow(line, pid, "not checked: the store refused an earlier row"))
                continue
            if pid in failed:
                unchecked.append(BadRow(line, pid, f"not checked: follows the bad line {failed[pid]} of {pid}"))
                continue
            try:
                r = _apply_one(st, pid, action, get["phase"], get["at"], get["note"], get["reason"])
            except UserError as exc:
                bad.append(BadRow(line, pid, str(exc)))
                if pid:
                    failed[pid] = line
                continue
            done.append({"line": line, "participant_id": pid, "action": action, **r})
        if bad:
            raise BadRows(source, bad, unchecked)
    return done

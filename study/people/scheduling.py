"""Scheduling: simulator appointments, day agenda, calendar export, planned vs actual.

Times of appointments are the lab's local wall-clock time (naive datetimes), the way a lab books a slot; the calendar
export writes them as floating local times (RFC 5545 §3.3.5), so a calendar shows them at the same clock time.

A slot lasts the planned duration of the participant's protocol (sum of its phases' ``planned_minutes``, as the
study's protocol file declares them) plus a buffer (default
:data:`study.people.defaults.DEFAULT_BUFFER_MINUTES`) for set-up, briefing and cleaning the simulator. Two booked slots on the same
simulator must not overlap; a participant holds at most one booked slot; excluded participants are not booked.

Booking a participant of a protocol with several ``orders`` assigns their order (balanced: :mod:`study.people.orders`).
"""
from __future__ import annotations

from datetime import date, datetime, timedelta
from pathlib import Path
from typing import Any

import pandas as pd

from study.common.errors import UserError
from study.common.times import when
from study.folder.protocol_file import planned_minutes
from study.people.defaults import DEFAULT_BUFFER_MINUTES, DEFAULT_SIMULATOR
from study.people.orders import ensure_order, exclusion_of, participant_row
from study.people.protocol import load_protocol, status

ACTIVE = "booked"
SIMULATOR_MAX = 40  # characters of a simulator name (the appointments table's CHECK)


# ---------------------------------------------------------------------------------------------- helpers
def parse_datetime(value: str | datetime) -> datetime:
    """ISO 8601 date-time (``2026-05-04T09:30`` or ``2026-05-04 09:30``) -> naive local datetime."""
    if isinstance(value, datetime):
        return value.replace(tzinfo=None)
    try:
        dt = datetime.fromisoformat(str(value).strip())
    except ValueError:
        raise UserError(f"malformed date-time {value!r} (use ISO 8601, e.g. 2026-05-04T09:30)") from None
    if dt.tzinfo is not None:
        raise UserError(f"give appointment times as the lab's local time without a zone, not {value!r}")
    return dt


def parse_date(value: str | date) -> date:
    if isinstance(value, date):
        return value
    try:
        return date.fromisoformat(str(value).strip())
    except ValueError:
        raise UserError(f"malformed date {value!r} (use ISO 8601, e.g. 2026-05-04)") from None


def _slot_end(start: datetime, length: timedelta) -> datetime:
    """`start` + `length`; UserError when the slot would end after 9999-12-31 23:59:59 (the last date-time)."""
    try:
        return start + length
    except OverflowError:
        raise UserError(f"a slot starting {when(start)} would end after 9999-12-31 (the latest date "
                        "there is); book an earlier slot") from None


def _simulator(name: str | None) -> str:
    """The simulator name stripped; UserError when it is empty or longer than SIMULATOR_MAX characters."""
    name = (name or "").strip()
    if not name:
        raise UserError("a simulator name is required")
    if len(name) > SIMULATOR_MAX:
        raise UserError(f"a simulator name has at most {SIMULATOR_MAX} characters, not {len(name)}")
    return name


def _active(st, participant_id: str) -> pd.DataFrame:
    return st.df("SELECT * FROM appointments WHERE participant_id = ? AND status = ?", [participant_id, ACTIVE])


def _check_free(st, simulator: str, start: datetime, end: datetime, ignore: int | None = None) -> None:
    clash = st.df("""SELECT appointment_id, participant_id, starts_at, ends_at FROM appointments
                     WHERE simulator = ? AND status = ? AND starts_at < ? AND ends_at > ?
                       AND appointment_id IS DISTINCT FROM ? ORDER BY starts_at LIMIT 1""",
                  [simulator, ACTIVE, end, start, ignore])
    if not clash.empty:
        c = clash.iloc[0]
        raise UserError(f"{simulator} is booked {when(c['starts_at'])}-{c['ends_at']:%H:%M} "
                        f"for {c['participant_id']}; the slot {when(start)}-{end:%H:%M} overlaps")


# ---------------------------------------------------------------------------------------------- appointments
def book(st, participant_id: str, at: str | datetime, simulator: str = DEFAULT_SIMULATOR,
         buffer_minutes: float = DEFAULT_BUFFER_MINUTES, now: datetime | None = None) -> dict[str, Any]:
    """Book a simulator slot starting `at` (local time) for the whole protocol plus `buffer_minutes`.

    Refused: unknown or excluded participant, a participant who already holds a booked slot (reschedule instead),
    a start in the past, a slot overlapping another booked slot on the same simulator. Multi-order protocols get
    the participant's order assigned here. Returns the stored appointment row.
    """
    start = parse_datetime(at)
    if start < (now or datetime.now()):
        raise UserError(f"{when(start)} is in the past; book a future slot")
    if not buffer_minutes >= 0:  # NaN too
        raise UserError(f"the buffer must be a number of minutes >= 0, not {buffer_minutes!r}")
    simulator = _simulator(simulator)
    p = participant_row(st, participant_id)
    proto = load_protocol(st, p["protocol"])
    minutes = planned_minutes(proto) + buffer_minutes
    if minutes <= 0:
        raise UserError(f"protocol {proto.name} plans no minutes; give a buffer to book a slot")
    try:
        length = timedelta(minutes=minutes)
    except (OverflowError, ValueError):  # too many minutes, or infinite
        raise UserError(f"a slot of {minutes:g} minutes is longer than any calendar; give a shorter buffer") from None
    end = _slot_end(start, length)
    with st.transaction():
        excluded = exclusion_of(st, participant_id)
        if excluded:
            raise UserError(f"{participant_id} is excluded ({excluded}) and cannot be booked")
        held = _active(st, participant_id)
        if not held.empty:
            raise UserError(f"{participant_id} already holds appointment {int(held.iloc[0]['appointment_id'])} "
                            f"at {when(held.iloc[0]['starts_at'])}; reschedule or cancel it")
        _check_free(st, simulator, start, end)
        ensure_order(st, participant_id)
        row = st.insert("appointments", {"participant_id": participant_id, "simulator": simulator,
                                         "starts_at": start, "ends_at": end, "status": ACTIVE,
                                         "protocol": proto.name})
    return row


def _held(st, participant_id: str) -> dict[str, Any]:
    participant_row(st, participant_id)
    held = _active(st, participant_id)
    if held.empty:
        raise UserError(f"{participant_id} holds no booked appointment")
    return held.iloc[0].to_dict()


def reschedule(st, participant_id: str, at: str | datetime, simulator: str | None = None,
               now: datetime | None = None) -> dict[str, Any]:
    """Move the participant's booked slot (same length) to `at`, optionally to another simulator; audited."""
    start = parse_datetime(at)
    if start < (now or datetime.now()):
        raise UserError(f"{when(start)} is in the past; reschedule to a future slot")
    with st.transaction():
        cur = _held(st, participant_id)
        sim = _simulator(simulator or cur["simulator"])
        end = _slot_end(start, cur["ends_at"] - cur["starts_at"])
        _check_free(st, sim, start, end, ignore=int(cur["appointment_id"]))
        return st.update("appointments", {"appointment_id": int(cur["appointment_id"])},
                         {"starts_at": start, "ends_at": end, "simulator": sim})


def set_status(st, participant_id: str, status: str, note: str | None = None) -> dict[str, Any]:
    """Close the participant's booked slot as cancelled | no_show | attended (audited); the slot becomes free."""
    if status not in ("cancelled", "no_show", "attended"):
        raise UserError(f"unknown appointment status {status!r}")
    with st.transaction():
        cur = _held(st, participant_id)
        values: dict[str, Any] = {"status": status}
        if note:
            values["note"] = note
        return st.update("appointments", {"appointment_id": int(cur["appointment_id"])}, values)


# ---------------------------------------------------------------------------------------------- views
def day_agenda(st, day: str | date, simulator: str | None = None) -> pd.DataFrame:
    """Appointments starting on `day` (all statuses), ordered by start: start, end, simulator, participant, status,
    protocol, order."""
    d = parse_date(day)
    return st.df("""
        SELECT strftime(a.starts_at, '%H:%M') AS start, strftime(a.ends_at, '%H:%M') AS "end", a.simulator,
               a.participant_id, a.status, a.protocol, o.order_name AS "order", a.appointment_id
        FROM appointments a LEFT JOIN order_assignments o USING (participant_id)
        WHERE CAST(a.starts_at AS DATE) = ? AND (? IS NULL OR a.simulator = ?)
        ORDER BY a.starts_at, a.simulator""", [d, simulator, simulator])


def to_ics(st, include_closed: bool = False) -> bytes:
    """RFC 5545 calendar: one VEVENT per appointment (booked ones, or all with `include_closed`); pseudonymous IDs
    only."""
    from icalendar import Calendar, Event

    cal = Calendar()
    cal.add("prodid", "-//pedas-study//scheduling//EN")
    cal.add("version", "2.0")
    rows = st.df("SELECT * FROM appointments" + ("" if include_closed else " WHERE status = 'booked'") +
                 " ORDER BY starts_at, appointment_id")
    stamp = datetime(2000, 1, 1)  # fixed DTSTAMP keeps the export reproducible for unchanged appointments
    for r in rows.itertuples():
        ev = Event()
        ev.add("uid", f"appointment-{r.appointment_id}@pedas-study")
        ev.add("dtstamp", stamp)
        ev.add("dtstart", r.starts_at.to_pydatetime())
        ev.add("dtend", r.ends_at.to_pydatetime())
        ev.add("summary", f"{r.participant_id} · {r.protocol}")
        ev.add("location", r.simulator)
        ev.add("status", "CANCELLED" if r.status in ("cancelled", "no_show") else "CONFIRMED")
        cal.add_component(ev)
    return cal.to_ical()


def export_ics(st, path: str | Path, include_closed: bool = False) -> int:
    """Write :func:`to_ics` to `path`; returns the number of events."""
    data = to_ics(st, include_closed)
    Path(path).write_bytes(data)
    return data.count(b"BEGIN:VEVENT")


def phase_durations(st, participant_id: str | None = None) -> pd.DataFrame:
    """Planned vs actual minutes per participant and phase from the recorded phase timestamps.

    Columns: participant_id, phase, planned_minutes, actual_minutes, delta_minutes, outcome. Phases not yet
    ended have no actual duration.
    """
    ids = [participant_id] if participant_id else st.df(
        "SELECT DISTINCT participant_id FROM phase_events ORDER BY 1")["participant_id"].tolist()
    frames = []
    for pid in ids:
        s = status(st, pid)
        s.insert(0, "participant_id", pid)
        frames.append(s)
    if not frames:
        return pd.DataFrame(columns=["participant_id", "phase", "planned_minutes", "actual_minutes",
                                     "delta_minutes", "outcome"])
    df = pd.concat(frames, ignore_index=True).rename(columns={"minutes": "actual_minutes"})
    df["actual_minutes"] = pd.to_numeric(df["actual_minutes"], errors="coerce")
    df["planned_minutes"] = pd.to_numeric(df["planned_minutes"], errors="coerce")
    df["delta_minutes"] = df["actual_minutes"] - df["planned_minutes"]
    return df[["participant_id", "phase", "planned_minutes", "actual_minutes", "delta_minutes", "outcome"]]

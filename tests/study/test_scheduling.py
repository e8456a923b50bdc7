"""Scheduling: protocol as data, appointments without double booking, balanced orders, agenda, iCalendar."""
from __future__ import annotations

from datetime import datetime, timedelta

import pytest

from study.common.errors import UserError
from study.people.protocol import load_protocol
from study.people.orders import assign_order, order_counts
from study.folder.protocol_file import planned_minutes, protocol_orders
from study.people.scheduling import book, day_agenda, phase_durations, reschedule, set_status, to_ics
from study.store.store import Store

FUTURE = (datetime.now() + timedelta(days=30)).replace(hour=9, minute=0, second=0, microsecond=0)  # a morning: +3 h stays that day


def _counts(st) -> dict[str, int]:
    return {t: st.one(f"SELECT count(*) FROM {t}") for t in ("appointments", "order_assignments", "audit_log")}


@pytest.fixture
def st(paper_db):
    with Store.open(paper_db, actor="tester") as st:
        from study.people.participants import add_participant
        for i in range(1, 4):
            add_participant(st, f"P{i:03d}", style="normal")
        yield st


def test_paper_protocol_is_data_with_planned_durations(st):
    proto = load_protocol(st, "paper_v1")
    assert proto.phases == ("familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey")
    assert planned_minutes(proto) == sum(p.planned_minutes for p in proto.steps) > 0
    assert protocol_orders(proto) == {"default": proto.phases}


def test_counterbalanced_protocol_has_two_orders_with_pedas_first_in_one(st):
    orders = protocol_orders(load_protocol(st, "counterbalanced_v1"))
    assert set(orders) == {"baseline_first", "pedas_first"}
    assert orders["pedas_first"].index("pedas_drive") < orders["pedas_first"].index("baseline_drive")
    assert orders["baseline_first"].index("baseline_drive") < orders["baseline_first"].index("pedas_drive")


def test_slot_length_is_protocol_plus_buffer(st):
    row = book(st, "P001", FUTURE, buffer_minutes=20)
    assert row["ends_at"] - row["starts_at"] == timedelta(minutes=planned_minutes(load_protocol(st, "paper_v1")) + 20)
    assert planned_minutes(load_protocol(st, "paper_v1")) == 10 + 20 + 10 + 10 + 20 + 15  # the file's phases


def test_slot_length_is_the_participants_protocol(lk_db):
    """A lane-keeping participant's slot lasts that study's protocol (5 + 8 + 8 + 10 min) plus the buffer."""
    from study.people.participants import add_participant

    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": 30})
        row = book(st, "LK-01", FUTURE, buffer_minutes=15)
        assert row["protocol"] == "lk_counterbalanced_v1"
        assert row["ends_at"] - row["starts_at"] == timedelta(minutes=31 + 15)
        # booking a counterbalanced participant assigns the order
        assert st.one("SELECT order_name FROM order_assignments") == "hud_first"


def test_overlap_on_same_simulator_refused_and_store_unchanged(st):
    book(st, "P001", FUTURE)
    before = _counts(st)
    with pytest.raises(UserError, match="overlaps"):
        book(st, "P002", FUTURE + timedelta(minutes=30))
    assert _counts(st) == before
    # another simulator at the same time is fine
    book(st, "P002", FUTURE + timedelta(minutes=30), simulator="sim2")


def test_back_to_back_slots_do_not_overlap(st):
    row = book(st, "P001", FUTURE)
    book(st, "P002", row["ends_at"])


def test_rescheduling_frees_the_old_slot(st):
    book(st, "P001", FUTURE)
    reschedule(st, "P001", FUTURE + timedelta(days=1))
    book(st, "P002", FUTURE)  # the old slot is free now
    moved = st.df("SELECT * FROM audit_log WHERE table_name = 'appointments' AND action = 'update'")
    assert len(moved) == 1


def test_reschedule_into_an_occupied_slot_refused(st):
    book(st, "P001", FUTURE)
    book(st, "P002", FUTURE + timedelta(days=1))
    with pytest.raises(UserError, match="overlaps"):
        reschedule(st, "P002", FUTURE + timedelta(minutes=10))


def test_cancel_and_no_show_free_the_slot(st):
    book(st, "P001", FUTURE)
    set_status(st, "P001", "no_show")
    book(st, "P002", FUTURE)
    set_status(st, "P002", "cancelled", note="ill")
    book(st, "P003", FUTURE)
    assert st.df("SELECT status FROM appointments ORDER BY appointment_id")["status"].tolist() == [
        "no_show", "cancelled", "booked"]


def test_excluded_participant_cannot_be_booked(st):
    from study.people.exclusions import exclude
    exclude(st, "P003", "all", "withdrawn")
    before = _counts(st)
    with pytest.raises(UserError, match="excluded"):
        book(st, "P003", FUTURE)
    assert _counts(st) == before


@pytest.mark.parametrize("bad, msg", [("2026-13-40T09:00", "malformed"), ("tomorrow", "malformed"),
                                      ("2020-01-01T09:00", "past")])
def test_bad_times_refused(st, bad, msg):
    before = _counts(st)
    with pytest.raises(UserError, match=msg):
        book(st, "P001", bad)
    assert _counts(st) == before


def test_balanced_orders_with_dropouts(paper_db):
    """10 participants on the counterbalanced protocol, 3 drop out: completed orders differ by at most one."""
    from study.people.exclusions import exclude
    from study.people.participants import add_participant
    from study.people.protocol import advance

    with Store.open(paper_db, actor="tester") as st:
        dropouts = {"P002", "P005", "P006"}
        completed: dict[str, str] = {}
        t = datetime(2026, 1, 5, 8, 0)
        for i in range(1, 11):
            pid = f"P{i:03d}"
            add_participant(st, pid, protocol="counterbalanced_v1")
            order = assign_order(st, pid)
            assert assign_order(st, pid) == order  # stored once
            phases = protocol_orders(load_protocol(st, "counterbalanced_v1"))[order]
            if pid in dropouts:
                advance(st, pid, phases[0], at=t)
                exclude(st, pid, "all", "withdrawn")
                continue
            for k, phase in enumerate(phases):
                advance(st, pid, phase, at=t + timedelta(minutes=10 * k))
            completed[pid] = order
            t += timedelta(days=1)
        per_order = order_counts(st, "counterbalanced_v1").set_index("order_name")["active"]
        assert per_order.sum() == 7
        assert per_order.max() - per_order.min() <= 1
        from collections import Counter
        c = Counter(completed.values())
        assert abs(c["baseline_first"] - c["pedas_first"]) <= 1
        # assignments are audited
        assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'order_assignments'") == 10


def test_counterbalanced_participant_follows_assigned_order(paper_db):
    from study.people.participants import add_participant
    from study.people.protocol import advance

    with Store.open(paper_db, actor="tester") as st:
        add_participant(st, "P001", protocol="counterbalanced_v1")
        add_participant(st, "P002", protocol="counterbalanced_v1")
        assert assign_order(st, "P001") == "baseline_first"  # tie -> first order in the file
        assert assign_order(st, "P002") == "pedas_first"
        advance(st, "P002", "familiarisation")
        with pytest.raises(UserError, match="out of order"):
            advance(st, "P002", "baseline_drive")
        advance(st, "P002", "pedas_intro")


@pytest.mark.parametrize("phase, msg", [("warmup", "unknown phase"), ("baseline_drive", "out of order")])
def test_refused_first_step_assigns_no_order(paper_db, phase, msg):
    """The first step of a counterbalanced participant assigns the order; a refused one leaves no trace."""
    from study.people.participants import add_participant
    from study.people.protocol import advance

    with Store.open(paper_db, actor="tester") as st:
        add_participant(st, "P001", protocol="counterbalanced_v1")
        before = _counts(st)
        with pytest.raises(UserError, match=msg):
            advance(st, "P001", phase)
        assert _counts(st) == before
        advance(st, "P001", "familiarisation")
        assert st.one("SELECT count(*) FROM order_assignments") == 1


def test_ics_parses_and_holds_every_appointment(st):
    from icalendar import Calendar

    for i, pid in enumerate(("P001", "P002", "P003")):
        book(st, pid, FUTURE + timedelta(days=i))
    cal = Calendar.from_ical(to_ics(st))
    events = [c for c in cal.walk("VEVENT")]
    assert len(events) == 3
    assert {str(e["summary"]).split(" ")[0] for e in events} == {"P001", "P002", "P003"}
    assert events[0].decoded("dtstart") == FUTURE
    assert to_ics(st) == to_ics(st)  # reproducible


def test_day_agenda_and_durations(st):
    from study.people.protocol import advance
    book(st, "P001", FUTURE)
    book(st, "P002", FUTURE + timedelta(hours=3))
    agenda = day_agenda(st, FUTURE.date())
    assert agenda["participant_id"].tolist() == ["P001", "P002"]
    t = datetime(2026, 1, 5, 8, 0)
    advance(st, "P003", "familiarisation", at=t)
    advance(st, "P003", "baseline_drive", at=t + timedelta(minutes=12))
    d = phase_durations(st, "P003").set_index("phase")
    assert d.loc["familiarisation", "actual_minutes"] == pytest.approx(12.0)
    assert d.loc["familiarisation", "delta_minutes"] == pytest.approx(12.0 - d.loc["familiarisation",
                                                                                   "planned_minutes"])


def test_cli_schedule_flow(cli, paper_db, tmp_path):
    assert cli("participant", "add", "P001").code == 0
    assert cli("participant", "add", "P002").code == 0
    at = FUTURE.strftime("%Y-%m-%dT%H:%M")
    r = cli("session", "schedule", "P001", "--at", at)
    assert r.code == 0, r.err
    r = cli("session", "schedule", "P002", "--at", at)
    assert r.code != 0 and "overlaps" in r.err and len(r.err.strip().splitlines()) == 1
    r = cli("session", "schedule", "P002", "--at", "not-a-date")
    assert r.code != 0 and "malformed" in r.err
    r = cli("participant", "add", "P003", "--protocol", "no_such_protocol")
    assert r.code == 2 and "unknown protocol 'no_such_protocol'" in r.err
    r = cli("schedule", "day", FUTURE.date().isoformat(), "--format", "csv")
    assert r.code == 0 and "P001" in r.out and "P002" not in r.out
    ics = tmp_path / "lab.ics"
    r = cli("schedule", "export", "--ics", ics)
    assert r.code == 0 and ics.read_bytes().count(b"BEGIN:VEVENT") == 1


def test_cli_appointment_life_cycle(cli, paper_db):
    """reschedule, cancel, no-show, attended, assign and durations through the CLI: each changes what it says,
    is audited, and a refused one leaves the store as it was."""
    for args in (("P001",), ("P002",), ("P003", "--protocol", "counterbalanced_v1")):
        assert cli("participant", "add", *args).code == 0
    at, later = FUTURE.strftime("%Y-%m-%dT%H:%M"), (FUTURE + timedelta(hours=3)).strftime("%Y-%m-%dT%H:%M")
    assert cli("session", "schedule", "P001", "--at", at).code == 0
    r = cli("session", "reschedule", "P001", "--at", later)
    assert r.code == 0, r.err
    assert cli("session", "schedule", "P002", "--at", at).code == 0         # the old slot is free again
    assert cli("session", "cancel", "P002", "--note", "ill").code == 0
    assert cli("session", "schedule", "P002", "--at", at).code == 0         # a cancelled slot is free
    assert cli("session", "no-show", "P002").code == 0
    assert cli("session", "attended", "P001").code == 0
    r = cli("session", "assign", "P003")
    assert r.code == 0 and "order" in r.out
    with Store.open(paper_db, read_only=True) as st:
        statuses = st.df("SELECT participant_id, status, note FROM appointments ORDER BY appointment_id")
        assert statuses[["participant_id", "status"]].values.tolist() == [
            ["P001", "attended"], ["P002", "cancelled"], ["P002", "no_show"]]
        assert statuses["note"].tolist()[1] == "ill"
        audited = st.df("SELECT action, new FROM audit_log WHERE table_name = 'appointments' "
                        "AND action = 'update' ORDER BY audit_id")
        assert [s for s in ("cancelled", "no_show", "attended") if any(s in str(v) for v in audited["new"])] == \
            ["cancelled", "no_show", "attended"]
        assert st.one("SELECT count(*) FROM order_assignments WHERE participant_id = 'P003'") == 1
        before = _counts(st)
    # refused: nothing booked any more, unknown participant
    for args, msg in ((("session", "cancel", "P001"), "holds no booked appointment"),
                      (("session", "reschedule", "P404", "--at", later), "P404")):
        r = cli(*args)
        assert r.code == 2 and msg in r.err and len(r.err.strip().splitlines()) == 1, r.err
    with Store.open(paper_db, read_only=True) as st:
        assert _counts(st) == before
    # planned vs actual durations from the recorded phases
    t0 = FUTURE - timedelta(days=40)
    for k, phase in enumerate(("familiarisation", "baseline_drive")):
        r = cli("session", "advance", "P001", phase, "--at", (t0 + timedelta(minutes=12 * k)).isoformat())
        assert r.code == 0, r.err
    r = cli("schedule", "durations", "P001", "--format", "csv")
    assert r.code == 0, r.err
    rows = [ln.split(",") for ln in r.out.strip().splitlines()]
    head, fam = rows[0], next(x for x in rows if "familiarisation" in x)
    assert float(fam[head.index("actual_minutes")]) == pytest.approx(12.0)

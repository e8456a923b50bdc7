"""The protocol definition and the phase log: order, abort, completion, status."""
import json
from pathlib import Path

import pytest

from study.common.errors import UserError
from study.people.exclusions import exclude
from study.people.participants import add_participant
from study.people.protocol import abort, advance, complete, load_protocol, protocol_of, status
from study.folder.protocol_file import parse_protocol
from study.store.store import Store

PHASES = ("familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey")
STUDIES = Path(__file__).resolve().parents[2] / "studies"


def test_paper_protocol_comes_from_the_stored_study(paper_db):
    with Store.open(paper_db) as st:
        p = load_protocol(st)
        assert load_protocol(st, "counterbalanced_v1").name == "counterbalanced_v1"
        with pytest.raises(UserError, match=r"unknown protocol 'paper_v9' \(study pedas_paper: paper_v1, "
                                            r"counterbalanced_v1\)"):
            load_protocol(st, "paper_v9")
    assert p.name == "paper_v1" and p.phases == PHASES
    assert [s.condition for s in p.steps if s.drive] == ["baseline", "pedas"]
    assert all(s.planned_minutes and s.planned_minutes > 0 for s in p.steps)


def test_parser_keeps_unknown_keys():
    data = json.loads((STUDIES / "pedas_paper" / "paper_v1.json").read_text())
    data["name"] = "x_v9"
    data["room"] = "sim-lab"
    data["phases"][0]["staff"] = 2
    p = parse_protocol(json.dumps(data), "x_v9.json")
    assert p.name == "x_v9" and p.phases == PHASES and p.extra["room"] == "sim-lab" and p.steps[0].extra["staff"] == 2


@pytest.mark.parametrize("change, msg", [
    (lambda d: d.update(phases=[]), "x.json: phases must be a non-empty list of distinct names"),
    (lambda d: d["phases"].append(dict(d["phases"][0])), "distinct names"),
    (lambda d: d["phases"][0].update(planned_minutes=-5), "planned_minutes must be a number >= 0"),
    (lambda d: d.update(orders={"a": ["familiarisation"]}), "order 'a' must list each phase exactly once"),
])
def test_parser_refuses_bad_protocols(change, msg):
    data = json.loads((STUDIES / "pedas_paper" / "paper_v1.json").read_text())
    change(data)
    with pytest.raises(UserError, match=msg):
        parse_protocol(json.dumps(data), "x.json")
    with pytest.raises(UserError, match=r"x.json:1: not valid JSON"):
        parse_protocol("{", "x.json")


def test_a_participant_follows_the_protocol_of_their_study(lk_db):
    """Phases, conditions and orders are the lane-keeping study's: the first participant gets hud_first."""
    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": 30})
        add_participant(st, "LK-02", {"age": 40})
        for pid in ("LK-01", "LK-02"):
            advance(st, pid, "familiarisation", at="2026-05-04T09:00")
        with pytest.raises(UserError, match="next is drive_no_hud, not drive_hud"):
            advance(st, "LK-02", "drive_hud", at="2026-05-04T09:10")
        advance(st, "LK-02", "drive_no_hud", at="2026-05-04T09:10")
        p1, p2 = protocol_of(st, "LK-01"), protocol_of(st, "LK-02")
        orders = dict(st.df("SELECT participant_id, order_name FROM order_assignments").values.tolist())
    assert orders == {"LK-01": "hud_first", "LK-02": "no_hud_first"}
    assert [s.condition for s in p1.steps if s.drive] == ["hud", "no_hud"]
    assert [s.condition for s in p2.steps if s.drive] == ["no_hud", "hud"]


@pytest.fixture
def st(paper_db):
    with Store.open(paper_db) as s:
        add_participant(s, "P001")
        yield s


def test_full_protocol_in_order(st):
    t = ["2026-05-04T09:00", "2026-05-04T09:10", "2026-05-04T09:31", "2026-05-04T09:40", "2026-05-04T09:50",
         "2026-05-04T10:12"]
    for phase, at in zip(PHASES, t):
        advance(st, "P001", phase, at=at)
    complete(st, "P001", at="2026-05-04T10:25")
    df = status(st, "P001")
    assert df["phase"].tolist() == list(PHASES)
    assert set(df["outcome"]) == {"completed"}
    # each phase ends when the next starts: hand-worked durations in minutes
    assert df["minutes"].round(6).tolist() == [10.0, 21.0, 9.0, 10.0, 22.0, 13.0]


def test_unknown_phase(st):
    with pytest.raises(UserError, match="unknown phase 'warmup'"):
        advance(st, "P001", "warmup")


def test_out_of_order(st):
    with pytest.raises(UserError, match="phase out of order"):
        advance(st, "P001", "baseline_drive")
    advance(st, "P001", "familiarisation")
    with pytest.raises(UserError, match="next is baseline_drive, not pedas_drive"):
        advance(st, "P001", "pedas_drive")
    with pytest.raises(UserError, match="already started familiarisation"):
        advance(st, "P001", "familiarisation")


def test_unknown_participant(st):
    with pytest.raises(UserError, match="unknown participant P999"):
        advance(st, "P999", "familiarisation")


def test_abort_then_continue(st):
    """A technical issue in the pEDAS drive aborts it; the survey still follows."""
    for phase in PHASES[:5]:
        advance(st, "P001", phase)
    assert abort(st, "P001", "simulator crashed") == "pedas_drive"
    advance(st, "P001", "survey")
    df = status(st, "P001").set_index("phase")
    assert df.loc["pedas_drive", "outcome"] == "aborted" and df.loc["pedas_drive", "note"] == "simulator crashed"
    assert df.loc["survey", "outcome"] == "in_progress"


def test_exclusion_all_closes_protocol(st):
    advance(st, "P001", "familiarisation")
    advance(st, "P001", "baseline_drive")
    abort(st, "P001", "motion sickness")
    exclude(st, "P001", "all", "motion_sickness")
    with pytest.raises(UserError, match="protocol is closed"):
        advance(st, "P001", "pedas_intro")
    df = status(st, "P001")
    assert df["outcome"].tolist() == ["completed", "aborted", "pending", "pending", "pending", "pending"]


def test_abort_needs_phase_and_reason(st):
    with pytest.raises(UserError, match="no phase in progress"):
        abort(st, "P001", "x")
    advance(st, "P001", "familiarisation")
    with pytest.raises(UserError, match="needs a reason"):
        abort(st, "P001", "  ")


def test_times_must_not_go_backwards(st):
    advance(st, "P001", "familiarisation", at="2026-05-04T09:00")
    with pytest.raises(UserError, match="before the start of familiarisation"):
        advance(st, "P001", "baseline_drive", at="2026-05-04T08:00")
    with pytest.raises(UserError, match="bad time"):
        advance(st, "P001", "baseline_drive", at="yesterday")


def test_every_step_is_audited(st):
    before = st.one("SELECT count(*) FROM audit_log")
    advance(st, "P001", "familiarisation")
    advance(st, "P001", "baseline_drive")   # update of familiarisation + insert of baseline_drive
    log = st.df("SELECT action, table_name FROM audit_log ORDER BY audit_id")[before:]
    assert log.values.tolist() == [["insert", "phase_events"], ["update", "phase_events"],
                                   ["insert", "phase_events"]]


def test_time_with_offset_is_stored_as_utc(st):
    advance(st, "P001", "familiarisation", at="2026-05-04T11:00+02:00")
    assert str(status(st, "P001").loc[0, "started_at"]) == "2026-05-04 09:00:00"

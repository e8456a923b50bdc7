"""The protocol definition and the phase log: order, abort, completion, status."""
import json

import pytest

from study.errors import UserError
from study.exclusions import exclude
from study.participants import add_participant
from study.protocol import PROTOCOL_DIR, abort, advance, complete, load_protocol, status
from study.store import Store

PHASES = ("familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey")


def test_paper_protocol():
    p = load_protocol()
    assert p.phases == PHASES
    assert [s.condition for s in p.steps if s.drive] == ["baseline", "pedas"]
    assert all(s.planned_minutes and s.planned_minutes > 0 for s in p.steps)


def test_loader_keeps_unknown_keys(tmp_path, monkeypatch):
    data = json.loads((PROTOCOL_DIR / "paper_v1.json").read_text())
    data["name"] = "x_v9"
    data["room"] = "sim-lab"
    data["phases"][0]["staff"] = 2
    (tmp_path / "x_v9.json").write_text(json.dumps(data))
    monkeypatch.setattr("study.protocol.PROTOCOL_DIR", tmp_path)
    load_protocol.cache_clear()
    try:
        p = load_protocol("x_v9")
        assert p.phases == PHASES and p.extra["room"] == "sim-lab" and p.steps[0].extra["staff"] == 2
    finally:
        load_protocol.cache_clear()


@pytest.fixture
def st(tmp_db):
    with Store.open(tmp_db) as s:
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

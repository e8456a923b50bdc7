"""A lab day through the CLI on a temporary store of the paper's study (`init --study studies/pedas_paper`): three
participants, three different ways through the protocol, and the refused steps (each leaves the store unchanged)."""
import json
from pathlib import Path

import pytest

from study.people.exclusions import included_participants
from study.store.store import Store

PAPER_STUDY = Path(__file__).resolve().parents[2] / "studies" / "pedas_paper"
PHASES = ["familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey"]


def snapshot(db):
    with Store.open(db) as st:
        return st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")


def ok(r):
    assert r.code == 0, r.err
    return r


def status(cli, pid):
    return json.loads(ok(cli("session", "status", pid, "--format", "json")).out)


def test_walkthrough(cli, tmp_db):
    ok(cli("init", "--study", PAPER_STUDY))
    ok(cli("participant", "add", "P001", "--attr", "age=34", "--attr", "gender=female", "--attr", "license_years=15",
           "--attr", "style=normal", "--attr", "eco_familiarity=3"))
    ok(cli("participant", "add", "P002", "--attr", "age=27", "--attr", "gender=male", "--style", "sporty"))
    ok(cli("participant", "add", "P003", "--age", "52", "--gender", "male", "--style", "cautious"))

    # P001: the full protocol
    for phase in PHASES:
        ok(cli("session", "advance", "P001", phase))
    ok(cli("session", "complete", "P001"))

    # P002: motion sickness in the baseline drive -> aborted, excluded from everything, protocol closed
    ok(cli("session", "advance", "P002", "familiarisation"))
    ok(cli("session", "advance", "P002", "baseline_drive"))
    ok(cli("session", "abort", "P002", "--reason", "motion sickness"))
    ok(cli("exclude", "P002", "--scope", "all", "--reason", "motion_sickness"))
    r = cli("session", "advance", "P002", "pedas_intro")
    assert r.code == 2 and "protocol is closed" in r.err

    # P003: technical issue in the pEDAS drive -> aborted, objective data excluded, survey still taken
    for phase in PHASES[:5]:
        ok(cli("session", "advance", "P003", phase))
    ok(cli("session", "abort", "P003", "--reason", "simulator froze"))
    ok(cli("exclude", "P003", "--scope", "objective", "--reason", "technical_issue", "--note", "simulator froze"))
    ok(cli("session", "advance", "P003", "survey"))
    ok(cli("session", "complete", "P003"))

    s1, s2, s3 = status(cli, "P001"), status(cli, "P002"), status(cli, "P003")
    assert [p["outcome"] for p in s1["phases"]] == ["completed"] * 6 and s1["exclusions"] == []
    assert all(p["started_at"] and p["ended_at"] for p in s1["phases"])
    assert [p["outcome"] for p in s2["phases"]] == ["completed", "aborted"] + ["pending"] * 4
    assert s2["phases"][1]["note"] == "motion sickness"
    assert [(e["scope"], e["reason"]) for e in s2["exclusions"]] == [("all", "motion_sickness")]
    assert [p["outcome"] for p in s3["phases"]] == ["completed"] * 4 + ["aborted", "completed"]
    assert [(e["scope"], e["reason"]) for e in s3["exclusions"]] == [("objective", "technical_issue")]

    # the human-readable status says the same
    out = ok(cli("session", "status", "P002")).out
    assert "baseline_drive" in out and "aborted" in out and "excluded: scope all, reason motion_sickness" in out

    with Store.open(tmp_db) as st:
        assert included_participants(st, "objective") == ["P001"]
        assert included_participants(st, "subjective") == ["P001", "P003"]

    listing = json.loads(ok(cli("participant", "list", "--format", "json")).out)
    assert {p["participant_id"]: p["excluded"] for p in listing} == {"P001": "", "P002": "all", "P003": "objective"}
    assert {p["participant_id"]: (p["age"], p["style"]) for p in listing} == {
        "P001": (34, "normal"), "P002": (27, "sporty"), "P003": (52, "cautious")}


@pytest.mark.parametrize("case", ["unknown_phase", "out_of_order", "duplicate_participant", "bad_id",
                                  "unknown_attribute", "attribute_out_of_range", "abort_without_phase",
                                  "exclude_twice"])
def test_refused_step_changes_nothing(cli, tmp_db, case):
    ok(cli("init", "--study", PAPER_STUDY))
    ok(cli("participant", "add", "P001", "--attr", "age=30"))
    ok(cli("session", "advance", "P001", "familiarisation"))
    ok(cli("exclude", "P001", "--scope", "subjective", "--reason", "other"))
    ok(cli("session", "complete", "P001"))
    before = snapshot(tmp_db)
    argv, msg = {
        "unknown_phase": (("session", "advance", "P001", "warmup"), "unknown phase 'warmup'"),
        "out_of_order": (("session", "advance", "P001", "pedas_drive"), "phase out of order"),
        "duplicate_participant": (("participant", "add", "P001", "--attr", "age=44"), "already exists"),
        "bad_id": (("participant", "add", "alice"), "bad participant id"),
        "unknown_attribute": (("participant", "add", "P002", "--attr", "shoe_size=44"),
                              "unknown participant attribute 'shoe_size'"),
        "attribute_out_of_range": (("participant", "add", "P002", "--attr", "age=7"), "age must be between 16"),
        "abort_without_phase": (("session", "abort", "P001", "--reason", "x"), "no phase in progress"),
        "exclude_twice": (("exclude", "P001", "--scope", "subjective", "--reason", "withdrawn"), "already excluded"),
    }[case]
    r = cli(*argv)
    assert r.code != 0
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and msg in lines[0]
    assert snapshot(tmp_db) == before


def test_help_for_every_command(cli):
    for argv in (("init",), ("participant", "add"), ("participant", "list"), ("session", "advance"),
                 ("session", "abort"), ("session", "complete"), ("session", "status"), ("exclude",),
                 ("drive", "import"), ("drive", "list"), ("export",)):
        r = cli(*argv, "--help")
        assert r.code == 0 and "usage: pedas-study" in r.out

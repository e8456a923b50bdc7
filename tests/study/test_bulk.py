"""Bulk files through the CLI: `participant import ROSTER.csv` and `session advance --from EVENTS.csv`, each all or
nothing with every bad row named by its line, and the same result as the single commands."""
from __future__ import annotations

import json
from datetime import datetime, timedelta
from pathlib import Path

import pandas as pd
import pytest

from study.common.bulk_rows import BadRows, read_rows
from study.common.errors import UserError
from study.people.participants import import_roster
from study.people.protocol import apply_events
from study.store.store import Store
from tests.conftest import LK_STUDY, PAPER_STUDY

GENDERS = ("female", "male", "diverse", "undisclosed")
PAPER_PHASES = ("familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey")
DAY = datetime(2026, 3, 2, 8, 0)  # in the past: times ahead of the clock are refused


def snapshot(db: Path):
    """Every table's row count and the whole audit log: a refused command must change neither."""
    with Store.open(db, read_only=True) as st:
        return st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")


def write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def lk_roster(n: int = 24) -> list[str]:
    """A good lane-keeping roster: LK-01..LK-n with age, gender and (for every other one) km_per_year."""
    rows = ["participant_id,age,gender,km_per_year"]
    for i in range(1, n + 1):
        km = f"{1000.5 * i}" if i % 2 else ""
        rows.append(f"LK-{i:02d},{20 + i},{GENDERS[i % 4]},{km}")
    return rows


def listed(cli, db: Path) -> pd.DataFrame:
    r = cli("participant", "list", "--format", "json", db=db)
    assert r.code == 0, r.err
    return pd.DataFrame(json.loads(r.out))


# ---------------------------------------------------------------------------------------------- rosters
def test_a_roster_of_24_registers_everyone_with_their_attributes(cli, lk_db, tmp_path):
    roster = write(tmp_path / "roster.csv", lk_roster())
    r = cli("participant", "import", roster, db=lk_db)
    assert (r.code, r.err) == (0, "")
    assert r.out == f"registered 24 participants from {roster}\n"
    df = listed(cli, lk_db).set_index("participant_id")
    assert df.index.tolist() == [f"LK-{i:02d}" for i in range(1, 25)]
    assert df["age"].tolist() == list(range(21, 45))
    assert df["gender"].tolist() == [GENDERS[i % 4] for i in range(1, 25)]
    assert df.loc["LK-03", "km_per_year"] == 3001.5 and pd.isna(df.loc["LK-04", "km_per_year"])
    assert set(df["protocol"]) == {"lk_counterbalanced_v1"}
    with Store.open(lk_db, read_only=True) as st:
        # one audited insert per participant and per given attribute, as 24 `participant add` calls write
        assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'participants'") == 24
        assert st.one("SELECT count(*) FROM participant_attributes") == 24 * 2 + 12


def test_the_roster_stores_what_participant_add_stores(cli, lk_db, tmp_path):
    """Roster and single command: the same participants and attribute rows (the text a value is stored as)."""
    single = tmp_path / "single.duckdb"
    assert cli("init", "--study", LK_STUDY, db=single).code == 0
    lines = lk_roster(6)
    for line in lines[1:]:
        pid, age, gender, km = line.split(",")
        args = ["participant", "add", pid, "--attr", f"age={age}", "--attr", f"gender={gender}"]
        args += ["--attr", f"km_per_year={km}"] if km else []
        assert cli(*args, db=single).code == 0
    assert cli("participant", "import", write(tmp_path / "r.csv", lines), db=lk_db).code == 0
    tables = []
    for db in (lk_db, single):
        with Store.open(db, read_only=True) as st:
            tables.append((st.df("SELECT participant_id, protocol, study_version FROM participants ORDER BY 1"),
                           st.df("SELECT * FROM participant_attributes ORDER BY 1, 2")))
    pd.testing.assert_frame_equal(tables[0][0], tables[1][0])
    pd.testing.assert_frame_equal(tables[0][1], tables[1][1])


def test_three_bad_rows_store_nothing_and_are_named_by_line(cli, lk_db, tmp_path):
    lines = lk_roster(6)
    lines[2] = "LK-2,40,male,"             # line 3: the id does not match ^LK-[0-9]{2}$
    lines[4] = "LK-04,17,female,100"       # line 5: age below the declared minimum 18
    lines.insert(6, "")                    # a blank line is skipped but counts: the next row is line 8
    lines.append("LK-01,50,male,")          # line 9: LK-01 is on line 2 already
    roster = write(tmp_path / "roster.csv", lines)
    before = snapshot(lk_db)
    r = cli("participant", "import", roster, db=lk_db)
    assert r.code == 2 and r.out == ""
    assert r.err.splitlines() == [
        f"pedas-study: error: {roster}: 3 bad row(s)",
        "line 3: LK-2: bad participant id 'LK-2': study lane_keeping uses ids matching ^LK-[0-9]{2}$, e.g. LK-01",
        "line 5: LK-04: age must be between 18 and 90, not 17",
        "line 9: LK-01: participant LK-01 is also on line 2",
    ]
    assert snapshot(lk_db) == before
    assert listed(cli, lk_db).empty


def test_a_roster_colliding_with_a_registered_id_stores_nothing(cli, lk_db, tmp_path):
    assert cli("participant", "add", "LK-05", "--attr", "age=30", db=lk_db).code == 0
    before = snapshot(lk_db)
    r = cli("participant", "import", write(tmp_path / "roster.csv", lk_roster(8)), db=lk_db)
    assert r.code == 2
    assert r.err.splitlines() == [f"pedas-study: error: {tmp_path}/roster.csv: 1 bad row(s)",
                                  "line 6: LK-05: participant LK-05 already exists"]
    assert snapshot(lk_db) == before
    assert listed(cli, lk_db)["participant_id"].tolist() == ["LK-05"]


def test_every_check_of_participant_add_applies_to_a_roster_row(cli, paper_db, tmp_path):
    """The paper's study: its [[checks]] (licence years vs age), choices, protocol names; the reasons are the single
    command's own."""
    rows = ["participant_id,age,license_years,style,protocol",
            "P001,20,6,normal,",                 # the study's check
            "P002,30,5,fast,",                   # not a declared choice
            "P003,30,5,normal,nope",             # unknown protocol
            "P004,thirty,5,normal,",             # not a number
            "P005,40,20,sporty,counterbalanced_v1"]
    before = snapshot(paper_db)
    r = cli("participant", "import", write(tmp_path / "paper.csv", rows), db=paper_db)
    assert r.code == 2
    reasons = {}
    for pid, attrs, proto in (("P001", ["--age", "20", "--license-years", "6", "--style", "normal"], []),
                              ("P002", ["--age", "30", "--license-years", "5", "--style", "fast"], []),
                              ("P003", ["--age", "30", "--license-years", "5", "--style", "normal"],
                               ["--protocol", "nope"]),
                              ("P004", ["--age", "thirty", "--license-years", "5", "--style", "normal"], [])):
        single = cli("participant", "add", pid, *attrs, *proto, db=paper_db)
        assert single.code == 2
        reasons[pid] = single.err.strip().removeprefix("pedas-study: error: ")
    assert r.err.splitlines() == [f"pedas-study: error: {tmp_path}/paper.csv: 4 bad row(s)"] + [
        f"line {n}: {pid}: {reasons[pid]}" for n, pid in ((2, "P001"), (3, "P002"), (4, "P003"), (5, "P004"))]
    assert "license years impossible at this age" in reasons["P001"]
    assert snapshot(paper_db) == before
    # the good row alone: registered with the protocol it names
    assert cli("participant", "import", write(tmp_path / "ok.csv", [rows[0], rows[5]]), db=paper_db).code == 0
    assert listed(cli, paper_db).loc[0, "protocol"] == "counterbalanced_v1"


@pytest.mark.parametrize("lines, message", [
    (["participant_id,age,shoe_size", "LK-01,30,44"],
     "roster.csv: unknown column(s) shoe_size; the columns are participant_id, age, gender, km_per_year, protocol, "
     "order (--ignore-columns shoe_size leaves them out)"),
    (["id,age", "LK-01,30"], "roster.csv: unknown column(s) id; the columns are participant_id, age, gender, "
                             "km_per_year, protocol, order (--ignore-columns id leaves them out)"),
    (["participant_id,gender", "LK-01,male"], "roster.csv: no column for the required attribute(s) age"),
    (["participant_id,age,age", "LK-01,30,31"], "roster.csv: duplicate column(s) age"),
    (["participant_id,age"], "roster.csv: no rows below the header"),
    ([""], "roster.csv: empty file (expected a header row, then one row per line)"),
])
def test_a_roster_with_bad_columns_is_refused_in_one_line(cli, lk_db, tmp_path, lines, message):
    before = snapshot(lk_db)
    r = cli("participant", "import", write(tmp_path / "roster.csv", lines), db=lk_db)
    assert (r.code, r.out, r.err) == (2, "", f"pedas-study: error: {tmp_path}/{message}\n")
    assert snapshot(lk_db) == before


def test_a_roster_s_own_columns_are_left_out_with_ignore_columns(cli, lk_db, tmp_path):
    roster = write(tmp_path / "roster.csv", ["participant_id,age,order_name,seat", "LK-01,30,A,1", "LK-02,31,B,2"])
    r = cli("participant", "import", roster, "--ignore-columns", "order_name, seat", db=lk_db)
    assert r.code == 0 and r.out.strip() == f"registered 2 participants from {roster}", r.err
    assert listed(cli, lk_db)["participant_id"].tolist() == ["LK-01", "LK-02"]


def test_rows_with_a_wrong_number_of_fields_are_named(cli, lk_db, tmp_path):
    roster = write(tmp_path / "roster.csv", ["participant_id,age", "LK-01,30", "LK-02,31,extra", "LK-03"])
    r = cli("participant", "import", roster, db=lk_db)
    assert r.code == 2
    assert r.err.splitlines() == [f"pedas-study: error: {roster}: 2 bad row(s)",
                                  "line 3: LK-02: 3 fields, the header has 2",
                                  "line 4: LK-03: 1 fields, the header has 2"]
    assert listed(cli, lk_db).empty


def test_read_rows_names_each_row_by_its_first_line(tmp_path):
    path = tmp_path / "r.csv"
    path.write_bytes('\ufeffparticipant_id, note \r\n\r\nP001," two\r\nlines"\r\nP002,  x \r\n'.encode())
    frame = read_rows(path)
    assert frame.columns.tolist() == ["participant_id", "note"]
    assert frame.index.tolist() == [3, 5]             # BOM header = line 1, blank line 2, P001's field spans 3-4
    assert frame.loc[3, "note"] == "two\nlines" and frame.loc[5, "note"] == "x"
    with pytest.raises(UserError, match="not found"):
        read_rows(tmp_path / "missing.csv")


def test_import_roster_takes_a_frame_built_in_code(lk_db):
    frame = pd.DataFrame({"participant_id": ["LK-01", "LK-02"], "age": [30, None]}, index=[10, 11])
    with Store.open(lk_db) as st:
        with pytest.raises(BadRows) as exc:
            import_roster(st, frame, source="frame")
        assert str(exc.value) == "frame: 1 bad row(s)"
        assert exc.value.lines() == ["line 11: LK-02: age is required"]
        assert st.one("SELECT count(*) FROM participants") == 0
        assert import_roster(st, frame.iloc[:1]) == 1
        assert st.one("SELECT value FROM participant_attributes WHERE attribute = 'age'") == "30"


# ---------------------------------------------------------------------------------------------- events
def paper_events(n: int = 24) -> list[tuple[str, ...]]:
    """(participant_id, phase, action, at, note, reason) for P001..P0n walking paper_v1: every phase advanced
    in turn, the survey completed; every fourth participant's baseline drive aborted, then continued."""
    events = []
    for i in range(1, n + 1):
        pid = f"P{i:03d}"
        t = DAY + timedelta(days=i)
        for k, phase in enumerate(PAPER_PHASES):
            at = (t + timedelta(minutes=15 * k)).isoformat(timespec="minutes")
            events.append((pid, phase, "advance", at, "late start" if k == 0 and i == 2 else "", ""))
            if phase == "baseline_drive" and i % 4 == 0:
                end = (t + timedelta(minutes=15 * k + 5)).isoformat(timespec="minutes")
                events.append((pid, phase, "abort", end, "", "motion sickness"))
        events.append((pid, "", "complete", (t + timedelta(minutes=100)).isoformat(timespec="minutes"), "done", ""))
    return events


def events_csv(path: Path, events) -> Path:
    return write(path, ["participant_id,phase,action,at,note,reason"] + [",".join(e) for e in events])


def single_commands(cli, db: Path, events) -> None:
    for pid, phase, action, at, note, reason in events:
        args = {"advance": ["session", "advance", pid, phase], "complete": ["session", "complete", pid],
                "abort": ["session", "abort", pid, "--reason", reason]}[action] + ["--at", at]
        args += ["--note", note] if note else []
        r = cli(*args, db=db)
        assert r.code == 0, r.err


def statuses(cli, db: Path, ids) -> dict:
    out = {}
    for pid in ids:
        r = cli("session", "status", pid, "--format", "json", db=db)
        assert r.code == 0, r.err
        out[pid] = json.loads(r.out)
    return out


@pytest.fixture
def paper_24(cli, paper_db, tmp_path):
    roster = ["participant_id,age,gender"] + [f"P{i:03d},{25 + i},{GENDERS[i % 4]}" for i in range(1, 25)]
    assert cli("participant", "import", write(tmp_path / "paper_roster.csv", roster), db=paper_db).code == 0
    return paper_db


@pytest.mark.slow
def test_an_events_file_walks_24_participants_as_the_single_commands_do(cli, paper_24, tmp_path):
    events = paper_events()
    single = tmp_path / "single.duckdb"
    assert cli("init", "--study", PAPER_STUDY, db=single).code == 0
    assert cli("participant", "import", tmp_path / "paper_roster.csv", db=single).code == 0
    single_commands(cli, single, events)
    r = cli("session", "advance", "--from", events_csv(tmp_path / "events.csv", events), db=paper_24)
    assert (r.code, r.err) == (0, "")
    assert r.out == f"applied {len(events)} events for 24 participants from {tmp_path / 'events.csv'}\n"
    ids = [f"P{i:03d}" for i in range(1, 25)]
    bulk = statuses(cli, paper_24, ids)
    assert bulk == statuses(cli, single, ids)
    p4 = {p["phase"]: p for p in bulk["P004"]["phases"]}
    assert p4["baseline_drive"]["outcome"] == "aborted" and p4["baseline_drive"]["note"] == "motion sickness"
    assert p4["baseline_drive"]["started_at"] == "2026-03-06T08:15:00.000"
    assert bulk["P002"]["phases"][0]["note"] == "late start"
    assert {p["outcome"] for p in bulk["P001"]["phases"]} == {"completed"}
    with Store.open(paper_24, read_only=True) as st:
        assert st.one("SELECT count(*) FROM phase_events") == 24 * 6


def test_a_counterbalanced_walk_assigns_orders_as_the_single_commands_do(cli, lk_db, tmp_path):
    """The lane-keeping protocol has two orders: each participant's first advance assigns one (balanced), so a
    file gives the orders the same commands one by one give."""
    assert cli("participant", "import", write(tmp_path / "roster.csv", lk_roster(4)), db=lk_db).code == 0
    single = tmp_path / "single.duckdb"
    assert cli("init", "--study", LK_STUDY, db=single).code == 0
    assert cli("participant", "import", tmp_path / "roster.csv", db=single).code == 0
    events = []
    for i in range(1, 5):
        at = (DAY + timedelta(hours=i)).isoformat(timespec="minutes")
        events.append((f"LK-{i:02d}", "familiarisation", "", at, "", ""))
    second = {"LK-01": "drive_hud", "LK-02": "drive_no_hud", "LK-03": "drive_hud", "LK-04": "drive_no_hud"}
    for i in range(1, 5):
        at = (DAY + timedelta(hours=i, minutes=10)).isoformat(timespec="minutes")
        events.append((f"LK-{i:02d}", second[f"LK-{i:02d}"], "", at, "", ""))
    r = cli("session", "advance", "--from", events_csv(tmp_path / "events.csv", events), db=lk_db)
    assert r.code == 0, r.err
    single_commands(cli, single, [(p, ph, a or "advance", at, n, rs) for p, ph, a, at, n, rs in events])
    ids = list(second)
    assert statuses(cli, lk_db, ids) == statuses(cli, single, ids)
    with Store.open(lk_db, read_only=True) as st:
        orders = st.df("SELECT participant_id, order_name FROM order_assignments ORDER BY 1")
    assert orders["order_name"].tolist() == ["hud_first", "no_hud_first", "hud_first", "no_hud_first"]


def test_one_out_of_order_phase_in_the_middle_stores_nothing(cli, paper_24, tmp_path):
    events = paper_events()
    bad = next(k for k, e in enumerate(events) if e[0] == "P012" and e[1] == "pedas_intro")
    line = bad + 2                                      # the header is line 1
    pid, _, action, at, note, reason = events[bad]
    events[bad] = (pid, "practice", action, at, note, reason)   # P012 skips pedas_intro
    later = [k + 2 for k, e in enumerate(events) if e[0] == "P012" and k > bad]
    before = snapshot(paper_24)
    r = cli("session", "advance", "--from", events_csv(tmp_path / "events.csv", events), db=paper_24)
    assert r.code == 2 and r.out == ""
    assert r.err.splitlines() == [
        f"pedas-study: error: {tmp_path}/events.csv: 1 bad row(s)",
        f"line {line}: P012: phase out of order: P012 is at baseline_drive, next is pedas_intro, not practice",
    ] + [f"line {n}: P012: not checked: follows the bad line {line} of P012" for n in later]
    assert snapshot(paper_24) == before


def test_each_bad_event_is_named_with_the_single_commands_reason(cli, paper_24, tmp_path):
    future = (datetime.now() + timedelta(days=2)).isoformat(timespec="minutes")
    rows = ["participant_id,phase,action,at,note,reason",
            "P001,familiarisation,,2026-03-02T09:00,,",
            "P001,,abort,2026-03-02T09:05,,",                           # 3: an abort needs a reason
            "P002,familiarisation,advance,2026-03-02T09:00,,sick",       # 4: a reason only with abort
            "P003,familiarisation,skip,2026-03-02T09:00,,",             # 5: unknown action
            f"P004,familiarisation,,{future},,",                         # 6: in the future
            "P005,familiarisation,,noon,,",                              # 7: not a time
            "P999,familiarisation,,2026-03-02T09:00,,",                 # 8: not registered
            "P006,baseline_drive,complete,2026-03-02T09:00,,",          # 9: nothing in progress
            "P007,familiarisation,,2026-03-02T09:00,,",
            "P007,familiarisation,complete,2026-03-02T08:00,,",         # 11: ends before it started
            "P008,familiarisation,,2026-03-02T09:00,,",
            "P008,baseline_drive,complete,2026-03-02T09:30,,",          # 13: not the phase in progress
            ",familiarisation,,2026-03-02T09:00,,"]                     # 14: no id
    before = snapshot(paper_24)
    r = cli("session", "advance", "--from", write(tmp_path / "ev.csv", rows), db=paper_24)
    assert r.code == 2
    lines = r.err.splitlines()
    assert lines[0] == f"pedas-study: error: {tmp_path}/ev.csv: 10 bad row(s)"
    assert lines[1:4] == ["line 3: P001: an abort needs a reason",
                          "line 4: P002: a reason goes with action abort, not advance (use note)",
                          "line 5: P003: action must be one of advance|complete|abort, not 'skip'"]
    assert lines[4].startswith("line 6: P004: time ") and "is in the future" in lines[4]
    assert lines[5:] == [
        "line 7: P005: bad time 'noon' (use ISO 8601, e.g. 2026-05-04T09:30)",
        "line 8: P999: unknown participant P999",
        "line 9: P006: P006 has no phase in progress to complete",
        "line 11: P007: end time 2026-03-02 08:00:00 is before the start of familiarisation (2026-03-02 09:00:00)",
        "line 13: P008: P008 is in familiarisation, not baseline_drive: complete ends the phase in progress",
        "line 14: (no id): participant_id is empty",
    ]
    assert snapshot(paper_24) == before


def test_events_file_columns_and_the_usage_of_advance(cli, paper_24, tmp_path):
    r = cli("session", "advance", "--from", write(tmp_path / "ev.csv", ["participant_id,stage", "P001,x"]),
            db=paper_24)
    assert r.err == (f"pedas-study: error: {tmp_path}/ev.csv: unknown column(s) stage; the columns are participant_id, "
                     "phase, action, at, note, reason (--ignore-columns stage leaves them out)\n")
    r = cli("session", "advance", "--from", write(tmp_path / "ev2.csv", ["participant_id,at", "P001,"]),
            db=paper_24)
    assert r.err == (f"pedas-study: error: {tmp_path}/ev2.csv: column(s) phase missing; the columns are participant_id, phase, "
                     "action, at, note, reason\n")
    r = cli("session", "advance", "P001", "--from", tmp_path / "ev.csv", db=paper_24)
    assert r.code == 2 and r.err.startswith("pedas-study session advance: error: --from takes every event from the "
                                            "file: give no ID, PHASE, --note or --at with it")
    r = cli("session", "advance", "P001", db=paper_24)
    assert r.code == 2 and r.err.startswith(
        "pedas-study session advance: error: the following arguments are required: PHASE")


def test_apply_events_returns_one_row_per_event(paper_24):
    frame = pd.DataFrame({"participant_id": ["P001", "P001", "P001"],
                          "phase": ["familiarisation", "baseline_drive", None],
                          "action": [None, "advance", "complete"],
                          "at": ["2026-03-02T09:00", "2026-03-02T09:10", "2026-03-02T09:30"]})
    with Store.open(paper_24) as st:
        done = apply_events(st, frame)
    assert done.to_dict("records") == [
        {"line": 0, "participant_id": "P001", "action": "advance", "phase": "familiarisation", "completed": None},
        {"line": 1, "participant_id": "P001", "action": "advance", "phase": "baseline_drive",
         "completed": "familiarisation"},
        {"line": 2, "participant_id": "P001", "action": "complete", "phase": "baseline_drive", "completed": None}]

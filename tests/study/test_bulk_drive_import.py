"""Many drive logs at once (study/logs/bulk_import.py): `drive import --dir DIR --pattern` and `--from MANIFEST` on the
takeover study (studies/takeover: 20 Hz logs in ms, mph, ft), after every participant has finished the protocol;
all or nothing, every problem of every file listed, files read in worker processes."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from study.store.store import Store
from tests.conftest import REPO
from tests.takeover_logs import write_log

STUDY = REPO / "studies" / "takeover"
PEOPLE = {"TOR-A01": "none-visual-audiovisual", "TOR-A02": "visual-audiovisual-none",
          "TOR-A03": "audiovisual-none-visual"}
DRIVES = (None, "none", "visual", "audiovisual")


def _counts(db) -> dict:
    with Store.open(db, read_only=True) as st:
        return {**st.counts(), "audit": st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")}


@pytest.fixture
def walked(cli, tmp_path):
    """The takeover study with three participants who have walked the whole protocol, and a folder of their 12
    logs; TOR-A03 stopped before their last drive (visual)."""
    assert cli("init", "--study", STUDY).code == 0
    roster = tmp_path / "roster.csv"
    pd.DataFrame({"participant_id": list(PEOPLE), "age": 30, "order": list(PEOPLE.values())}).to_csv(roster,
                                                                                                   index=False)
    assert cli("participant", "import", roster).code == 0
    protocol = json.loads((STUDY / "protocol.json").read_text())
    events = []
    for pid, order in PEOPLE.items():
        for phase in protocol["orders"][order]:
            if pid == "TOR-A03" and phase == "drive_visual":
                events.append((pid, "", "abort", "motion sickness"))
                break
            events.append((pid, phase, "advance", ""))
        else:
            events.append((pid, "", "complete", ""))
    pd.DataFrame(events, columns=["participant_id", "phase", "action", "reason"]).to_csv(tmp_path / "ev.csv",
                                                                                         index=False)
    assert cli("session", "advance", "--from", tmp_path / "ev.csv").code == 0
    logs = tmp_path / "logs"
    logs.mkdir()
    for pid in PEOPLE:
        for c in DRIVES:
            write_log(logs, pid, c)
    return logs


def test_a_folder_of_logs_imports_after_the_fact_all_at_once(cli, tmp_db, walked):
    (walked / "TOR-A03_visual.csv").unlink()       # never driven
    (walked / "README.txt").write_text("copied from the simulator PC")
    r = cli("drive", "import", "--dir", walked, "--pattern", "{participant}_{condition}.csv")
    assert r.code == 0, r.err
    assert r.out.strip() == f"11 drive logs of 3 participants from {walked}: 11 imported (16,500 samples)"
    assert "note: 1 file(s) of" in r.err and "README.txt" in r.err
    drives = json.loads(cli("drive", "list", "--format", "json").out)
    assert sorted((d["participant_id"], d["condition"] or d["phase"]) for d in drives) == sorted(
        (p, c or "familiarisation") for p in PEOPLE for c in DRIVES if (p, c) != ("TOR-A03", "visual"))
    # the same folder again: nothing new
    r = cli("drive", "import", "--dir", walked, "--pattern", "{participant}_{condition}.csv", "--jobs", "1")
    assert r.code == 0 and r.out.strip().endswith("0 imported, 11 unchanged (0 samples)")


def test_every_problem_of_every_file_is_listed_and_nothing_is_stored(cli, tmp_db, walked, tmp_path):
    (walked / "TOR-A02_none.csv").write_text("time_ms,speed\n0,1\n")          # not the lab's log format
    (walked / "TOR-A04_none.csv").write_bytes((walked / "TOR-A01_none.csv").read_bytes())
    before = _counts(tmp_db)
    r = cli("drive", "import", "--dir", walked, "--pattern", "{participant}_{condition}.csv")
    assert r.code == 2 and r.out == ""
    lines = r.err.splitlines()
    assert lines[0] == f"pedas-study: error: {walked}: 3 bad row(s)"
    assert lines[1].startswith(f"TOR-A02: {walked}/TOR-A02_none.csv: the log has no column 'speed_mph'")
    assert lines[2] == (f"TOR-A03: {walked}/TOR-A03_visual.csv: TOR-A03 has not entered the drive of visual "
                        "(drive_visual); phases entered: familiarisation, drive_audiovisual, "
                        "survey_after_audiovisual, drive_none, survey_after_none (aborted)")
    assert lines[3] == f"TOR-A04: {walked}/TOR-A04_none.csv: unknown participant TOR-A04"
    assert _counts(tmp_db) == before
    # a manifest: its lines name the problems; a drive twice; files relative to the manifest
    manifest = tmp_path / "manifest.csv"
    manifest.write_text("participant,phase,file\nTOR-A01,familiarisation,logs/TOR-A01_familiarisation.csv\n"
                        "TOR-A01,none,logs/TOR-A01_none.csv\nTOR-A01,none,logs/TOR-A01_visual.csv\n"
                        "TOR-A01,visual,logs/missing.csv\n", encoding="utf-8")
    r = cli("drive", "import", "--from", manifest)
    assert r.code == 2 and r.err.splitlines()[1:] == [
        f"line 4: TOR-A01: {walked}/TOR-A01_visual.csv: the none drive of TOR-A01 is also line 3: "
        f"{walked}/TOR-A01_none.csv",
        f"line 5: TOR-A01: no such file: {walked}/missing.csv"]
    assert _counts(tmp_db) == before


def test_a_manifest_read_in_workers_stores_what_one_by_one_stores(cli, tmp_db, walked, tmp_path):
    rows = [(p, c or "familiarisation", f"logs/{p}_{c or 'familiarisation'}.csv") for p in ("TOR-A01", "TOR-A02")
            for c in DRIVES]
    pd.DataFrame(rows, columns=["participant_id", "condition", "file"]).to_csv(tmp_path / "m.csv", index=False)
    r = cli("drive", "import", "--from", tmp_path / "m.csv", "--jobs", "2")
    assert r.code == 0 and "8 imported (12,000 samples)" in r.out, r.err
    with Store.open(tmp_db, read_only=True) as st:
        bulk = st.df("SELECT participant_id, coalesce(condition, phase) AS d, checksum, meta FROM drives ORDER BY 1, 2")
        samples = st.df("SELECT d.participant_id, coalesce(d.condition, d.phase) AS d, s.* EXCLUDE (drive_id) "
                        "FROM drive_samples s JOIN drives d USING (drive_id) ORDER BY 1, 2, idx")
    single = tmp_path / "single.duckdb"
    assert cli("init", "--study", STUDY, db=single).code == 0
    assert cli("participant", "import", tmp_path / "roster.csv", db=single).code == 0
    for p, c, f in rows:
        assert cli("drive", "import", p, c, tmp_path / f, db=single).code == 0
    with Store.open(single, read_only=True) as st:
        one = st.df("SELECT participant_id, coalesce(condition, phase) AS d, checksum, meta FROM drives ORDER BY 1, 2")
        one_samples = st.df("SELECT d.participant_id, coalesce(d.condition, d.phase) AS d, s.* EXCLUDE (drive_id) "
                            "FROM drive_samples s JOIN drives d USING (drive_id) ORDER BY 1, 2, idx")
    assert bulk.equals(one) and samples.equals(one_samples)


def test_the_bulk_options_are_checked(cli, tmp_db, walked):
    r = cli("drive", "import", "--dir", walked)
    assert r.code == 2 and "--dir needs --pattern" in r.err
    r = cli("drive", "import", "--dir", walked, "--pattern", "{participant}.csv")
    assert r.code == 2 and "use each of {participant} and {condition} once" in r.err
    r = cli("drive", "import", "TOR-A01", "none", walked / "TOR-A01_none.csv", "--dir", walked)
    assert r.code == 2 and "give no ID, CONDITION, FILE" in r.err
    r = cli("drive", "import", "TOR-A01")
    assert r.code == 2 and "required: CONDITION, FILE (or --from MANIFEST" in r.err


def test_familiarisation_drives_are_summarised_apart_from_the_conditions(cli, tmp_db, walked, tmp_path):
    assert cli("drive", "import", "--dir", walked, "--pattern", "{participant}_{condition}.csv").code == 2  # TOR-A03
    (walked / "TOR-A03_visual.csv").unlink()
    assert cli("drive", "import", "--dir", walked, "--pattern", "{participant}_{condition}.csv").code == 0
    assert cli("analyze", "drives", "--out", tmp_path / "d").code == 0
    kpis = pd.read_csv(tmp_path / "d" / "kpis.csv")
    assert list(kpis.columns[:4]) == ["participant_id", "condition", "phase", "drive_id"]
    fam = kpis[kpis["phase"] == "familiarisation"]
    assert len(fam[fam["segment"] == "overall"]) == 3 and fam["condition"].isna().all()
    phases = pd.read_csv(tmp_path / "d" / "phases.csv")
    trip = phases[(phases["phase"] == "familiarisation") & (phases["metric"] == "trip_time_s")].iloc[0]
    assert trip["n"] == 3 and trip["mean"] == pytest.approx(fam.loc[fam["segment"] == "overall", "trip_time_s"].mean())
    assert (tmp_path / "d" / "phases.md").read_text().startswith("### KPIs of the drives outside the compared")

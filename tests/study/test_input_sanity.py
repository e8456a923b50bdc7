"""Input sanity: times in the future, protocol and instrument given as paths, implausible drive logs. Each bad
input of issue 15 through the real CLI process: one line on stderr, exit 2, the store's content unchanged."""
from __future__ import annotations

import hashlib
import json
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from study.store.audit_trail import CLOCK_SKEW, not_in_future, utcnow
from study.logs.validation import MAGNITUDES, SAMPLING_S, plausibility
from study.common.errors import UserError
from study.store.store import Store
from tests.study.test_drive_import import make_drive


def content(db: Path) -> tuple[dict[str, int], str]:
    """(row count per table, sha256 over every table's rows in a fixed order)."""
    h = hashlib.sha256()
    with Store.open(db, read_only=True) as st:
        counts = st.counts()
        for t in st.tables():
            for row in st.con.execute(f'SELECT * FROM "{t}" ORDER BY ALL').fetchall():
                h.update(repr(row).encode())
    return counts, h.hexdigest()


@pytest.fixture
def lab(paper_db, tmp_path, cli_proc):
    assert cli_proc("participant", "add", "P001", db=paper_db).code == 0
    drive = make_drive(n=600, dt=0.1)                     # 60 s, ~890 m
    ms = drive.assign(t=drive["t"] * 1000)                # t in milliseconds: 59,900 "s" for ~890 m
    ms.to_csv(tmp_path / "ms.csv", index=False)
    drive.assign(p_batt=-1e12).to_csv(tmp_path / "pbatt.csv", index=False)
    drive.assign(t=drive["t"] / 20).to_csv(tmp_path / "fast.csv", index=False)   # 200 Hz: 0.005 s steps
    drive.assign(ft=2e6).to_csv(tmp_path / "ft.csv", index=False)
    return paper_db, tmp_path


def _bad(lab_dir: Path) -> list[tuple[list[str], str]]:
    return [
        (["session", "advance", "P001", "familiarisation", "--at", "9999-12-31T23:59"],
         "time 9999-12-31 23:59:00 is in the future"),
        (["participant", "add", "P002", "--protocol", "../../x"],
         "protocol '../../x' is a path; give the name of one the study declares (paper_v1, counterbalanced_v1)"),
        (["participant", "add", "P002", "--protocol", "studies/pedas_paper/paper_v1.json"], "is a path"),
        (["survey", "status", "--instrument", "../.."],
         "instrument '../..' is a path; give the name of one the study declares (pedas_acceptance_v1)"),
        (["survey", "link", "P001", "--instrument", "..\\codebook"], "instrument '..\\\\codebook' is a path"),
        (["drive", "import", "P001", "baseline", str(lab_dir / "ms.csv")],
         "ms.csv: column t rows 1-600: median sampling interval 100 s outside 0.01-1 s: looks like a time in "
         "ms read as s (if this is right, import with --force REASON)"),
        (["drive", "import", "P001", "baseline", str(lab_dir / "pbatt.csv")],
         "pbatt.csv: column p_batt row 1: battery power -1e+12 W beyond ±1e+06 W (implausible for a passenger car)"),
        (["drive", "import", "P001", "baseline", str(lab_dir / "fast.csv")],
         "median sampling interval 0.005 s outside 0.01-1 s"),
        (["drive", "import", "P001", "baseline", str(lab_dir / "ft.csv")], "traction force 2e+06 N beyond ±50000 N"),
        (["drive", "import", "P001", "baseline", str(lab_dir / "pbatt.csv"), "--force", " "],
         "--force needs a reason"),
    ]


@pytest.mark.slow
def test_each_bad_input_one_line_exit_2_store_unchanged(lab, cli_proc):
    db, d = lab
    before = content(db)
    for args, message in _bad(d):
        r = cli_proc(*args, db=db)
        assert r.code == 2, (args, r.err)
        assert r.out == "" and r.err.count("\n") == 1, (args, r.err)
        assert r.err.startswith("pedas-study: error: ") and message in r.err, (args, r.err)
        print(f"{' '.join(args[:4])} ...: {r.err.strip()}")
        assert content(db) == before, args


def test_force_imports_and_records_it(lab, cli_proc):
    db, d = lab
    r = cli_proc("drive", "import", "P001", "baseline", str(d / "pbatt.csv"), "--force", "bench rig log", db=db)
    assert r.code == 0 and "note: imported with --force despite: column p_batt row 1" in r.err
    with Store.open(db, read_only=True) as st:
        meta = json.loads(st.one("SELECT meta FROM drives WHERE participant_id = 'P001'"))
    assert meta["forced"]["reason"] == "bench rig log"
    assert meta["forced"]["overridden"][0].startswith("column p_batt row 1: battery power -1e+12 W")


def test_clock_skew_bound():
    now = utcnow()
    assert not_in_future(now + CLOCK_SKEW - timedelta(seconds=5)) == now + CLOCK_SKEW - timedelta(seconds=5)
    assert not_in_future(now - timedelta(days=300)) == now - timedelta(days=300)   # a paper log entered later
    with pytest.raises(UserError, match="is in the future"):
        not_in_future(now + CLOCK_SKEW + timedelta(seconds=5))


def test_advance_within_the_skew_is_accepted(lab, cli_proc):
    db, _ = lab
    at = (utcnow() + timedelta(minutes=2)).isoformat(timespec="seconds")
    r = cli_proc("session", "advance", "P001", "familiarisation", "--at", at, db=db)
    assert r.code == 0, r.err


@pytest.mark.parametrize("dt,ok", [(0.01, True), (0.1, True), (1.0, True), (0.009, False), (1.2, False)])
def test_sampling_interval_bounds(dt, ok):
    """The median interval must lie in SAMPLING_S; with 1.2 s the gap check (max 1 s) fires as well."""
    assert SAMPLING_S == (0.01, 1.0)
    frame = make_drive(n=200, dt=dt)
    problems = plausibility(frame, max_gap_s=2.0)
    assert (not any("median sampling interval" in p for p in problems)) == ok, problems


@pytest.mark.parametrize("col", list(MAGNITUDES))
def test_magnitude_bounds(col):
    bound = MAGNITUDES[col][0]
    frame = make_drive(n=200)
    assert plausibility(frame.assign(**{col: np.full(200, -bound)})) == []        # the bound itself is plausible
    x = np.zeros(200)
    x[57] = bound * 1.01
    problems = plausibility(frame.assign(**{col: x}))
    assert len(problems) == 1 and problems[0].startswith(f"column {col} row 58: ")

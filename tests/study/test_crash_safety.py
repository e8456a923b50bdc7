"""A process killed (SIGKILL) while importing a >= 1 M-row drive log leaves the drive absent or complete."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.store.store import Store

REPO = Path(__file__).resolve().parents[2]
N = 1_200_000


def big_log(path: Path, n: int = N) -> None:
    t = np.arange(n) * 0.02
    v = 15.0 + 5.0 * np.sin(t / 30.0)
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.02)])
    highway = np.arange(n) >= n // 2
    seg = pd.Categorical.from_codes(highway.astype(np.int8), categories=["urban", "highway"])
    pd.DataFrame({"t": t, "s": s, "v": v, "segment": seg, "speed_limit": np.where(highway, 33.33, 13.89),
                  "controller": pd.Categorical.from_codes(np.zeros(n, np.int8), categories=["rt"])}).to_parquet(path)


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "big.parquet"
    big_log(path)
    return path


def kill_during(db: Path, log: Path, marker: str, delay: float) -> int:
    """Start `drive import` in a subprocess, SIGKILL it `delay` s after stderr shows `marker`; its exit code."""
    argv = [sys.executable, "-m", "pedas_study.cli", f"--db={db}", "drive", "import", "P001", "baseline", str(log),
            "-v"]
    p = subprocess.Popen(argv, cwd=REPO, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        for line in p.stderr:
            if marker in line:
                if delay:
                    time.sleep(delay)
                os.kill(p.pid, signal.SIGKILL)
                break
        return p.wait(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def drive_state(db: Path) -> str:
    with Store.open(db) as st:
        drives = st.df("SELECT drive_id, n_samples FROM drives")
        n_samples = st.one("SELECT count(*) FROM drive_samples")
        audited = st.one("SELECT count(*) FROM audit_log WHERE table_name = 'drives'")
    if drives.empty:
        assert n_samples == 0 and audited == 0, "samples or audit rows without their drive"
        return "absent"
    assert len(drives) == 1 and n_samples == drives["n_samples"].iloc[0] == N, "partial drive"
    assert audited == 1
    return "complete"


@pytest.fixture
def setup(paper_db, log):
    from study.people.participants import add_participant

    with Store.open(paper_db) as st:
        add_participant(st, "P001")
    return paper_db, log


def test_kill_while_writing_samples(setup):
    db, log = setup
    code = kill_during(db, log, "writing", 0.0)
    assert code == -signal.SIGKILL  # it really died mid-import
    assert drive_state(db) == "absent"
    # the store is usable afterwards and the same import then succeeds completely
    with Store.open(db) as st:
        from study.logs.importing import import_drive_file
        assert import_drive_file(st, "P001", "baseline", log).status == "imported"
    assert drive_state(db) == "complete"


@pytest.mark.slow
@pytest.mark.parametrize("marker, delay", [("read", 0.0), ("writing", 0.3), ("committing", 0.0),
                                           ("committing", 0.05)])
def test_kill_at_other_moments(setup, marker, delay):
    db, log = setup
    kill_during(db, log, marker, delay)
    assert drive_state(db) in ("absent", "complete")

"""A lab's day of drive logs (`pedas-study bench bulk-import`): the takeover study's 72 logs (18 participants x
familiarisation + three conditions, 20 Hz, ms/mph/ft, :mod:`tests.takeover_logs`) imported after every participant
finished the protocol, as a lab runs it from a shell: one `drive import --dir DIR --pattern ...` against the peer,
72 `drive import ID CONDITION FILE` calls, each a fresh process. Each run starts from a copy of the same walked store.
Reported: the medians, their ratio, and the peak resident memory of the largest process of a run (the command or
one of its worker processes; getrusage(RUSAGE_CHILDREN) of a wrapper process)."""
from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from pedas.paths import REPO_ROOT

STUDY = REPO_ROOT / "studies" / "takeover"
#: 2,300 samples a drive at 20 Hz: the study's 4 km route holds about 120 s at the generator's ~118 km/h (the
#: lab's own logs, ~3,300 samples each, came from a longer drive)
DURATION_S = 115.0
PATTERN = "{participant}_{condition}.csv"
#: runs a command and prints the peak RSS (kB) of its largest process
_WRAPPER = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
            "sys.stderr.write(r.stderr); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); "
            "sys.exit(r.returncode)")


@dataclass(frozen=True)
class BulkImportBench:
    logs: int
    samples: int
    cores: int
    bulk_repeats: int
    single_repeats: int
    bulk_s: list[float]
    single_s: list[float]
    bulk_median_s: float
    single_median_s: float
    ratio: float                 # one by one / bulk
    bulk_peak_mb: float
    single_peak_mb: float

    def as_dict(self) -> dict:
        return asdict(self)

    def to_text(self) -> str:
        return (f"{self.logs} drive logs ({self.samples:,} samples, 20 Hz) on {self.cores} core(s), each run from "
                f"the same walked store:\n"
                f"  drive import --dir (one process):     median {self.bulk_median_s:7.2f} s of {self.bulk_repeats} "
                f"({', '.join(f'{s:.2f}' for s in self.bulk_s)}), peak {self.bulk_peak_mb:.0f} MB\n"
                f"  {self.logs} x drive import (one by one):  median {self.single_median_s:7.2f} s of "
                f"{self.single_repeats} ({', '.join(f'{s:.2f}' for s in self.single_s)}), peak "
                f"{self.single_peak_mb:.0f} MB\n"
                f"  ratio one by one / bulk: {self.ratio:.1f}x; target <= 20 s: "
                f"{'met' if self.bulk_median_s <= 20 else 'NOT met'}")


def _run(args: list[str], env: dict) -> tuple[float, float]:
    """(wall s, peak RSS MB of the largest process) of one command."""
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _WRAPPER, *args], env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(args[3:])}: exit {r.returncode}: {r.stderr.strip()[:400]}")
    return dt, int(r.stdout.strip().splitlines()[-1]) / 1024


def walked_store(folder: Path, duration_s: float = DURATION_S) -> tuple[Path, Path, list[tuple[str, str, Path]]]:
    """(a store of the takeover study whose 18 participants walked the whole protocol, the folder of their 72
    logs, [(participant, drive, file)])."""
    sys.path.insert(0, str(REPO_ROOT))
    from tests.takeover_logs import write_log

    from study.logs.bulk_import import folder_items

    protocol = json.loads((STUDY / "protocol.json").read_text())
    orders = list(protocol["orders"])
    people = [(f"TOR-A{k:02d}", orders[(k - 1) % len(orders)]) for k in range(1, 19)]
    (folder / "roster.csv").write_text("participant_id,age,order\n" + "".join(
        f"{p},{21 + k},{o}\n" for k, (p, o) in enumerate(people)), encoding="utf-8")
    (folder / "events.csv").write_text("participant_id,phase,action\n" + "".join(
        "".join(f"{p},{ph},advance\n" for ph in protocol["orders"][o]) + f"{p},,complete\n" for p, o in people),
        encoding="utf-8")
    logs = folder / "logs"
    logs.mkdir()
    for p, _ in people:
        for c in (None, "none", "visual", "audiovisual"):
            write_log(logs, p, c, duration_s)
    db = folder / "walked.duckdb"
    env = dict(os.environ, PEDAS_STUDY_ACTOR="bench")
    for args in (["init", "--study", str(STUDY)], ["participant", "import", str(folder / "roster.csv")],
                 ["session", "advance", "--from", str(folder / "events.csv")]):
        subprocess.run([sys.executable, "-m", "pedas_study.cli", f"--db={db}", *args], env=env, check=True,
                       capture_output=True)
    items, _ = folder_items(logs, PATTERN)
    return db, logs, [(i.participant_id, i.drive, i.path) for i in items]


def bench_bulk_import(bulk_repeats: int = 3, single_repeats: int = 1, duration_s: float = DURATION_S,
                      progress=None) -> BulkImportBench:
    from study.logs.bulk_import import workers

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db, logs, items = walked_store(tmp, duration_s)
        samples = sum(sum(1 for _ in open(path)) - 1 for _, _, path in items)
        env = dict(os.environ, PEDAS_STUDY_ACTOR="bench")
        cli = [sys.executable, "-m", "pedas_study.cli"]
        bulk, bulk_peak = [], 0.0
        for i in range(bulk_repeats):
            run_db = tmp / f"bulk{i}.duckdb"
            shutil.copy(db, run_db)
            dt, peak = _run([*cli, f"--db={run_db}", "drive", "import", "--dir", str(logs), "--pattern", PATTERN], env)
            bulk.append(dt)
            bulk_peak = max(bulk_peak, peak)
            if progress:
                progress(f"bulk run {i + 1}: {dt:.2f} s")
        single, single_peak = [], 0.0
        for i in range(single_repeats):
            run_db = tmp / f"single{i}.duckdb"
            shutil.copy(db, run_db)
            total = 0.0
            for pid, drive, path in items:
                dt, peak = _run([*cli, f"--db={run_db}", "drive", "import", pid, drive, str(path)], env)
                total += dt
                single_peak = max(single_peak, peak)
            single.append(total)
            if progress:
                progress(f"one-by-one run {i + 1}: {total:.2f} s")
    mb, ms = statistics.median(bulk), statistics.median(single)
    return BulkImportBench(len(items), samples, workers(), bulk_repeats, single_repeats, bulk, single, mb, ms,
                           ms / mb, bulk_peak, single_peak)

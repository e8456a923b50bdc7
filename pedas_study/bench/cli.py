"""Wall time of everyday commands as a lab runs them (`pedas-study bench cli`): each command is a fresh process, as
from a shell, on a store of the paper's study with 100 registered participants; the peer is the bare interpreter
start (`python -c pass`) in the same run, the floor every command pays.

Timed: `--help`; `participant list`; `participant add`; `session advance`; `drive import` of a 10 Hz, 15-minute log
(9,000 samples); `participant import` of a 24-row roster into a fresh store; `plan power` (analytic); `analyze
survey --extended` without bootstrap on the reference answers (one run, the fit shared), and beside it, without a
target, `analyze survey` and `analyze extended` as two runs. Medians over `repeats`; each repeat of a writing command
acts on another participant, so every run does the same work.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pedas.paths import REPO_ROOT

STUDY = REPO_ROOT / "studies" / "pedas_paper"
ANSWERS = REPO_ROOT / "data" / "reference" / "survey.csv"
#: command -> its target median (s) (docs/store.md, "CLI"); None: no target
TARGETS = {"--help": 0.15, "participant list": 0.5, "participant add": 0.5, "session advance": 0.5,
           "drive import (9,000 samples)": 0.8, "participant import (24 rows)": 1.0, "plan power": 5.0,
           "analyze survey --extended": 5.0, "analyze survey; analyze extended": None}
ROSTER_HEADER = "participant_id,age,gender,license_years,style,eco_familiarity\n"


@dataclass(frozen=True)
class CliBench:
    repeats: int
    python_s: float                                   # median of `python -c pass`, the peer
    medians: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict:
        return asdict(self)

    def to_text(self) -> str:
        lines = [f"median wall time of {self.repeats} runs, each a fresh process (peer: python -c pass "
                 f"{self.python_s:.3f} s)", f"{'command':32s} {'median s':>9s} {'x peer':>7s}  target"]
        for name, s in self.medians.items():
            target = TARGETS.get(name)
            verdict = "-" if target is None else f"<= {target:g} s: {'met' if s <= target else 'NOT met'}"
            lines.append(f"{name:32s} {s:9.3f} {s / self.python_s:7.1f}  {verdict}")
        return "\n".join(lines)


def _roster(ids: list[str]) -> str:
    styles = ("normal", "cautious", "sporty")
    return ROSTER_HEADER + "".join(f"{p},{20 + k % 40},{('female', 'male')[k % 2]},{1 + k % 4},{styles[k % 3]},"
                                   f"{1 + k % 5}\n" for k, p in enumerate(ids))


def _timed(args: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(args, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(str(a) for a in args[3:])}: exit {r.returncode}: {r.stderr.strip()[:300]}")
    return dt


def bench_cli(repeats: int = 5) -> CliBench:
    """Median wall time of each command (module docstring) and of the interpreter start, on a temporary store."""
    from pedas_study.bench.store_import import synthetic_log

    if repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {repeats}")
    py = [sys.executable]
    env = {**os.environ, "PEDAS_STUDY_ACTOR": "bench"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db = tmp / "study.duckdb"
        cli = [*py, "-m", "pedas_study.cli", f"--db={db}"]
        _timed([*cli, "init", "--study", str(STUDY)], env)
        # 100 registered participants, the first `repeats` of them in the baseline drive
        roster = tmp / "roster.csv"
        roster.write_text(_roster([f"P{k:03d}" for k in range(1, 101)]), encoding="utf-8")
        _timed([*cli, "participant", "import", str(roster)], env)
        runs: dict[str, list[float]] = {name: [] for name in TARGETS}
        python = []
        for i in range(repeats):
            pid_new, pid = f"P{101 + i:03d}", f"P{1 + i:03d}"
            python.append(_timed([*py, "-c", "pass"], env))
            runs["--help"].append(_timed([*cli, "--help"], env))
            runs["participant list"].append(_timed([*cli, "participant", "list"], env))
            runs["participant add"].append(_timed([*cli, "participant", "add", pid_new, "--attr", "age=30",
                                                   "--attr", "gender=female", "--attr", "license_years=5",
                                                   "--attr", "style=normal", "--attr", "eco_familiarity=3"], env))
            runs["session advance"].append(_timed([*cli, "session", "advance", pid, "familiarisation"], env))
            _timed([*cli, "session", "advance", pid, "baseline_drive"], env)
            log = tmp / f"log{i}.parquet"     # another log each time: the same log twice is refused as stored
            synthetic_log(9000, seed=1 + i).to_parquet(log)
            runs["drive import (9,000 samples)"].append(_timed([*cli, "drive", "import", pid, "baseline", str(log)],
                                                                env))
            fresh = tmp / f"roster{i}.duckdb"
            _timed([*py, "-m", "pedas_study.cli", f"--db={fresh}", "init", "--study", str(STUDY)], env)
            small = tmp / f"roster{i}.csv"
            small.write_text(_roster([f"P{k:03d}" for k in range(1, 25)]), encoding="utf-8")
            runs["participant import (24 rows)"].append(
                _timed([*py, "-m", "pedas_study.cli", f"--db={fresh}", "participant", "import", str(small)], env))
            runs["plan power"].append(_timed([*cli, "plan", "power", "--responses", str(ANSWERS), "--study",
                                              str(STUDY), "--out", str(tmp / f"power{i}")], env))

            def analyze(what: str, *extra: str) -> float:
                return _timed([*cli, "analyze", what, "--responses", str(ANSWERS), "--study", str(STUDY),
                               "--bootstrap", "0", "--out", str(tmp / f"{what}{i}-{len(extra)}"), *extra], env)

            runs["analyze survey --extended"].append(analyze("survey", "--extended"))
            runs["analyze survey; analyze extended"].append(analyze("survey") + analyze("extended"))
    return CliBench(repeats, statistics.median(python), {k: statistics.median(v) for k, v in runs.items()})

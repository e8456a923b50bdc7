"""The what-if sweep: its design (sizes, seeds, ranges, bad input), and end to end through the CLI on a temporary
drive cache: reproducible outputs, a LocalCluster giving the local pool's points, kill -9 and resume, and the
committed sweep (data/sweep) still what the simulation gives."""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.sweep.design import (SweepSpec, check_spec, cohort, morris_design, parse_factors, sobol_design,
                                   whatif_of)
from pedas.whatif import FACTORS, WhatIf
from study.common.errors import UserError

REPO = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------------------------------------ the design
def test_morris_design_sizes_ranges_and_seed():
    spec = SweepSpec(factors=parse_factors(None), trajectories=3, seed=5)
    d = morris_design(spec)
    k = len(FACTORS)
    assert len(d) == 3 * (k + 1) and d["point"].tolist() == list(range(len(d)))
    assert (d["phase"] == "morris").all()
    for f in FACTORS.values():
        assert d[f.name].between(f.lo, f.hi).all(), f.name
        assert d[f.name].nunique() > 1, f.name
    # a Morris trajectory moves one factor per step
    x = d[list(FACTORS)].to_numpy()
    for t in range(3):
        steps = np.diff(x[t * (k + 1):(t + 1) * (k + 1)], axis=0)
        assert ((steps != 0).sum(axis=1) == 1).all()
    pd.testing.assert_frame_equal(d, morris_design(spec))
    assert not morris_design(SweepSpec(factors=spec.factors, trajectories=3, seed=6)).equals(d)


def test_factor_choice_holds_the_others_at_their_defaults():
    spec = SweepSpec(factors=parse_factors(["hud_band_kmh=1:3", "speeding_shift"]), trajectories=2)
    d = morris_design(spec)
    assert len(d) == 2 * 3
    assert d["hud_band_kmh"].between(1, 3).all() and d["speeding_shift"].between(-0.05, 0.10).all()
    assert (d["urban_density"] == 1.0).all() and d["lorry_share"].isna().all()
    w = whatif_of(d.iloc[0])
    assert dict(w.items()).keys() <= {"hud_band_kmh", "speeding_shift"}
    assert whatif_of(pd.Series({f: np.nan for f in FACTORS})) == WhatIf()


def test_sobol_design_sizes():
    spec = SweepSpec(factors=parse_factors(None), sobol_n=8, seed=1)
    d = sobol_design(spec, ["speeding_shift", "urban_density"], start=40)
    assert len(d) == 8 * (2 + 2) and d["point"].iloc[0] == 40 and (d["phase"] == "sobol").all()
    assert d["speeding_shift"].nunique() > 1 and (d["compliance_shift"] == 0.0).all()
    pd.testing.assert_frame_equal(d, sobol_design(spec, ["speeding_shift", "urban_density"], start=40))


def test_reduced_cohort_is_k_per_style_in_id_order():
    ref = pd.read_csv(REPO / "data" / "reference" / "participants.csv", dtype={"participant_id": str})
    people = cohort(SweepSpec(factors=parse_factors(None), participants=2))
    assert people["style"].value_counts().to_dict() == {"cautious": 2, "normal": 2, "sporty": 2}
    for style, g in people.groupby("style"):
        assert g["participant_id"].tolist() == sorted(ref[ref["style"] == style]["participant_id"])[:2]
    one = cohort(SweepSpec(factors=parse_factors(None), participants=1, styles=("sporty",)))
    assert one["participant_id"].tolist() == sorted(ref[ref["style"] == "sporty"]["participant_id"])[:1]


@pytest.mark.parametrize("texts, message", [
    (["warp_factor"], "unknown factor 'warp_factor'"),
    (["hud_band_kmh=3:1"], "lo must be below hi"),
    (["hud_band_kmh=2:2"], "lo must be below hi"),
    (["hud_band_kmh=a:b"], "two numbers"),
    (["hud_band_kmh", "hud_band_kmh=1:2"], "given twice"),
])
def test_bad_factors(texts, message):
    with pytest.raises(UserError, match=re.escape(message)):
        parse_factors(texts)


@pytest.mark.parametrize("kw, message", [
    ({"trajectories": 1}, "--trajectories must be >= 2"),
    ({"sobol_n": 6}, "power of 2"),
    ({"top": 0}, "--top must be between 1"),
    ({"participants": 0}, "--participants must be >= 1"),
    ({"styles": ("wild",)}, "--styles"),
    ({"styles": ("normal", "normal")}, "--styles"),
])
def test_bad_sizes(kw, message):
    with pytest.raises(UserError, match=re.escape(message)):
        check_spec(SweepSpec(factors=parse_factors(["hud_band_kmh", "speeding_shift"]),
                             **{"trajectories": 2, "top": 2, **kw}))
    with pytest.raises(UserError, match="at least 2 factors"):
        check_spec(SweepSpec(factors=parse_factors(["hud_band_kmh"]), top=1))


@pytest.mark.parametrize("args, message", [
    (["--factors", "nope"], "unknown factor 'nope'"),
    (["--factors", "lorry_share=0.3:0.1", "hud_band_kmh"], "lo must be below hi"),
    (["--factors", "lorry_share=0.5:1.5", "hud_band_kmh"], "lorry_share must be within [0, 1]"),
    (["--trajectories", "1"], "--trajectories must be >= 2"),
    (["--sobol-n", "3"], "power of 2"),
    (["--top", "9"], "--top must be between 1"),
    (["--participants", "99"], "fewer than 99 people"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--scenario", "moon"], "--scenario"),
])
def test_cli_bad_input_is_one_line_exit_2_and_writes_nothing(cli, tmp_path, args, message):
    out = tmp_path / "out"
    r = cli("simulate", "sweep", *args, "--out", out, "--cache-dir", tmp_path / "cache", db=None)
    assert r.code == 2
    assert message in r.err and len(r.err.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "cache").exists()


# ------------------------------------------------------------------------------------------------ end to end
# the single-lane scenario: these tests check the sweep's machinery (caching, Sobol, a cluster, kill -9), which does
# not depend on the traffic, at half the cost of a motorway drive; the committed sweep's test below drives the
# motorway
TINY = ["--factors", "compliance_shift", "speeding_shift", "--trajectories", "2", "--participants", "1",
        "--styles", "normal", "--seed", "0", "--scenario", "single-lane"]
SOBOL = ["--sobol-n", "1", "--top", "1"]
ANALYSIS = ["design.csv", "points.csv", "indices.csv", "indices.md", "indices.tex", "region.csv", "region.md",
            "region.tex", "figures/sweep_indices.png", "figures/sweep_indices.svg",
            "figures/sweep_indices.pdf"]


def _sweep(*args, timeout=600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pedas_study.cli", "simulate", "sweep", "--no-progress",
                           *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=REPO, **kw)


def _cached(stdout: str) -> list[int]:
    return [int(n) for n in re.findall(r"(\d+) already cached", stdout)]


def _same_outputs(a: Path, b: Path) -> None:
    for name in ANALYSIS:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


_POOLED: dict[str, tuple[Path, Path, Path]] = {}


@pytest.fixture
def pooled(tmp_path_factory):
    """The tiny sweep without a Sobol phase on 2 local workers: (cache, out, a copy of the cache as this run left
    it). Run once per test process (kept in `_POOLED`, not by a module scope, which pytest may tear down and set up
    again between the tests of the group)."""
    if "run" not in _POOLED:
        root = tmp_path_factory.mktemp("sweep")
        p = _sweep(*TINY, "--sobol-n", "0", "--workers", "2", "--cache-dir", root / "cache", "--out", root / "out")
        assert p.returncode == 0, p.stderr
        print("local pool:", p.stdout)
        shutil.copytree(root / "cache", root / "morris-cache")  # the cache, used by later runs, grows
        _POOLED["run"] = root / "cache", root / "out", root / "morris-cache"
    return _POOLED["run"]


def _cache_without(cache: Path, into: Path, k: int) -> int:
    """A copy of the drive cache `cache` in `into` without its first `k` drives (by name); the number kept."""
    drives = sorted(cache.glob("*.parquet"))
    assert len(drives) > k
    into.mkdir(parents=True)
    for d in drives[k:]:
        for f in (d, d.with_suffix(".json")):
            shutil.copy2(f, into / f.name)
    return len(drives) - k


@pytest.mark.slow
@pytest.mark.sumo
@pytest.mark.xdist_group("sweep")  # one worker: the pooled sweep is shared
def test_tiny_sweep_end_to_end_with_sobol_and_reproducible(pooled, tmp_path):
    cache, plain, _ = pooled
    first = _sweep(*TINY, *SOBOL, "--workers", "2", "--cache-dir", cache, "--out", tmp_path / "a")
    assert first.returncode == 0, first.stderr
    # the Morris points are the sweep above, cached; the Sobol phase's 1 x (1 + 2) points are new
    assert _cached(first.stdout) == [12, 0]
    assert "9 design points, 18 drives" in first.stdout and "Sobol factors: " in first.stdout
    points = pd.read_csv(tmp_path / "a" / "points.csv")
    assert points["phase"].value_counts().to_dict() == {"morris": 6, "sobol": 3}
    assert points["saving_overall_pct"].notna().all()
    ind = pd.read_csv(tmp_path / "a" / "indices.csv")
    assert set(ind["phase"]) == {"morris", "sobol"} and len(ind[ind["phase"] == "sobol"]) == 6
    # the Morris phase's points do not depend on whether a Sobol phase follows
    pd.testing.assert_frame_equal(points.iloc[:6], pd.read_csv(plain / "points.csv"))
    again = _sweep(*TINY, *SOBOL, "--workers", "2", "--cache-dir", cache, "--out", tmp_path / "b")
    assert _cached(again.stdout) == [12, 6]
    _same_outputs(tmp_path / "a", tmp_path / "b")


@pytest.mark.slow
@pytest.mark.sumo
@pytest.mark.xdist_group("sweep")  # one worker: the pooled sweep is shared
def test_local_cluster_gives_the_local_pool_points(pooled, tmp_path):
    from distributed import LocalCluster

    _, plain, morris = pooled
    # the pool's cache less 2 drives: the cluster drives those two, and the points are the pool's
    kept = _cache_without(morris, tmp_path / "cache", 2)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        p = _sweep(*TINY, "--sobol-n", "0", "--scheduler", lc.scheduler_address, "--cache-dir",
                   tmp_path / "cache", "--out", tmp_path / "out")
    assert p.returncode == 0, p.stderr
    print("LocalCluster:", p.stdout)
    assert _cached(p.stdout) == [kept]
    assert len(list((tmp_path / "cache").glob("*.parquet"))) == 12
    _same_outputs(plain, tmp_path / "out")


@pytest.mark.slow
@pytest.mark.sumo
@pytest.mark.xdist_group("sweep")  # one worker: the pooled sweep is shared
def test_kill_9_then_resume(pooled, tmp_path):
    _, plain, morris = pooled
    cache, out = tmp_path / "cache", tmp_path / "out"
    kept = _cache_without(morris, cache, 3)  # 3 drives left to drive: the kill comes after the first of them
    args = [sys.executable, "-m", "pedas_study.cli", "simulate", "sweep", "--no-progress", *TINY, "--sobol-n", "0",
            "--workers", "2", "--cache-dir", str(cache), "--out", str(out)]
    proc = subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)  # its own process group: the workers die with it

    def done() -> list[Path]:
        return [p for p in cache.glob("*.parquet") if p.with_suffix(".json").exists()] if cache.exists() else []

    deadline = time.monotonic() + 300
    while len(done()) < kept + 1 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for q in done() for p in (q, q.with_suffix(".json"))}
    assert kept < len(before) // 2 < 12, "the kill came before the first new drive or after the last"
    assert not out.exists()
    rerun = _sweep(*TINY, "--sobol-n", "0", "--workers", "2", "--cache-dir", cache, "--out", out)
    assert rerun.returncode == 0, rerun.stderr
    print(f"killed with {len(before) // 2} drives in the cache; rerun:", rerun.stdout)
    assert _cached(rerun.stdout)[0] >= len(before) // 2
    for p, stamp in before.items():
        assert (p.stat().st_ino, p.stat().st_mtime_ns) == stamp, f"{p.name} was rewritten"
    _same_outputs(plain, out)


POINT0 = REPO / "tests" / "data" / "sweep" / "point0_people.csv"


def _point0_people(n: int, cache_dir: Path | None = None) -> pd.DataFrame:
    """The first `n` people of the committed sweep's cohort at its first design point, driven now: their rows of
    :func:`analysis.sweep.run.point_effects` (both drives' KPIs, the reductions)."""
    from analysis.sweep.run import drive_points, point_effects, read_run, spec_of

    design, _, meta = read_run(REPO / "data" / "sweep")
    spec = spec_of(meta)
    people = cohort(spec).iloc[:n]
    tasks, logs = drive_points(design.iloc[:1], people, spec, workers=2, cache_dir=cache_dir, progress=False,
                               echo=lambda _: None)
    return point_effects(design.iloc[:1], people, tasks, logs)


@pytest.mark.slow
@pytest.mark.sumo
@pytest.mark.xdist_group("sweep")  # one worker: the pooled sweep is shared
def test_committed_sweep_first_point_still_simulates_to_its_values(tmp_path):
    """data/sweep is the committed sweep the report analyses. The reductions of its first design point's six people
    (tests/data/sweep/point0_people.csv, written by `python -m tests.e2e.test_sweep`, which drives all 12 drives) give
    the committed point's KPIs, and the first person's two drives, driven again, give that person's whole row: a
    change of the simulation that makes the committed sweep stale fails, at the cost of 2 drives instead of 12."""
    from analysis.sweep.design import KPIS
    from analysis.sweep.run import point_id, point_row, read_run, spec_of

    _, points, meta = read_run(REPO / "data" / "sweep")
    people = cohort(spec_of(meta))
    assert list(people["participant_id"]) == meta["cohort"]
    committed = pd.read_csv(POINT0)
    assert committed["participant_id"].tolist() == [point_id(0, slot) for slot in range(len(people))]
    row, _ = point_row(committed)
    for kpi in KPIS:  # points.csv keeps 12 significant digits
        want = points.loc[0, kpi]
        assert (pd.isna(want) and pd.isna(row[kpi])) or row[kpi] == pytest.approx(want, rel=1e-10, abs=1e-10), kpi
    again = _point0_people(1, cache_dir=tmp_path / "cache")
    pd.testing.assert_frame_equal(again, committed.iloc[:1], check_dtype=False, rtol=1e-12, atol=0)


if __name__ == "__main__":  # rewrite tests/data/sweep/point0_people.csv (all 12 drives of the point, 2 workers)
    from analysis.sweep.run import read_run

    _point0_people(len(read_run(REPO / "data" / "sweep")[2]["cohort"])).to_csv(POINT0, index=False,
                                                                                float_format="%.17g")

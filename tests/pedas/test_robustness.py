"""Robustness sweep: bookkeeping with a fake drive, the CI-sized sweep of real drives, and the CLI's input errors."""
from __future__ import annotations

import time

import pandas as pd
import pytest

from pedas_study.bench.robustness import (COLUMNS, SweepTask, robustness_sweep, run_one, summarise, sweep_tasks,
                                    traffic_design, wall_time)
from pedas.drive import DriveError, LivenessViolation, SafetyViolation


def fake_drive(seed, style, condition, *, traffic_seed=None, **kw):
    """Stands in for pedas.drive.drive (top level: it has to reach spawned workers). Fails for chosen inputs;
    early tasks sleep longest so that completion order differs from task order."""
    time.sleep(0.05 * max(0, 3 - seed))
    name = SweepTask(seed, style, condition, seed if traffic_seed is None else traffic_seed).label()
    if seed == 1 and style == "sporty" and condition == "pedas":  # named like the drive loop's errors
        raise SafetyViolation(f"{name}: collision at t=12.0 s, s=340.0 m", "collision")
    if seed == 2 and style == "cautious" and traffic_seed == 7:  # not named: the sweep names it
        raise LivenessViolation("stood still for 60 s at t=80.0 s, s=1200.0 m")
    if seed == 3 and condition == "baseline" and style == "normal":
        return {}["no such key"]  # an unexpected bug: KeyError
    if seed == 3 and condition == "pedas" and style == "cautious":  # the drive loop wraps what it did not expect
        raise DriveError(f"{name}: ValueError: boom") from ValueError("boom")
    df = pd.DataFrame({"t": [0.0, 0.2, 0.4]})
    df.attrs["drive"] = {"duration_s": 0.4 + seed, "steps": 3}
    return df


def test_design_is_sorted_and_resolves_the_traffic_seed():
    tasks = sweep_tasks([5, 1], ["sporty", "cautious"], ["pedas", "baseline"], [None, 9])
    assert len(tasks) == 2 * 2 * 2 * 2 and tasks == sorted(tasks)
    assert tasks[0] == SweepTask(1, "cautious", "baseline", 1) and tasks[1] == SweepTask(1, "cautious", "baseline", 9)
    assert len(sweep_tasks([9], ["normal"], ["pedas"], [None, 9])) == 1  # the same drive runs once
    assert traffic_design([1, 2, 4], 3) == (None, 3, 5)  # K different traffics per person
    assert traffic_design([1], 1) == (None,)


def test_sweep_counts_failures_by_kind_and_keeps_task_order():
    df = robustness_sweep([1, 2, 3], traffic_seeds=[None, 7], workers=2, progress=False, drive_fn=fake_drive)
    assert tuple(df.columns) == COLUMNS and len(df) == 3 * 3 * 2 * 2
    keys = list(zip(df["seed"], df["style"], df["condition"], df["traffic_seed"]))
    assert keys == sorted(keys)
    bad = df[~df["ok"]]
    assert sorted(bad["kind"].unique()) == ["collision", "exception:KeyError", "exception:ValueError", "standstill"]
    assert (bad["kind"] == "collision").sum() == 2  # both traffic seeds of (1, sporty, pedas)
    assert (bad["kind"] == "standstill").sum() == 2 and (bad["kind"] == "exception:KeyError").sum() == 2
    # every message names its drive, traffic included, once and in one line
    for row in bad.itertuples():
        cond = "pEDAS" if row.condition == "pedas" else row.condition
        assert row.message.startswith(f"{cond} drive of participant seed {row.seed} ({row.style}, "
                                      f"traffic seed {row.traffic_seed}): ")
        assert row.message.count("participant seed") == 1 and "\n" not in row.message
    assert bad.loc[bad["kind"] == "collision", "message"].iloc[0] == \
        "pEDAS drive of participant seed 1 (sporty, traffic seed 1): collision at t=12.0 s, s=340.0 m"
    ok = df[df["ok"]]
    assert (ok["kind"] == "ok").all() and ok["message"].isna().all() and (ok["steps"] == 3).all()
    assert (ok["duration_s"] == ok["seed"] + 0.4).all() and bad["duration_s"].isna().all()
    assert (df["wall_s"] >= 0).all() and df.attrs["workers"] == 2 and df.attrs["wall_s"] > 0

    s = summarise(df)
    assert s.to_dict("list")["kind"] == ["collision", "exception:KeyError", "exception:ValueError", "standstill"]
    assert s["failures"].tolist() == [2, 2, 2, 2] and s["share"].iloc[0] == pytest.approx(2 / 36)
    w = wall_time(df)
    assert set(w["median_by_condition"]) == {"baseline", "pedas"} and w["max"] >= w["median"] > 0


def test_summary_of_a_clean_sweep_shows_zero_failures():
    rows = [run_one(SweepTask(5, "normal", c, 5), fake_drive) for c in ("baseline", "pedas")]
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    assert df["ok"].all()
    assert summarise(df).to_dict("records") == [{"kind": "none", "failures": 0, "share": 0.0}]


def test_bad_design_is_rejected_before_any_drive():
    with pytest.raises(ValueError, match="sideways"):
        robustness_sweep([1], conditions=["sideways"], drive_fn=fake_drive, progress=False)
    with pytest.raises(ValueError, match="no drives"):
        robustness_sweep([], drive_fn=fake_drive, progress=False)


@pytest.mark.parametrize("args,msg", [
    (["--seeds", "5-3"], "--seeds"), (["--seeds", "ten"], "--seeds"), (["--seeds", "0"], "--seeds"),
    (["--styles", "fast"], "'fast'"), (["--conditions", ""], "--conditions"),
    (["--traffic-seeds", "0"], "--traffic-seeds"), (["--workers", "0"], "--workers"),
])
def test_cli_rejects_bad_arguments_in_one_line(cli, args, msg):
    r = cli("bench", "robustness", "--no-progress", *args, db=None)
    assert r.code == 2 and r.out == "" and msg in r.err
    assert r.err.startswith("pedas-study: error:") and len(r.err.strip().splitlines()) == 1


def test_cli_prints_failures_by_kind_and_exits_1(cli, monkeypatch, tmp_path):
    """The command's output and exit code, with the fake drive in place of SUMO."""
    import json

    import pedas_study.bench.robustness as br

    real = br.robustness_sweep
    monkeypatch.setattr(br, "robustness_sweep", lambda *a, **k: real(*a, **{**k, "drive_fn": fake_drive}))
    r = cli("bench", "robustness", "--seeds", "1-3", "--workers", "2", "--no-progress", "--out", tmp_path / "s.csv",
            db=None)
    assert r.code == 1, r.err
    lines = r.out.splitlines()
    assert lines[0].startswith("18 drives (3 person seeds x 3 styles x 2 conditions x 1 traffic seed) on 2 workers")
    # the standstill needs traffic seed 7
    assert lines[1] == "failures: 3 (collision 1, exception:KeyError 1, exception:ValueError 1)"
    assert lines[2] == "  collision: pEDAS drive of participant seed 1 (sporty, traffic seed 1): " \
        "collision at t=12.0 s, s=340.0 m"
    assert lines[3] == "  exception:ValueError: pEDAS drive of participant seed 3 (cautious, traffic seed 3): " \
        "ValueError: boom"  # failures in table order
    assert lines[4] == "  exception:KeyError: baseline drive of participant seed 3 (normal, traffic seed 3): " \
        "'no such key'"
    assert len(lines) == 5 and len(pd.read_csv(tmp_path / "s.csv")) == 18
    clean = cli("bench", "robustness", "--seeds", "4-5", "--styles", "normal", "--traffic-seeds", "2",
                "--no-progress", db=None)
    assert clean.code == 0 and clean.out.splitlines()[1] == "failures: 0"
    assert clean.out.startswith("8 drives (2 person seeds x 1 styles x 2 conditions x 2 traffic seeds)")
    js = json.loads(cli("bench", "robustness", "--seeds", "1-1", "--json", "--no-progress", db=None).out)
    assert js["drives"] == 6 and js["failures"] == 1 and js["failures_by_kind"] == {"collision": 1}


# ------------------------------------------------------------------------------------------------ real drives
@pytest.mark.sumo
@pytest.mark.slow
def test_ci_sweep_of_real_drives_has_no_failure(cli, tmp_path):
    """Real drives through the CLI on 2 workers (person seed 2000, fixed in advance, normal style, both conditions,
    own traffic): every drive completes without a safety, liveness or timeout failure. Every style and condition
    is driven by tests/pedas/test_drive.py (seed 31), through the same invariants."""
    out = tmp_path / "sweep.csv"
    r = cli("bench", "robustness", "--seeds", "2000-2000", "--styles", "normal", "--workers", "2", "--no-progress",
            "--out", out, db=None)
    assert r.code == 0 and "failures: 0" in r.out, r.out + r.err
    df = pd.read_csv(out)
    assert len(df) == 2 and df["ok"].all() and (df["kind"] == "ok").all() and (df["duration_s"] > 0).all()

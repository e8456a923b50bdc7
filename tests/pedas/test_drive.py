"""The drive loop in real SUMO traffic: log format, invariants, determinism, and that SUMO hides no bug."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pedas.constants import DT, ROUTE_LENGTH
from pedas.drive import HUD_LOG_COLUMNS, LOG_COLUMNS, SafetyGuard, SafetyViolation, drive, green_crossings
from pedas.route import Route, StopSign, TrafficLight

pytestmark = pytest.mark.sumo


# the tests of this drive are in one xdist group: one worker drives it once
@pytest.fixture(scope="module")
def baseline_log():
    return drive(21, "normal", "baseline")


def check_log(df: pd.DataFrame) -> None:
    """Invariants re-checked on a finished log (the drive loop raises during the drive already)."""
    from pedas.route_study import study_route

    route = study_route()
    # a pEDAS drive carries what its HUD showed after the drive-log columns (pedas.hud_log)
    assert tuple(df.columns) == LOG_COLUMNS + (HUD_LOG_COLUMNS if df.attrs["drive"]["condition"] == "pedas" else ())
    assert df["t"].iloc[0] == 0.0
    assert np.allclose(np.diff(df["t"]), DT)
    assert df["s"].iloc[-1] == pytest.approx(ROUTE_LENGTH, abs=100.0)
    assert np.all(np.diff(df["s"]) >= -1e-9) and np.all(df["v"] >= 0)
    assert set(df["segment"].unique()) == {"urban", "highway"}
    gap = df["leader_gap"].dropna()
    assert (gap > 0).all()
    s, t0 = df["s"].to_numpy(), df["t"].to_numpy()
    t_sim = df.attrs["drive"]["t_insert"] + t0
    for tl in route.lights:  # crossing step never starts at red
        k = np.flatnonzero((s[:-1] < tl.s) & (s[1:] >= tl.s))
        assert k.size == 1 and tl.state_at(t_sim[k[0]]) != "red"
    for ss in route.stops:  # a full stop close before each stop line
        near = (s >= ss.s - 10.0) & (s <= ss.s)
        assert (df["v"].to_numpy()[near] < 0.1).any()


@pytest.mark.xdist_group("baseline_log")
def test_baseline_drive_log(baseline_log):
    df = baseline_log
    check_log(df)
    assert (df["controller"] == "none").all() and df["v_advice"].isna().all()
    info = df.attrs["drive"]
    assert info["style"] == "normal" and info["condition"] == "baseline"
    # the highway instruction: >= 80 km/h on the main carriageway (v_min > 0)
    from pedas.route_study import study_route

    route = study_route()
    on_main = route.at(df["s"].to_numpy(), "v_min") > 0
    free = ~(df["leader_gap"] < 150.0)  # no overtaking: behind a slower vehicle the driver may fall below
    assert on_main.sum() > 1000
    assert df["v"][on_main & free].min() >= 80 / 3.6 - 0.5 if (on_main & free).any() else True
    assert df["v"][on_main].min() >= 70 / 3.6  # behind a lorry (80 km/h) at worst
    # the store's validation accepts the log as it is
    from study.logs.validation import validate_drive

    frame, ignored = validate_drive(df)
    assert ignored == () and len(frame) == len(df)


@pytest.mark.xdist_group("baseline_log")
def test_traffic_is_met_in_town_and_on_the_highway(baseline_log):
    df = baseline_log
    follow = df["leader_gap"] < 100.0
    assert follow[df["segment"] == "urban"].mean() > 0.1
    assert follow[df["segment"] == "highway"].mean() > 0.1


@pytest.mark.xdist_group("baseline_log")
def test_same_seed_gives_a_byte_identical_log(baseline_log, tmp_path):
    again = drive(21, "normal", "baseline")
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    baseline_log.to_csv(a, index=False)
    again.to_csv(b, index=False)
    assert a.read_bytes() == b.read_bytes()
    other = drive(22, "normal", "baseline")
    assert not other["v"].equals(baseline_log["v"])


def test_sumo_does_not_hide_a_reckless_driver(monkeypatch):
    """A driver model that ignores everything must trip an invariant: SUMO's own checks are off for the ego."""
    from pedas import drivers

    monkeypatch.setattr(drivers.HumanDriver, "act", lambda self, t, s, v, obs: 2.0 if v < 15.0 else 0.0)
    with pytest.raises(SafetyViolation, match="red light|collision|stop sign"):
        drive(21, "normal", "baseline")


def test_pedas_drive_log():
    df = drive(21, "normal", "pedas")
    check_log(df)
    assert set(df["controller"].unique()) <= {"rt", "cf"} and df["v_advice"].notna().all()
    assert set(df["hud_arrow"].dropna().unique()) <= {-1, 0, 1}
    stats = df.attrs["drive"]["controller_stats"]
    assert stats["steps"] == len(df)
    # the HUD channels agree with the logged speed, limit and arrow (whole km/h rounded half up)
    assert (df["hud_speed"] == np.floor(df["v"] * 3.6 + 0.5)).all()
    # the sign shows the legal limit in force, the logged one (never a value between two limits)
    assert (df["hud_limit"] == np.floor(df["speed_limit"] * 3.6 + 0.5)).all()
    assert (df.loc[df["hud_arrow"] == 0, "hud_arrow_len"] == 0).all() and df["hud_arrow_len"].between(0, 1).all()
    # the tone: a slow-down advice not followed (the arrow down at this sample or, as the timer counts, the last)
    down = df["hud_arrow"].fillna(0).to_numpy() == -1
    assert (down | np.r_[False, down[:-1]])[df["hud_tone"].to_numpy() == 1].all() and df["hud_tone"].any()
    assert df["hud_countdown"].notna().equals(df["hud_light"].notna()) and df["hud_countdown"].notna().any()


# --------------------------------------------------------------------------------------- the guard itself
def _route():
    tl = TrafficLight("T", 100.0, (("red", 30.0), ("green", 30.0)), offset=0.0)
    return Route.synthetic(length=500.0, ds=1.0, lights=[tl], stops=[StopSign("S", 300.0)])


def test_guard_catches_a_red_light_crossing():
    g = SafetyGuard(_route())
    g.check(10.0, 99.0, 5.0, None, False)
    with pytest.raises(SafetyViolation, match="red light T"):
        g.check(10.2, 100.5, 5.0, None, False)


def test_guard_allows_green_and_requires_a_stop_at_the_sign():
    g = SafetyGuard(_route())
    g.check(35.0, 99.0, 5.0, None, False)
    g.check(35.2, 100.5, 5.0, None, False)  # green: fine
    g.check(60.0, 299.0, 3.0, None, False)
    with pytest.raises(SafetyViolation, match="stop sign S"):
        g.check(60.2, 300.2, 3.0, None, False)
    g2 = SafetyGuard(_route())
    g2.check(35.0, 295.0, 0.0, None, False)  # halted 5 m before the line
    g2.check(40.0, 300.5, 2.0, None, False)


def test_guard_catches_collisions():
    g = SafetyGuard(_route())
    with pytest.raises(SafetyViolation, match="collision"):
        g.check(1.0, 10.0, 5.0, -0.01, False)
    with pytest.raises(SafetyViolation, match="collision"):
        SafetyGuard(_route()).check(1.0, 10.0, 5.0, 3.0, True)


def test_green_crossings_counts_a_stop_then_green_as_not_a_green_pass():
    df = pd.DataFrame({"tl_id": ["A"] * 4 + ["B"] * 3 + [None],
                       "tl_state": ["red", "red", "green", "green", "green", "green", "green", None],
                       "v": [5.0, 0.0, 2.0, 5.0, 10.0, 10.0, 10.0, 10.0],
                       "d_tl": [30.0, 5.0, 3.0, 0.5, 50.0, 20.0, 1.0, np.nan]})
    g = green_crossings(df)
    assert g.to_dict("list") == {"tl_id": ["A", "B"], "state_at_crossing": ["green", "green"],
                                 "stopped": [True, False], "green_pass": [False, True]}


@pytest.mark.slow
@pytest.mark.parametrize("style", ["cautious", "normal", "sporty"])
@pytest.mark.parametrize("condition", ["baseline", "pedas"])
def test_every_style_and_condition_completes_safely(style, condition):
    df = drive(31, style, condition)
    check_log(df)


def car_following_share(df: pd.DataFrame, segment: str | None = None, within: float = 100.0) -> float:
    """Share of drive time with a leader within `within` m (optionally of one segment)."""
    sel = df if segment is None else df[df["segment"] == segment]
    return float((sel["leader_gap"] < within).mean())


@pytest.mark.slow
@pytest.mark.parametrize("participant,style", [("P001", "cautious"), ("P002", "normal")])
def test_car_following_happens_in_both_conditions(participant, style):
    """The demand puts vehicles ahead of the ego in both conditions: the car-following share (leader within 100 m)
    of a few persons of the cohort (seed 0), in town and overall; a pEDAS drive is slower than the surrounding
    traffic, so its share is lower than baseline but not negligible."""
    from pedas.cohort import participant_seed

    seed = participant_seed(participant, 0)
    for condition in ("baseline", "pedas"):
        df = drive(seed, style, condition)
        assert car_following_share(df) >= 0.15, (condition, car_following_share(df))
        assert car_following_share(df, "urban") >= 0.15, (condition, car_following_share(df, "urban"))
        if condition == "baseline":
            assert car_following_share(df, "highway") > 0.1
        if condition == "pedas":  # the car-following MPC is exercised, not only the signal MPC
            assert (df["controller"] == "cf").mean() > 0.1


@pytest.mark.xdist_group("baseline_log")
def test_traffic_alone_replays_the_drive_it_times(baseline_log):
    """bench drive's floor: the baseline drive's speeds replayed into SUMO arrive after the logged steps; a log
    whose speeds were changed does not, and is refused instead of timed."""
    from pedas_study.bench.drive import traffic_alone

    res = traffic_alone(baseline_log)
    assert res["steps"] == baseline_log.attrs["drive"]["steps"] and res["ms_per_step"] > 0 and res["start_s"] > 0
    slower = baseline_log.copy()
    slower.attrs = baseline_log.attrs
    slower["v"] = slower["v"] * 0.9
    with pytest.raises(RuntimeError, match="did not reproduce"):
        traffic_alone(slower)


def test_bench_drive_reports_the_traffic_alone(cli):
    """bench drive prints SUMO's own share: the replayed baseline drive's ms/step and real-time factor."""
    import re

    r = cli("bench", "drive", "--cohort", "0", "--scenario", "single-lane", db=None)
    assert r.code == 0, r.err
    m = re.search(r"^traffic alone \(SUMO replaying the baseline drive\): ([\d.]+) ms/step -> (\d+)x real time",
                  r.out, re.M)
    assert m and float(m[1]) > 0 and int(m[2]) > 0, r.out
    assert re.search(r"^  \+ SUMO's start and the steps before the ego's insertion: [\d.]+ s per drive", r.out, re.M)
    # one round: each drive's ratio is its ms/step over the traffic alone's (the printed values, two decimals each)
    ratio = re.search(r"^ms/step over the traffic alone's in the same round, median \(range\) of 1: baseline "
                      r"([\d.]+)x \(([\d.]+)-([\d.]+)\), pedas \(daqp\) ([\d.]+)x", r.out, re.M)
    assert ratio and ratio[1] == ratio[2] == ratio[3], r.out
    pedas = re.search(r"^pedas \(daqp\) +drive: .* ([\d.]+) ms/step", r.out, re.M)
    assert float(ratio[4]) == pytest.approx(float(pedas[1]) / float(m[1]), rel=0.1), r.out

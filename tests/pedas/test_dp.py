"""Offline DP reference v_DP (Sec. 3.2): limits, acceleration bounds, stop signs, energy-vs-time weight."""
from __future__ import annotations

import numpy as np
import pytest

from pedas.constants import KMH, STOP_DWELL
from pedas.dp import A_MAX_DEFAULT, A_MIN_DEFAULT, cruise_cost_per_m, dp_reference
from pedas.power import trace_energy
from pedas.route import Route, StopSign


def accelerations(res):
    return np.diff(res.v_dp ** 2) / (2 * np.diff(res.s))


def profile_to_time(res):
    """(t, v) of the DP profile: constant acceleration per stage -> time per stage 2 ds / (v_i + v_i+1)."""
    vm = 0.5 * (res.v_dp[1:] + res.v_dp[:-1])
    t = np.concatenate([[0.0], np.cumsum(np.diff(res.s) / vm)])
    return t, res.v_dp


@pytest.fixture(scope="module")
def town():
    kappa = np.zeros(301)
    kappa[150:156] = 1 / 30.0  # a tight corner at 1.5 km: v_curve = sqrt(2 * 30) = 7.75 m/s
    return Route.synthetic(3000.0, ds=10.0, speed_limit=50 * KMH, curvature=kappa, stops=[StopSign("SS1", 2000.0)])


@pytest.fixture(scope="module")
def town_dp(town):
    return dp_reference(town)


def test_dp_respects_speed_limits_and_curve(town, town_dp):
    v_max = town.at(town_dp.s, "v_max")
    assert np.all(town_dp.v_dp <= v_max + 1e-9)
    assert town_dp.v_dp[150] <= np.sqrt(60.0) + 1e-9
    assert town_dp.v_dp.max() > 12.0  # it does drive near the 13.9 m/s limit in between


def test_dp_respects_acceleration_bounds(town_dp):
    a = accelerations(town_dp)
    assert a.max() <= A_MAX_DEFAULT + 1e-9 and a.min() >= A_MIN_DEFAULT - 1e-9


def test_dp_halts_at_the_stop_sign_and_counts_the_dwell(town, town_dp):
    assert town_dp.v_dp[0] == 0.0 and town_dp.v_dp[-1] == 0.0
    assert town_dp.at(2000.0) == 0.0
    t, v = profile_to_time(town_dp)
    assert town_dp.time_s == pytest.approx(t[-1] + STOP_DWELL, rel=1e-9)
    free = dp_reference(town, stop_at_signs=False)
    assert free.at(2000.0) > 5.0


def test_dp_energy_matches_the_trace_energy_of_its_profile(town_dp):
    t, v = profile_to_time(town_dp)
    e = trace_energy(t, v)  # finite-difference trace vs constant-acceleration stages: close, not identical
    dwell_wh = 300.06 * STOP_DWELL / 3600.0
    assert town_dp.energy_wh == pytest.approx(e.wh + dwell_wh, rel=0.05)


def test_more_weight_on_time_drives_faster_and_costs_energy():
    road = Route.synthetic(4000.0, ds=20.0, speed_limit=130 * KMH, segment="highway")
    slow = dp_reference(road, ds=20.0, w_time=1000.0)
    fast = dp_reference(road, ds=20.0, w_time=15_000.0)
    assert slow.time_s > fast.time_s
    assert slow.energy_wh < fast.energy_wh
    assert np.mean(slow.v_dp) < np.mean(fast.v_dp)
    # the cruise part sits near the per-metre optimum of (P + w) / v
    v = np.arange(5.0, 36.0, 0.25)
    for res, w in ((slow, 1000.0), (fast, 15_000.0)):
        v_opt = v[np.argmin(cruise_cost_per_m(v, w))]
        assert np.median(res.v_dp) == pytest.approx(v_opt, abs=1.5)


def test_highway_minimum_speed_holds_except_where_a_stop_forces_it():
    road = Route.synthetic(3000.0, ds=10.0, speed_limit=120 * KMH, v_min=80 * KMH, segment="highway")
    res = dp_reference(road, v0=80 * KMH, v_end=None)
    assert np.all(res.v_dp >= 80 * KMH - 1e-9)
    assert np.all(res.v_dp <= 120 * KMH + 1e-9)
    stopping = dp_reference(road, v0=80 * KMH, v_end=0.0)
    assert stopping.v_dp[-1] == 0.0
    assert np.all(stopping.v_dp[: int(0.8 * stopping.s.size)] >= 80 * KMH - 1e-9)


def test_uphill_costs_more_than_flat():
    flat = dp_reference(Route.synthetic(2000.0, ds=10.0))
    hill = dp_reference(Route.synthetic(2000.0, ds=10.0, grade=0.03))
    assert hill.energy_wh > flat.energy_wh + 40.0  # + m g h = 1600*9.81*60 m / 3600 = 262 Wh / efficiency


def test_infeasible_profile_is_a_one_line_error():
    road = Route.synthetic(500.0, ds=10.0, speed_limit=30.0, v_min=25.0)
    with pytest.raises(ValueError, match="no feasible"):
        dp_reference(road, v0=0.0, v_end=None)
    with pytest.raises(ValueError):
        dp_reference(road, ds=-1.0)


def test_13_2_km_route_runs_and_reports_its_runtime():
    road = Route.synthetic_mixed(stops=[StopSign("SS1", 2000.0)])
    res = dp_reference(road)
    assert res.s[-1] == pytest.approx(13_200.0) and res.runtime_s > 0
    hw = road.at(res.s, "segment") == "highway"
    assert np.mean(res.v_dp[hw]) < 100 * KMH  # energy weighted: well below the 120 km/h limit


def test_dp_profile_figure(tmp_path, town, town_dp):
    from pedas.figures_core import plot_dp_profile

    files = plot_dp_profile(tmp_path, town, town_dp)
    assert {f.name for f in files} == {"dp_profile.png", "dp_profile.svg", "dp_profile.pdf"}

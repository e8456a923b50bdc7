"""Green-wave reference eq. (1): band from the SPaT, choice of v_ref,min, fallback to v_DP, stop-sign exemption."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pedas.constants import DT, KMH, STOP_DWELL
from pedas.greenwave import green_wave_band, green_wave_reference
from pedas.route import Route, StopSign, TrafficLight

TL = TrafficLight("TL1", 300.0, (("green", 20.0), ("yellow", 3.0), ("red", 27.0)), offset=5.0)
V50 = 50 * KMH


def test_band_hand_worked_future_window():
    # t = 0: next green 5-25 s -> [300/25, 300/5] = [12, 60] m/s, cut by v_max = 13.89
    assert green_wave_band(300.0, 0.0, TL, 0.0, V50, margin=0.0) == (pytest.approx(12.0), pytest.approx(V50))


def test_band_hand_worked_current_window_too_short():
    # t = 10: green ends at 25 -> needs >= 300/15 = 20 m/s > v_max; next window 55-75 -> [300/65, 300/45]
    lo, hi = green_wave_band(300.0, 10.0, TL, 0.0, V50, margin=0.0)
    assert (lo, hi) == (pytest.approx(300 / 65), pytest.approx(300 / 45))


def test_margin_shrinks_the_window():
    lo, hi = green_wave_band(300.0, 10.0, TL, 0.0, V50, margin=1.5)
    assert (lo, hi) == (pytest.approx(300 / 63.5), pytest.approx(300 / 46.5))


def test_parameters_default_to_the_controller_settings():
    from pedas.params import CONTROLLER

    default = green_wave_band(300.0, 10.0, TL, 0.0, V50)
    assert default == green_wave_band(300.0, 10.0, TL, 0.0, V50, CONTROLLER.gw_horizon, CONTROLLER.gw_margin,
                                      v_floor=CONTROLLER.gw_v_floor)
    assert green_wave_band(300.0, 10.0, TL, 0.0, V50, horizon=30.0) is None    # next window starts at 55 s
    # v_max below v_floor is "crawl": no band
    assert green_wave_band(30.0, 0.0, TL, 0.0, 1.5) is not None
    assert green_wave_band(30.0, 0.0, TL, 0.0, 1.5, v_floor=2.0) is None
    road = Route.synthetic(3000.0, lights=[TrafficLight("far", 2500.0, TL.phases)])
    assert green_wave_reference(road, 0.0, 0.0, 12.0).tl_id is None
    assert green_wave_reference(road, 0.0, 0.0, 12.0, spat_range=3000.0).tl_id == "far"


def test_v_min_empties_the_band_and_the_reference_falls_back_to_dp():
    assert green_wave_band(300.0, 10.0, TL, 8.0, V50) is None
    road = Route.synthetic(600.0, v_min=8.0, lights=[TL])
    gw = green_wave_reference(road, 0.0, 10.0, v_dp_at_s=11.0)
    assert (gw.mode, gw.v_ref, gw.tl_id, gw.band) == ("dp", 11.0, "TL1", None)


def test_reference_is_v_ref_min_of_the_band():
    road = Route.synthetic(600.0, lights=[TL])
    gw = green_wave_reference(road, 0.0, 10.0, v_dp_at_s=13.0)
    assert gw.mode == "green_wave" and gw.tl_id == "TL1"
    assert gw.v_ref == gw.band[0] == pytest.approx(300 / 63.5)


def test_no_light_or_out_of_spat_range_gives_dp():
    road = Route.synthetic(3000.0, lights=[TrafficLight("far", 2500.0, TL.phases)])
    assert green_wave_reference(road, 0.0, 0.0, 12.0).mode == "dp"
    assert green_wave_reference(road, 0.0, 0.0, 12.0).tl_id is None
    assert green_wave_reference(road, 2100.0, 0.0, 12.0).tl_id == "far"
    assert green_wave_reference(road, 2600.0, 0.0, 12.0) == green_wave_reference(road, 2600.0, 0.0, 12.0)


def test_stop_signs_are_exempt_from_the_band():
    with_sign = Route.synthetic(600.0, lights=[TL], stops=[StopSign("SS1", 100.0)])
    without = Route.synthetic(600.0, lights=[TL])
    # before the sign: its compulsory halt rules (v_DP, mode 'stop'); the band ignores it
    gw = green_wave_reference(with_sign, 50.0, 10.0, v_dp_at_s=4.0)
    assert (gw.mode, gw.tl_id, gw.v_ref) == ("stop", "SS1", 4.0)
    # past the sign: exactly the band of the route without it
    assert green_wave_reference(with_sign, 150.0, 10.0, 9.0) == green_wave_reference(without, 150.0, 10.0, 9.0)
    # a sign beyond the light does not matter
    after = Route.synthetic(600.0, lights=[TL], stops=[StopSign("SS9", 500.0)])
    assert green_wave_reference(after, 0.0, 10.0, 9.0) == green_wave_reference(without, 0.0, 10.0, 9.0)


def test_curve_before_the_light_caps_v_ref_max():
    kappa = np.zeros(61)
    kappa[20] = 1 / 18.0  # v_curve = 6 m/s at 200 m
    road = Route.synthetic(600.0, lights=[TL], curvature=kappa)
    gw = green_wave_reference(road, 0.0, 0.0, 13.0)
    assert gw.band is None or gw.band[1] <= 6.0 + 1e-9


@settings(max_examples=150, deadline=None)
@given(d=st.floats(5.0, 500.0), t=st.floats(0.0, 500.0), v_min=st.sampled_from([0.0, 5.0]),
       v_max=st.floats(8.0, 20.0))
def test_constant_speed_at_the_band_edges_arrives_in_green(d, t, v_min, v_max):
    band = green_wave_band(d, t, TL, v_min, v_max)
    assume(band is not None)
    lo, hi = band
    assert max(v_min, 1.0) - 1e-9 <= lo <= hi <= v_max + 1e-9
    for v in (lo, hi, 0.5 * (lo + hi)):
        assert TL.state_at(t + d / v) == "green"


def simulate(route, v0=10.0, v_dp=13.8, a_lim=(-2.5, 1.5), tau=1.0, green_wave=True):
    """Point-mass driver tracking the reference: a = (v_ref - v) / tau within a_lim. Approaching a stop sign
    (mode 'stop') it brakes to the line at 1.5 m/s^2, halts there and waits STOP_DWELL s. With green_wave=False it
    tracks v_DP and ignores the lights. Returns the crossings (id, time, state), the trace and the stops made."""
    s, v, t, dwell_until, done_stops = 0.0, v0, 0.0, -1.0, set()
    crossings, trace = [], []
    while s < route.length - 10.0 and t < 600.0:
        gw = green_wave_reference(route, s, t, v_dp)
        v_ref = gw.v_ref if green_wave else v_dp
        ss = route.next_stop(s)
        if gw.mode == "stop":
            v_ref = min(v_dp, math.sqrt(2 * 1.5 * max(ss.s - s, 0.0)))
        a = float(np.clip((v_ref - v) / tau, *a_lim))
        v1 = max(v + a * DT, 0.0)
        s1 = s + 0.5 * (v + v1) * DT
        if t < dwell_until:
            s1, v1 = s, 0.0
        elif ss is not None and ss.ss_id not in done_stops and s1 >= ss.s:  # halt at the line
            s1, v1, dwell_until = ss.s + 1e-6, 0.0, t + DT + STOP_DWELL
            done_stops.add(ss.ss_id)
        for tl in route.lights:
            if s < tl.s <= s1:
                tc = t + DT * (tl.s - s) / (s1 - s)
                crossings.append((tl.tl_id, tc, tl.state_at(tc)))
        trace.append((t, s, v, gw.mode))
        s, v, t = s1, v1, t + DT
    return crossings, trace, done_stops


def test_two_light_route_is_crossed_in_green_when_following_v_ref():
    tl1 = TrafficLight("TL2", 400.0, (("green", 25.0), ("yellow", 3.0), ("red", 30.0)), offset=0.0)
    tl2 = TrafficLight("TL3", 900.0, (("green", 25.0), ("yellow", 3.0), ("red", 30.0)), offset=20.0)
    road = Route.synthetic(1200.0, lights=[tl1, tl2], stops=[StopSign("SS1", 150.0)])
    # driving v_DP regardless of the lights meets red: the test is not trivial
    naive, _, _ = simulate(road, green_wave=False)
    assert any(state != "green" for _, _, state in naive), naive
    crossings, trace, stops = simulate(road)
    assert [c[0] for c in crossings] == ["TL2", "TL3"]
    assert all(state == "green" for _, _, state in crossings), crossings
    assert stops == {"SS1"}  # the stop sign was honoured with its dwell
    modes = {m for *_, m in trace}
    assert {"stop", "green_wave"} <= modes
    # no stop at the lights: the speed stays above 1 m/s within 50 m of each light
    for tl in (tl1, tl2):
        near = [v for _, s, v, _ in trace if tl.s - 50.0 <= s <= tl.s]
        assert min(near) > 1.0


def test_space_time_figure_and_its_scenario(tmp_path):
    from pedas.figures_core import green_wave_example, plot_green_wave, simulate_reference_following

    route = green_wave_example()
    t, s, v = simulate_reference_following(route)
    for tl in route.lights:  # the drawn green-wave trajectory crosses every light in green, without stopping
        i = int(np.searchsorted(s, tl.s))
        assert tl.state_at(t[i]) == "green" and v[i] > 1.0
    t_dp, s_dp, v_dp = simulate_reference_following(route, green_wave=False)
    assert np.any((v_dp < 0.1) & (np.abs(s_dp - route.lights[0].s) < 2.0))  # the v_DP driver waits at red
    files = plot_green_wave(tmp_path, route)
    assert {f.name for f in files} == {"green_wave_space_time.png", "green_wave_space_time.svg", "green_wave_space_time.pdf"}

"""The virtual driver model on synthetic routes, without SUMO: parameters, IDM terms, lights, stop signs, leaders,
advisory tracking."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pedas.constants import DT, HUD_BAND, KMH
from pedas.drivers import (HALT_BAND, PARAM_DISTRIBUTIONS, STYLES, HumanDriver, Perception, desired_speed_profile,
                           idm_free, idm_interaction, sample_driver)
from pedas.route import Route, StopSign, TrafficLight


def test_same_seed_same_person_and_bounds():
    for style in STYLES:
        a, b = sample_driver(7, style), sample_driver(7, style)
        assert a == b
        assert sample_driver(8, style) != a
        for name, dist in PARAM_DISTRIBUTIONS[style].items():
            if name in a.as_dict():
                assert dist.lo <= a.as_dict()[name] <= dist.hi
        assert a.hud_delay > a.reaction  # reading the HUD adds a glance
        assert 0.7 <= a.reaction <= 1.5  # perception-reaction time range of Green (2000), docs/drivers.md


def test_unknown_style_is_refused():
    with pytest.raises(ValueError, match="unknown driving style"):
        sample_driver(1, "reckless")


def test_styles_are_ordered_as_documented():
    draws = {st: [sample_driver(i, st) for i in range(150)] for st in STYLES}
    mean = {st: {k: np.mean([getattr(d, k) for d in ds]) for k in ("speed_factor", "a_max", "headway", "a_lat")}
            for st, ds in draws.items()}
    assert mean["cautious"]["speed_factor"] < mean["normal"]["speed_factor"] < mean["sporty"]["speed_factor"]
    assert mean["cautious"]["a_max"] < mean["normal"]["a_max"] < mean["sporty"]["a_max"]
    assert mean["cautious"]["headway"] > mean["normal"]["headway"] > mean["sporty"]["headway"]
    assert mean["cautious"]["a_lat"] < mean["sporty"]["a_lat"]
    # comfortable accelerations ~1-2 m/s^2 (docs/drivers.md), means within the documented bands
    assert 0.9 <= mean["cautious"]["a_max"] and mean["sporty"]["a_max"] <= 2.2


def test_idm_terms_hand_worked():
    p = sample_driver(1, "normal")
    assert idm_free(10.0, 10.0, 1.5) == pytest.approx(0.0)
    assert idm_free(0.0, 10.0, 1.5) == pytest.approx(1.5)
    assert idm_free(5.0, 10.0, 2.0) == pytest.approx(2.0 * (1 - 0.5 ** 4))
    # s* = s0 + v T + v dv / (2 sqrt(a b)); a_int = -a (s*/s)^2
    v, gap, dv = 10.0, 30.0, 2.0
    s_star = p.s0 + v * p.headway + v * dv / (2 * math.sqrt(p.a_max * p.b_comf))
    assert idm_interaction(v, gap, dv, p) == pytest.approx(-p.a_max * (s_star / gap) ** 2)


def _drive_alone(route, drv, t_end=400.0, assisted=False, advice=None, leader=None, t0=0.0):
    """Kinematic loop of the driver model (no SUMO); returns arrays t, s, v, a."""
    human = HumanDriver(route, drv, assisted=assisted)
    t, s, v = t0, 0.0, 0.0
    out = []
    lead = leader
    while t < t_end and s < route.length - 1.0:
        tl = route.next_light(s)
        gap = lv = la = None
        if lead is not None:
            gap, lv, la = lead(t, s)
        obs = Perception(t, gap, lv, tl.state_at(t) if tl else None, tl.remaining(t) if tl else None,
                         advice(t, s, v) if advice else None, False, s=s, leader_a=la or 0.0)
        a = human.act(t, s, v, obs)
        v1 = max(v + a * DT, 0.0)
        out.append((t, s, v, (v1 - v) / DT))
        s += DT * (v + v1) / 2
        v = v1
        t += DT
    return np.array(out).T


def test_free_road_reaches_wish_speed_and_keeps_it():
    route = Route.synthetic(length=3000.0, ds=1.0, speed_limit=50 * KMH)
    drv = sample_driver(3, "normal")
    t, s, v, a = _drive_alone(route, drv)
    cruise = v[(s > 1000) & (s < 2000)]
    assert cruise == pytest.approx(50 * KMH * drv.speed_factor, abs=0.3)
    assert a.max() <= drv.a_max + 1e-9  # never harder than the comfortable acceleration on a free road


def test_anticipates_a_curve():
    curv = np.zeros(3001)
    curv[2000:2100] = 1 / 40.0
    route = Route.synthetic(length=3000.0, ds=1.0, speed_limit=50 * KMH, curvature=curv)
    drv = sample_driver(4, "normal")
    t, s, v, a = _drive_alone(route, drv)
    in_curve = v[(s >= 2000) & (s <= 2100)]
    assert in_curve.max() <= math.sqrt(drv.a_lat * 40.0) + 0.05  # own lateral-acceleration preference
    assert a.min() >= -1.1 * drv.b_comf  # slowed down in time, (about) comfortably
    assert np.all(desired_speed_profile(route, drv) <= 50 * KMH * drv.speed_factor + 1e-9)


@pytest.mark.parametrize("style", STYLES)
def test_stops_at_red_never_crosses(style):
    # red for the first 60 s, then green
    tl = TrafficLight("X", 400.0, (("red", 60.0), ("green", 60.0)), offset=0.0)
    route = Route.synthetic(length=800.0, ds=1.0, speed_limit=50 * KMH, lights=[tl])
    drv = sample_driver(11, style)
    t, s, v, a = _drive_alone(route, drv, t_end=150.0)
    before = t < 60.0
    assert s[before].max() < 400.0  # waited behind the line while red
    stood = (s > 390.0) & (v < 0.01)
    assert stood.any() and s[stood].max() <= 400.0 - 0.2  # stood close to the line
    assert s.max() > 600.0  # went on at green


def test_yellow_dilemma_never_ends_in_red_crossing():
    """Arriving at every phase of the cycle: stop or go at yellow, but never in the line at red."""
    route_len = 600.0
    for style in STYLES:
        drv = sample_driver(5, style)
        for off in np.arange(0.0, 60.0, 2.5):
            tl = TrafficLight("Y", 450.0, (("green", 30.0), ("yellow", 4.0), ("red", 26.0)), offset=off)
            route = Route.synthetic(length=route_len, ds=1.0, speed_limit=50 * KMH, lights=[tl])
            t, s, v, a = _drive_alone(route, drv, t_end=200.0)
            k = np.flatnonzero((s[:-1] < 450.0) & (s[1:] >= 450.0))
            assert k.size == 1
            assert tl.state_at(t[k[0]]) != "red", (style, off)


def test_stop_sign_full_halt_then_dwell():
    route = Route.synthetic(length=600.0, ds=1.0, speed_limit=50 * KMH, stops=[StopSign("S", 300.0)])
    drv = sample_driver(6, "sporty")
    t, s, v, a = _drive_alone(route, drv, t_end=120.0)
    halted = (v < 0.05) & (s > 300.0 - HALT_BAND) & (s <= 300.0)
    assert halted.any()
    assert halted.sum() * DT >= drv.stop_dwell - DT - 1e-9
    assert s.max() > 500.0


@pytest.mark.parametrize("style", STYLES)
@pytest.mark.parametrize("decel", [4.5, 8.0])
def test_no_rear_end_when_the_leader_brakes_hard(style, decel):
    """A leader at the same speed brakes to a stop at `decel` (SUMO's normal and emergency braking)."""
    route = Route.synthetic(length=3000.0, ds=1.0, speed_limit=50 * KMH)
    for seed in range(4):
        drv = sample_driver(seed, style)
        state = {"x": 60.0, "v": 13.0, "t": 0.0}  # leader rear bumper position, speed

        def leader(t, s):
            dt = t - state["t"]
            state["t"] = t
            acc = -decel if t > 40.0 else 0.0
            v0 = state["v"]
            state["v"] = max(v0 + acc * dt, 0.0)
            state["x"] += dt * (v0 + state["v"]) / 2
            return state["x"] - s, state["v"], acc if state["v"] > 0 else 0.0

        t, s, v, a = _drive_alone(route, drv, t_end=70.0, leader=leader)
        # gap to the stopped leader at the end stays positive (the loop evaluates the gap every step)
        assert state["x"] - s[-1] > 0.5, (style, seed)


def test_assisted_driver_coasts_inside_the_band_and_tracks_outside():
    route = Route.synthetic(length=5000.0, ds=1.0, speed_limit=100 * KMH)
    drv = sample_driver(9, "normal")
    human = HumanDriver(route, drv, assisted=True)
    v = 20.0
    # full compliance target for the test: use the driver's own wish equal to the advice
    own = human.v_wish(1000.0)
    a = human.act(0.0, 1000.0, v, Perception(0.0, None, None, None, None, advice=own - 0.5 * HUD_BAND))
    # the advice is perceived hud_delay late: the first call already sees it (buffer starts with it)
    target = own - 0.5 * HUD_BAND
    if abs(v - target) <= HUD_BAND:
        assert a == pytest.approx(human.coast_accel(v, 1000.0))
    human2 = HumanDriver(route, drv, assisted=True)
    a_up = human2.act(0.0, 1000.0, 10.0, Perception(0.0, None, None, None, None, advice=25.0))
    assert 0.0 < a_up <= drv.a_max
    human3 = HumanDriver(route, drv, assisted=True)
    in_band = human3.act(0.0, 1000.0, 20.0, Perception(0.0, None, None, None, None, advice=20.0 + 0.2))
    # in band of the advice but compliance < 1 pulls the target towards the own wish: coast or accelerate gently
    assert in_band <= drv.a_max


def test_assisted_drive_follows_advice_on_a_free_road():
    route = Route.synthetic(length=4000.0, ds=1.0, speed_limit=50 * KMH)
    drv = sample_driver(2, "cautious")
    t, s, v, a = _drive_alone(route, drv, assisted=True, advice=lambda t, s, v: 40 * KMH)
    target = 40 * KMH + (1 - drv.compliance) * (50 * KMH * drv.speed_factor - 40 * KMH)
    late = v[s > 2000]
    assert np.abs(late - target).max() <= HUD_BAND + 0.3 * KMH  # stays in (about) the band
    assert (a[s > 2000] <= 0.0).mean() > 0.3  # and coasts a good part of the time


def test_a_driver_committed_at_yellow_does_not_slow_into_the_red():
    """Decided to go at a yellow light, the driver brakes at most down to the deceleration that still covers the
    distance to the line + 1 m in the yellow left less one step: a = 2 (d + 1 - v T) / T^2 (hand-worked), even
    under a falling advice with a warning tone, which on green makes the same driver brake hard."""
    tl = TrafficLight("Y", 440.0, (("green", 30.0), ("yellow", 4.0), ("red", 26.0)), offset=0.0)
    route = Route.synthetic(length=600.0, ds=1.0, speed_limit=50 * KMH, lights=[tl])
    drv = sample_driver(5, "normal")
    human = HumanDriver(route, drv, assisted=True)
    # 20 m before the line at the own wish speed (too close to stop comfortably), yellow left for 21 m + 0.3 s: go
    s, v = 420.0, human.v_wish(440.0)
    left = 21.0 / v + 0.3
    on_yellow = human.act(30.5, s, v, Perception(30.5, None, None, "yellow", left, advice=5.0, warning=True, s=s))
    assert human.events == [(30.5, "Y", "yellow:go")]
    tt = left - DT
    assert on_yellow == pytest.approx(2.0 * (20.0 + 1.0 - v * tt) / tt ** 2)
    assert -1.5 < on_yellow < 0.0
    on_green = HumanDriver(route, drv, assisted=True).act(
        20.0, s, v, Perception(20.0, None, None, "green", 10.0, advice=5.0, warning=True, s=s))
    assert on_green < on_yellow - 1.0

"""Route type: fixed-time SPaT of traffic lights, profiles, curve limit, lookup of the objects ahead."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pedas.constants import HIGHWAY_MIN_SPEED, KMH, ROUTE_LENGTH
from pedas.route import CLOCK_MAX, Route, StopSign, TrafficLight

TL = TrafficLight("TL1", 300.0, (("green", 20.0), ("yellow", 3.0), ("red", 27.0)), offset=5.0)


def test_cycle_and_states_hand_worked():
    assert TL.cycle == 50.0
    # the cycle starts at t = 5: green 5-25, yellow 25-28, red 28-55 (and -22..5 before)
    assert [TL.state_at(t) for t in (0.0, 5.0, 24.9, 25.0, 27.9, 28.0, 54.9, 55.0)] == \
        ["red", "green", "green", "yellow", "yellow", "red", "red", "green"]
    assert TL.remaining(0.0) == pytest.approx(5.0)
    assert TL.remaining(10.0) == pytest.approx(15.0)
    assert TL.remaining(26.0) == pytest.approx(2.0)
    assert TL.state_at(-30.0) == "green"  # the plan repeats before the offset too


def test_green_windows_are_unclipped_and_merged():
    assert TL.green_windows(0.0, 100.0) == [(5.0, 25.0), (55.0, 75.0)]
    assert TL.green_windows(10.0, 60.0) == [(5.0, 25.0), (55.0, 75.0)]
    assert TL.green_windows(26.0, 50.0) == []
    two_greens = TrafficLight("X", 0.0, (("green", 5.0), ("green", 5.0), ("red", 10.0)))
    assert two_greens.green_windows(0.0, 15.0) == [(0.0, 10.0)]
    always = TrafficLight("A", 0.0, (("green", 30.0),))
    assert always.green_windows(3.0, 10.0) == [(0.0, math.inf)]


def test_next_phase_starts():
    assert TL.next_phase_starts(0.0, 60.0) == [(5.0, "green"), (25.0, "yellow"), (28.0, "red"), (55.0, "green")]
    assert TL.next_phase_starts(5.0, 10.0) == []


@pytest.mark.parametrize("t", [1e18, -1e300, 1e308, math.inf, math.nan, CLOCK_MAX * (1 + 1e-15)])
def test_a_clock_beyond_its_range_is_refused_not_scanned(t):
    """Beyond ~1e16 s adding a phase no longer moves the clock: the scan over phase starts would never end (and
    grew a server by gigabytes). Every look-up refuses such a time at once."""
    for call in (lambda: TL.spat(t, 60.0), lambda: TL.state_at(t), lambda: TL.green_windows(t, t + 60.0),
                 lambda: TL.next_phase_starts(0.0, t)):
        with pytest.raises(ValueError, match="outside the signal clock's range"):
            call()


@settings(max_examples=60, deadline=None)
@given(t0=st.floats(-CLOCK_MAX, CLOCK_MAX - 200.0), horizon=st.floats(0.0, 200.0))
def test_phase_starts_within_the_clock_are_complete(t0, horizon):
    """At any time in range the scan ends by its bound and finds every phase start: the starts in (t0, t0 + h]
    step through the plan's phases in order, each one phase length after the one before."""
    changes = TL.next_phase_starts(t0, horizon)
    assert len(changes) in (math.floor(horizon / 50.0) * 3 + k for k in range(4))
    states = [s for _, s in changes]
    assert all(b == {"green": "yellow", "yellow": "red", "red": "green"}[a] for a, b in zip(states, states[1:]))
    durations = {"green": 20.0, "yellow": 3.0, "red": 27.0}
    assert all(abs(t2 - t1 - durations[s1]) < 1e-6 for (t1, s1), (t2, _) in zip(changes, changes[1:]))


def test_traffic_light_validation():
    with pytest.raises(ValueError, match="state"):
        TrafficLight("bad", 0.0, (("blue", 3.0),))
    with pytest.raises(ValueError, match="duration"):
        TrafficLight("bad", 0.0, (("red", 0.0),))
    with pytest.raises(ValueError, match="no phases"):
        TrafficLight("bad", 0.0, ())


@settings(max_examples=200, deadline=None)
@given(t=st.floats(-500.0, 5000.0), horizon=st.floats(0.0, 120.0))
def test_spat_is_the_three_calls_from_one_look_up(t, horizon):
    """The controller's one look-up per step gives the very numbers of state_at, remaining, next_phase_starts."""
    assert TL.spat(t, horizon) == (TL.state_at(t), TL.remaining(t), TL.next_phase_starts(t, horizon))
    assert TL.spat(5.0, 25.0) == ("green", 20.0, [(25.0, "yellow"), (28.0, "red")])
    assert TL.state_remaining(t) == (TL.state_at(t), TL.remaining(t))   # the drive loop's look-up

@settings(max_examples=80, deadline=None)
@given(t=st.floats(-500.0, 5000.0))
def test_remaining_is_consistent_with_state(t):
    rem = TL.remaining(t)
    assert 0 < rem <= 27.0 + 1e-9
    assert TL.state_at(t + rem - 1e-6) == TL.state_at(t)
    assert TL.state_at(t + rem + 1e-6) != TL.state_at(t)


def test_synthetic_route_profiles():
    r = Route.synthetic(1000.0, ds=10.0, grade=0.02, lights=[TL], stops=[StopSign("SS1", 100.0)])
    assert r.length == 1000.0 and r.s.size == 101
    assert r.z[-1] == pytest.approx(1000.0 * math.tan(0.02))
    assert r.at(55.0, "speed_limit") == pytest.approx(50 * KMH)
    assert r.at(55.0, "segment") == "urban"
    assert np.all(np.isinf(r.v_curve)) and np.allclose(r.v_max, 50 * KMH)
    assert r.next_light(0.0) is TL and r.next_light(300.0) is TL and r.next_light(300.1) is None
    assert r.next_stop(0.0).ss_id == "SS1" and r.next_stop(150.0) is None


def test_curve_limit_from_lateral_acceleration():
    kappa = np.zeros(101)
    kappa[40:61] = -1 / 50.0  # left or right curve: only |kappa| counts
    r = Route.synthetic(1000.0, curvature=kappa, a_lat_max=2.0)
    assert r.v_curve[50] == pytest.approx(10.0)  # sqrt(2 * 50)
    assert r.v_max[50] == pytest.approx(10.0) and r.v_max[0] == pytest.approx(50 * KMH)
    assert r.min_over(0.0, 1000.0) == pytest.approx(10.0)
    assert r.min_over(0.0, 300.0) == pytest.approx(50 * KMH)


@pytest.mark.parametrize("kw,msg", [
    (dict(s=[0.0, 10.0, 5.0]), "ascending"),
    (dict(s=[1.0, 10.0, 20.0]), "start at 0"),
    (dict(z=[0.0, 1.0]), "z"),
    (dict(segment=["urban", "city", "urban"]), "segment"),
    (dict(speed_limit=0.0), "speed_limit"),
    (dict(lights=(TrafficLight("far", 99.0, (("red", 1.0),)),)), "outside"),
])
def test_route_validation(kw, msg):
    base = dict(name="r", s=[0.0, 10.0, 20.0], z=0.0, grade=0.0, curvature=0.0, speed_limit=10.0, v_min=0.0,
                segment="urban")
    with pytest.raises(ValueError, match=msg):
        Route(**{**base, **kw})


def test_synthetic_mixed_route_is_13_2_km_with_a_highway_minimum():
    r = Route.synthetic_mixed()
    assert r.length == pytest.approx(ROUTE_LENGTH)
    assert r.at(9000.0, "v_min") == pytest.approx(HIGHWAY_MIN_SPEED)
    assert r.at(9000.0, "segment") == "highway" and r.at(1000.0, "segment") == "urban"
    assert r.at(1000.0, "v_min") == 0.0

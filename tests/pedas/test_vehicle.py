"""Vehicle dynamics eq. (2)-(3a), linearisations (Fig. 5a, eq. 6a), braking split (Sec. 3.5), inverse dynamics."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pedas.constants import DT
from pedas.params import LEAF
from pedas.vehicle import (AeroLinearisation, fit_aero, fit_traction_limit, forces_from_trace, linear_model, resistance, split_braking,
                           step, traction_envelope)


def test_leaf_parameters_hold_the_issue_values():
    assert LEAF.P_max == 80_000.0 and LEAF.T_max == 280.0
    assert LEAF.m_eq > LEAF.m_v  # rotating masses add to the inertia


def test_resistance_hand_worked_flat():
    # 20 m/s: aero 0.5*1.2*2.29*0.28*400 = 153.888 N; rolling 0.009*1600*9.81 = 141.264 N
    assert resistance(20.0) == pytest.approx(153.888 + 141.264, rel=1e-9)


def test_resistance_hand_worked_uphill():
    # 10 m/s on 0.05 rad: aero 38.472; rolling 141.264*cos(0.05) = 141.0875; grade 15696*sin(0.05) = 784.473
    expected = 38.472 + 141.264 * math.cos(0.05) + 15696.0 * math.sin(0.05)
    assert resistance(10.0, 0.05) == pytest.approx(expected, rel=1e-9)
    assert expected == pytest.approx(964.03, abs=0.01)


def test_step_hand_worked():
    # eq. (3a): 10 + 0.2/1664 * (1000 - 0 - (38.472 + 141.264)) = 10.098590...
    assert DT == 0.2
    assert step(10.0, 1000.0, 0.0) == pytest.approx(10.0 + 0.2 / 1664.0 * (1000.0 - 179.736), rel=1e-12)
    assert step(10.0, 1000.0, 0.0) == pytest.approx(10.09859, abs=1e-5)


def test_step_never_reverses():
    assert step(0.5, 0.0, 15_000.0) == 0.0


def test_step_vectorised_matches_scalar():
    v = np.array([0.0, 5.0, 20.0])
    out = step(v, np.array([500.0, 0.0, 2000.0]), np.array([0.0, 300.0, 0.0]), np.array([0.0, 0.02, -0.01]))
    for i in range(3):
        assert out[i] == pytest.approx(step(v[i], [500.0, 0.0, 2000.0][i], [0.0, 300.0, 0.0][i],
                                            [0.0, 0.02, -0.01][i]))


def test_traction_envelope_hand_worked():
    # peak force: 280 Nm * 7.9377 * 0.97 / 0.307 m = 7022.41 N; power region at 30 m/s: 80 kW * 0.97 / 30
    assert LEAF.F_t_peak == pytest.approx(7022.41, abs=0.01)
    assert traction_envelope(5.0) == pytest.approx(LEAF.F_t_peak)
    assert traction_envelope(30.0) == pytest.approx(80_000 * 0.97 / 30.0)


def test_fit_aero_matches_the_continuous_least_squares_line():
    # best line through v^2 on [0, V] (uniform): slope V, intercept -V^2/6
    V = 130 / 3.6
    p1, p2 = fit_aero(LEAF, 0.0, V, n=2001)
    assert p1 == pytest.approx(V, rel=1e-3)
    assert p2 == pytest.approx(-V * V / 6, rel=1e-2)


def test_fit_aero_bad_range():
    with pytest.raises(ValueError):
        fit_aero(LEAF, 10.0, 5.0)


def test_conservative_traction_line_stays_under_the_envelope():
    p3, p4 = fit_traction_limit(LEAF, 0.0, 130 / 3.6)
    v = np.linspace(0.0, 130 / 3.6, 1001)
    assert np.all(p3 * v + p4 <= traction_envelope(v) + 1e-6)
    assert p3 < 0  # the limit falls with speed (power region)
    # the plain least-squares line over-promises somewhere
    q3, q4 = fit_traction_limit(LEAF, 0.0, 130 / 3.6, conservative=False)
    assert np.any(q3 * v + q4 > traction_envelope(v) + 1.0)


def test_linear_model_is_cached_and_consistent():
    m = linear_model()
    assert m is linear_model()
    assert (m.p1, m.p2) == fit_aero(LEAF, m.v_lo, m.v_hi)
    assert m.c_a == pytest.approx(0.5 * 1.2 * 2.29 * 0.28)
    assert m.ft_max(10.0) == pytest.approx(m.p3 * 10 + m.p4)


def test_split_braking_follows_section_3_5():
    m = linear_model()
    cap = abs(m.ft_max(15.0))
    regen, friction = split_braking(0.5 * cap, 15.0)
    assert (regen, friction) == (pytest.approx(0.5 * cap), 0.0)
    regen, friction = split_braking(cap + 1000.0, 15.0)
    assert regen == pytest.approx(cap) and friction == pytest.approx(1000.0)


def test_forces_from_trace_hand_worked():
    # cruising at 20 m/s: traction equals the road load, no braking
    ft, fb = forces_from_trace(20.0, 0.0)
    assert (ft, fb) == (pytest.approx(295.152), 0.0)
    # braking at -2 m/s^2 from 10 m/s: 1664*(-2) + 179.736 = -3148.264 N
    ft, fb = forces_from_trace(10.0, -2.0)
    assert (ft, fb) == (0.0, pytest.approx(3148.264))


@settings(max_examples=60, deadline=None)
@given(v=st.floats(0.5, 40.0), a=st.floats(-3.0, 2.0), grade=st.floats(-0.08, 0.08))
def test_inverse_dynamics_inverts_the_step(v, a, grade):
    """Forces from (v, a) fed into eq. (3a) reproduce v + a DT (as long as the car keeps moving)."""
    ft, fb = forces_from_trace(v, a, grade)
    if v + a * DT > 0:
        assert step(v, ft, fb, grade) == pytest.approx(v + a * DT, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(v1=st.floats(0.0, 40.0), v2=st.floats(0.0, 40.0), grade=st.floats(-0.1, 0.1))
def test_resistance_increases_with_speed(v1, v2, grade):
    lo, hi = sorted((v1, v2))
    assert resistance(lo, grade) <= resistance(hi, grade) + 1e-9


def test_aero_linearisation_object_and_its_error():
    lin = AeroLinearisation.fit(LEAF, 0.0, 130 / 3.6)
    m = linear_model()
    assert (lin.p1, lin.p2) == (pytest.approx(m.p1), pytest.approx(m.p2))
    assert lin(20.0) == pytest.approx(m.aero(20.0))
    # error of the best line through v^2 on [0, V] is largest at the ends: V^2/6 -> c_a * 217 ~ 83 N
    assert lin.max_abs_error() == pytest.approx(m.c_a * (130 / 3.6) ** 2 / 6, rel=0.02)


def test_figures_aero_and_speed_correction(tmp_path):
    from pedas.figures_core import plot_aero_linearisation, plot_speed_correction, v_corr

    files = plot_aero_linearisation(tmp_path) + plot_speed_correction(tmp_path)
    assert sorted(f.suffix for f in files) == [".pdf", ".pdf", ".png", ".png", ".svg", ".svg"]
    assert all(f.stat().st_size > 1000 for f in files)
    assert all(b"/Type3" not in f.read_bytes() for f in files if f.suffix == ".pdf")  # TrueType fonts embedded
    # eq. (11) at psi = -5: 0.008 * 25 * (-0.05 * 25 + 0.4 * -5) = -0.65 m/s
    assert v_corr(-5.0) == pytest.approx(-0.65)

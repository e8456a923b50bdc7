"""Exact, machine-independent fits of the vehicle model and their committed coefficients."""
from __future__ import annotations

import json
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from pedas import coefficients, exact_lstsq, fitted
from pedas.params import LEAF
from pedas.power import PowerMap, fit_power_map, power_map
from pedas.vehicle import V_RANGE_DEFAULT, fit_traction_limit, linear_model, traction_envelope


def test_lstsq_hand_worked():
    # points (0, 1), (1, 3), (2, 4): slope 3/2, intercept 7/6 (normal equations by hand)
    A = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])
    assert exact_lstsq.lstsq_fractions(A, np.array([1.0, 3.0, 4.0])) == [Fraction(3, 2), Fraction(7, 6)]
    assert exact_lstsq.lstsq(A, np.array([1.0, 3.0, 4.0])) == (1.5, 7 / 6)


def test_lstsq_refuses_rank_deficient_and_non_finite_data():
    with pytest.raises(exact_lstsq.FitError, match="rank-deficient"):
        exact_lstsq.lstsq(np.ones((4, 2)), np.arange(4.0))
    with pytest.raises(ValueError):
        exact_lstsq.lstsq(np.array([[1.0, np.nan]]), np.array([1.0]))


def test_line_below_hand_worked():
    # f = (0, 1, 0) at v = 0, 1, 2: the free line is flat at 1/3, above f at v = 0 and 2; the best line under all
    # three points is flat through both zeros
    a, b = exact_lstsq.line_below(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 0.0]))
    assert (a, b) == (0.0, 0.0)
    # points already on a line: that line
    v = np.array([0.0, 1.0, 2.0, 3.0])
    assert exact_lstsq.line_below(v, 2.0 * v + 1.0) == (2.0, 1.0)


@pytest.mark.parametrize("seed", range(5))
def test_line_below_is_feasible_and_no_worse_than_any_feasible_line(seed):
    """Property: the result lies under every point, and small feasible perturbations never fit better."""
    rng = np.random.default_rng(seed)
    v = np.sort(rng.uniform(0, 30, 40))
    f = 5000 - 40 * v + 300 * np.sin(v / 3) + rng.normal(0, 50, v.size)
    a, b = exact_lstsq.line_below(v, f)
    assert np.all(a * v + b <= f)
    best = np.sum((a * v + b - f) ** 2)
    for da in np.linspace(-2, 2, 21):
        bb = np.min(f - (a + da) * v)  # the highest feasible intercept for this slope
        assert np.sum(((a + da) * v + bb - f) ** 2) >= best - 1e-6 * best


def test_traction_line_pinned_and_under_the_envelope():
    p3, p4 = fit_traction_limit()
    # pinned: an exact fit has one answer (SLSQP used to return 0.0 / 2148.9 on some BLAS kernels)
    assert (p3, p4) == (-158.8726590130504, 7022.3979767317405)
    v = np.linspace(*V_RANGE_DEFAULT, 10_001)
    assert np.all(p3 * v + p4 <= traction_envelope(v))
    assert p4 <= LEAF.F_t_peak  # it touches the torque limit at standstill


def test_committed_coefficients_are_what_a_refit_gives():
    """The committed file is reproduced bit for bit by refitting (`python -m pedas.fitted`)."""
    doc = json.loads(coefficients.FITS_FILE.read_text())
    rec = doc["fits"][0]
    new = fitted.refit(LEAF, V_RANGE_DEFAULT)
    assert {k: rec[k] for k in new} == new
    m = linear_model()
    assert (m.p1, m.p2, m.p3, m.p4) == (*rec["aero"].values(), *rec["traction_limit"].values())
    assert power_map() == PowerMap(**rec["power_map"]) == fit_power_map()[0]
    # pinned values (SI): the aero line of Fig. 5a and the power map of eq. (5)
    assert (m.p1, m.p2) == (36.111111111111114, -216.24325330355487)
    assert power_map().a00 == 1242.5577273751321 and power_map().a02 == 0.00012629386376121788


def test_other_vehicles_are_fitted_not_looked_up():
    heavy = replace(LEAF, m_v=2000.0, m_eq=2080.0, T_max=320.0)
    assert coefficients.committed(heavy, V_RANGE_DEFAULT) is None
    m = linear_model(heavy)
    assert (m.p3, m.p4) == fit_traction_limit(heavy)
    assert m.p4 <= heavy.F_t_peak

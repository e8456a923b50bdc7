"""Speed correction v_corr, eq. (11), against hand-worked numbers."""
from __future__ import annotations

import numpy as np
import pytest

from pedas.constants import ALPHA1, ALPHA2, ALPHA3
from pedas.speed_correction import corrected_speed, v_corr


@pytest.mark.parametrize("psi, expected", [
    (0.0, 0.0),
    (-1.0, -0.0036),    # 0.008 * 1 * (-0.05 - 0.4)
    (-5.0, -0.65),      # 0.008 * 25 * (-0.05 * 25 - 0.4 * 5) = 0.2 * (-3.25)
    (-10.0, -7.2),      # 0.008 * 100 * (-5 - 4)
    (2.0, 0.0192),      # 0.008 * 4 * (-0.2 + 0.8): positive branch (never applied by the controller)
])
def test_v_corr_hand_worked(psi, expected):
    assert v_corr(psi) == pytest.approx(expected, abs=1e-12)


def test_constants_are_the_paper_values():
    assert (ALPHA1, ALPHA2, ALPHA3) == (0.008, -0.05, 0.4)


def test_v_corr_vectorised_and_decreasing_in_the_third_quadrant():
    psi = np.linspace(-20.0, 0.0, 401)
    vc = v_corr(psi)
    assert vc.shape == psi.shape
    assert np.all(vc[:-1] <= 0.0)
    assert np.all(np.diff(vc) > 0.0)          # the deeper inside d_s, the larger the decrement
    assert np.allclose(vc, ALPHA1 * psi**2 * (ALPHA2 * psi**2 + ALPHA3 * psi))


def test_corrected_speed():
    assert corrected_speed(12.0, 3.0) == 12.0             # psi >= 0: unchanged
    assert corrected_speed(12.0, -5.0) == pytest.approx(12.0 - 0.65)
    assert corrected_speed(3.0, -10.0) == 0.0             # clipped at standstill

"""Speed correction v_corr of eq. (11) (Sec. 3.6, "MPC infeasibility").

When the driver has let the gap shrink below the safe distance (psi = d_rel - d_s < 0) the hard constraint
eq. (7a) cannot hold and the car-following MPC has no feasible plan; the advised speed is then the measured speed
plus v_corr(psi), a parabolic decrement that grows the deeper the host vehicle is inside d_s (Fig. 6b).
"""
from __future__ import annotations

import numpy as np

from pedas.constants import ALPHA1, ALPHA2, ALPHA3


def v_corr(psi):
    """v_corr(psi) = alpha1 psi^2 (alpha2 psi^2 + alpha3 psi) in m/s (eq. 11); psi = d_rel - d_s in m.

    Defined for any psi (floats or arrays); the controller applies it only when psi < 0, where it is <= 0.
    """
    psi = np.asarray(psi, dtype=float)
    out = ALPHA1 * psi**2 * (ALPHA2 * psi**2 + ALPHA3 * psi)
    return float(out) if out.ndim == 0 else out


def corrected_speed(v: float, psi: float) -> float:
    """v_h,k+1 = v_h,k + v_corr(psi) (eq. 11), clipped at standstill; the unchanged v when psi >= 0."""
    if psi >= 0.0:
        return float(v)
    return max(0.0, float(v) + v_corr(psi))

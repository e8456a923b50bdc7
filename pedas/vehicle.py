"""Longitudinal vehicle dynamics of the host BEV, eq. (2)-(3a), and the linear approximations the MPCs use.

- `resistance`: exact F_res = F_a + F_r + F_g (eq. 2).
- `fit_aero`: F_a ~ 1/2 rho A_f c_w (p1 v + p2), a least-squares line through v^2 over a speed range (Fig. 5a).
- `fit_traction_limit`: F_t,max ~ p3 v + p4 (eq. 6a) under the motor's torque/power envelope.
- `step`: the discrete update of eq. (3a) with the sample time DT.
- `split_braking`: regenerative vs friction part of F_b (Sec. 3.5).
- `forces_from_trace`: inverse dynamics (F_t, F_b) of a measured speed/acceleration trace.
All functions accept numpy arrays (broadcasting) as well as floats.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pedas import exact_lstsq
from pedas.constants import DT, KMH
from pedas.coefficients import committed
from pedas.params import LEAF, VehicleParams

V_RANGE_DEFAULT = (0.0, 130.0 * KMH)  # m/s, speed range the linear model is fitted over (route: 0-130 km/h)


def resistance(v, grade=0.0, p: VehicleParams = LEAF):
    """F_res in N (eq. 2): aerodynamic 1/2 rho A_f c_w v^2 + rolling c_r m_v g cos(theta) + gradient m_v g sin(theta).

    v in m/s, grade theta in rad (positive uphill). Exact (quadratic) aerodynamics; for the simulated plant and
    the energy model. Aerodynamic drag opposes motion, so it is taken as v|v| (v >= 0 in practice).
    """
    v = np.asarray(v, dtype=float)
    grade = np.asarray(grade, dtype=float)
    f_a = 0.5 * p.rho * p.A_f * p.c_w * v * np.abs(v)
    f_r = p.c_r * p.m_v * p.g * np.cos(grade)
    f_g = p.m_v * p.g * np.sin(grade)
    out = f_a + f_r + f_g
    return float(out) if out.ndim == 0 else out


def aero_force(v, p: VehicleParams = LEAF):
    """F_a = 1/2 rho A_f c_w v^2 in N (eq. 2)."""
    v = np.asarray(v, dtype=float)
    out = 0.5 * p.rho * p.A_f * p.c_w * v * np.abs(v)
    return float(out) if out.ndim == 0 else out


def fit_aero(p: VehicleParams = LEAF, v_lo: float = V_RANGE_DEFAULT[0], v_hi: float = V_RANGE_DEFAULT[1],
             n: int = 200) -> tuple[float, float]:
    """(p1, p2) of the aerodynamic linearisation F_a ~ 1/2 rho A_f c_w (p1 v + p2) (Sec. 3.3, Fig. 5a).

    Least squares of v^2 ~ p1 v + p2 on an even speed grid over [v_lo, v_hi] m/s; p1 in m/s, p2 in m^2/s^2.
    (Independent of p: the constant 1/2 rho A_f c_w factors out; p is kept for a uniform signature.)
    """
    if not v_hi > v_lo >= 0:
        raise ValueError(f"need 0 <= v_lo < v_hi, got {v_lo}, {v_hi}")
    v = np.linspace(v_lo, v_hi, n)
    p1, p2 = exact_lstsq.lstsq(np.column_stack([v, np.ones_like(v)]), v * v)
    return p1, p2


def traction_envelope(v, p: VehicleParams = LEAF):
    """Physical maximum traction force at the wheels in N: min(T_max i eta / r, P_max eta / v), 0 above top speed."""
    v = np.asarray(v, dtype=float)
    f_torque = p.F_t_peak
    with np.errstate(divide="ignore"):
        f_power = np.where(v > 0, p.P_max * p.eta_gear / np.maximum(v, 1e-9), np.inf)
    out = np.minimum(f_torque, f_power)
    out = np.where(v > p.v_top, 0.0, out)
    return float(out) if out.ndim == 0 else out


def fit_traction_limit(p: VehicleParams = LEAF, v_lo: float = V_RANGE_DEFAULT[0],
                       v_hi: float = V_RANGE_DEFAULT[1], n: int = 200,
                       conservative: bool = True) -> tuple[float, float]:
    """(p3, p4) of the line F_t,max ~ p3 v + p4 (eq. 6a) fitted to the 80 kW / 280 Nm envelope over [v_lo, v_hi].

    `conservative=True` (default): the least-squares line subject to lying on or below the envelope at every grid
    speed, so the MPC never plans a force the motor cannot deliver (the envelope is convex above base speed, so a
    line under it exists); solved exactly and proven optimal (:func:`pedas.exact_lstsq.line_below`), then lowered
    by any excess over the envelope between the grid speeds (where the convex part can dip below the line). `conservative=False`: the plain least-squares line ("line approximation"), exact.
    p3 in N/(m/s), p4 in N. The same bits on every machine: no floating-point solver or BLAS call is involved.
    """
    if not v_hi > v_lo >= 0:
        raise ValueError(f"need 0 <= v_lo < v_hi, got {v_lo}, {v_hi}")
    v = np.linspace(v_lo, v_hi, n)
    f = traction_envelope(v, p)
    if not conservative:
        p3, p4 = exact_lstsq.lstsq(np.column_stack([v, np.ones_like(v)]), f)
        return p3, p4
    p3, p4 = exact_lstsq.line_below(v, f)
    # between grid speeds the envelope's convex part P/v can dip under the line: the excess a v + b - P/v is
    # concave there, largest at v* = sqrt(-P/a); check it, the kinks and a dense grid, and lower the line by the
    # largest excess plus 1 uN (so that rounding at any speed cannot put it above the envelope)
    p_eff = p.P_max * p.eta_gear
    v_b = p_eff / p.F_t_peak  # base speed: torque limit -> power limit
    special = [v_b, p.v_top] + ([np.sqrt(-p_eff / p3)] if p3 < 0 else [])
    vd = np.concatenate([np.linspace(v_lo, v_hi, 50 * n), [x for x in special if v_lo <= x <= v_hi]])
    excess = float(np.max(p3 * vd + p4 - traction_envelope(vd, p)))
    p4 -= max(excess, 0.0) + 1e-6
    if not (np.all(p3 * v + p4 <= f) and np.all(p3 * vd + p4 <= traction_envelope(vd, p))):  # postcondition
        raise exact_lstsq.FitError("the traction-limit line lies above the motor envelope")
    return p3, p4


@dataclass(frozen=True)
class LinearModel:
    """Coefficients of the MPCs' linear vehicle model: F_a ~ c_a (p1 v + p2), F_t,max ~ p3 v + p4.

    c_a = 1/2 rho A_f c_w (N s^2/m^2). v_lo, v_hi: the speed range (m/s) the lines were fitted over.
    """

    p1: float
    p2: float
    p3: float
    p4: float
    c_a: float
    v_lo: float
    v_hi: float

    def aero(self, v):
        """Linearised aerodynamic force c_a (p1 v + p2) in N (Fig. 5a)."""
        return self.c_a * (self.p1 * np.asarray(v, dtype=float) + self.p2)

    def ft_max(self, v):
        """Linear traction limit p3 v + p4 in N (eq. 6a)."""
        return self.p3 * np.asarray(v, dtype=float) + self.p4


@dataclass(frozen=True)
class AeroLinearisation:
    """The line F_a ~ c_a (p1 v + p2) of Fig. 5a with the range it was fitted over; calling it gives N."""

    p1: float
    p2: float
    c_a: float
    v_lo: float
    v_hi: float

    @classmethod
    def fit(cls, p: VehicleParams = LEAF, v_lo: float = V_RANGE_DEFAULT[0],
            v_hi: float = V_RANGE_DEFAULT[1]) -> "AeroLinearisation":
        p1, p2 = fit_aero(p, v_lo, v_hi)
        return cls(p1, p2, 0.5 * p.rho * p.A_f * p.c_w, float(v_lo), float(v_hi))

    def __call__(self, v):
        return self.c_a * (self.p1 * np.asarray(v, dtype=float) + self.p2)

    def max_abs_error(self, p: VehicleParams = LEAF, n: int = 400) -> float:
        """Largest |F_a - linear| in N over the fitted range."""
        v = np.linspace(self.v_lo, self.v_hi, n)
        return float(np.max(np.abs(aero_force(v, p) - self(v))))


@lru_cache(maxsize=32)
def linear_model(p: VehicleParams = LEAF, v_range: tuple[float, float] = V_RANGE_DEFAULT) -> LinearModel:
    """The (cached) linear model of `p` over `v_range` m/s: the committed coefficients where they exist for exactly
    these inputs (:mod:`pedas.coefficients`), else fitted now with the same exact methods."""
    v_lo, v_hi = float(v_range[0]), float(v_range[1])
    rec = committed(p, (v_lo, v_hi))
    if rec is not None:  # the committed coefficients (pedas/fitted_coefficients.json)
        (p1, p2), (p3, p4) = rec["aero"].values(), rec["traction_limit"].values()
    else:
        p1, p2 = fit_aero(p, v_lo, v_hi)
        p3, p4 = fit_traction_limit(p, v_lo, v_hi)
    return LinearModel(p1, p2, p3, p4, 0.5 * p.rho * p.A_f * p.c_w, v_lo, v_hi)


def step(v, ft, fb, grade=0.0, p: VehicleParams = LEAF, dt: float = DT):
    """v_{k+1} = v_k + dt/m_eq (F_t - F_b - F_res(v_k)) (eq. 3a), exact F_res, m/s.

    A vehicle does not roll backwards when braking: the result is clipped at 0 (a standstill holds).
    """
    v = np.asarray(v, dtype=float)
    v_next = v + dt / p.m_eq * (np.asarray(ft, dtype=float) - np.asarray(fb, dtype=float) - resistance(v, grade, p))
    out = np.maximum(v_next, 0.0)
    return float(out) if out.ndim == 0 else out


def split_braking(fb, v, p: VehicleParams = LEAF, model: LinearModel | None = None):
    """(regen, friction) parts of the braking force F_b in N (Sec. 3.5).

    As the paper states: if F_b <= |F_t,max(v)| all of F_b is regenerative; otherwise |F_t,max| is regenerative
    and the rest friction. F_t,max is the linear limit p3 v + p4 of eq. (6a) (the MPC's model).
    """
    m = model or linear_model(p)
    fb = np.asarray(fb, dtype=float)
    cap = np.abs(m.ft_max(np.asarray(v, dtype=float)))
    regen = np.minimum(np.maximum(fb, 0.0), cap)
    friction = np.maximum(fb, 0.0) - regen
    if regen.ndim == 0:
        return float(regen), float(friction)
    return regen, friction


def forces_from_trace(v, a, grade=0.0, p: VehicleParams = LEAF):
    """Inverse dynamics (ft, fb) in N of a speed/acceleration trace (eq. 2 solved for the forces).

    ft = max(m_eq a + F_res, 0), fb = max(-(m_eq a + F_res), 0); exact F_res.
    """
    f = p.m_eq * np.asarray(a, dtype=float) + resistance(v, grade, p)
    f = np.asarray(f, dtype=float)
    ft, fb = np.maximum(f, 0.0), np.maximum(-f, 0.0)
    if ft.ndim == 0:
        return float(ft), float(fb)
    return ft, fb

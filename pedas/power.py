"""Battery power of the Leaf: a physically based loss model, its quadratic power map eq. (5), trace energy.

`battery_power(v, ft, fb)` is the reference model: wheel forces -> motor torque/speed through the reduction gear,
motor+inverter losses (copper k_c T^2, iron k_i w, windage k_w w^3, constant electronics loss), regenerative braking
limited by the paper's split (Sec. 3.5), the regen power limit and a low-speed fade, auxiliary load, and the
battery's internal resistance (power drawn from the cells, V_oc * I). Positive = discharge.

`fit_power_map` fits P(v, F_t) = a00 + a10 v + a01 F_t + a11 v F_t + a20 v^2 + a02 F_t^2 (eq. 5) by least squares
on the traction half of the map (F_t >= 0, the "half-map approximation"); braking is handled in the MPCs by the
F_b^2 penalty, not by the map.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pedas import exact_lstsq
from pedas.coefficients import committed
from pedas.params import LEAF, VehicleParams
from pedas.vehicle import V_RANGE_DEFAULT, forces_from_trace, split_braking, traction_envelope

V_NEG_TOL = 0.1  # m/s: negative speeds down to this are standstill noise (clipped), below it bad input
T_SMOOTH = 10.0  # Nm: speed-dependent inverter/iron losses ramp in over this torque so P is continuous at F=0


def _motor_losses(T_m, omega, p: VehicleParams):
    """Motor + inverter losses in W for shaft torque T_m (Nm, any sign) at speed omega (rad/s)."""
    on = np.minimum(np.abs(T_m) / T_SMOOTH, 1.0)  # an idle (zero-torque) inverter draws ~nothing
    # products, not `** 3`: numpy's power ufunc is CPU-dispatched (SIMD variants may differ in the last bit)
    return p.k_copper * T_m * T_m + on * (p.k_iron * omega + p.k_wind * omega * omega * omega + p.P_const_loss)


def _cells_power(p_terminal, p: VehicleParams):
    """Power drawn from the cells (V_oc * I) for a terminal power p_terminal, with the internal resistance R_int.

    V_oc I - R I^2 = P_term  ->  I = (V_oc - sqrt(V_oc^2 - 4 R P_term)) / (2 R).
    """
    disc = np.maximum(p.V_oc ** 2 - 4 * p.R_int * p_terminal, 0.0)
    current = (p.V_oc - np.sqrt(disc)) / (2 * p.R_int)
    return p.V_oc * current


def regen_force(fb, v, p: VehicleParams = LEAF):
    """Regenerative part of the braking force in N: the Sec. 3.5 split (F_b up to |F_t,max|), further limited by the
    regen power P_regen_max / v and faded linearly to zero below v_regen_fade (friction brake at creep speed)."""
    v = np.asarray(v, dtype=float)
    regen, _ = split_braking(fb, v, p)
    regen = np.minimum(np.asarray(regen, dtype=float), p.P_regen_max / np.maximum(v, 1e-3))
    regen = np.minimum(regen, traction_envelope(v, p))
    fade = np.clip(v / p.v_regen_fade, 0.0, 1.0) if p.v_regen_fade > 0 else 1.0
    return regen * fade


def battery_power(v, ft, fb=0.0, grade=0.0, p: VehicleParams = LEAF):
    """Battery (cell) power in W at speed v (m/s) with wheel traction force ft (N) and braking force fb (N).

    Vectorised over numpy arrays (broadcast). `grade` is accepted for a uniform signature; the forces already
    contain the road load. Traction: P_mech = F_t v / eta_gear at the motor shaft plus motor/inverter losses.
    Braking: the regenerative part (see `regen_force`) recovers eta_gear * F_reg * v minus losses (never a net
    draw: below that point the friction brake does the work); friction braking recovers nothing. Plus P_aux; then the battery's internal resistance.
    """
    del grade
    v = np.maximum(np.asarray(v, dtype=float), 0.0)
    ft = np.maximum(np.asarray(ft, dtype=float), 0.0)
    fb = np.maximum(np.asarray(fb, dtype=float), 0.0)
    omega = v * p.i_gear / p.r_wheel
    # traction: shaft torque including the gear loss
    T_trac = ft * p.r_wheel / (p.i_gear * p.eta_gear)
    # regeneration: shaft torque after the gear loss (negative = generating)
    T_reg = -regen_force(fb, v, p) * p.r_wheel * p.eta_gear / p.i_gear
    T_m = T_trac + T_reg  # both non-zero only when a controller commands both at once
    p_elec = T_m * omega + _motor_losses(T_m, omega, p)
    # the drive only regenerates when it nets energy back; otherwise that braking is left to the friction brake
    p_elec = np.where(T_m < 0, np.minimum(p_elec, 0.0), p_elec)
    out = _cells_power(p_elec + p.P_aux, p)
    return float(out) if np.ndim(out) == 0 else out


@dataclass(frozen=True)
class PowerMap:
    """Quadratic BEV power map P(v, F_t) in W (eq. 5); v in m/s, F_t in N."""

    a00: float
    a10: float
    a01: float
    a11: float
    a20: float
    a02: float

    def __call__(self, v, ft):
        v = np.asarray(v, dtype=float)
        ft = np.asarray(ft, dtype=float)
        out = (self.a00 + self.a10 * v + self.a01 * ft + self.a11 * v * ft
               + self.a20 * v ** 2 + self.a02 * ft ** 2)  # eq. (5)
        return float(out) if np.ndim(out) == 0 else out

    @property
    def hessian(self) -> np.ndarray:
        """Hessian of P w.r.t. (v, F_t): [[2 a20, a11], [a11, 2 a02]]."""
        return np.array([[2 * self.a20, self.a11], [self.a11, 2 * self.a02]])

    @property
    def jointly_convex(self) -> bool:
        """P is convex in (v, F_t) iff a20 >= 0, a02 >= 0 and 4 a20 a02 >= a11^2."""
        return self.a20 >= 0 and self.a02 >= 0 and 4 * self.a20 * self.a02 >= self.a11 ** 2


@dataclass(frozen=True)
class FitReport:
    """Quality of the power-map fit on the traction half-map (W); convexity of the fitted quadratic."""

    r2: float
    max_abs_error_W: float
    rmse: float
    n_points: int
    v_range: tuple[float, float]
    ft_range: tuple[float, float]
    convex: bool  # 4 a20 a02 >= a11^2 (and a20, a02 >= 0)
    convexity_margin: float  # 4 a20 a02 - a11^2; negative: not jointly convex in (v, F_t)

    def summary(self) -> str:
        c = "jointly convex" if self.convex else "NOT jointly convex (4 a20 a02 < a11^2)"
        return (f"R2={self.r2:.4f} RMSE={self.rmse:.0f} W max|err|={self.max_abs_error_W:.0f} W "
                f"over v={self.v_range[0]:.1f}-{self.v_range[1]:.1f} m/s, F_t={self.ft_range[0]:.0f}-"
                f"{self.ft_range[1]:.0f} N (n={self.n_points}); {c}")


def half_map_grid(p: VehicleParams = LEAF, v_range=V_RANGE_DEFAULT, ft_range=None, nv: int = 60, nf: int = 60):
    """Sample points (v, F_t) of the traction half-map: F_t from ft_range[0] up to min(ft_range[1], envelope(v))."""
    v_lo, v_hi = float(v_range[0]), float(v_range[1])
    ft_lo, ft_hi = (0.0, p.F_t_peak) if ft_range is None else (float(ft_range[0]), float(ft_range[1]))
    if not (v_hi > v_lo >= 0 and ft_hi > ft_lo >= 0):
        raise ValueError(f"bad fit ranges v={v_range}, ft={ft_range}")
    v = np.linspace(v_lo, v_hi, nv)
    frac = np.linspace(0.0, 1.0, nf)
    top = np.minimum(ft_hi, traction_envelope(v, p))
    V = np.repeat(v, nf)
    F = ft_lo + np.outer(np.maximum(top - ft_lo, 0.0), frac).ravel()
    return V, F


def fit_power_map(p: VehicleParams = LEAF, v_range=V_RANGE_DEFAULT, ft_range=None,
                  nv: int = 60, nf: int = 60) -> tuple[PowerMap, FitReport]:
    """Least-squares fit of eq. (5) to `battery_power` on the traction half-map (F_t >= 0, fb = 0).

    v_range m/s, ft_range N (default 0 .. peak traction force; capped by the motor envelope at each speed).
    """
    V, F = half_map_grid(p, v_range, ft_range, nv, nf)
    P = battery_power(V, F, 0.0, p=p)
    A = np.column_stack([np.ones_like(V), V, F, V * F, V * V, F * F])
    pm = PowerMap(*exact_lstsq.lstsq(A, P))  # exact: the same coefficients on every machine
    resid = P - pm(V, F)
    ss_res = float(np.sum(resid ** 2))
    ss_tot = float(np.sum((P - P.mean()) ** 2))
    margin = 4 * pm.a20 * pm.a02 - pm.a11 ** 2
    rep = FitReport(r2=1 - ss_res / ss_tot, max_abs_error_W=float(np.max(np.abs(resid))),
                    rmse=float(np.sqrt(ss_res / P.size)), n_points=int(P.size),
                    v_range=(float(V.min()), float(V.max())), ft_range=(float(F.min()), float(F.max())),
                    convex=pm.jointly_convex, convexity_margin=float(margin))
    return pm, rep


@lru_cache(maxsize=8)
def _cached_fit(p: VehicleParams) -> tuple[PowerMap, FitReport]:
    return fit_power_map(p)


@lru_cache(maxsize=8)
def power_map(p: VehicleParams = LEAF) -> PowerMap:
    """The power map of `p` over 0-130 km/h: the committed coefficients where they exist for `p`
    (:mod:`pedas.coefficients`), else fitted now (exactly)."""
    rec = committed(p, V_RANGE_DEFAULT)
    return PowerMap(**rec["power_map"]) if rec is not None else _cached_fit(p)[0]


def power_map_report(p: VehicleParams = LEAF) -> FitReport:
    """Fit report of `power_map(p)`."""
    return _cached_fit(p)[1]


@dataclass(frozen=True)
class EnergyResult:
    """Battery energy of a trace: wh (Wh, net of regeneration), wh_per_km, distance_m, duration_s."""

    wh: float
    wh_per_km: float
    distance_m: float
    duration_s: float


def _check_trace(t, v, grade):
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    if t.ndim != 1 or t.shape != v.shape:
        raise ValueError("trace: t and v must be 1-D of equal length")
    if t.size < 2:
        raise ValueError("trace: need at least two samples")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise ValueError("trace: t and v must be finite numbers")
    if np.any(np.diff(t) <= 0):
        raise ValueError("trace: t must be strictly increasing")
    if np.any(v < -V_NEG_TOL):  # logged speeds may dither slightly below zero at standstill: clipped to 0
        raise ValueError("trace: v must be >= 0 (m/s)")
    if grade is None:
        g = np.zeros_like(t)
    else:
        g = np.broadcast_to(np.asarray(grade, dtype=float), t.shape).astype(float)
        if not np.all(np.isfinite(g)) or np.any(np.abs(g) > 0.5):
            raise ValueError("trace: grade must be finite and in radians (|grade| <= 0.5)")
    return t, np.maximum(v, 0.0), g


def trace_power(t, v, grade=None, p: VehicleParams = LEAF):
    """(a, ft, fb, p_batt) along a speed trace: a by central differences (m/s^2), inverse-dynamics forces (N),
    battery power (W)."""
    t, v, g = _check_trace(t, v, grade)
    a = np.gradient(v, t)
    ft, fb = forces_from_trace(v, a, g, p)
    return a, ft, fb, battery_power(v, ft, fb, p=p)


def trace_energy(t, v, grade=None, p: VehicleParams = LEAF) -> EnergyResult:
    """Battery energy of a speed trace t (s), v (m/s), optional grade (rad): trapezoidal integral of battery power."""
    t, v, g = _check_trace(t, v, grade)
    _, _, _, pb = trace_power(t, v, g, p)
    joules = float(np.trapezoid(pb, t))
    dist = float(np.trapezoid(v, t))
    wh = joules / 3600.0
    return EnergyResult(wh=wh, wh_per_km=wh / (dist / 1000.0) if dist > 0 else float("nan"),
                        distance_m=dist, duration_s=float(t[-1] - t[0]))


def fill_drive_columns(df, p: VehicleParams = LEAF):
    """A copy of a drive-log DataFrame (t s, v m/s[, grade rad, a]) with the optional columns a, ft, fb, p_batt
    computed where absent. Present columns are never overwritten; grade is used when present (else 0)."""
    missing = [c for c in ("t", "v") if c not in df.columns]
    if missing:
        raise ValueError(f"drive log lacks column(s) {', '.join(missing)}")
    out = df.copy()
    t = out["t"].to_numpy(dtype=float, na_value=np.nan)
    v = out["v"].to_numpy(dtype=float, na_value=np.nan)
    g = None
    if "grade" in out.columns:  # missing grade values are taken as a flat road
        g = np.nan_to_num(out["grade"].to_numpy(dtype=float, na_value=np.nan), nan=0.0)
    t, v, g = _check_trace(t, v, g)
    a_calc = np.gradient(v, t)
    if "a" in out.columns:  # a given acceleration is used where it has a value
        a_given = out["a"].to_numpy(dtype=float, na_value=np.nan)
        a = np.where(np.isfinite(a_given), a_given, a_calc)
    else:
        a = a_calc
    ft, fb = forces_from_trace(v, a, g, p)
    if "a" not in out.columns:
        out["a"] = a
    if "ft" in out.columns:
        given = out["ft"].to_numpy(dtype=float, na_value=np.nan)
        ft = np.where(np.isfinite(given), given, ft)
    else:
        out["ft"] = ft
    if "fb" in out.columns:
        given = out["fb"].to_numpy(dtype=float, na_value=np.nan)
        fb = np.where(np.isfinite(given), given, fb)
    else:
        out["fb"] = fb
    if "p_batt" not in out.columns:
        out["p_batt"] = battery_power(v, ft, fb, p=p)
    return out

"""Offline dynamic-programming reference speed v_DP over the route (Sec. 3.2, Fig. 2b).

State: speed on a grid at distance stages s_0 = 0 < s_1 < ... < s_N = L. Transition j -> k over one stage of
length h assumes constant acceleration a = (v_k^2 - v_j^2) / (2 h), travel time dt = 2 h / (v_j + v_k) and the
mean speed for the road load. Stage cost = battery energy (inverse dynamics with the grade, `battery_power`, so
regeneration earns energy back and friction braking wastes it) + w_time * dt. Constraints: v_min <= v <= v_max
(speed limit and curve limit) at every stage, a_min <= a <= a_max, F_t within the motor envelope, F_b <= F_b_max.
Stop signs: v = 0 is forced at the stage of each stop line (the compulsory halt, Sec. 3.2); the STOP_DWELL is
added to the reported trip time and its auxiliary energy to the energy. Traffic lights are left to the green
wave / MPC (their timing is not known offline).

The recursion loops over distance stages only; each stage is one vectorised (n_v x n_v) numpy evaluation.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pedas.constants import STOP_DWELL
from pedas.params import LEAF, VehicleParams
from pedas.power import battery_power
from pedas.route import Route
from pedas.vehicle import resistance, traction_envelope

# Value of travel time in J/s (= W): 1 s of trip time costs as much as W_TIME J of battery energy. The paper
# weights energy over time ("lower mean speeds on the highway"); with 4 kW the unconstrained cruise optimum on a
# flat road is ~61 km/h, so on the highway the minimum of 80 km/h binds (the DP cruises just above it) while
# town segments run at the 50 km/h limit between stops. See docs/vehicle_and_references.md for the sweep.
W_TIME_DEFAULT = 4000.0
A_MAX_DEFAULT = 1.0  # m/s^2, comfortable acceleration of the reference (eco driving)
A_MIN_DEFAULT = -1.5  # m/s^2, comfortable deceleration of the reference


@dataclass(frozen=True)
class DPResult:
    """v_DP (m/s) on the stage grid s (m); energy_wh and time_s of the DP profile (incl. stop-sign dwell);
    runtime_s of the computation; plus the settings used."""

    s: np.ndarray
    v_dp: np.ndarray
    energy_wh: float
    time_s: float
    runtime_s: float
    ds: float = 0.0
    dv: float = 0.0
    w_time: float = 0.0
    n_speeds: int = 0

    def at(self, s) -> np.ndarray | float:
        """v_DP interpolated at distance(s) s (m/s)."""
        out = np.interp(np.asarray(s, dtype=float), self.s, self.v_dp)
        return float(out) if np.ndim(out) == 0 else out


def cruise_cost_per_m(v, w_time: float = W_TIME_DEFAULT, grade: float = 0.0, p: VehicleParams = LEAF):
    """DP cost per metre (J/m) of cruising at constant speed v (m/s): (P_batt(v, F_res) + w_time) / v."""
    v = np.asarray(v, dtype=float)
    f = resistance(v, grade, p)
    return (battery_power(v, np.maximum(f, 0), np.maximum(-f, 0), p=p) + w_time) / v


def _stage_cost(vj, vk, h, grade, p, w_time, a_min, a_max):
    """(n_v, n_v) cost matrix J of going from speed vj[:, None] to vk[None, :] over h metres; inf if infeasible."""
    VJ, VK = vj[:, None], vk[None, :]
    vm = 0.5 * (VJ + VK)
    a = (VK ** 2 - VJ ** 2) / (2 * h)
    with np.errstate(divide="ignore"):
        dt = np.where(vm > 0, h / np.maximum(vm, 1e-12), np.inf)
    f = p.m_eq * a + resistance(vm, grade, p)
    ft, fb = np.maximum(f, 0.0), np.maximum(-f, 0.0)
    bad = (a > a_max + 1e-9) | (a < a_min - 1e-9) | ~np.isfinite(dt)
    dt = np.where(bad, 0.0, dt)  # standstill-to-standstill has no finite time: masked out below
    e = battery_power(vm, ft, fb, p=p) * dt
    cost = e + w_time * dt
    bad |= ft > traction_envelope(vm, p) + 1e-6
    bad |= fb > p.F_b_max
    return np.where(bad, np.inf, cost), np.where(bad, 0.0, e), np.where(bad, 0.0, dt)


def dp_reference(route: Route, p: VehicleParams = LEAF, ds: float = 10.0, dv: float = 0.25,
                 w_time: float = W_TIME_DEFAULT, v0: float = 0.0, v_end: float | None = 0.0,
                 a_min: float = A_MIN_DEFAULT, a_max: float = A_MAX_DEFAULT,
                 stop_at_signs: bool = True) -> DPResult:
    """Energy-time optimal speed profile v_DP over `route` (Sec. 3.2).

    ds: stage length (m, the last stages are equal and <= ds); dv: speed grid step (m/s); w_time: J per s of trip
    time; v0 / v_end: speed at the start / end (None = free end); a_min, a_max: acceleration bounds (m/s^2).
    Raises ValueError when no feasible profile exists (e.g. v_min unreachable within the acceleration bounds).
    """
    if not (ds > 0 and dv > 0 and w_time >= 0 and a_max > 0 > a_min):
        raise ValueError("dp_reference: need ds > 0, dv > 0, w_time >= 0, a_min < 0 < a_max")
    t_start = time.perf_counter()
    L = route.length
    n_st = int(np.ceil(L / ds - 1e-9)) + 1
    s = np.linspace(0.0, L, n_st)
    v_hi = np.minimum(route.at(s, "v_max"), p.v_top)
    v_lo = np.minimum(route.at(s, "v_min"), v_hi)
    v_grid = np.arange(0.0, float(v_hi.max()) + dv / 2, dv)
    nv = v_grid.size
    stop_stage = [int(np.argmin(np.abs(s - ss.s))) for ss in route.stops] if stop_at_signs else []
    # v_min never forbids a forced stop (stop sign, route end): where the stop is not reachable from v_min with
    # 80 % of |a_min| (slack for the speed quantisation), the minimum is dropped
    forced = [(s[i], 0.0) for i in stop_stage] + ([(L, float(v_end))] if v_end is not None else [])
    for s_stop, v_stop in forced:
        v_reach = np.sqrt(v_stop ** 2 + 2 * 0.8 * abs(a_min) * np.maximum(s_stop - s, 0.0))
        v_lo = np.where((s <= s_stop) & (v_reach < v_lo + dv), 0.0, v_lo)
    allowed = (v_grid[None, :] <= v_hi[:, None] + 1e-9) & (v_grid[None, :] >= v_lo[:, None] - 1e-9)
    # a limit between grid speeds with v_min above the highest grid speed below it: keep that grid speed
    empty = ~allowed.any(axis=1)
    for i in np.flatnonzero(empty):
        allowed[i, np.searchsorted(v_grid, v_hi[i], side="right") - 1] = True
    for i in stop_stage:
        allowed[i, :] = False
        allowed[i, 0] = True
    j0 = int(np.argmin(np.abs(v_grid - v0)))
    allowed[0, :] = False
    allowed[0, j0] = True
    if v_end is not None:
        k_end = int(np.argmin(np.abs(v_grid - v_end)))
        allowed[-1, :] = False
        allowed[-1, k_end] = True
    grade_mid = route.at(0.5 * (s[1:] + s[:-1]), "grade")

    # backward recursion: J[i][j] = min_k cost_i[j, k] + J[i+1][k]
    J_next = np.where(allowed[-1], 0.0, np.inf)
    policy = np.zeros((n_st - 1, nv), dtype=np.int32)
    for i in range(n_st - 2, -1, -1):
        rows = np.flatnonzero(allowed[i])
        cols = np.flatnonzero(allowed[i + 1] & np.isfinite(J_next))
        J_cur = np.full(nv, np.inf)
        if rows.size and cols.size:
            c, _, _ = _stage_cost(v_grid[rows], v_grid[cols], s[i + 1] - s[i], grade_mid[i], p, w_time, a_min, a_max)
            tot = c + J_next[cols][None, :]
            best = np.argmin(tot, axis=1)
            J_cur[rows] = tot[np.arange(rows.size), best]
            policy[i, rows] = cols[best]
        J_next = J_cur
    if not np.isfinite(J_next[j0]):
        raise ValueError("dp_reference: no feasible speed profile (check v_min/v_max and the acceleration bounds)")

    idx = np.empty(n_st, dtype=np.int64)
    idx[0] = j0
    for i in range(n_st - 1):
        idx[i + 1] = policy[i, idx[i]]
    v_dp = v_grid[idx]
    energy_j = 0.0
    time_s = 0.0
    for i in range(n_st - 1):  # evaluation of the chosen path (scalar per stage, cheap)
        _, e, dt = _stage_cost(v_grid[idx[i]:idx[i] + 1], v_grid[idx[i + 1]:idx[i + 1] + 1], s[i + 1] - s[i],
                               grade_mid[i], p, w_time, a_min, a_max)
        energy_j += float(e[0, 0])
        time_s += float(dt[0, 0])
    dwell = STOP_DWELL * len(stop_stage)
    energy_j += float(battery_power(0.0, 0.0, 0.0, p=p)) * dwell
    time_s += dwell
    return DPResult(s=s, v_dp=v_dp, energy_wh=energy_j / 3600.0, time_s=time_s,
                    runtime_s=time.perf_counter() - t_start, ds=float(s[1] - s[0]), dv=dv, w_time=w_time,
                    n_speeds=nv)

"""The pEDAS controller (Sec. 3.1, 3.5-3.8): switching between the two MPCs, speed correction, fallback, HUD.

``PedasController(route, params, v_dp, settings=CONTROLLER).step(t, s, v, leader) -> Advisory`` once per sample
(DT = 0.2 s). Every tuning value comes from ``settings``, a :class:`pedas.params.ControllerParams`; ``step`` runs
these stages in order:

1. ``_measure``: measured acceleration and real sample time for the HUD and the stop-sign dwell;
2. ``_predict``: the horizon is laid out along the route with the previous plan (shifted one step) as prediction
   of the positions s_k, which also serves as linearisation point of the power term (see :mod:`pedas.mpc`);
   route profiles (grade, v_max, v_DP, curve envelope; the speed limit at s) are looked up there;
3. ``_objects_ahead``: the next light and stop sign; the stop-sign state machine (released after the vehicle has
   stood STOP_DWELL s inside the stop-line band [0, d_s,ITS] before the line, counted as missed when passed
   without it); a red (or non-passable yellow) light and every stop sign constrain d_ITS >= 0 (eq. 8c) at the
   horizon steps where the light is not green (all steps for a stop sign);
4. ``_reference``: v_ref from the green wave (eq. 1) when a green window of the next light is reachable within
   [v_min, v_max], else v_DP; capped by the curve and stop envelopes; the speed bounds and the d_ITS rows;
5. ``_solve``: leader within SENSOR_RANGE -> car-following MPC eq. (10), else reference-tracking MPC eq. (9);
   after a switch rt <-> cf the new MPC is warm-started from the old plan; every solve's status is checked and a
   failed/infeasible solve yields a fallback plan flagged ``fallback=True``;
6. ``_advise``: psi = d_rel - d_s < 0 -> the advice is at most v + v_corr(psi) (eq. 11); after a switch the advised
   speed is rate-limited to blend_max_step per sample for blend_steps samples (the documented bound on the
   hand-over jump); the plan is kept for the next step's prediction and warm start;
7. ``_hud``: the HUD record from the pure :func:`pedas.hud.advisory`.
"""
from __future__ import annotations

import dataclasses
import math
from bisect import bisect_left, bisect_right
from collections.abc import Mapping
from dataclasses import dataclass
from math import isfinite
from typing import NamedTuple

import numpy as np

from pedas._qpkernel import Horizon
from pedas.constants import DT, N_HORIZON, SENSOR_RANGE, STOP_DWELL
from pedas.greenwave import green_wave_band
from pedas.hud import HudAdvice, HudContext, HudState, advisory, update_unfollowed
from pedas.mpc import INF, MpcPlan, vehicle_model
from pedas.mpc_cf import CarFollowingMpc
from pedas.mpc_rt import ReferenceTrackingMpc
from pedas.params import CONTROLLER, LEAF, ControllerParams, VehicleParams
from pedas.records import fast_init
from pedas.route import StopSign, TrafficLight, braking_envelope
from pedas.speed_correction import corrected_speed


@fast_init
@dataclass(frozen=True)
class Advisory:
    """One controller output (the drive log stores these).

    v_advice: m/s, the optimal speed v_h,opt (first planned step, or the corrected speed of eq. 11);
    controller 'rt'|'cf'; mode 'green_wave'|'dp'|'stop'|'follow'; ft, fb: first planned forces (N);
    hud_arrow -1|0|1, arrow_len 0..1, hud_in_band, warning, tl_countdown (s or None), icon; solve_status (QP
    status text, 'speed_correction' or 'fallback:<status>'), fallback flag, plan_v: N predicted speeds v_1..v_N;
    speed_limit: m/s at the vehicle's position (shown on the HUD); tl_phase: the phase of the counted-down light;
    tone: the HUD's warning tone (pedas.hud.advisory: a slow-down advice not followed).
    """

    v_advice: float
    controller: str
    mode: str
    ft: float
    fb: float
    hud_arrow: int
    arrow_len: float
    hud_in_band: bool
    warning: bool
    tl_countdown: float | None
    icon: str | None
    solve_status: str
    fallback: bool
    plan_v: tuple
    speed_limit: float | None = None
    tl_phase: str | None = None
    tone: bool = False


class RefusedMeasurement(ValueError):
    """A measurement handed to :meth:`PedasController.step` is not a finite number; no advice was computed and the
    controller is unchanged. ``status``: ``refused:<field>`` for the first bad field of t, s, v, leader_gap,
    leader_v (the message names it and its value)."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status

    @classmethod
    def of(cls, t, s, v, leader) -> RefusedMeasurement:
        """The refusal naming the first non-finite field (t s, s m, v m/s, leader gap m, leader speed m/s)."""
        fields = [("t", t, "s"), ("s", s, "m"), ("v", v, "m/s")]
        if leader is not None:
            fields += [("leader_gap", leader[0], "m"), ("leader_v", leader[1], "m/s")]
        name, value, unit = next(f for f in fields if not _isfinite(f[1]))
        return cls(f"refused:{name}", f"refused measurement: {name} = {value!r} {unit} is not a finite number "
                                      "(no advice computed, controller state unchanged)")


def _isfinite(x) -> bool:
    """x is a finite real number (False for NaN, +-inf, None and anything that is no number)."""
    try:
        return math.isfinite(x)
    except TypeError:
        return False


_MODES = ("green_wave", "dp", "stop")   # the reference modes by the index Horizon.reference returns


class _Prediction(NamedTuple):
    """Stage ``_predict``: linearisation trajectory (k = 0..N-1) and route profiles at the predicted positions."""

    v_lin: np.ndarray    # m/s, speeds at k = 0..N-1 (previous plan shifted, v_0 measured)
    ft_lin: np.ndarray   # N, traction forces at k = 0..N-1 (previous plan shifted)
    s_pred: np.ndarray   # m, predicted positions at k = 1..N
    grade: np.ndarray    # rad, at k = 0..N-1
    vmax: np.ndarray     # m/s, v_max at k = 1..N
    limit: float         # m/s, the speed limit at the vehicle (k = 0)
    vdp: np.ndarray      # m/s, v_DP at k = 1..N
    venv: np.ndarray     # m/s, curve envelope at k = 1..N


class _Objects(NamedTuple):
    """Stage ``_objects_ahead``: the next light and stop sign and the stop line that constrains d_ITS."""

    tl: TrafficLight | None   # the next light (or None)
    d_tl: float | None        # m to its stop line
    ss: StopSign | None       # the next unserved stop sign (or None)
    d_ss: float | None        # m to its stop line
    tl_near: bool             # the light is within spat_range (green wave and red-light logic apply)
    tl_remaining: float | None  # s left in the light's phase (SPaT), None beyond spat_range
    tl_state: str | None      # the light's phase now (SPaT), None beyond spat_range
    go: bool                  # the light will be passed (green long enough, or yellow too close to stop)
    stop_d: float | None      # m to the stop line that constrains d_ITS (None: no stop required)
    d_hard: np.ndarray | None  # k = 1..N: 0 where d_ITS >= 0 is enforced, -inf elsewhere
    stop_kind: str | None     # 'ss' | 'tl' | None


class _Reference(NamedTuple):
    """Stage ``_reference``: mode, v_ref and the bounds handed to the MPC."""

    mode: str                 # 'green_wave' | 'dp' | 'stop'
    v_ref: np.ndarray         # m/s, k = 1..N
    v_lo: np.ndarray          # m/s, k = 1..N
    v_hi: np.ndarray          # m/s, k = 1..N
    reach: np.ndarray         # m/s, k = 1..N: the current speed reduced at a_reach (lowest admissible v_hi)
    d_hard: np.ndarray | None  # as _Objects.d_hard, None when the stop line is beyond the horizon's reach
    d_its0: float             # m, initial d_ITS state (0 when unbounded)
    d_sits: float             # m, soft stop-line approach d_s,ITS (inf unless mode 'stop')


class _Solution(NamedTuple):
    """Stage ``_solve``: the controller used and its (possibly fallback) plan."""

    ctrl: str                 # 'rt' | 'cf'
    mode: str                 # the reference mode, or 'follow'
    plan: MpcPlan
    status: str               # the QP backend's status, or 'fallback:<status>'
    fallback: bool
    psi: float | None         # m, d_rel - d_s (car following only)


class PedasController:
    """pEDAS for one route: both MPCs built once, then :meth:`step` per sample.

    ``settings`` (:class:`pedas.params.ControllerParams`, default :data:`pedas.params.CONTROLLER`) holds the MPC
    weights, the QP backend (``qp_backend``: DAQP or OSQP) and its settings, and every threshold of the controller, HUD
    and green wave. ``osqp_settings`` (a mapping of :class:`pedas.params.OsqpSettings` fields) overrides
    ``settings.osqp`` for solver experiments (``pedas-study bench mpc``).
    """

    def __init__(self, route, params: VehicleParams = LEAF, v_dp=None, n: int = N_HORIZON, dt: float = DT, *,
                 settings: ControllerParams = CONTROLLER, osqp_settings: Mapping | None = None) -> None:
        self.route, self.params, self.n, self.dt = route, params, n, dt
        self.settings = settings
        self.model = vehicle_model(params)
        if osqp_settings:   # the one place where OSQP overrides meet settings.osqp
            settings = dataclasses.replace(settings, osqp=dataclasses.replace(settings.osqp, **osqp_settings))
            self.settings = settings
        qp = dict(backend=settings.qp_backend, osqp=settings.osqp, daqp=settings.daqp)
        self.rt = ReferenceTrackingMpc(self.model, settings.rt_weights, n=n, dt=dt, **qp)
        self.cf = CarFollowingMpc(self.model, settings.cf_weights, n=n, dt=dt, **qp)
        self.h_s, self.d_min = settings.cf_weights.h_s, settings.cf_weights.d_min
        self._hud_kw = dict(arrow_full_scale=settings.arrow_full_scale, icon_range=settings.icon_range,
                            warn_delay=settings.warn_delay, standstill=settings.standstill,
                            start_min=settings.start_min, band=settings.hud_band)
        if v_dp is None:
            from pedas.dp import dp_reference
            v_dp = dp_reference(route, params)
        if hasattr(v_dp, "s") and hasattr(v_dp, "v_dp"):
            self._dp_s, self._dp_v = np.asarray(v_dp.s, float), np.asarray(v_dp.v_dp, float)
        else:  # (s, v) pair of arrays
            self._dp_s, self._dp_v = (np.asarray(a, float) for a in v_dp)
        # route profiles on the route grid (interpolated per step)
        self._s = np.asarray(route.s, float)
        self._vmax = np.asarray(route.v_max, float)
        self._vmin = np.asarray(route.v_min, float)
        self._grade = np.asarray(route.grade, float)
        self._limit = np.asarray(route.speed_limit, float)
        # curve envelope: the highest speed from which every later v_max is reachable at a_stop (backward pass)
        self._venv = braking_envelope(self._s, self._vmax, settings.a_stop)
        # starts of curves whose limit is below the legal limit (for the HUD curve icon)
        curvy = np.asarray(route.v_curve, float) < self._limit - 1e-9
        starts = np.flatnonzero(curvy & ~np.r_[False, curvy[:-1]])
        self._curve_s = self._s[starts]
        ends = np.flatnonzero(curvy & ~np.r_[curvy[1:], False]) + 1
        v_curve = np.asarray(route.v_curve, float)
        self._curve_v = np.array([v_curve[i:j].min() for i, j in zip(starts, ends)])
        self._lights = tuple(route.lights)
        self._stops = tuple(route.stops)
        self._d_sits = float(route.d_stopline)
        self._k = np.arange(1, n + 1)
        self._dtk = (dt * self._k).tolist()   # s, the horizon's sample times after now (a list: Python floats)
        self._frac8 = np.linspace(0.0, 1.0, 8)
        # work vectors of one step (nothing keeps them across steps: the MPCs copy what they are given)
        self._vlin = np.empty(n)
        self._ftlin = np.empty(n)
        self._spred = np.empty(n)
        self._vref, self._vhi, self._vlo, self._reachv = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        self._vhicf, self._margin = np.empty(n), np.empty(n)
        self._pred_out = tuple(np.empty(n) for _ in range(4))   # grade, v_max, v_DP, v_env
        # the prediction, reference and car-following stages compiled (pedas/_qpkernel.c): the route tables and the
        # horizon ramps of the settings copied in (the same products as (a dt) k per step), the work vectors written
        # in place (the horizon holds the two only it uses: the grade positions and a scratch vector)
        k = self._k
        self._horizon = Horizon(
            (self._s, self._grade, self._vmax, self._venv, self._vmin, self._limit, self._dp_s, self._dp_v),
            float(dt), (settings.a_depart * dt * k, settings.a_reach * dt * k, settings.psi_recovery * k),
            (2 * settings.a_stop, float(settings.cruise_look), float(settings.safe_backoff)),
            (self._vlin, self._ftlin, self._spred, np.empty(n), *self._pred_out, self._vref, self._vlo, self._vhi,
             self._reachv, np.empty(n), self._vhicf, self._margin))
        self._curve_list = self._curve_s.tolist()
        self._s_list = self._s.tolist()
        self.reset()

    def reset(self) -> None:
        """Forget the drive state (plans, stop-sign dwell, counters, the solvers' hot starts)."""
        self.rt.reset()
        self.cf.reset()
        self._tl_i = 0
        self._ss_i = 0
        self._dwell = 0.0
        self._prev: MpcPlan | None = None
        self._prev_ctrl: str | None = None
        self._prev_advice: float | None = None
        self._prev_ft: float | None = None
        self._blend = 0
        self._t_prev: float | None = None
        self._v_prev = 0.0
        self._unfollowed = 0.0
        self._last_arrow = 0
        self.stats = {"steps": 0, "rt": 0, "cf": 0, "solved": 0, "fallbacks": 0, "corrections": 0,
                      "switches": 0, "stops_served": 0, "stops_missed": 0}

    # ------------------------------------------------------------------------------------------------------
    def step(self, t: float, s: float, v: float, leader: tuple[float, float] | None = None) -> Advisory:
        """Advice for the measured state: time t (s), route position s (m), speed v (m/s), leader = (gap d_rel m,
        its speed v_p m/s) or None. A measurement that is not a finite number raises :class:`RefusedMeasurement`
        before anything changes (no advice, no state: the next finite step is as if this one never came)."""
        try:   # one guarded test of all fields (a value that is no number raises TypeError: refused as well)
            finite = isfinite(t) and isfinite(s) and isfinite(v) and (
                leader is None or (isfinite(leader[0]) and isfinite(leader[1])))
        except TypeError:
            finite = False
        if not finite:
            raise RefusedMeasurement.of(t, s, v, leader)
        v = max(float(v), 0.0)
        self.stats["steps"] += 1
        a_meas, dt_real = self._measure(t, v)
        pred = self._predict(s, v)
        obj = self._objects_ahead(t, s, v, dt_real, pred.s_pred)
        ref = self._reference(t, s, v, leader, pred, obj)
        sol = self._solve(v, leader, pred, ref)
        v_adv, status = self._advise(v, sol)
        plan = sol.plan
        plan_v = (v_adv, *plan.v[2:].tolist())
        hud = self._hud(s, v, a_meas, dt_real, pred, obj, sol, plan_v)
        # forces within solver tolerance of 0 are reported as 0 (the QP bounds are F >= 0)
        return Advisory(v_advice=v_adv, controller=sol.ctrl, mode=sol.mode, ft=max(float(plan.ft[0]), 0.0),
                        fb=max(float(plan.fb[0]), 0.0),
                        hud_arrow=hud.hud_arrow, arrow_len=hud.arrow_len, hud_in_band=hud.hud_in_band,
                        warning=hud.warning, tl_countdown=hud.tl_countdown, icon=hud.icon, solve_status=status,
                        fallback=sol.fallback, plan_v=plan_v, speed_limit=hud.speed_limit,
                        tl_phase=hud.tl_phase, tone=hud.tone)

    # ---- stages of step, in order ---------------------------------------------------------------------------
    def _measure(self, t: float, v: float) -> tuple[float, float]:
        """Measured acceleration (m/s^2) and the real time since the previous step (s; DT at the first step)."""
        dt = self.dt
        a_meas = (v - self._v_prev) / (t - self._t_prev) if self._t_prev is not None and t > self._t_prev else 0.0
        dt_real = (t - self._t_prev) if self._t_prev is not None and t > self._t_prev else dt
        self._t_prev, self._v_prev = t, v
        return a_meas, dt_real

    def _predict(self, s: float, v: float) -> _Prediction:
        """Linearisation / prediction trajectory (the previous plan shifted by one sample) and the route profiles
        at the predicted positions: v_lin = (v, v_2..v_N of the previous plan), ft_lin = (F_t,1..F_t,N-1, F_t,N-1),
        or v and 0 without one; s_pred = s + dt cumsum(max(v_lin, 0)) at k = 1..N; grade at k = 0..N-1 (s, then
        s_pred); v_max, v_DP and the curve envelope at s_pred; the speed limit at s. One compiled call
        (``pedas._qpkernel.Horizon.predict``: numpy's operations and interp, the same bits)."""
        prev = self._prev
        limit = (self._horizon.predict(s, v, None, None) if prev is None
                 else self._horizon.predict(s, v, prev.v, prev.ft))
        grade, vmax, vdp, venv = self._pred_out
        return _Prediction(self._vlin, self._ftlin, self._spred, grade, vmax, limit, vdp, venv)

    def _objects_ahead(self, t: float, s: float, v: float, dt_real: float, s_pred: np.ndarray) -> _Objects:
        """The next light and stop sign, the stop-sign dwell state machine, and which stop line constrains d_ITS
        at which horizon steps (eq. 8c)."""
        cfg, N, st = self.settings, self.n, self.stats
        lights, stops = self._lights, self._stops
        while self._tl_i < len(lights) and lights[self._tl_i].s < s - 0.5:
            self._tl_i += 1
        tl = lights[self._tl_i] if self._tl_i < len(lights) else None
        d_tl = tl.s - s if tl is not None else None
        ss = stops[self._ss_i] if self._ss_i < len(stops) else None
        d_ss = ss.s - s if ss is not None else None
        if ss is not None and d_ss < -cfg.ss_passed:  # passed without completing the dwell
            st["stops_missed"] += 1
            self._ss_i += 1
            self._dwell = 0.0
            ss = stops[self._ss_i] if self._ss_i < len(stops) else None
            d_ss = ss.s - s if ss is not None else None
        # a standstill anywhere short of "passed" serves the stop; a narrower window would leave a car that crept
        # just past the line waiting for an advice of 0 km/h forever
        if ss is not None and v < cfg.v_stopped and -cfg.ss_passed <= d_ss <= self._d_sits + cfg.band_tol:
            self._dwell += dt_real
            if self._dwell >= STOP_DWELL - 1e-9:
                st["stops_served"] += 1
                self._ss_i += 1
                self._dwell = 0.0
                ss = stops[self._ss_i] if self._ss_i < len(stops) else None
                d_ss = ss.s - s if ss is not None else None

        stop_d = None          # distance to the stop line that constrains d_ITS
        d_hard = None
        go = False
        tl_near = tl is not None and d_tl <= cfg.spat_range
        state = tl_remaining = None
        if tl_near:
            state, tl_remaining, changes = tl.spat(t, N * self.dt)
            mask = self._nongreen(state, changes, t)
            red_ahead = True in mask
            if state == "green":
                if red_ahead:
                    k_r = mask.index(True)          # index of the first non-green step (time k_r + 1)
                    go = s_pred[k_r] > tl.s + 1.0 if k_r > 0 else False
                else:
                    go = True
            elif state == "yellow":
                go = d_tl < v * v / (2 * cfg.yellow_go_decel)
            if not go and red_ahead:
                stop_d, d_hard = d_tl, np.array([0.0 if ng else -INF for ng in mask])
        if ss is not None and (stop_d is None or d_ss < stop_d):
            stop_d, d_hard = d_ss, np.zeros(N)
            stop_kind = "ss"
        else:
            stop_kind = "tl" if stop_d is not None else None
        return _Objects(tl, d_tl, ss, d_ss, tl_near, tl_remaining, state, go, stop_d, d_hard, stop_kind)

    def _green_wave(self, t: float, s: float, pred: _Prediction, obj: _Objects) -> tuple[float | None, bool]:
        """(v_ref,min of eq. (1) or None, stop at the light expected) for the light within spat_range."""
        if not obj.tl_near:
            return None, False
        cfg, tl, d_tl, ss = self.settings, obj.tl, obj.d_tl, obj.ss
        # eq. (1) with v_max the lowest limit up to the line and v_min >= gw_min_fraction x speed limit
        v_hi_gw = self._horizon.line_min(s, max(d_tl, 0.0), self._frac8)
        v_lo_gw = max(self._horizon.v_min(s), cfg.gw_min_fraction * pred.limit)
        gw_ok = d_tl > 0 and (ss is None or ss.s > tl.s)            # a stop sign before the light goes first
        band = green_wave_band(d_tl, t, tl, min(v_lo_gw, v_hi_gw), v_hi_gw, cfg.gw_horizon, cfg.gw_margin,
                               v_floor=cfg.gw_v_floor) if gw_ok else None
        v_gw = band[0] if band is not None else None                # v_ref,min
        return v_gw, v_gw is None and not obj.go                    # eq. (1) empty: stopping is unavoidable

    def _reference(self, t: float, s: float, v: float, leader, pred: _Prediction, obj: _Objects) -> _Reference:
        """v_ref (green wave, else v_DP with a departure ramp; curve and stop envelopes), the speed bounds and the
        d_ITS rows. The vectors in one compiled call (``pedas._qpkernel.Horizon.reference``: numpy's operations,
        the same bits):

        * with a green-wave band, v_ref = min(v_env, v_ref,min) (mode green_wave); else v_DP floored by its maximum
          over the next cruise_look m, reached from v with the departure ramp and capped by v_env (mode dp);
        * at a stop sign, and at a light when eq. (1) has no band (stopping unavoidable), v_ref is capped by the stop
          envelope sqrt(2 a_stop max(d_target, 0)) with d_target = stop line - stop_aim d_s,ITS - (s_pred - s); mode
          stop when it binds at k = N or the light's stop is expected. With a green-wave band the hard d_ITS rows
          alone keep the plan out of the red phases;
        * v_hi = max(v_max, v - a_reach dt k); v_lo = min(v_min, v) at s_pred without a leader in modes green_wave
          and dp, else 0; then v_lo = min(v_lo, v_hi).
        """
        cfg, N, dt = self.settings, self.n, self.dt
        v_gw, tl_stop_expected = self._green_wave(t, s, pred, obj)
        envelope_d = None
        if obj.stop_kind == "ss":
            envelope_d = obj.d_ss
        elif obj.tl is not None and tl_stop_expected:
            envelope_d = obj.d_tl
        target = None if envelope_d is None else envelope_d - cfg.stop_aim * self._d_sits
        mode_i, v_hi_max = self._horizon.reference(s, v, v_gw, target, obj.stop_kind == "tl" and tl_stop_expected,
                                                   leader is None)
        mode = _MODES[mode_i]
        d_sits = self._d_sits if mode == "stop" else INF
        d_hard, stop_d = obj.d_hard, obj.stop_d
        if d_hard is None or stop_d > v_hi_max * N * dt + 5.0:
            # no stop object within reach of the horizon: the d_ITS rows cannot bind; unbounding them and keeping the
            # state at 0 also keeps OSQP's relative tolerance from scaling with a distance of several hundred m
            d_hard, d_its0, d_sits = None, 0.0, INF
        else:
            d_its0 = stop_d
        return _Reference(mode, self._vref, self._vlo, self._vhi, self._reachv, d_hard, d_its0, d_sits)

    def _solve(self, v: float, leader, pred: _Prediction, ref: _Reference) -> _Solution:
        """Controller choice, warm start at a hand-over, the MPC solve and the fallback plan on failure."""
        cfg, st = self.settings, self.stats
        use_cf = leader is not None and leader[0] <= SENSOR_RANGE
        ctrl = "cf" if use_cf else "rt"
        st[ctrl] += 1
        prev = self._prev
        if self._prev_ctrl is not None and ctrl != self._prev_ctrl:
            st["switches"] += 1
            self._blend = cfg.blend_steps
            if prev is not None:
                (self.cf if use_cf else self.rt).warm_start_from(prev.v, prev.ft, prev.fb)
        psi = None
        fallback = False
        mode = ref.mode
        if use_cf:
            d_rel, v_p = float(leader[0]), float(leader[1])
            psi = d_rel - (self.d_min + self.h_s * v)
            mode = "follow"
            # v_hi = min(v_hi, max(v_DP, min(v + departure ramp, v_max), reach)); the safe margin backs off
            # safe_backoff above d_s, approached from the current margin psi at psi_recovery m per sample (with
            # psi < 0 eq. (7a) cannot hold at k=1; eq. (11) then sets the advice). One compiled call
            # (``Horizon.follow``: numpy's operations, the same bits) writes both
            self._horizon.follow(v, psi)
            plan = self.cf.plan(v, d_rel, v_p, ref.v_lo, self._vhicf, pred.grade, d_its0=ref.d_its0,
                                d_hard_lo=ref.d_hard, d_s_its=ref.d_sits, ft_prev=self._prev_ft, v_lin=pred.v_lin,
                                ft_lin=pred.ft_lin, safe_margin=self._margin)
        else:
            plan = self.rt.plan(v, ref.v_ref, ref.v_lo, ref.v_hi, pred.grade, d_its0=ref.d_its0,
                                d_hard_lo=ref.d_hard, d_s_its=ref.d_sits, ft_prev=self._prev_ft, v_lin=pred.v_lin,
                                ft_lin=pred.ft_lin)
        status = plan.status
        if plan.ok:
            st["solved"] += 1
        else:
            st["fallbacks"] += 1
            fallback = True
            plan = self._fallback_plan(v, mode, status, ref.v_hi)
            status = "fallback:" + status
        return _Solution(ctrl, mode, plan, status, fallback, psi)

    def _advise(self, v: float, sol: _Solution) -> tuple[float, str]:
        """(advised speed, solve status): the first planned speed, the speed correction eq. (11) when psi < 0 and
        the rate limit after a hand-over; remembers the plan for the next step."""
        cfg, st = self.settings, self.stats
        plan, psi, status, fallback = sol.plan, sol.psi, sol.status, sol.fallback
        v_adv = float(plan.v[1])
        if psi is not None and psi < 0.0:
            v_c = corrected_speed(v, psi)   # eq. (11)
            st["corrections"] += 1
            if v_c < v_adv:
                v_adv = v_c
                status = "speed_correction" if not fallback else status
        if self._blend > 0 and self._prev_advice is not None and not (psi is not None and psi < 0.0):
            v_adv = float(np.clip(v_adv, self._prev_advice - cfg.blend_max_step,
                                  self._prev_advice + cfg.blend_max_step))
            self._blend -= 1
        self._prev = plan if (plan.ok and not fallback) else None
        self._prev_ft = float(plan.ft[0]) if self._prev is not None else None
        self._prev_ctrl = sol.ctrl
        self._prev_advice = v_adv
        return v_adv, status

    def _hud(self, s: float, v: float, a_meas: float, dt_real: float, pred: _Prediction, obj: _Objects,
             sol: _Solution, plan_v: tuple) -> HudAdvice:
        """The HUD record (pedas.hud.advisory) and the unfollowed-advice timer behind its warning tone."""
        cfg = self.settings
        self._unfollowed = update_unfollowed(self._unfollowed, self._last_arrow, a_meas, dt_real,
                                             not_decel=cfg.not_decel)
        ctx = self._hud_context(s, v, pred, obj, sol)
        hud = advisory(HudState(v=v, a=a_meas, slow_unfollowed=self._unfollowed), plan_v, ctx, **self._hud_kw)
        self._last_arrow = hud.hud_arrow
        return hud

    def _legal_limit(self, s: float) -> float:
        """The legal limit in force at s (m/s): that of the last route grid point at or before s, the sign the car
        has passed (never a value interpolated between two limits, which no sign shows)."""
        i = bisect_right(self._s_list, s) - 1   # np.searchsorted(self._s, s, side="right") - 1, on a list
        return float(self._limit[min(max(i, 0), self._limit.size - 1)])

    def _hud_context(self, s: float, v: float, pred: _Prediction, obj: _Objects, sol: _Solution) -> HudContext:
        """What the HUD shows besides the advice: the mode, the next light, stop sign and (slower) curve ahead."""
        curve_d = None
        if self._curve_list:
            j = bisect_left(self._curve_list, s)
            if j < self._curve_s.size and self._curve_v[j] < v:
                curve_d = float(self._curve_s[j] - s)
        return HudContext(mode=sol.mode, tl_distance=obj.d_tl, tl_remaining=obj.tl_remaining, stop_distance=obj.d_ss,
                          curve_distance=curve_d, psi=sol.psi, speed_limit=self._legal_limit(s),
                          tl_state=obj.tl_state)

    # ------------------------------------------------------------------------------------------------------
    def _nongreen(self, state: str, changes: list[tuple[float, str]], t: float) -> list[bool]:
        """Mask over k=1..N: the light (in `state` at t, then the phase `changes` (time, state)) is not green at
        t + k dt. A list: the step asks whether any is true, the first true and, at most once, the d_ITS rows
        (on 20 values, Python's list operations take a third of the time of numpy's calls)."""
        n = self.n
        tk = [t + d for d in self._dtk]   # the same float additions as t + dt k in numpy
        mask = [state != "green"] * n
        for tc, st in changes:   # tk ascends: the steps with tk >= tc are the tail from the first of them
            i = bisect_left(tk, tc)
            mask[i:] = [st != "green"] * (n - i)
        return mask

    # ------------------------------------------------------------------------------------------------------
    def _fallback_plan(self, v0: float, mode: str, status: str, v_hi: np.ndarray) -> MpcPlan:
        """Safe braking plan (settings.fallback_decel) when stopping/following or infeasible; otherwise hold the
        speed, capped by the speed limit envelope."""
        N, k, decel = self.n, self._k, self.settings.fallback_decel
        if mode in ("stop", "follow") or "infeasible" in status:
            v = np.r_[v0, np.maximum(v0 - decel * self.dt * k, 0.0)]
            fb = np.full(N, min(self.model.F_b_max, self.model.m_eq * decel))
            fb[v[:-1] <= 0.0] = 0.0
            ft = np.zeros(N)
        else:
            v = np.r_[v0, np.minimum(np.full(N, v0), v_hi)]
            ft = np.zeros(N)
            fb = np.zeros(N)
        return MpcPlan("fallback", False, v, ft, fb, np.zeros(N + 1), None, np.zeros(N), np.zeros(N), None, 0, None)

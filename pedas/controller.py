"""The pEDAS controller (Sec. 3.1, 3.5-3.8): switching between the two MPCs, speed correction, fallback, HUD.

``PedasController(route, params, v_dp).step(t, s, v, leader) -> Advisory`` once per sample (DT = 0.2 s):

1. the horizon is laid out along the route with the previous plan (shifted one step) as prediction of the
   positions s_k, which also serves as linearisation point of the power term (see :mod:`pedas.mpc`);
2. leader within SENSOR_RANGE -> car-following MPC eq. (10), else reference-tracking MPC eq. (9) with v_ref from
   the green wave (eq. 1) when a green window of the next light is reachable within [v_min, v_max], else v_DP;
3. stop logic: a red (or non-passable yellow) light and every stop sign constrain d_ITS >= 0 (eq. 8c) at the
   horizon steps where the light is not green (all steps for a stop sign); the stop sign is released after the
   vehicle has stood STOP_DWELL s inside the stop-line band [0, d_s,ITS] before the line;
4. psi = d_rel - d_s < 0 -> the MPC is not solved (eq. 7a cannot hold) and the advice is v + v_corr(psi) (eq. 11);
5. every solve's status is checked; a failed/infeasible solve yields a fallback plan flagged ``fallback=True``;
6. after a switch rt <-> cf the new MPC is warm-started from the old plan and the advised speed is rate-limited to
   BLEND_MAX_STEP per sample for BLEND_STEPS samples (the documented bound on the hand-over jump);
7. the HUD record comes from the pure :func:`pedas.hud.advisory`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pedas.constants import DT, N_HORIZON, SENSOR_RANGE, STOP_DWELL
from pedas.greenwave import SPAT_RANGE, green_wave_band
from pedas.hud import HudContext, HudState, advisory, update_unfollowed
from pedas.mpc import INF, MpcPlan, vehicle_model
from pedas.mpc_cf import CF_WEIGHTS, SAFE_BACKOFF, CarFollowingMpc
from pedas.mpc_rt import RT_WEIGHTS, ReferenceTrackingMpc
from pedas.params import LEAF, VehicleParams
from pedas.route import braking_envelope
from pedas.speed_correction import corrected_speed

A_STOP = 1.0  # m/s^2, deceleration of the stop / curve approach envelope of v_ref (early and gentle)
STOP_AIM = 0.9  # the stop envelope ends 0.9 d_s,ITS before the stop line: a lagging driver still stops in the band
A_DEPART = 1.0  # m/s^2, acceleration of the departure ramp of v_ref (matches the DP's a_max)
A_REACH = 3.0  # m/s^2, a speed limit below the current speed is imposed no faster than this (keeps the QP feasible)
CRUISE_LOOK = 100.0  # m, v_DP is floored by its maximum over this look-ahead (forced DP zeros at served stops)
GW_RANGE = SPAT_RANGE  # m, the green wave (and the red-light logic) considers lights within this distance
GW_MIN_FRACTION = 0.6  # eq. (1) lower road speed where the route has v_min = 0 (town): 0.6 x limit (30 of 50 km/h)
YELLOW_GO_DECEL = 3.0  # m/s^2, at yellow the vehicle goes when stopping would need more than this
FALLBACK_DECEL = 3.0  # m/s^2, deceleration of the safe braking fallback plan
V_STOPPED = 0.3  # m/s, below this the vehicle counts as standing (stop-sign dwell)
BAND_TOL = 0.5  # m, tolerance on the stop-line band when counting the dwell
SS_PASSED = 1.0  # m past the stop sign after which it counts as passed (missed if the dwell was not served)
PSI_RECOVERY = 0.2  # m per sample: rate at which the planned safe-distance margin may recover to SAFE_BACKOFF
BLEND_STEPS = 10  # samples (2 s) of rate-limited advice after a controller switch
BLEND_MAX_STEP = 0.4  # m/s per sample (2 m/s^2): bound on the advised-speed change during a hand-over


@dataclass(frozen=True)
class Advisory:
    """One controller output (the drive log stores these).

    v_advice: m/s, the optimal speed v_h,opt (first planned step, or the corrected speed of eq. 11);
    controller 'rt'|'cf'; mode 'green_wave'|'dp'|'stop'|'follow'; ft, fb: first planned forces (N);
    hud_arrow -1|0|1, arrow_len 0..1, hud_in_band, warning, tl_countdown (s or None), icon; solve_status (OSQP
    status text, 'speed_correction' or 'fallback:<status>'), fallback flag, plan_v: N predicted speeds v_1..v_N.
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


class PedasController:
    """pEDAS for one route: both MPCs built once, then :meth:`step` per sample."""

    def __init__(self, route, params: VehicleParams = LEAF, v_dp=None, n: int = N_HORIZON, dt: float = DT,
                 rt_weights=RT_WEIGHTS, cf_weights=CF_WEIGHTS, osqp_settings: dict | None = None) -> None:
        self.route, self.params, self.n, self.dt = route, params, n, dt
        self.model = vehicle_model(params)
        self.rt = ReferenceTrackingMpc(self.model, rt_weights, n=n, dt=dt, settings=osqp_settings)
        self.cf = CarFollowingMpc(self.model, cf_weights, n=n, dt=dt, settings=osqp_settings)
        self.h_s, self.d_min = cf_weights.h_s, cf_weights.d_min
        if v_dp is None:
            from pedas.dp import dp_reference
            v_dp = dp_reference(route, params)
        if hasattr(v_dp, "s") and hasattr(v_dp, "v_dp"):
            self._dp_s, self._dp_v = np.asarray(v_dp.s, float), np.asarray(v_dp.v_dp, float)
        else:  # (s, v) pair of arrays
            self._dp_s, self._dp_v = (np.asarray(a, float) for a in v_dp)
        # route profiles on the route grid (np.interp per step)
        self._s = np.asarray(route.s, float)
        self._vmax = np.asarray(route.v_max, float)
        self._vmin = np.asarray(route.v_min, float)
        self._grade = np.asarray(route.grade, float)
        self._limit = np.asarray(route.speed_limit, float)
        # curve envelope: the highest speed from which every later v_max is reachable at A_STOP (backward pass)
        self._venv = braking_envelope(self._s, self._vmax, A_STOP)
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
        self._frac8 = np.linspace(0.0, 1.0, 8)
        self._vlin = np.empty(n)
        self._ftlin = np.empty(n)
        self._sgrade = np.empty(n)
        self.reset()

    def reset(self) -> None:
        """Forget the drive state (plans, stop-sign dwell, counters)."""
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
    def _nongreen(self, tl, t: float) -> np.ndarray:
        """Mask over k=1..N: the light is not green at t + k dt."""
        tk = t + self.dt * self._k
        state = tl.state_at(t)
        mask = np.full(self.n, state != "green")
        for tc, st in tl.next_phase_starts(t, self.n * self.dt):
            mask[tk >= tc] = st != "green"
        return mask

    def step(self, t: float, s: float, v: float, leader: tuple[float, float] | None = None) -> Advisory:
        """Advice for the measured state: time t (s), route position s (m), speed v (m/s), leader = (gap d_rel m,
        its speed v_p m/s) or None."""
        N, dt = self.n, self.dt
        v = max(float(v), 0.0)
        st = self.stats
        st["steps"] += 1
        a_meas = (v - self._v_prev) / (t - self._t_prev) if self._t_prev is not None and t > self._t_prev else 0.0
        dt_real = (t - self._t_prev) if self._t_prev is not None and t > self._t_prev else dt
        self._t_prev, self._v_prev = t, v

        # linearisation / prediction trajectory: previous plan shifted by one sample
        prev = self._prev
        if prev is not None:
            v_lin = self._vlin
            v_lin[0] = v                                            # v_k ~ previous v_{k+1}, v_0 measured
            v_lin[1:] = prev.v[2:]
            ft_lin = self._ftlin
            ft_lin[:-1] = prev.ft[1:]
            ft_lin[-1] = prev.ft[-1]
        else:
            v_lin = np.full(N, v)
            ft_lin = np.zeros(N)
        s_pred = s + dt * np.cumsum(np.maximum(v_lin, 0.0))        # positions at k = 1..N
        s_grade = self._sgrade                                      # positions at k = 0..N-1
        s_grade[0] = s
        s_grade[1:] = s_pred[:-1]
        grade = np.interp(s_grade, self._s, self._grade)
        vmax = np.interp(s_pred, self._s, self._vmax)
        vmin = np.interp(s_pred, self._s, self._vmin)
        vdp = np.interp(s_pred, self._dp_s, self._dp_v)
        venv = np.interp(s_pred, self._s, self._venv)

        # ---- objects ahead: lights and stop signs -------------------------------------------------------
        lights, stops = self._lights, self._stops
        while self._tl_i < len(lights) and lights[self._tl_i].s < s - 0.5:
            self._tl_i += 1
        tl = lights[self._tl_i] if self._tl_i < len(lights) else None
        d_tl = tl.s - s if tl is not None else None
        ss = stops[self._ss_i] if self._ss_i < len(stops) else None
        d_ss = ss.s - s if ss is not None else None
        if ss is not None and d_ss < -SS_PASSED:  # passed without completing the dwell
            st["stops_missed"] += 1
            self._ss_i += 1
            self._dwell = 0.0
            ss = stops[self._ss_i] if self._ss_i < len(stops) else None
            d_ss = ss.s - s if ss is not None else None
        # a standstill anywhere short of "passed" serves the stop; a narrower window would leave a car that crept
        # just past the line waiting for an advice of 0 km/h forever
        if ss is not None and v < V_STOPPED and -SS_PASSED <= d_ss <= self._d_sits + BAND_TOL:
            self._dwell += dt_real
            if self._dwell >= STOP_DWELL - 1e-9:
                st["stops_served"] += 1
                self._ss_i += 1
                self._dwell = 0.0
                ss = stops[self._ss_i] if self._ss_i < len(stops) else None
                d_ss = ss.s - s if ss is not None else None

        stop_d = None          # distance to the stop line that constrains d_ITS
        d_hard = None
        tl_stop_expected = False
        v_gw = None
        if tl is not None and d_tl <= GW_RANGE:
            mask = self._nongreen(tl, t)
            state = tl.state_at(t)
            go = False
            if state == "green":
                if mask.any():
                    k_r = int(np.argmax(mask))          # index of the first non-green step (time k_r + 1)
                    go = s_pred[k_r] > tl.s + 1.0 if k_r > 0 else False
                else:
                    go = True
            elif state == "yellow":
                go = d_tl < v * v / (2 * YELLOW_GO_DECEL)
            if not go and mask.any():
                stop_d, d_hard = d_tl, np.where(mask, 0.0, -INF)
            # eq. (1) with v_max the lowest limit up to the line and v_min >= GW_MIN_FRACTION x speed limit
            v_hi_gw = float(np.interp(s + max(d_tl, 0.0) * self._frac8, self._s, self._vmax).min())
            v_lo_gw = max(float(np.interp(s, self._s, self._vmin)),
                          GW_MIN_FRACTION * float(np.interp(s, self._s, self._limit)))
            gw_ok = d_tl > 0 and (ss is None or ss.s > tl.s)            # a stop sign before the light goes first
            band = green_wave_band(d_tl, t, tl, min(v_lo_gw, v_hi_gw), v_hi_gw) if gw_ok else None
            v_gw = band[0] if band is not None else None                # v_ref,min
            tl_stop_expected = v_gw is None and not go              # eq. (1) empty: stopping is unavoidable
        if ss is not None and (stop_d is None or d_ss < stop_d):
            stop_d, d_hard = d_ss, np.zeros(N)
            stop_kind = "ss"
        else:
            stop_kind = "tl" if stop_d is not None else None
        # the stop envelope of v_ref: at a stop sign, and at a light when eq. (1) has no band (stop unavoidable);
        # with a green-wave band the hard d_ITS rows alone keep the plan out of the red phases
        envelope_d = None
        if stop_kind == "ss":
            envelope_d = d_ss
        elif tl is not None and tl_stop_expected:
            envelope_d = d_tl

        # ---- reference and speed bounds ---------------------------------------------------------------
        if v_gw is not None:
            v_ref = np.full(N, v_gw)
            mode = "green_wave"
        else:
            # v_DP floored by its look-ahead maximum, reached with a departure ramp (zeros at served stops)
            j0, j1 = np.searchsorted(self._dp_s, [s, s + CRUISE_LOOK])
            cruise = float(self._dp_v[j0:max(j1, j0 + 1)].max()) if j0 < self._dp_v.size else float(self._dp_v[-1])
            v_ref = np.maximum(vdp, np.minimum(v + A_DEPART * dt * self._k, cruise))
            mode = "dp"
        v_ref = np.minimum(v_ref, venv)
        if envelope_d is not None:
            d_target = envelope_d - STOP_AIM * self._d_sits - (s_pred - s)   # aim inside the stop-line band
            stop_env = np.sqrt(2 * A_STOP * np.maximum(d_target, 0.0))
            if stop_env[-1] < v_ref[-1] or (stop_kind == "tl" and tl_stop_expected):
                mode = "stop"
            v_ref = np.minimum(v_ref, stop_env)
        reach = v - A_REACH * dt * self._k
        v_hi = np.maximum(vmax, reach)
        if mode in ("green_wave", "dp") and leader is None:
            v_lo = np.minimum(vmin, v)
        else:
            v_lo = np.zeros(N)
        v_lo = np.minimum(v_lo, v_hi)
        d_sits = self._d_sits if mode == "stop" else INF
        if d_hard is None or stop_d > float(v_hi.max()) * N * dt + 5.0:
            # no stop object within reach of the horizon: the d_ITS rows cannot bind; unbounding them and keeping the
            # state at 0 also keeps OSQP's relative tolerance from scaling with a distance of several hundred m
            d_hard, d_its0, d_sits = None, 0.0, INF
        else:
            d_its0 = stop_d

        # ---- controller choice -------------------------------------------------------------------------
        use_cf = leader is not None and leader[0] <= SENSOR_RANGE
        ctrl = "cf" if use_cf else "rt"
        st[ctrl] += 1
        if self._prev_ctrl is not None and ctrl != self._prev_ctrl:
            st["switches"] += 1
            self._blend = BLEND_STEPS
            if prev is not None:
                (self.cf if use_cf else self.rt).warm_start_from(prev.v, prev.ft, prev.fb)
        psi = None
        fallback = False
        if use_cf:
            d_rel, v_p = float(leader[0]), float(leader[1])
            psi = d_rel - (self.d_min + self.h_s * v)
            mode = "follow"
            v_hi_cf = np.minimum(v_hi, np.maximum(np.maximum(vdp, np.minimum(v + A_DEPART * dt * self._k,
                                                                              vmax)), reach))
            # back-off SAFE_BACKOFF above d_s, approached from the current margin psi at PSI_RECOVERY m per sample
            # (with psi < 0 eq. (7a) cannot hold at k=1; eq. (11) then sets the advice)
            margin = np.minimum(SAFE_BACKOFF, psi + PSI_RECOVERY * self._k)
            plan = self.cf.plan(v, d_rel, v_p, v_lo, v_hi_cf, grade, d_its0=d_its0, d_hard_lo=d_hard,
                                d_s_its=d_sits, ft_prev=self._prev_ft, v_lin=v_lin, ft_lin=ft_lin,
                                safe_margin=margin)
        else:
            plan = self.rt.plan(v, v_ref, v_lo, v_hi, grade, d_its0=d_its0, d_hard_lo=d_hard, d_s_its=d_sits,
                                ft_prev=self._prev_ft, v_lin=v_lin, ft_lin=ft_lin)
        status = plan.status
        if plan.ok:
            st["solved"] += 1
        else:
            st["fallbacks"] += 1
            fallback = True
            plan = self._fallback_plan(v, mode, status, v_hi)
            status = "fallback:" + status
        v_adv = float(plan.v[1])
        if psi is not None and psi < 0.0:
            v_c = corrected_speed(v, psi)   # eq. (11)
            st["corrections"] += 1
            if v_c < v_adv:
                v_adv = v_c
                status = "speed_correction" if not fallback else status
        if self._blend > 0 and self._prev_advice is not None and not (psi is not None and psi < 0.0):
            v_adv = float(np.clip(v_adv, self._prev_advice - BLEND_MAX_STEP, self._prev_advice + BLEND_MAX_STEP))
            self._blend -= 1
        self._prev = plan if (plan.ok and not fallback) else None
        self._prev_ft = float(plan.ft[0]) if self._prev is not None else None
        self._prev_ctrl = ctrl
        self._prev_advice = v_adv

        # ---- HUD -----------------------------------------------------------------------------------------
        self._unfollowed = update_unfollowed(self._unfollowed, self._last_arrow, a_meas, dt_real)
        curve_d = None
        if self._curve_s.size:
            j = int(np.searchsorted(self._curve_s, s))
            if j < self._curve_s.size and self._curve_v[j] < v:
                curve_d = float(self._curve_s[j] - s)
        ctx = HudContext(mode=mode, tl_distance=d_tl, tl_remaining=tl.remaining(t) if tl is not None else None,
                         stop_distance=d_ss, curve_distance=curve_d, psi=psi,
                         speed_limit=float(np.interp(s, self._s, self._limit)))
        plan_v = (v_adv,) + tuple(plan.v[2:].tolist())
        hud = advisory(HudState(v=v, a=a_meas, slow_unfollowed=self._unfollowed), plan_v, ctx)
        self._last_arrow = hud.hud_arrow
        # forces within solver tolerance of 0 are reported as 0 (the QP bounds are F >= 0)
        return Advisory(v_advice=v_adv, controller=ctrl, mode=mode, ft=max(float(plan.ft[0]), 0.0),
                        fb=max(float(plan.fb[0]), 0.0),
                        hud_arrow=hud.hud_arrow, arrow_len=hud.arrow_len, hud_in_band=hud.hud_in_band,
                        warning=hud.warning, tl_countdown=hud.tl_countdown, icon=hud.icon, solve_status=status,
                        fallback=fallback, plan_v=plan_v)

    # ------------------------------------------------------------------------------------------------------
    def _fallback_plan(self, v0: float, mode: str, status: str, v_hi: np.ndarray) -> MpcPlan:
        """Safe braking plan (FALLBACK_DECEL) when stopping/following or infeasible; otherwise hold the speed,
        capped by the speed limit envelope."""
        N, k = self.n, self._k
        if mode in ("stop", "follow") or "infeasible" in status:
            v = np.r_[v0, np.maximum(v0 - FALLBACK_DECEL * self.dt * k, 0.0)]
            fb = np.full(N, min(self.model.F_b_max, self.model.m_eq * FALLBACK_DECEL))
            fb[v[:-1] <= 0.0] = 0.0
            ft = np.zeros(N)
        else:
            v = np.r_[v0, np.minimum(np.full(N, v0), v_hi)]
            ft = np.zeros(N)
            fb = np.zeros(N)
        return MpcPlan("fallback", False, v, ft, fb, np.zeros(N + 1), None, np.zeros(N), np.zeros(N), None,
                       float("nan"), 0, None)

"""Virtual participants: a human-like longitudinal driver model, with and without the pEDAS advisory.

**Baseline** (own driving style): the Human Driver Model (Treiber, Kesting & Helbing 2006), i.e. the Intelligent
Driver Model (IDM, Treiber, Hennecke & Helbing 2000) with a reaction time and temporal anticipation. The driver
perceives everything outside the car (leader gap and speed, signal state) `reaction` s late and extrapolates the
gap over that delay; the own speed is felt immediately. The desired speed is the legal limit times a personal
speed factor, limited in curves by a preferred lateral acceleration and anticipated with the comfortable
deceleration (the driver sees limits and curves ahead). Red lights, yellow lights the driver decides to stop at
and stop signs are standing virtual obstacles at the stop line. At a stop sign the driver halts completely and
waits a personal dwell. On the highway the desired speed is at least 80 km/h + a margin (the instruction,
Sec. 4.3). No overtaking: the model only controls the longitudinal motion behind its leader.

**Assisted** (pEDAS): the same person (same parameters) perceives the HUD advisory `hud_delay` s late and tracks
it with a personal `compliance` (0..1: the share of the gap between own wish and advice that is given up):
inside the +-2 km/h band the driver coasts (no pedal), outside it accelerates/brakes towards the target within
the own comfortable limits. The own safety behaviour (leader, red light, stop sign) stays active: the applied
acceleration is the minimum of tracking and safety. A warning tone makes the driver follow the slow-down advice
fully.

Parameters are drawn per participant from truncated normal distributions whose means and spreads per style are
documented (with sources) in ``docs/drivers.md``; :func:`sample_driver` is a pure function of (seed, style).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

from pedas.constants import DT, HIGHWAY_MIN_SPEED, HUD_BAND, KMH
from pedas.hud import wants_start
from pedas.params import LEAF, VehicleParams
from pedas.route import braking_envelope
from pedas.vehicle import traction_envelope
from pedas.vocabulary import STYLES

IDM_DELTA = 4.0  # IDM acceleration exponent (Treiber et al. 2000)
HIGHWAY_MARGIN = 5.0 * KMH  # m/s, drivers keep their wish a little above the instructed 80 km/h minimum
STOP_MARGIN = 0.5  # m, drivers aim to stand this far before the stop line
HALT_SPEED = 0.05  # m/s, counts as standing still (full stop at a stop sign)
HALT_BAND = 3.0  # m, the driver's halt at a stop sign is this close to the line (else it moves up and halts again)
ANTICIPATION = 0.8  # drivers plan to slow for a curve / lower limit ahead at this share of b_comf
BRAKE_LIGHT = 1.0  # m/s^2, a leader decelerating harder than this is noticed as braking
MAX_BRAKE = 8.0  # m/s^2, emergency braking the driver may apply (tyre/road limit ~ 8-9 m/s^2 dry)
TRACK_TIME = 1.5  # s, time constant with which an assisted driver closes a speed gap outside the band
TRACK_DONE = 0.3 * KMH  # m/s, an assisted driver accelerating towards the target stops pressing this close to it
COAST_EXCESS = 6.0 * KMH  # m/s, above the target by less than this the assisted driver coasts instead of braking
WARN_BRAKE = 3.5  # m/s^2, firm braking on the warning tone (a slow-down advice that was not followed)
WARN_MEMORY = 5.0  # s, after a warning tone the driver follows the advice fully for this long


@dataclass(frozen=True)
class Dist:
    """A truncated normal N(mean, sd) clipped to [lo, hi]."""

    mean: float
    sd: float
    lo: float
    hi: float

    def draw(self, rng: np.random.Generator) -> float:
        return float(np.clip(rng.normal(self.mean, self.sd), self.lo, self.hi))


# Per-style distributions (sources in docs/drivers.md). Order of the draws is fixed: changing it changes people.
PARAM_DISTRIBUTIONS: dict[str, dict[str, Dist]] = {
    "cautious": dict(
        speed_factor=Dist(0.96, 0.04, 0.85, 1.05), speed_factor_hw=Dist(0.92, 0.04, 0.80, 1.00),
        a_max=Dist(1.0, 0.15, 0.7, 1.4), b_comf=Dist(1.6, 0.2, 1.2, 2.2), a_lat=Dist(1.6, 0.2, 1.2, 2.2),
        headway=Dist(1.8, 0.2, 1.4, 2.4), s0=Dist(2.5, 0.3, 2.0, 3.5), reaction=Dist(1.1, 0.15, 0.7, 1.5),
        yellow_decel=Dist(3.5, 0.3, 2.8, 4.2), stop_dwell=Dist(2.5, 0.5, 1.5, 4.0),
        compliance=Dist(0.85, 0.08, 0.6, 1.0), hud_glance=Dist(0.4, 0.1, 0.2, 0.7),
        warn_learning=Dist(0.25, 0.15, 0.0, 0.6)),
    "normal": dict(
        speed_factor=Dist(1.04, 0.04, 0.95, 1.15), speed_factor_hw=Dist(1.00, 0.04, 0.90, 1.10),
        a_max=Dist(1.4, 0.2, 1.0, 2.0), b_comf=Dist(2.0, 0.25, 1.5, 2.8), a_lat=Dist(2.2, 0.3, 1.6, 3.0),
        headway=Dist(1.4, 0.2, 1.0, 1.9), s0=Dist(2.0, 0.3, 1.5, 3.0), reaction=Dist(1.0, 0.15, 0.7, 1.5),
        yellow_decel=Dist(3.0, 0.3, 2.4, 3.8), stop_dwell=Dist(1.8, 0.5, 1.0, 3.0),
        compliance=Dist(0.75, 0.1, 0.45, 1.0), hud_glance=Dist(0.4, 0.1, 0.2, 0.7),
        warn_learning=Dist(0.25, 0.15, 0.0, 0.6)),
    "sporty": dict(
        speed_factor=Dist(1.12, 0.05, 1.00, 1.25), speed_factor_hw=Dist(1.08, 0.05, 0.95, 1.20),
        a_max=Dist(2.0, 0.3, 1.4, 2.8), b_comf=Dist(2.7, 0.3, 2.0, 3.5), a_lat=Dist(3.0, 0.4, 2.2, 4.0),
        headway=Dist(1.1, 0.15, 0.8, 1.5), s0=Dist(1.8, 0.3, 1.2, 2.5), reaction=Dist(0.9, 0.15, 0.7, 1.3),
        yellow_decel=Dist(2.6, 0.3, 2.0, 3.4), stop_dwell=Dist(1.2, 0.3, 0.8, 2.0),
        compliance=Dist(0.65, 0.12, 0.35, 0.95), hud_glance=Dist(0.4, 0.1, 0.2, 0.7),
        warn_learning=Dist(0.25, 0.15, 0.0, 0.6)),
}
_STYLE_CODE = {"cautious": 1, "normal": 2, "sporty": 3}


@dataclass(frozen=True)
class DriverParams:
    """One virtual participant.

    speed_factor (town) / speed_factor_hw (highway): desired speed / legal limit; a_max, b_comf (m/s^2): IDM
    comfortable acceleration and deceleration; a_lat (m/s^2): preferred lateral acceleration in curves; headway
    (s) and s0 (m): IDM desired time gap and standstill gap; reaction (s): perception-reaction time;
    yellow_decel (m/s^2): deceleration up to which the driver stops at yellow; stop_dwell (s): halt at stop signs;
    compliance (0..1) and hud_delay (s): tracking of the HUD advisory (assisted drives); warn_learning (0..1):
    share of the gap between compliance and 1 that each new warning tone closes (how much the person adapts).
    """

    style: str
    seed: int
    speed_factor: float
    speed_factor_hw: float
    a_max: float
    b_comf: float
    a_lat: float
    headway: float
    s0: float
    reaction: float
    yellow_decel: float
    stop_dwell: float
    compliance: float
    hud_delay: float
    warn_learning: float

    def as_dict(self) -> dict:
        return asdict(self)


def sample_driver(seed: int, style: str) -> DriverParams:
    """The parameters of participant `seed` with driving `style` (same inputs -> same person)."""
    if style not in PARAM_DISTRIBUTIONS:
        raise ValueError(f"unknown driving style {style!r} (expected one of {', '.join(STYLES)})")
    rng = np.random.default_rng([int(seed), _STYLE_CODE[style], 0xD41E])
    d = PARAM_DISTRIBUTIONS[style]
    vals = {k: dist.draw(rng) for k, dist in d.items()}
    hud_glance = vals.pop("hud_glance")
    # reading the HUD adds a glance to the perception-reaction time
    return DriverParams(style=style, seed=int(seed), hud_delay=vals["reaction"] + hud_glance, **vals)


def curve_speed_profile(route, drv: DriverParams) -> np.ndarray:
    """The driver's own curve speed sqrt(a_lat / |kappa|) along the route grid, anticipated (m/s)."""
    k = np.abs(np.asarray(route.curvature, float))
    with np.errstate(divide="ignore"):
        v_curve = np.where(k > 1e-9, np.sqrt(drv.a_lat / np.maximum(k, 1e-12)), 1e3)
    return braking_envelope(np.asarray(route.s, float), v_curve, ANTICIPATION * drv.b_comf)


def desired_speed_profile(route, drv: DriverParams) -> np.ndarray:
    """The driver's wish speed along the route grid (m/s), anticipated: at each point the highest speed from
    which every later wish can be reached braking at ANTICIPATION x b_comf (a backward pass over the route)."""
    limit = np.asarray(route.speed_limit, float)
    hw = np.asarray(route.segment) == "highway"
    v_wish = limit * np.where(hw, drv.speed_factor_hw, drv.speed_factor)
    k = np.abs(np.asarray(route.curvature, float))
    with np.errstate(divide="ignore"):
        v_curve = np.where(k > 1e-9, np.sqrt(drv.a_lat / np.maximum(k, 1e-12)), np.inf)
    v_wish = np.minimum(v_wish, v_curve)
    on_main = np.asarray(route.v_min, float) > 0  # the instructed highway minimum applies here
    v_wish = np.where(on_main, np.maximum(v_wish, HIGHWAY_MIN_SPEED + HIGHWAY_MARGIN), v_wish)
    return braking_envelope(np.asarray(route.s, float), v_wish, ANTICIPATION * drv.b_comf)


def idm_free(v: float, v0: float, a: float) -> float:
    """IDM free-road term a [1 - (v/v0)^delta] (m/s^2)."""
    if v0 <= 0.0:
        return -a
    return a * (1.0 - (v / v0) ** IDM_DELTA)


def idm_interaction(v: float, gap: float, dv: float, drv: DriverParams) -> float:
    """IDM interaction term -a (s*/s)^2 with s* = s0 + max(0, v T + v dv / (2 sqrt(a b))) (m/s^2).

    gap: bumper-to-bumper distance (m); dv = v - v_leader (approach rate, m/s)."""
    s_star = drv.s0 + max(0.0, v * drv.headway + v * dv / (2.0 * math.sqrt(drv.a_max * drv.b_comf)))
    g = max(gap, 0.1)
    return -drv.a_max * (s_star / g) ** 2


@dataclass
class Perception:
    """What the driver sees at one instant (the drive loop fills it every step)."""

    t: float
    leader_gap: float | None
    leader_v: float | None
    tl_state: str | None  # next light's state (green|yellow|red)
    tl_remaining: float | None  # s left in that phase (the driver watches the light; estimate from the cycle)
    advice: float | None = None  # HUD v_advice (assisted)
    warning: bool = False
    s: float = 0.0  # own position (m), to know how far the car moved since a delayed perception
    leader_a: float = 0.0  # leader's acceleration (m/s^2), seen as brake lights / closing speed


class HumanDriver:
    """The longitudinal driver model of one participant on one route (baseline or assisted).

    Call :meth:`act` once per step with the current time, position, speed and perception; it returns the
    acceleration (m/s^2) applied during the next step.
    """

    def __init__(self, route, params: DriverParams, assisted: bool = False, vehicle: VehicleParams = LEAF,
                 dt: float = DT, band: float = HUD_BAND) -> None:
        self.route, self.p, self.assisted, self.vehicle, self.dt = route, params, assisted, vehicle, dt
        self.band = band  # m/s, the HUD's coast band (the same the HUD uses: ControllerParams.hud_band)
        self._s = np.asarray(route.s, float)
        # the profiles looked up every step, as lists: an index gives a Python float (the same value) instead of
        # a numpy scalar, and the driver's scalar arithmetic stays on Python floats
        self._v0 = desired_speed_profile(route, params).tolist()
        self._v_curve = curve_speed_profile(route, params).tolist()
        self._grade = np.asarray(route.grade, float).tolist()
        self._n = self._s.size
        self._inv_ds = 1.0 / float(self._s[1] - self._s[0])
        vp = vehicle
        self._k_aero = 0.5 * vp.rho * vp.A_f * vp.c_w
        self._k_roll = vp.c_r * vp.m_v * vp.g
        self._k_grav = vp.m_v * vp.g
        self._f_peak = float(traction_envelope(0.0, vp))
        self._p_max = vp.P_max * vp.eta_gear
        self._tracking = False  # assisted: closing a gap to the target (pedal hysteresis)
        self._warned_until = -math.inf  # assisted: follows the advice fully until then (after a warning tone)
        self.compliance = params.compliance  # grows with every warning tone (params.warn_learning)
        self._v_min = np.asarray(route.v_min, float).tolist()
        self._t = 0.0
        self._lights = tuple(route.lights)
        self._stops = tuple(route.stops)
        n_delay = max(0, int(round(params.reaction / dt)))
        n_hud = max(0, int(round(params.hud_delay / dt)))
        self._buf: deque[Perception] = deque(maxlen=n_delay + 1)
        self._hud: deque[tuple[float | None, bool]] = deque(maxlen=n_hud + 1)
        self._tl_i = 0
        self._ss_i = 0
        self._tl_decision: dict[str, str] = {}  # light id -> 'stop'|'go' decided at the perceived yellow
        self._halt_time = 0.0
        self.events: list[tuple[float, str, str]] = []  # (t, object id, what) for diagnostics

    def _idx(self, s: float) -> int:
        """Grid index at or before s (the route grid is uniform)."""
        i = int(s * self._inv_ds)
        return 0 if i < 0 else (self._n - 1 if i >= self._n else i)

    def v_wish(self, s: float) -> float:
        """Anticipated wish speed at s (m/s)."""
        return self._v0[self._idx(s)]

    def _road_load(self, v: float, s: float) -> float:
        """F_res (N) at speed v and position s (eq. 2, scalar form of pedas.vehicle.resistance)."""
        g = self._grade[self._idx(s)]
        return self._k_aero * v * v + self._k_roll * math.cos(g) + self._k_grav * math.sin(g)

    def _vehicle_limits(self, v: float, s: float) -> tuple[float, float]:
        f_res = self._road_load(v, s)
        f_trac = self._f_peak if v <= 0.0 else min(self._f_peak, self._p_max / v)
        a_hi = (f_trac - f_res) / self.vehicle.m_eq
        a_lo = -min(MAX_BRAKE, (self.vehicle.F_b_max + f_res) / self.vehicle.m_eq)
        return a_lo, a_hi

    def coast_accel(self, v: float, s: float) -> float:
        """Acceleration with both pedals released (road load only), m/s^2."""
        return -self._road_load(v, s) / self.vehicle.m_eq

    def act(self, t: float, s: float, v: float, obs: Perception) -> float:
        """Acceleration (m/s^2) for the next step from the perception `reaction` s ago (anticipated).

        IDM: a = free-road term + the most restrictive interaction term (leader or stop-line obstacle); a stop
        line closer than the comfortable braking distance imposes the kinematic deceleration v^2 / (2 d).
        """
        p = self.p
        self._t = t
        self._buf.append(obs)
        seen = self._buf[0]  # the oldest = `reaction` s ago (shorter at the start of the drive)
        lag = t - seen.t
        a_int = math.inf  # IDM interaction term (most restrictive)
        a_hard = math.inf  # kinematic deceleration needed to stop before a line
        a_go = -math.inf  # committed to go at a yellow light: the least acceleration that reaches the line before red

        # --- leader: the delayed view extrapolated over the lag (HDM temporal anticipation): the leader keeps its
        # seen acceleration (until it stands), the own car moved s - seen.s meanwhile
        if seen.leader_gap is not None:
            a_l = min(seen.leader_a, 0.0) if seen.leader_v > 0.0 else 0.0
            tt = lag if a_l >= 0.0 else min(lag, seen.leader_v / -a_l)
            v_l = max(seen.leader_v + a_l * tt, 0.0)
            gap = seen.leader_gap + seen.leader_v * tt + 0.5 * a_l * tt * tt - (s - seen.s)
            a_int = min(a_int, idm_interaction(v, gap, v - v_l, p))
            if a_l < -BRAKE_LIGHT:
                # brake lights: make sure to stop behind the point where the leader stops at its deceleration
                # (the safe-speed rule of Gipps 1981 with the observed instead of an assumed deceleration)
                room = gap - STOP_MARGIN + v_l * v_l / (2.0 * -a_l)
                need = v * v / (2.0 * max(room, 0.1))
                if need > 0.8 * p.b_comf:
                    a_hard = min(a_hard, -need)

        # --- traffic light ahead (the stop line is a fixed, known position; its state is seen late)
        while self._tl_i < len(self._lights) and self._lights[self._tl_i].s < s - 0.1:
            self._tl_i += 1
        tl = self._lights[self._tl_i] if self._tl_i < len(self._lights) else None
        if tl is not None:
            d = tl.s - s
            state = seen.tl_state
            decision = self._tl_decision.get(tl.tl_id)
            if state == "green":
                self._tl_decision.pop(tl.tl_id, None)
                decision = None
            elif state == "yellow" and decision is None:
                # stop if comfortable enough, else go if the line is reached before red, else stop hard. The time
                # to the line counts with the driver's own slowing before it (a turn or curve just after the
                # light): the mean of v and the anticipated wish at the line, not v
                need = v * v / (2.0 * max(d - STOP_MARGIN, 0.1))
                left = (seen.tl_remaining or 0.0) - lag
                v_go = 0.5 * (v + min(v, self._v0[self._idx(tl.s)]))
                decision = "stop" if (need <= p.yellow_decel or v_go * max(left, 0.0) < d + 1.0) else "go"
                self._tl_decision[tl.tl_id] = decision
                self.events.append((t, tl.tl_id, f"yellow:{decision}"))
            elif state == "red" and decision != "go":
                decision = "stop"
            if decision == "stop":
                a_int, a_hard = self._stop_line(v, d, a_int, a_hard)
            elif decision == "go" and state == "yellow":
                # a driver who has decided to go does not slow down into the red (for a turn behind the light,
                # or an advice falling after the decision): cover d + 1 m in the yellow left, less one step
                tt = max((seen.tl_remaining or 0.0) - lag - self.dt, self.dt)
                a_go = min(2.0 * (d + 1.0 - v * tt) / (tt * tt), p.a_max)
        a_lead = a_int  # only the leader so far: a commitment to a yellow light never overrides it

        # --- stop sign: a standing obstacle until the driver has halted at the line for the dwell time
        while self._ss_i < len(self._stops) and self._stops[self._ss_i].s < s - 0.1:
            self._ss_i += 1
            self._halt_time = 0.0
        ss = self._stops[self._ss_i] if self._ss_i < len(self._stops) else None
        if ss is not None:
            d = ss.s - s
            if v <= HALT_SPEED and d <= HALT_BAND:
                self._halt_time += self.dt
            if self._halt_time < p.stop_dwell:
                a_int, a_hard = self._stop_line(v, d, a_int, a_hard)

        # --- free road (baseline) or advisory tracking (assisted), then the safety terms
        v0 = self.v_wish(s)
        a_int = 0.0 if a_int == math.inf else a_int
        if self.assisted and obs.advice is not None:
            self._hud.append((obs.advice, obs.warning))
            adv, warn = self._hud[0]
            a = min(self._track(v, s, v0, adv, warn), p.a_max + a_int)  # IDM with an unbounded wish speed
        else:
            a = idm_free(v, v0, p.a_max) + a_int
            # the IDM alone lags behind a falling wish (curve, lower limit ahead): stay on the braking envelope
            v0_next = self.v_wish(s + v * self.dt)
            if v > v0_next:
                a = min(a, (v0_next - v) / self.dt)
        a = max(a, min(a_go, p.a_max + a_lead))
        a = min(a, a_hard)
        a_lo, a_hi = self._vehicle_limits(v, s)
        a = min(max(a, a_lo), a_hi)
        if v + a * self.dt < 0.0:  # standstill: brakes hold, no rolling backwards
            a = -v / self.dt
        return a

    def _stop_line(self, v: float, d: float, a_int: float, a_hard: float) -> tuple[float, float]:
        """Add a standing obstacle at the stop line (the driver aims to stand STOP_MARGIN before it)."""
        p = self.p
        room = d - STOP_MARGIN
        # the IDM settles at s0 behind an obstacle: put the virtual one s0 beyond the aimed stopping point
        a_int = min(a_int, idm_interaction(v, room + p.s0, v, p))
        if room <= 0.05:
            a_hard = min(a_hard, -v / self.dt)
        else:
            need = v * v / (2.0 * room)
            if need > 0.8 * p.b_comf:  # closer than comfortable: brake as much as needed
                a_hard = min(a_hard, -need)
        return a_int, a_hard

    def _track(self, v: float, s: float, v_own: float, adv: float, warn: bool) -> float:
        """Assisted longitudinal command towards target = advice + (1 - compliance) (own wish - advice).

        Inside the band (+-2 km/h in the paper) the driver coasts (the paper's instruction for a short arrow), unless the car
        stands and the target lies above it (:func:`pedas.hud.wants_start`): then the driver drives off. Below the band
        the driver accelerates and keeps the pedal until the target is reached (hysteresis instead of pedal
        chatter at the band edge); above it the driver first lifts off (coasts) and brakes only when the
        excess exceeds COAST_EXCESS or a warning tone sounds (then the advice is followed fully). The own curve
        speed is never exceeded.
        """
        p = self.p
        if warn and adv < v:
            if self._t >= self._warned_until:  # a new warning: the driver learns to comply more
                self.compliance += (1.0 - self.compliance) * self.p.warn_learning
            self._warned_until = self._t + WARN_MEMORY
        c = 1.0 if self._t < self._warned_until else self.compliance
        target = adv + (1.0 - c) * (v_own - adv)
        if self._v_min[self._idx(s)] > 0.0:  # the instructed highway minimum holds whatever the advice
            target = max(target, self._v_min[self._idx(s)] + self.band + 0.5 * KMH)
        err = target - v
        # standing, the band's "coast" means "stay": a person advised to drive off does (pedas.hud.wants_start)
        if err > self.band or (self._tracking and err > TRACK_DONE) or wants_start(v, target):
            self._tracking = True
            a = min(err / TRACK_TIME, p.a_max)
        else:
            self._tracking = False
            warned = self._t < self._warned_until
            if err < -COAST_EXCESS or (warned and err < -self.band):
                a = max(err / TRACK_TIME, -(WARN_BRAKE if warned else p.b_comf))
                a = min(a, self.coast_accel(v, s))
            else:
                a = self.coast_accel(v, s)
        # never faster through a curve than the own comfort allows (IDM free term on the curve envelope)
        return min(a, idm_free(v, self._v_curve[self._idx(s)], p.a_max))

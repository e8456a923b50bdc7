"""The drive loop: one virtual participant drives the study route once, in SUMO traffic, with or without pEDAS.

:func:`drive` returns the drive log in the columns of docs/contracts.md, one row every DT = 0.2 s from the ego's
insertion to its arrival at the end of the route. Every step checks the safety invariants and raises
:class:`SafetyViolation` when one fails — SUMO's own safety checks are switched off for the ego vehicle
(:mod:`pedas.traffic`), so a bug in the driver model or the controller cannot be hidden by the simulator:

* no collision: the bumper-to-bumper gap to the leader stays > 0 and SUMO reports no collision of the ego;
* no red-light crossing: the stop line of a light is never crossed during a step that starts at red (the signal
  state in force during SUMO's step from t to t + DT is the route program's state at t, checked in the tests);
* no stop-sign roll-through: before crossing a stop sign's line the ego has stood still (v <= HALT_CHECK m/s)
  within STOP_CHECK_BAND m before it.

and the liveness invariant (:class:`LivenessGuard`): the ego never stands still for more than STANDSTILL_LIMIT s
while nothing holds it (no red or yellow light and no vehicle within LIVENESS_REACH m ahead); a person at a green
light on a free road drives off. Every error of a drive is a :class:`DriveError` whose message starts with the
drive (condition, participant seed, style, traffic seed) and whose ``kind`` names the failure.

What the HUD displayed: a pEDAS drive whose advice the loop computes itself (no ``controller`` given) carries, after
the drive-log columns, the HUD channels :data:`HUD_LOG_COLUMNS` (:data:`pedas.hud_log.HUD_CHANNELS`): per sample
:func:`pedas.hud_log.channel_values` of the frame :func:`pedas.hud_frame.hud_frame` draws for the measured speed and
the advice, so that a stored drive replays exactly what was shown. A baseline drive shows no advice and carries none.

Time: the log's `t` counts from the ego's insertion; the controller and the signal programs use SUMO time.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from pedas.constants import DT
from pedas.drivers import DriverParams, HumanDriver, Perception, sample_driver
from pedas.hud_frame import hud_frame
from pedas.hud_log import HUD_CHANNELS, channel_values
from pedas.network import build_network
from pedas.params import CONTROLLER
from pedas.route_study import study_route
from pedas.scenario import get_scenario
from pedas.traffic import Traffic, load_demand
from pedas.vocabulary import CONDITIONS
from pedas.whatif import WhatIf

LOG_COLUMNS = ("t", "s", "v", "segment", "speed_limit", "a", "grade", "ft", "fb", "p_batt", "tl_id", "tl_state",
               "d_tl", "leader_gap", "leader_v", "v_advice", "controller", "hud_arrow", "hud_in_band", "warning")
#: the HUD channels a pEDAS drive carries after LOG_COLUMNS (what the HUD displayed, pedas.hud_log)
HUD_LOG_COLUMNS = tuple(name for name, _, _ in HUD_CHANNELS)
#: what the drive loop records per sample (the rest of LOG_COLUMNS follows from the route and the trace)
ROW_FIELDS = ("t", "s", "v", "a", "tl_id", "tl_state", "d_tl", "leader_gap", "leader_v", "v_advice", "controller",
              "hud_arrow", "hud_in_band", "warning")
_NO_ADVICE = (math.nan, "none", None, None, None)   # the ROW_FIELDS from v_advice on of a sample without advice
HALT_CHECK = 0.1  # m/s, standing still for the stop-sign invariant
STOP_CHECK_BAND = 10.0  # m, the halt must happen this close before the stop line
MAX_DURATION = 3600.0  # s of simulated driving after which a drive is declared stuck
STANDSTILL_LIMIT = 20.0  # s an unheld standstill may last (reaction + start-up take a few s; a dwell at most 4 s)
LIVENESS_REACH = 50.0  # m, a red/yellow light or a vehicle this close ahead holds the ego legitimately


class DriveError(RuntimeError):
    """A simulated drive failed. ``kind`` names the failure (for the robustness sweep's counts); the message
    starts with the drive it belongs to (condition, participant seed, style, traffic seed) and says t and s."""

    kind = "error"

    def __init__(self, message: str, kind: str | None = None) -> None:
        super().__init__(message)
        if kind is not None:
            self.kind = kind

    def __reduce__(self):  # keep the kind across process boundaries (pool workers pickle exceptions)
        return type(self), (str(self), self.kind)

    def named(self, prefix: str) -> "DriveError":
        """The same error with `prefix: ` before its message."""
        return type(self)(f"{prefix}: {self}", self.kind)


class SafetyViolation(DriveError):
    """A safety invariant failed during a drive; ``kind`` is collision|red_light|stop_sign|backwards."""

    kind = "safety"


class LivenessViolation(DriveError):
    """The ego stood still for more than STANDSTILL_LIMIT s although nothing held it: no red or yellow light and
    no vehicle within LIVENESS_REACH m ahead (a deadlock of driver and advice; a person would drive off)."""

    kind = "standstill"


class DriveTimeout(DriveError):
    """The drive did not reach the end of the route within its maximum duration."""

    kind = "timeout"


@dataclass
class DriveInfo:
    """Side information of one drive (kept in ``df.attrs['drive']``)."""

    participant_seed: int
    style: str
    condition: str
    traffic_seed: int
    scenario: str  # the traffic scenario (pedas.scenario)
    driver: dict
    t_insert: float  # SUMO time of the ego's insertion (s)
    duration_s: float  # simulated drive time (s)
    wall_s: float  # wall-clock time of the drive loop (s), excl. one-time setup (network, DP)
    steps: int
    max_vehicles: int
    controller_stats: dict | None


class SafetyGuard:
    """Checks the invariants between consecutive samples of one drive."""

    def __init__(self, route) -> None:
        self.route = route
        self._lights = tuple(route.lights)
        self._stops = tuple(route.stops)
        self._halted = [False] * len(self._stops)
        self._prev: tuple[float, float] | None = None  # (t, s) at the start of the last step

    def check(self, t: float, s: float, v: float, leader_gap: float | None, collided: bool) -> None:
        """Check the step that ended at (t, s, v)."""
        if collided or (leader_gap is not None and leader_gap <= 0.0):
            raise SafetyViolation(f"collision at t={t:.1f} s, s={s:.1f} m (gap {leader_gap})", "collision")
        if v <= HALT_CHECK:
            for i, ss in enumerate(self._stops):
                if -0.01 <= ss.s - s <= STOP_CHECK_BAND:
                    self._halted[i] = True
        if self._prev is not None:
            t0, s0 = self._prev
            if s < s0 - 1e-6:
                raise SafetyViolation(f"the ego vehicle moved backwards at t={t:.1f} s, s={s:.1f} m", "backwards")
            if s > s0:   # a line at x was crossed when s0 < x <= s: none while standing
                for tl in self._lights:
                    if s0 < tl.s <= s and tl.state_at(t0) == "red":
                        raise SafetyViolation(f"red light {tl.tl_id} crossed at t={t0:.1f}-{t:.1f} s "
                                              f"(s={tl.s:.1f} m)", "red_light")
                for i, ss in enumerate(self._stops):
                    if s0 < ss.s <= s and not self._halted[i]:
                        raise SafetyViolation(f"stop sign {ss.ss_id} passed without a full stop at t={t:.1f} s, "
                                              f"s={s:.1f} m", "stop_sign")
        self._prev = (t, s)


class LivenessGuard:
    """Raises :class:`LivenessViolation` when the ego stands still (v <= HALT_CHECK m/s) for more than `limit` s
    while nothing holds it: the next light is green or farther than LIVENESS_REACH m, and no vehicle is within
    LIVENESS_REACH m ahead. A stop sign does not stop the clock: its halt lasts a few seconds."""

    def __init__(self, limit: float = STANDSTILL_LIMIT) -> None:
        self.limit = limit
        self._since: float | None = None  # start of the current unheld standstill

    def check(self, t: float, s: float, v: float, leader_gap: float | None, tl_state: str | None,
              d_tl: float | None) -> None:
        held_by_light = tl_state in ("red", "yellow") and d_tl is not None and d_tl <= LIVENESS_REACH
        held_by_leader = leader_gap is not None and leader_gap <= LIVENESS_REACH
        if v > HALT_CHECK or held_by_light or held_by_leader:
            self._since = None
            return
        if self._since is None:
            self._since = t
        elif t - self._since > self.limit:
            ahead = f"light {tl_state} {d_tl:.0f} m ahead" if d_tl is not None else "no light ahead"
            raise LivenessViolation(f"standing still for {t - self._since:.1f} s at t={t:.1f} s, s={s:.1f} m with "
                                    f"nothing holding the car ({ahead}, no vehicle within {LIVENESS_REACH:.0f} m)")


def drive_name(participant_seed: int, style: str, condition: str, traffic_seed: int) -> str:
    """How messages name a drive: "pEDAS drive of participant seed 7 (sporty, traffic seed 7)"."""
    return (f"{'pEDAS' if condition == 'pedas' else condition} drive of participant seed {participant_seed} "
            f"({style}, traffic seed {traffic_seed})")


@lru_cache(maxsize=8)
def _setup(net_file: str, scenario: str, dp_time_weight: float):
    """Route and DP reference of a scenario's network (the DP's time weight x `dp_time_weight`), once per process
    (the DP takes ~1 s)."""
    from pedas.dp import W_TIME_DEFAULT, dp_reference

    route = study_route(net_file, scenario=scenario)
    return route, dp_reference(route, w_time=W_TIME_DEFAULT * dp_time_weight)


def study_route_and_reference(scenario: str | None = None):
    """(route, DP reference) of the study network in a traffic scenario (default
    :data:`pedas.scenario.DEFAULT_SCENARIO`), the network built when needed; cached per process."""
    sc = get_scenario(scenario)
    return _setup(str(build_network(scenario=sc)), sc.name, 1.0)


def drive(participant_seed: int, style: str, condition: str, *, traffic_seed: int | None = None,
          driver: DriverParams | None = None, net_file: str | Path | None = None,
          max_duration: float = MAX_DURATION, settings=None, controller=None,
          scenario: str | None = None, whatif: WhatIf | None = None,
          hud_channels: bool | None = None) -> pd.DataFrame:
    """Drive the study route once; the drive log (docs/contracts.md columns, every DT s) as a DataFrame.

    participant_seed: the virtual person (driver parameters, :func:`pedas.drivers.sample_driver`); style:
    cautious|normal|sporty; condition: baseline (own style) | pedas (tracking the HUD advisory). traffic_seed:
    the surrounding traffic (default: the participant seed, so both conditions of a person meet the same
    demand). settings: the controller's :class:`pedas.params.ControllerParams` (default
    :data:`pedas.params.CONTROLLER`). controller: the advice of the pedas condition from this object's
    ``step(t, s, v, leader)`` instead of a new PedasController (the live reference client,
    :class:`pedas.live_client.RemoteController`). scenario: the traffic scenario (:mod:`pedas.scenario`, default
    :data:`pedas.scenario.DEFAULT_SCENARIO`). whatif: unpublished settings moved away from the scenario's
    (:class:`pedas.whatif.WhatIf`: traffic volumes, lorry share, the person's compliance and speeding, the HUD
    band, the DP's time weight; default none). hud_channels: append :data:`HUD_LOG_COLUMNS` to a pEDAS drive's log
    (default: when the advice is computed here, i.e. no `controller` is given — a remote controller's advice does
    not carry the whole frame its server showed; that server logs it). Raises SafetyViolation when an invariant
    fails.
    ``df.attrs['drive']`` holds a :class:`DriveInfo` as dict (with the non-default what-if settings under
    ``whatif``).
    """
    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r} (expected baseline|pedas)")
    sc = get_scenario(scenario)
    net_file = str(net_file or build_network(scenario=sc))
    wi = whatif or WhatIf()
    route, v_dp = _setup(net_file, sc.name, wi.dp_time_weight)
    drv = wi.driver(driver or sample_driver(participant_seed, style))
    tseed = int(participant_seed if traffic_seed is None else traffic_seed)
    assisted = condition == "pedas"
    cs = wi.controller(settings or CONTROLLER)
    human = HumanDriver(route, drv, assisted=assisted, band=cs.hud_band)  # the band the HUD shows
    ctrl = controller if assisted else None
    if assisted and ctrl is None:
        from pedas.controller import PedasController

        ctrl = PedasController(route, v_dp=v_dp, settings=cs)
    guard = SafetyGuard(route)
    alive = LivenessGuard()
    lights = tuple(route.lights)
    rows: list[tuple] = []   # one ROW_FIELDS tuple per sample
    hud = [] if assisted and (controller is None if hud_channels is None else hud_channels) else None
    wall0 = time.perf_counter()
    try:
        demand = wi.demand(load_demand(scenario=sc))
        with Traffic(tseed, net_file, demand=demand, scenario=sc) as tr:
            steps, max_veh, t_ins = _loop(tr, lights, human, ctrl, guard, alive, rows, hud, max_duration)
    except DriveError as exc:
        raise exc.named(drive_name(participant_seed, style, condition, tseed)) from None
    except Exception as exc:  # any other failure still says which drive it was
        raise DriveError(f"{drive_name(participant_seed, style, condition, tseed)}: {type(exc).__name__}: "
                         f"{exc}") from exc
    wall = time.perf_counter() - wall0
    df = _log_frame(rows, hud, route)
    info = DriveInfo(int(participant_seed), style, condition, tseed, sc.name, drv.as_dict(), float(t_ins),
                     float(df["t"].iloc[-1]), wall, steps, max_veh, dict(ctrl.stats) if ctrl is not None else None)
    df.attrs["drive"] = info.__dict__
    if not wi.is_default():
        df.attrs["drive"]["whatif"] = dict(wi.items())
    return df


def _loop(tr: Traffic, lights, human: HumanDriver, ctrl, guard: SafetyGuard, alive: LivenessGuard, rows: list,
          hud: list | None, max_duration: float) -> tuple[int, int, float]:
    """Step the drive until the ego arrives; appends one ROW_FIELDS tuple per sample to `rows` (and the HUD channels
    of the frame shown to `hud` unless it is None); returns (steps, max vehicles, SUMO insertion time)."""
    steps = 0
    max_veh = 0
    t_ins = tr.insert_ego()
    tr.subscribe_ego()
    observe, advance, act = tr.observe, tr.advance, human.act
    n_lights = len(lights)
    tl_i = 0
    while True:
        t, s, v, lead, collided = observe()
        if lead is not None:
            gap, lead_v, lead_a = lead.gap, lead.v, lead.a
        else:
            gap = lead_v = None
            lead_a = 0.0
        guard.check(t, s, v, gap, collided)
        while tl_i < n_lights and lights[tl_i].s < s:
            tl_i += 1
        if tl_i < n_lights:
            tl = lights[tl_i]
            tl_id, d_tl = tl.tl_id, tl.s - s
            tl_state, tl_left = tl.state_remaining(t)
        else:
            tl_id = tl_state = d_tl = tl_left = None
        alive.check(t - t_ins, s, v, gap, tl_state, d_tl)
        if ctrl is not None:
            adv = ctrl.step(t, s, v, (gap, lead_v) if lead is not None else None)
            advice = (adv.v_advice, adv.controller, adv.hud_arrow, adv.hud_in_band, adv.warning)
            obs = Perception(t, gap, lead_v, tl_state, tl_left, adv.v_advice, bool(adv.warning), s=s, leader_a=lead_a)
        else:
            adv, advice = None, _NO_ADVICE
            obs = Perception(t, gap, lead_v, tl_state, tl_left, None, False, s=s, leader_a=lead_a)
        a = act(t, s, v, obs)
        v_next = max(v + a * DT, 0.0)
        a = (v_next - v) / DT
        rows.append((t - t_ins, s, v, a, tl_id, tl_state, math.nan if d_tl is None else d_tl,
                     math.nan if gap is None else gap, math.nan if lead_v is None else lead_v, *advice))
        if hud is not None:   # the frame the driver saw: measured speed and this step's advice
            hud.append(channel_values(hud_frame(v, adv, None if lead is None else (gap, lead_v))))
        steps += 1
        if steps % 50 == 0:
            max_veh = max(max_veh, tr.vehicle_count())
        if t - t_ins > max_duration:
            raise DriveTimeout(f"did not finish within {max_duration:.0f} s (at t={t - t_ins:.1f} s, "
                               f"s={s:.1f} m)")
        if advance(v_next):
            return steps, max_veh, t_ins


def _log_frame(rows: list, hud: list | None, route) -> pd.DataFrame:
    """Assemble the drive log from the loop's ROW_FIELDS tuples (and HUD channels): route columns by position,
    forces and battery power from the trace."""
    from pedas.power import fill_drive_columns

    cols = {name: list(col) for name, col in zip(ROW_FIELDS, zip(*rows))}
    s = np.asarray(cols["s"], float)
    idx = np.clip(np.searchsorted(route.s, s, side="right") - 1, 0, route.s.size - 1)
    df = pd.DataFrame({
        "t": np.round(np.asarray(cols["t"], float), 6),
        "s": s,
        "v": np.asarray(cols["v"], float),
        "segment": pd.array(route.segment[idx].astype(str), dtype="string"),
        "speed_limit": route.speed_limit[idx],
        "a": np.asarray(cols["a"], float),
        "grade": route.grade[idx],
    })
    df = fill_drive_columns(df)
    df["tl_id"] = pd.array(cols["tl_id"], dtype="string")
    df["tl_state"] = pd.array(cols["tl_state"], dtype="string")
    df["d_tl"] = np.asarray(cols["d_tl"], float)
    df["leader_gap"] = np.asarray(cols["leader_gap"], float)
    df["leader_v"] = np.asarray(cols["leader_v"], float)
    df["v_advice"] = np.asarray(cols["v_advice"], float)
    df["controller"] = pd.array(cols["controller"], dtype="string")
    df["hud_arrow"] = pd.array(cols["hud_arrow"], dtype="Int8")
    df["hud_in_band"] = pd.array(cols["hud_in_band"], dtype="boolean")
    df["warning"] = pd.array(cols["warning"], dtype="boolean")
    df = df[list(LOG_COLUMNS)]
    if hud is not None:
        df = pd.concat([df, pd.DataFrame.from_records(hud, columns=list(HUD_LOG_COLUMNS)).astype("float64")], axis=1)
    return df


def green_crossings(df: pd.DataFrame, stop_zone: float = 100.0) -> pd.DataFrame:
    """Per traffic light passed in a drive log: tidy frame tl_id, state_at_crossing, stopped, green_pass.

    The crossing is the last sample with this light ahead; `stopped` = the vehicle stood (v < 0.1 m/s) within
    `stop_zone` m before its stop line; `green_pass` = crossed in green without having stopped for it (a stop
    at red followed by a start in green is not a green crossing).
    """
    rows = []
    ids = df["tl_id"].astype(object).where(df["tl_id"].notna(), None).to_numpy()
    states = df["tl_state"].astype(object).to_numpy()
    v = df["v"].to_numpy(float)
    d = df["d_tl"].to_numpy(float)
    change = np.flatnonzero(ids[:-1] != ids[1:])
    for i in change:
        if ids[i] is None:
            continue
        sel = (ids == ids[i]) & (d <= stop_zone)
        stopped = bool(np.any(v[sel] < 0.1))
        rows.append((ids[i], states[i], stopped, states[i] == "green" and not stopped))
    return pd.DataFrame(rows, columns=["tl_id", "state_at_crossing", "stopped", "green_pass"])

"""The drive loop: one virtual participant drives the study route once, in SUMO traffic, with or without pEDAS.

:func:`drive` returns the drive log in the DESIGN.md columns, one row every DT = 0.2 s from the ego's insertion
to its arrival at the end of the route. Every step checks the safety invariants and raises
:class:`SafetyViolation` when one fails — SUMO's own safety checks are switched off for the ego vehicle
(:mod:`pedas.traffic`), so a bug in the driver model or the controller cannot be hidden by the simulator:

* no collision: the bumper-to-bumper gap to the leader stays > 0 and SUMO reports no collision of the ego;
* no red-light crossing: the stop line of a light is never crossed during a step that starts at red (the signal
  state in force during SUMO's step from t to t + DT is the route program's state at t, checked in the tests);
* no stop-sign roll-through: before crossing a stop sign's line the ego has stood still (v <= HALT_CHECK m/s)
  within STOP_CHECK_BAND m before it.

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
from pedas.network import build_network
from pedas.route_study import study_route
from pedas.traffic import Traffic

CONDITIONS = ("baseline", "pedas")
LOG_COLUMNS = ("t", "s", "v", "segment", "speed_limit", "a", "grade", "ft", "fb", "p_batt", "tl_id", "tl_state",
               "d_tl", "leader_gap", "leader_v", "v_advice", "controller", "hud_arrow", "hud_in_band", "warning")
HALT_CHECK = 0.1  # m/s, standing still for the stop-sign invariant
STOP_CHECK_BAND = 10.0  # m, the halt must happen this close before the stop line
MAX_DURATION = 3600.0  # s of simulated driving after which a drive is declared stuck


class SafetyViolation(RuntimeError):
    """A safety invariant failed during a drive (collision, red-light crossing, stop-sign roll-through)."""


@dataclass
class DriveInfo:
    """Side information of one drive (kept in ``df.attrs['drive']``)."""

    participant_seed: int
    style: str
    condition: str
    traffic_seed: int
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
            raise SafetyViolation(f"collision at t={t:.1f} s, s={s:.1f} m (gap {leader_gap})")
        for i, ss in enumerate(self._stops):
            d = ss.s - s
            if v <= HALT_CHECK and -0.01 <= d <= STOP_CHECK_BAND:
                self._halted[i] = True
        if self._prev is not None:
            t0, s0 = self._prev
            if s < s0 - 1e-6:
                raise SafetyViolation(f"the ego vehicle moved backwards at t={t:.1f} s")
            for tl in self._lights:
                if s0 < tl.s <= s and tl.state_at(t0) == "red":
                    raise SafetyViolation(f"red light {tl.tl_id} crossed at t={t0:.1f}-{t:.1f} s (s={tl.s:.1f} m)")
            for i, ss in enumerate(self._stops):
                if s0 < ss.s <= s and not self._halted[i]:
                    raise SafetyViolation(f"stop sign {ss.ss_id} passed without a full stop at t={t:.1f} s")
        self._prev = (t, s)


@lru_cache(maxsize=2)
def _setup(net_file: str):
    """Route and DP reference of a network, once per process (the DP takes ~1 s)."""
    from pedas.dp import dp_reference

    route = study_route(net_file)
    return route, dp_reference(route)


def drive(participant_seed: int, style: str, condition: str, *, traffic_seed: int | None = None,
          driver: DriverParams | None = None, net_file: str | Path | None = None,
          max_duration: float = MAX_DURATION) -> pd.DataFrame:
    """Drive the study route once; the drive log (DESIGN.md columns, every DT s) as a DataFrame.

    participant_seed: the virtual person (driver parameters, :func:`pedas.drivers.sample_driver`); style:
    cautious|normal|sporty; condition: baseline (own style) | pedas (tracking the HUD advisory). traffic_seed:
    the surrounding traffic (default: the participant seed, so both conditions of a person meet the same
    demand). Raises SafetyViolation when an invariant fails. ``df.attrs['drive']`` holds a :class:`DriveInfo`
    as dict.
    """
    if condition not in CONDITIONS:
        raise ValueError(f"unknown condition {condition!r} (expected baseline|pedas)")
    net_file = str(net_file or build_network())
    route, v_dp = _setup(net_file)
    drv = driver or sample_driver(participant_seed, style)
    tseed = int(participant_seed if traffic_seed is None else traffic_seed)
    assisted = condition == "pedas"
    human = HumanDriver(route, drv, assisted=assisted)
    ctrl = None
    if assisted:
        from pedas.controller import PedasController

        ctrl = PedasController(route, v_dp=v_dp)
    guard = SafetyGuard(route)
    lights = tuple(route.lights)
    cols: dict[str, list] = {c: [] for c in ("t", "s", "v", "a", "tl_id", "tl_state", "d_tl", "leader_gap",
                                             "leader_v", "v_advice", "controller", "hud_arrow", "hud_in_band",
                                             "warning")}
    wall0 = time.perf_counter()
    steps = 0
    max_veh = 0
    with Traffic(tseed, net_file) as tr:
        t_ins = tr.insert_ego()
        tl_i = 0
        while True:
            t = tr.time
            s, v = tr.ego_state()
            lead = tr.leader()
            gap = lead.gap if lead is not None else None
            try:
                guard.check(t, s, v, gap, tr.ego_collided())
            except SafetyViolation as exc:
                raise SafetyViolation(f"{condition} drive of participant seed {participant_seed} ({style}): "
                                      f"{exc}") from None
            while tl_i < len(lights) and lights[tl_i].s < s:
                tl_i += 1
            tl = lights[tl_i] if tl_i < len(lights) else None
            tl_state = tl.state_at(t) if tl is not None else None
            adv = None
            if ctrl is not None:
                adv = ctrl.step(t, s, v, (lead.gap, lead.v) if lead is not None else None)
            obs = Perception(t, gap, lead.v if lead is not None else None, tl_state,
                             tl.remaining(t) if tl is not None else None,
                             adv.v_advice if adv is not None else None, bool(adv.warning) if adv is not None else False,
                             s=s, leader_a=lead.a if lead is not None else 0.0)
            a = human.act(t, s, v, obs)
            v_next = max(v + a * DT, 0.0)
            a = (v_next - v) / DT
            cols["t"].append(t - t_ins)
            cols["s"].append(s)
            cols["v"].append(v)
            cols["a"].append(a)
            cols["tl_id"].append(tl.tl_id if tl is not None else None)
            cols["tl_state"].append(tl_state)
            cols["d_tl"].append(tl.s - s if tl is not None else math.nan)
            cols["leader_gap"].append(gap if gap is not None else math.nan)
            cols["leader_v"].append(lead.v if lead is not None else math.nan)
            cols["v_advice"].append(adv.v_advice if adv is not None else math.nan)
            cols["controller"].append(adv.controller if adv is not None else "none")
            cols["hud_arrow"].append(adv.hud_arrow if adv is not None else None)
            cols["hud_in_band"].append(adv.hud_in_band if adv is not None else None)
            cols["warning"].append(adv.warning if adv is not None else None)
            steps += 1
            if steps % 50 == 0:
                max_veh = max(max_veh, tr.vehicle_count())
            if t - t_ins > max_duration:
                raise RuntimeError(f"drive did not finish within {max_duration} s (stuck at s={s:.0f} m)")
            tr.set_ego_speed(v_next)
            tr.step()
            if tr.ego_arrived():
                break
    wall = time.perf_counter() - wall0
    df = _log_frame(cols, route)
    info = DriveInfo(int(participant_seed), style, condition, tseed, drv.as_dict(), float(t_ins),
                     float(df["t"].iloc[-1]), wall, steps, max_veh, dict(ctrl.stats) if ctrl is not None else None)
    df.attrs["drive"] = info.__dict__
    return df


def _log_frame(cols: dict, route) -> pd.DataFrame:
    """Assemble the drive log: route columns by position, forces and battery power from the trace."""
    from pedas.power import fill_drive_columns

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
    return df[list(LOG_COLUMNS)]


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

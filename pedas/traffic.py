"""Surrounding traffic of the study route in SUMO, through libsumo; the ego vehicle is driven from Python.

One :class:`Traffic` is one SUMO simulation. libsumo holds a single simulation per process, so drives run one at a
time per process (the cohort runs them in worker processes). Traffic other than the ego vehicle uses SUMO's own
Krauss car-following model; its demand comes from ``data/network/demand.json`` and is drawn from the seed:
departure times of every flow (Poisson arrivals with a minimum headway) by numpy, the vehicles' speed factors and
driver imperfection by SUMO's RNG seeded with the same seed. Same seed -> same traffic.

The ego vehicle follows the speed set every step with ``vehicle.setSpeed``; speed mode 32 switches off all of
SUMO's own checks (safe speed, acceleration bounds, right of way, red lights) so that SUMO never silently
corrects the driver model: safety is checked by the drive loop, not hidden by the simulator. The drive loop reads
what it needs each step (time, the ego's odometer, speed and leader, collisions, arrivals) from libsumo
subscriptions (:meth:`Traffic.subscribe_ego`, :meth:`Traffic.observe`, :meth:`Traffic.advance`): the getters'
values, with two calls a step instead of six.

The network, routes, vehicle types and demand are those of a traffic scenario (:mod:`pedas.scenario`). In the
motorway scenario the ego enters the motorway on an acceleration lane and leaves it by SUMO's strategic lane change
(lane-change mode EGO_LANE_MERGE); it changes lanes for nothing else.

Every PRUNE_EVERY steps the simulation drops the vehicles the ego can no longer meet: those behind it on its route
and those that would join the route where the ego has already passed, as long as their route has one lane from
there on: nobody overtakes on one lane, so they could only ever follow the ego (a vehicle that reaches a part with
two lanes stays: it may overtake the ego there). Leaving them out saves SUMO's time (~10 % of a pEDAS drive's wall time
with the demand running until 1400 s). SUMO draws its random numbers (the drivers' dawdling) per lane, so the
others on a lane see different draws once a vehicle is gone: a pruned drive is another realisation of the same
seeded traffic, still the same for the same seed, not the unpruned run with fewer vehicles.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import pandas as pd

from pedas.constants import DT
from pedas.network import build_network
from pedas.records import fast_init
from pedas.scenario import get_scenario

EGO_ID = "ego"
EGO_ROUTE = "ego"
EGO_TYPE = "ego"
EGO_SPEED_MODE = 32  # all checks off: speed exactly as commanded (TraCI speed-mode bits 0-5)
# lane-change modes of the ego (TraCI bits 0-1 strategic, 2-3 cooperative, 4-5 speed gain, 6-7 keep right):
EGO_LANE_KEEP = 0  # no lane change at all (the single-lane scenario)
EGO_LANE_MERGE = 1  # strategic changes only: leaving an acceleration lane, never overtaking or keeping right
LEADER_LOOKAHEAD = 250.0  # m, how far getLeader searches along the ego's route
PRUNE_EVERY = 25  # steps (5 s) between removals of the vehicles the ego can no longer meet
_ACTIVE: "Traffic | None" = None  # the process's running simulation (libsumo allows one)


def load_demand(path: Path | None = None, scenario=None) -> dict:
    """The demand definition (the scenario's ``demand.json``): ego_depart (s), min_headway (s) and the flows."""
    return json.loads(Path(path or get_scenario(scenario).demand).read_text())


DEPARTURE_FIELDS = ("veh_id", "route", "type", "depart", "depart_speed", "depart_lane")


def departures(seed: int, demand: dict | None = None) -> pd.DataFrame:
    """Seeded departures of the surrounding traffic: tidy frame veh_id, route, type, depart (s), depart_speed,
    depart_lane (SUMO's departLane, the flow's `depart_lane`, default "first"); the rows of
    :func:`departure_rows`.

    Per flow, headways are min_headway + Exp(mean 3600/rate - min_headway) so that the mean rate is `rate` veh/h
    and no two vehicles of a flow depart closer than min_headway; a flow with `period` (s) runs to a timetable
    with that headway and a seeded phase.
    """
    return pd.DataFrame(departure_rows(seed, demand), columns=list(DEPARTURE_FIELDS))


def departure_rows(seed: int, demand: dict | None = None) -> list[tuple]:
    """The departures of :func:`departures` as DEPARTURE_FIELDS tuples, ordered by departure time, then vehicle id
    (what :meth:`Traffic.start` adds to SUMO, without building a frame)."""
    demand = demand or load_demand()
    rng = np.random.default_rng([int(seed), 0x7AFF1C])
    h_min = float(demand.get("min_headway", 2.0))
    rows = []
    for k, f in enumerate(demand["flows"]):
        period = f.get("period")  # a timetable (buses): fixed headway, seeded phase
        mean = float(period) if period else 3600.0 / float(f["rate"])
        t = float(f["start"]) + rng.uniform(0.0, mean)
        times = []
        while t <= float(f["end"]):
            times.append(t)
            t += mean if period else h_min + rng.exponential(max(mean - h_min, 0.1))
        types = _vehicle_types(f, len(times), np.random.default_rng([int(seed), 0x7AFF1C, k]))
        for i, (t, vtype) in enumerate(zip(times, types)):
            rows.append((f"f{k}.{i}", f["route"], vtype, round(t, 1), str(f.get("depart_speed", "max")),
                         str(f.get("depart_lane", "first"))))
    rows.sort(key=lambda r: (r[3], r[0]))   # (depart, veh_id): unique, so any sort gives this order
    return rows


def _vehicle_types(flow: dict, n: int, rng: np.random.Generator) -> list[str]:
    """Vehicle types of the `n` departures of one flow: its `type` (default 'car'), or its `mix` {type: share}.

    A mix is applied by systematic sampling with a seeded random start (every 1/share-th vehicle on average, the
    classes interleaved in a seeded random order): each drive meets the mix's shares up to one vehicle, instead of
    a binomial draw that leaves some drives without any heavy vehicle. The rest of the flow is 'car'.
    """
    mix = flow.get("mix")
    if not mix:
        return [flow.get("type", "car")] * n
    types = ["car"] * n
    taken = np.zeros(n, bool)
    for vtype, share in mix.items():
        share = float(share)
        if vtype == "car" or share <= 0.0:
            continue
        pos = (rng.uniform(0.0, 1.0) + np.arange(int(np.ceil(n * share)) + 1)) / share
        for p in pos.astype(int):
            while p < n and taken[p]:  # two classes on the same vehicle: the next free one
                p += 1
            if p < n:
                types[p], taken[p] = vtype, True
    return types


def route_edges(path: Path | None = None, scenario=None) -> dict[str, list[str]]:
    """{route id: edge ids} of the routes file (default: the scenario's)."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path or get_scenario(scenario).routes).getroot()
    return {r.get("id"): r.get("edges").split() for r in root.iter("route")}


def join_index(routes: dict[str, list[str]], ego_route: str = EGO_ROUTE) -> dict[str, int]:
    """{route id: index in the ego's route of the first ego-route edge it uses}; routes that never use an edge of
    the ego's route (cross traffic) are left out."""
    position = {e: i for i, e in enumerate(routes[ego_route])}
    return {rid: next(position[e] for e in edges if e in position)
            for rid, edges in routes.items() if any(e in position for e in edges)}


def leave_index(routes: dict[str, list[str]], ego_route: str = EGO_ROUTE) -> dict[str, int]:
    """{route id: index in the ego's route of the last ego-route edge it uses} (routes of :func:`join_index`)."""
    position = {e: i for i, e in enumerate(routes[ego_route])}
    return {rid: max(position[e] for e in edges if e in position)
            for rid, edges in routes.items() if any(e in position for e in edges)}


@fast_init
@dataclass(frozen=True)
class Leader:
    """The vehicle ahead of the ego on its route: id, bumper-to-bumper gap (m), speed (m/s), acceleration
    (m/s^2; what a driver reads from brake lights and closing speed)."""

    veh_id: str
    gap: float
    v: float
    a: float = 0.0


class _Subscription(NamedTuple):
    """The subscription result getters of :meth:`Traffic.subscribe_ego` and the TraCI variable ids they key by."""

    ego: Callable[[str], dict]
    sim: Callable[[], dict]
    lookahead: float
    distance: int
    speed: int
    leader: int
    time: int
    arrived: int
    colliding: int


class Traffic:
    """A libsumo simulation of the study network with seeded traffic and the ego vehicle.

    Use as a context manager: ``with Traffic(seed) as tr: tr.insert_ego(); while ...: tr.set_ego_speed(v);
    tr.step()``. Times are SUMO simulation times (s).
    """

    def __init__(self, seed: int, net_file: Path | None = None, demand: dict | None = None,
                 step_length: float = DT, scenario=None) -> None:
        self.seed = int(seed)
        self.scenario = get_scenario(scenario)
        self.net_file = Path(net_file or build_network(scenario=self.scenario))
        self.demand = demand or load_demand(scenario=self.scenario)
        self.step_length = float(step_length)
        self.ego_depart = float(self.demand["ego_depart"])
        self.ego_min_gap = 0.0
        self._s_offset = 0.0
        self._ls = None
        self._steps = 0
        self._ego_in = False
        self._removed = False  # the last step's prune removed vehicles (the subscribed leader predates it)
        self._sub = None       # subscription result getters and variable ids (subscribe_ego)
        self._sim = None       # the simulation's subscription results read by advance() after the last step
        routes = route_edges(self.scenario.routes)
        self._ego_edges = {e: i for i, e in enumerate(routes[EGO_ROUTE])}
        self._route_join = join_index(routes)
        self._route_leave = leave_index(routes)
        self._join: dict[str, int] = {}  # veh_id -> ego-route index where it joins (only vehicles that do)
        # first ego-route index with more than one lane (set at start): there, vehicles from behind can overtake
        # the ego and come ahead of it, so a vehicle that reaches it is never pruned
        self._overtaking_from = len(routes[EGO_ROUTE])

    # --- life cycle -------------------------------------------------------------------------------------------
    def sumo_args(self) -> list[str]:
        """Command line of the SUMO run (no GUI, ballistic position update as eq. (3b), no teleports)."""
        return ["sumo", "-n", str(self.net_file), "-r", str(self.scenario.routes), "-a", str(self.scenario.vtypes),
                "--step-length", f"{self.step_length}", "--seed", str(self.seed % 2**31),
                "--step-method.ballistic", "true", "--time-to-teleport", "-1", "--no-step-log", "true",
                "--no-warnings", "true", "--xml-validation", "never", "--collision.action", "warn",
                "--collision.check-junctions", "false", "--collision.mingap-factor", "0", "--begin", "0"]

    def start(self) -> "Traffic":
        """Start SUMO and add the seeded traffic (departures in the future are queued by SUMO)."""
        global _ACTIVE
        import libsumo

        if _ACTIVE is not None:
            raise RuntimeError("a SUMO simulation is already running in this process (libsumo allows one)")
        libsumo.start(self.sumo_args())
        _ACTIVE = self
        self._ls = libsumo
        multi = [i for e, i in self._ego_edges.items() if libsumo.edge.getLaneNumber(e) > 1]
        self._overtaking_from = min(multi, default=len(self._ego_edges))
        for veh_id, route, vtype, depart, depart_speed, depart_lane in departure_rows(self.seed, self.demand):
            if route in self._route_join and self._route_leave[route] < self._overtaking_from:
                self._join[veh_id] = self._route_join[route]
            libsumo.vehicle.add(veh_id, route, typeID=vtype, depart=f"{depart:.1f}", departLane=depart_lane,
                                departPos="base", departSpeed=depart_speed)
        libsumo.vehicle.add(EGO_ID, EGO_ROUTE, typeID=EGO_TYPE, depart=f"{self.ego_depart:.1f}", departLane="first",
                            departPos="0", departSpeed="0")
        self.ego_min_gap = float(libsumo.vehicletype.getMinGap(EGO_TYPE))
        return self

    def close(self) -> None:
        """End the simulation (idempotent)."""
        global _ACTIVE
        if self._ls is not None:
            try:
                self._ls.close()
            finally:
                self._ls = None
                _ACTIVE = None

    def __enter__(self) -> "Traffic":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    # --- stepping ---------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Current simulation time in s."""
        return float(self._ls.simulation.getTime())

    def step(self) -> None:
        """Advance one step of `step_length` s (every PRUNE_EVERY steps with the ego in the network: :meth:`prune`)."""
        self._ls.simulationStep()
        self._steps += 1
        self._removed = False
        self._sim = None
        if self._steps % PRUNE_EVERY == 0 and self._ego_in:
            self.prune()

    def prune(self) -> int:
        """Remove the vehicles the ego can no longer meet; their number.

        A vehicle goes when it is on the ego's route behind the ego (an earlier edge, or the same edge further
        back), or is waiting to depart, or still on its way to the route, and joins it at an edge the ego has
        reached. Internal junction lanes are left for the next call. Cross traffic that never uses the ego's route
        stays: it shares the junctions with vehicles that may still come ahead of the ego. So does every vehicle
        whose route reaches a part of the ego's route with more than one lane (the motorway scenario): there it
        may overtake the ego and come ahead of it.
        """
        ls = self._ls
        v = ls.vehicle
        running = set(v.getIDList())
        if EGO_ID not in running:
            return 0
        # on a junction's internal lane the route index is the edge just left and the position is on the internal
        # lane: the comparison below then keeps the vehicles on that edge until the next call
        ego_idx, ego_pos = int(v.getRouteIndex(EGO_ID)), float(v.getLanePosition(EGO_ID))
        gone = []
        for vid in v.getLoadedIDList():
            j = self._join.get(vid)
            if j is None or vid == EGO_ID:
                continue
            if vid not in running:
                behind = j <= ego_idx
            else:
                edge = v.getRoadID(vid)
                if edge.startswith(":"):
                    continue
                k = self._ego_edges.get(edge)
                if k is None:  # before joining (side street, ramp) or already turned off the route
                    behind = j <= ego_idx
                else:
                    behind = k < ego_idx or (k == ego_idx and float(v.getLanePosition(vid)) < ego_pos)
            if behind:
                gone.append(vid)
        for vid in gone:
            v.remove(vid)
            del self._join[vid]
        self._removed = self._removed or bool(gone)
        return len(gone)

    def insert_ego(self, max_wait: float = 120.0) -> float:
        """Step until the ego vehicle is in the network (it departs at `ego_depart`, later if its start is
        blocked); switch off SUMO's speed checks and lane changes for it. Returns the insertion time (s)."""
        ls = self._ls
        t_end = self.ego_depart + max_wait
        while EGO_ID not in ls.vehicle.getIDList():
            if self.time > t_end:
                raise RuntimeError(f"ego vehicle could not be inserted before t={t_end} s")
            self.step()
        ls.vehicle.setSpeedMode(EGO_ID, EGO_SPEED_MODE)
        # no overtaking (Sec. 4.3): no lane change at all, or (motorway) only the merge off an acceleration lane
        ls.vehicle.setLaneChangeMode(EGO_ID, EGO_LANE_MERGE if self.scenario.ego_merges else EGO_LANE_KEEP)
        # SUMO places the front bumper one vehicle length into the first lane; the route position s counts
        # from the lane start, the odometer from the insertion point
        self._s_offset = float(ls.vehicle.getLanePosition(EGO_ID)) - float(ls.vehicle.getDistance(EGO_ID))
        self._ego_in = True
        return self.time

    # --- ego state --------------------------------------------------------------------------------------------
    def ego_arrived(self) -> bool:
        """True once the ego vehicle has reached the end of its route and left the simulation."""
        return EGO_ID in self._ls.simulation.getArrivedIDList()

    def ego_state(self) -> tuple[float, float]:
        """(s, v): position of the front bumper along the route (m, = odometer + insertion position) and speed
        (m/s)."""
        ls = self._ls
        return float(ls.vehicle.getDistance(EGO_ID)) + self._s_offset, float(ls.vehicle.getSpeed(EGO_ID))

    def leader(self, lookahead: float = LEADER_LOOKAHEAD) -> Leader | None:
        """The vehicle ahead on the ego's route within `lookahead` m (``vehicle.getLeader``), else None.

        getLeader reports the gap minus the ego's minGap; it is added back to give the bumper-to-bumper gap, and a
        vehicle whose bumper-to-bumper gap is beyond `lookahead` (getLeader searches a little further) is None.
        """
        return self._leader(self._ls.vehicle.getLeader(EGO_ID, lookahead), lookahead)

    def _leader(self, res, lookahead: float) -> Leader | None:
        """The Leader of a getLeader result (vehicle id, gap less the ego's minGap; an empty id or None: none)."""
        if not res or not res[0]:
            return None
        vid, gap = res[0], float(res[1]) + self.ego_min_gap
        if gap > lookahead:
            return None
        v = self._ls.vehicle
        return Leader(vid, gap, float(v.getSpeed(vid)), float(v.getAcceleration(vid)))

    def set_ego_speed(self, v: float) -> None:
        """Command the ego's speed (m/s) for the next step."""
        self._ls.vehicle.setSpeed(EGO_ID, max(float(v), 0.0))

    def ego_collided(self) -> bool:
        """True if SUMO detected a collision involving the ego vehicle in the last step."""
        return EGO_ID in self._ls.simulation.getCollidingVehiclesIDList()

    def vehicle_count(self) -> int:
        """Vehicles currently in the network (incl. the ego)."""
        return int(self._ls.vehicle.getIDCount())

    # --- the drive loop's per-step exchange (subscriptions) ------------------------------------------------------
    def subscribe_ego(self, lookahead: float = LEADER_LOOKAHEAD) -> None:
        """Have SUMO collect, after every step, the ego's odometer, speed and leader within `lookahead` m and the
        simulation's time, arrivals and collisions (libsumo subscriptions): :meth:`observe` and :meth:`advance` then
        read them with one call each instead of one getter call per value. Call after :meth:`insert_ego`."""
        from libsumo import constants as tc

        ls = self._ls
        ls.vehicle.subscribe(EGO_ID, [tc.VAR_DISTANCE, tc.VAR_SPEED, tc.VAR_LEADER],
                             parameters={tc.VAR_LEADER: float(lookahead)})
        ls.simulation.subscribe([tc.VAR_TIME, tc.VAR_ARRIVED_VEHICLES_IDS, tc.VAR_COLLIDING_VEHICLES_IDS])
        self._sub = _Subscription(ls.vehicle.getSubscriptionResults, ls.simulation.getSubscriptionResults,
                                  float(lookahead), tc.VAR_DISTANCE, tc.VAR_SPEED, tc.VAR_LEADER, tc.VAR_TIME,
                                  tc.VAR_ARRIVED_VEHICLES_IDS, tc.VAR_COLLIDING_VEHICLES_IDS)
        self._sim = None

    def observe(self) -> tuple[float, float, float, Leader | None, bool]:
        """(t s, s m, v m/s, leader, collided) now: the values of :attr:`time`, :meth:`ego_state`, :meth:`leader`
        and :meth:`ego_collided`, read from the subscriptions of :meth:`subscribe_ego`. SUMO collects them at the
        end of its step, before :meth:`prune`; after a step whose prune removed vehicles the leader is asked again
        (removing other vehicles changes neither the ego's own values nor the simulation's lists)."""
        sub = self._sub
        ego, sim = sub.ego(EGO_ID), sub.sim() if self._sim is None else self._sim
        res = self._ls.vehicle.getLeader(EGO_ID, sub.lookahead) if self._removed else ego[sub.leader]
        return (float(sim[sub.time]), float(ego[sub.distance]) + self._s_offset, float(ego[sub.speed]),
                self._leader(res, sub.lookahead), EGO_ID in sim[sub.colliding])

    def advance(self, v: float) -> bool:
        """Command the ego's speed v (m/s), step, and whether the ego has arrived: :meth:`set_ego_speed`,
        :meth:`step` and :meth:`ego_arrived` in one call (the arrivals from the subscription of
        :meth:`subscribe_ego`)."""
        self._ls.vehicle.setSpeed(EGO_ID, max(float(v), 0.0))
        self.step()
        self._sim = self._sub.sim()   # what the next observe() reads as well: nothing steps in between
        return EGO_ID in self._sim[self._sub.arrived]

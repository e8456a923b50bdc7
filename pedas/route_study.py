"""The study route as a distance-indexed :class:`pedas.route.Route`, read from the built SUMO network.

The same `.net.xml` that SUMO simulates is the source of the pEDAS route description, so distances agree
exactly with the ego vehicle's odometer in SUMO (`vehicle.getDistance`):

* the ego path is the lane sequence of the scenario's ego route (:func:`ego_edges`; :data:`EGO_EDGES` in the
  single-lane scenario) joined by the internal junction lanes (the `via` chain of each connection, on the lanes
  :func:`ego_connections` follows); `s` is the cumulative SUMO lane length along it;
* curvature (1/m, signed, left positive) from the lane shapes, grade (rad) from the shapes' z (node elevations);
* speed limits from the lanes (junction lanes keep the limit of the approach; the turn speed follows from
  the curvature); v_min = 80 km/h on the highway main carriageway (Sec. 4.3), 0 elsewhere;
* traffic lights from the `tlLogic` programs: the state of the ego's link, stop line = end of the approach lane;
* stop signs at the `priority_stop` junctions the ego approaches on the minor road.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from pedas.constants import HIGHWAY_MIN_SPEED
from pedas.route import Route, StopSign, TrafficLight
from pedas.route_toml import Light, Stop, dump_route

URBAN_EDGES = ("u01", "u02", "u03", "u04", "u05", "u06", "u07", "u08", "u09", "u10", "u11")
HIGHWAY_EDGES = ("r01", "h01", "h02", "h03", "h04", "h05")  # r01 is the on-ramp from town onto the highway
EGO_EDGES = URBAN_EDGES + HIGHWAY_EDGES  # the single-lane scenario's; a scenario's own: ego_edges()
V_MIN_FROM_EDGE = "h01"  # the 80 km/h minimum applies on the main carriageway, not on the on-ramp ...
V_MIN_RAMP_UP = 250.0  # m ... and from this far into it (the acceleration lane after the ramp's curve)
DS = 1.0  # m, grid of the route description
JOIN_TOLERANCE = 0.5  # m, consecutive lane shapes further apart than this are a lane change, not a bend
# m, moving-average windows over the heading derivative: the lane shapes are polylines whose (0.01 m rounded)
# vertices put the curvature into spikes; town turns are short (~15 m arcs), highway curves hundreds of metres
CURVATURE_WINDOW = 9.0
CURVATURE_WINDOW_HIGHWAY = 51.0

# SUMO signal characters -> the route's three states ('s' stop sign, 'o' off and 'u' red-yellow never occur here)
_SUMO_STATE = {"G": "green", "g": "green", "y": "yellow", "Y": "yellow", "u": "red", "r": "red", "R": "red"}


@dataclass(frozen=True)
class PathLane:
    """One lane of the ego path: SUMO lane id, start offset along the route (m), length (m), legal limit (m/s)."""

    lane_id: str
    s0: float
    length: float
    speed: float
    edge: str  # the route edge this lane belongs to or follows (junction lanes: the approach edge)
    internal: bool


def _shape(text: str) -> np.ndarray:
    pts = [tuple(float(c) for c in p.split(",")) for p in text.split()]
    return np.array([p if len(p) == 3 else (*p, 0.0) for p in pts], dtype=float)


@lru_cache(maxsize=4)
def _parse(net_file: str) -> dict:
    root = ET.parse(net_file).getroot()
    lanes = {}
    for e in root.iter("edge"):
        for ln in e.iter("lane"):
            lanes[ln.get("id")] = dict(length=float(ln.get("length")), speed=float(ln.get("speed")),
                                       shape=_shape(ln.get("shape")), edge=e.get("id"),
                                       internal=e.get("function") == "internal")
    conns = {}
    for c in root.iter("connection"):
        conns.setdefault((c.get("from"), c.get("to")), []).append(c.attrib)
    tls = {}
    for t in root.iter("tlLogic"):
        tls[t.get("id")] = dict(offset=float(t.get("offset", 0.0)),
                                phases=[(p.get("state"), float(p.get("duration"))) for p in t.iter("phase")])
    junctions = {j.get("id"): j.attrib for j in root.iter("junction")}
    edges = {e.get("id"): e.attrib for e in root.iter("edge")}
    return dict(lanes=lanes, conns=conns, tls=tls, junctions=junctions, edges=edges)


def ego_edges(scenario=None) -> tuple[str, ...]:
    """The edges of the ego's route in `scenario` (its routes file's route "ego")."""
    from pedas.scenario import get_scenario
    from pedas.traffic import EGO_ROUTE, route_edges

    return tuple(route_edges(get_scenario(scenario).routes)[EGO_ROUTE])


def ego_connections(net_file: str | Path, edges: tuple[str, ...] = EGO_EDGES) -> list[tuple[int, dict]]:
    """Per edge of `edges` but the last: (lane index the ego drives on, the connection it leaves the edge by).

    The ego starts on lane 0 and follows each lane's connection to the next edge (its toLane; where a lane fans
    out, the branch that goes on along `edges`). A lane without one is an acceleration lane that ends: the ego
    leaves it by the nearest lane to its left that continues (the merge; the adjacent lane in the networks here).
    """
    conns = _parse(str(net_file))["conns"]
    lane, out = 0, []
    for i, (edge, nxt) in enumerate(zip(edges[:-1], edges[1:])):
        cs = sorted(conns.get((edge, nxt), []), key=lambda c: (int(c["fromLane"]), int(c["toLane"])))
        if not cs:
            raise ValueError(f"network has no connection {edge} -> {nxt}")
        if i + 2 < len(edges):  # a lane that fans out (a deceleration lane begins): the branch that goes on
            onward = {int(c["fromLane"]) for c in conns.get((nxt, edges[i + 2]), [])}
            cs = [c for c in cs if int(c["toLane"]) in onward] or cs
        c = next((c for c in cs if int(c["fromLane"]) == lane), None) or \
            next((c for c in cs if int(c["fromLane"]) > lane), None)
        if c is None:
            raise ValueError(f"network has no connection {edge} -> {nxt} from lane {lane} or a lane left of it")
        out.append((lane, c))
        lane = int(c["toLane"])
    return out


def ego_path(net_file: str | Path, edges: tuple[str, ...] = EGO_EDGES) -> list[PathLane]:
    """The lanes the ego vehicle drives along `edges`, in order, with their start offsets (m) along the route.

    On an edge the lane the ego enters on stands for the edge (every lane of a SUMO edge has the edge's length);
    the junction lanes are those of the connection it leaves by (:func:`ego_connections`)."""
    net = _parse(str(net_file))
    lanes, conns = net["lanes"], net["conns"]
    out: list[PathLane] = []
    s = 0.0

    def add(lane_id: str, edge: str, internal: bool, speed: float) -> None:
        nonlocal s
        ln = lanes[lane_id]
        out.append(PathLane(lane_id, s, ln["length"], speed, edge, internal))
        s += ln["length"]

    leave = ego_connections(net_file, edges)
    entry = 0
    for i, edge in enumerate(edges):
        lane = f"{edge}_{entry}"
        if lane not in lanes:
            raise ValueError(f"network has no lane {lane}: not the study network?")
        add(lane, edge, False, lanes[lane]["speed"])
        if i + 1 == len(edges):
            break
        nxt = edges[i + 1]
        c = leave[i][1]
        entry = int(c["toLane"])
        via = c.get("via")
        while via:  # internal lanes (a left turn may be split in two at an internal junction)
            add(via, edge, True, lanes[lane]["speed"])
            via_edge = lanes[via]["edge"]
            nxt_c = [c for c in conns.get((via_edge, nxt), [])]
            via = nxt_c[0].get("via") if nxt_c else None
    return out


def _resample(path: list[PathLane], net: dict, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, y, z of the ego path at the distances s (each lane's shape scaled to its SUMO length).

    netconvert cuts an edge at its junction's border but keeps the node's z there, so the first and last point
    of a multi-point lane carry a height that belongs a few metres away (a spurious grade step). z is therefore
    interpolated from the interior shape points of such lanes (two-point lanes keep their ends) and not from
    junction lanes.

    Where the ego changes lanes (off an acceleration lane) the next lane's shape starts a lane width to the side
    of where the last one ended; x and y serve only the curvature, so the following shapes are shifted to join
    (a sideways jump would be a curvature spike, not a curve).
    """
    xs, ys, ss, zs_s, zs = [], [], [], [], []
    shift = np.zeros(2)
    end = None
    for pl in path:
        shp = net["lanes"][pl.lane_id]["shape"]
        if end is not None and np.hypot(*(shp[0, :2] + shift - end)) > JOIN_TOLERANCE:
            shift = end - shp[0, :2]
        seg = np.hypot(np.diff(shp[:, 0]), np.diff(shp[:, 1]))
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        scale = pl.length / cum[-1] if cum[-1] > 0 else 0.0
        s_pts = pl.s0 + cum * scale
        ss.append(s_pts)
        xs.append(shp[:, 0] + shift[0]); ys.append(shp[:, 1] + shift[1])
        end = shp[-1, :2] + shift
        if not pl.internal:
            sel = slice(1, -1) if len(shp) > 2 else slice(None)
            zs_s.append(s_pts[sel]); zs.append(shp[sel, 2])
    s_all, x, y = (np.concatenate(a) for a in (ss, xs, ys))
    # drop repeated points where one lane ends and the next begins
    keep = np.concatenate([[True], np.diff(s_all) > 1e-6])
    s_all, x, y = s_all[keep], x[keep], y[keep]
    sz, z = np.concatenate(zs_s), np.concatenate(zs)
    keep = np.concatenate([[True], np.diff(sz) > 1e-6])
    return np.interp(s, s_all, x), np.interp(s, s_all, y), np.interp(s, sz[keep], z[keep])


def _moving_average(a: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return a
    pad = n // 2
    ap = np.concatenate([np.full(pad, a[0]), a, np.full(n - 1 - pad, a[-1])])
    # a mean over sliding windows, not np.convolve: convolve sums through BLAS, whose last bits depend on the kernel
    return np.lib.stride_tricks.sliding_window_view(ap, n).mean(axis=-1)


def study_route(net_file: str | Path | None = None, ds: float = DS, scenario=None) -> Route:
    """The 13.2 km study route of `scenario` (default :data:`pedas.scenario.DEFAULT_SCENARIO`) as a
    :class:`Route` (grid `ds` m), built from its network (`build_network(scenario=...)` unless `net_file`)."""
    if net_file is None:
        from pedas.network import build_network

        net_file = build_network(scenario=scenario)
    return _study_route(str(net_file), float(ds), ego_edges(scenario))


@lru_cache(maxsize=4)
def _study_route(net_file: str, ds: float, edges: tuple[str, ...]) -> Route:
    net = _parse(net_file)
    path = ego_path(net_file, edges)
    length = path[-1].s0 + path[-1].length
    n = int(math.floor(length / ds)) + 1
    s = np.arange(n) * ds
    if s[-1] < length - 1e-6:
        s = np.append(s, length)
    x, y, z = _resample(path, net, s)

    # curvature kappa = d(heading)/ds, smoothed over a few metres (eq. 6c's v_max uses |kappa|)
    hw_start = next(pl.s0 for pl in path if pl.edge == HIGHWAY_EDGES[0] and not pl.internal)
    vmin_start = next(pl.s0 for pl in path if pl.edge == V_MIN_FROM_EDGE and not pl.internal) + V_MIN_RAMP_UP
    heading = np.unwrap(np.arctan2(np.gradient(y, s), np.gradient(x, s)))
    dh = np.gradient(heading, s)
    kappa = np.where(s >= vmin_start, _moving_average(dh, max(1, int(round(CURVATURE_WINDOW_HIGHWAY / ds)))),
                     _moving_average(dh, max(1, int(round(CURVATURE_WINDOW / ds)))))
    # grade from the heights, smoothed like the curvature (netconvert's cuts leave small height steps at joints)
    dz = np.gradient(z, s)
    grade = np.arctan(np.where(s >= vmin_start, _moving_average(dz, max(1, int(round(CURVATURE_WINDOW_HIGHWAY / ds)))),
                               _moving_average(dz, max(1, int(round(CURVATURE_WINDOW / ds))))))

    starts = np.array([pl.s0 for pl in path])
    idx = np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(path) - 1)
    speed_limit = np.array([path[i].speed for i in idx])
    segment = np.where(s >= hw_start, "highway", "urban").astype(object)
    v_min = np.where(s >= vmin_start, HIGHWAY_MIN_SPEED, 0.0)

    lights, stops = [], []
    for edge, (_, c) in zip(edges, ego_connections(net_file, edges)):
        stop_line = next(pl.s0 + pl.length for pl in path if pl.edge == edge and not pl.internal)
        junction = net["edges"][edge].get("to")
        if c.get("tl"):
            prog = net["tls"][c["tl"]]
            k = int(c["linkIndex"])
            phases: list[tuple[str, float]] = []
            for state, dur in prog["phases"]:
                st = _SUMO_STATE[state[k]]
                if phases and phases[-1][0] == st:
                    phases[-1] = (st, phases[-1][1] + dur)
                else:
                    phases.append((st, dur))
            lights.append(TrafficLight(c["tl"], stop_line, tuple(phases), offset=sumo_cycle_start(prog["offset"])))
        elif net["junctions"][junction].get("type") in ("priority_stop", "allway_stop"):
            stops.append(StopSign(junction, stop_line))
    return Route(name="study-13.2km", s=s, z=z, grade=grade, curvature=kappa, speed_limit=speed_limit,
                 v_min=v_min, segment=segment, lights=tuple(lights), stops=tuple(stops))


def sumo_cycle_start(offset: float) -> float:
    """Absolute time (s) at which a SUMO static program with `offset` starts its first phase.

    SUMO shifts a program by its offset such that the cycle begins at time `-offset` (mod cycle); the route
    type counts the cycle from `TrafficLight.offset`, so the sign flips (checked against libsumo in the tests).
    """
    return float(offset)


# ---------------------------------------------------------------------------------------------- route file
ROUTE_FILE_HEADER = """The paper's study route (13.2 km: town, on-ramp, highway) as a route file (docs/drive_logs.md).
Generated from the SUMO network by `python -m pedas.route_study studies/pedas_paper/route.toml`;
do not edit by hand (tests/test_drive_mapping.py checks that regenerating gives this file).
Sections: the ego path's lanes merged where limit and segment agree (junction lanes keep the limit of their
approach), positions in m along the path from the start of lane u01_0 (a SUMO vehicle's position on u01 plus its
odometer), limits in m/s as in the network;
lights: stop line and fixed-time plan of the ego's signal; stops: stop lines of the priority_stop junctions."""


def route_file_text(net_file: str | Path | None = None, scenario=None) -> str:
    """The paper's route as the text of a route file (:mod:`pedas.route_toml`), built from the network of
    `scenario` (default :data:`pedas.scenario.DEFAULT_SCENARIO`; `net_file`: its network, built if None)."""
    if net_file is None:
        from pedas.network import build_network

        net_file = build_network(scenario=scenario)
    path = ego_path(net_file, ego_edges(scenario))
    route = study_route(net_file, scenario=scenario)
    hw_start = next(pl.s0 for pl in path if pl.edge == HIGHWAY_EDGES[0] and not pl.internal)
    sections: list[list] = []
    for pl in path:
        seg = "highway" if pl.s0 >= hw_start else "urban"
        a, b = round(pl.s0, 3), round(pl.s0 + pl.length, 3)
        if sections and sections[-1][2] == pl.speed and sections[-1][3] == seg:
            sections[-1][1] = b
        else:
            sections.append([a, b, pl.speed, seg])
    lights = [Light(tl.tl_id, round(tl.s, 3), tl.phases, tl.offset) for tl in route.lights]
    stops = [Stop(ss.ss_id, round(ss.s, 3)) for ss in route.stops]
    return dump_route(route.name, [tuple(x) for x in sections], lights, stops, speed_unit="m/s",
                      header=ROUTE_FILE_HEADER)


def write_route_file(out: str | Path, net_file: str | Path | None = None) -> Path:
    """Write :func:`route_file_text` to `out`; returns the path."""
    out = Path(out)
    out.write_text(route_file_text(net_file), encoding="utf-8")
    return out


if __name__ == "__main__":
    import sys

    if len(sys.argv) != 2:
        raise SystemExit("usage: python -m pedas.route_study FILE   (writes the paper's route file to FILE)")
    print(write_route_file(sys.argv[1]))

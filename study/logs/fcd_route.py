"""The route a SUMO FCD log is joined to: its own SUMO network (``drive import --net FILE``), or the study's route
file when the log provably drives that route; never a route the log was not driven on (docs/drive_logs.md).

* **Own network** (:func:`net_route`, read with sumolib): the vehicle's path is the sequence of lanes in the log's
  ``lane`` column, joined by the network's connections (their junction-internal ``via`` lanes, and whole edges a
  1 s sample may have skipped, at most :data:`MAX_SKIPPED_EDGES`). Per sample: ``speed_limit`` = the ``speed`` of
  its lane (m/s; on a junction-internal lane the limit of the approach lane, as the study route keeps it),
  ``segment`` = the SUMO edge id (junction-internal lanes: the approach edge), ``tl_id``/``d_tl`` = the next
  traffic light on the path at or ahead of the sample and the distance (m, along the lanes) to its stop line, the
  end of the approach lane, and ``tl_state`` = that light's signal for the vehicle's link (green|yellow|red) from a
  ``static`` program at SUMO's clock: cycle position (t − offset) mod cycle, ``G``/``g`` green, ``y``/``Y``
  yellow, ``r``/``R``/``u``/``s`` red, ``o``/``O`` (off) NULL. Actuated and other programs depend on the traffic,
  so their state stays NULL. A lane the network does not have, or two lanes it does not connect, refuse the log.
* **The study's route** (:func:`check_on_route`): the log mapping lists the route's SUMO edges in driving order
  (``[log] route_edges``); every lane of the log (junction-internal ``:`` lanes aside) must lie on one of them, in
  that order, and when ``s`` is read from ``start_lane_distance`` the vehicle must start on the first one.
  Without that list the log's route is unknown and the import is refused.
"""
from __future__ import annotations

import hashlib
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from study.common.errors import UserError

MAX_SKIPPED_EDGES = 3   # edges a vehicle may cross between two samples (short edges at 1 s steps, fast)
SUMO_SIGNAL = {"G": "green", "g": "green", "y": "yellow", "Y": "yellow", "r": "red", "R": "red", "u": "red",
               "s": "red"}  # 'o'/'O' (off): no state


def check_net_option(net, kind: str, mapping) -> None:
    """`--net FILE` is for a SUMO FCD log read through a log mapping, and the file must exist."""
    if net is None:
        return
    if kind != "sumo-fcd":
        raise UserError(f"--net is for SUMO FCD logs (this log is {kind})")
    if mapping is None:
        raise UserError("--net needs a log mapping of the FCD file (the study's [files] log_mapping or --map)")
    if not Path(net).is_file():
        raise UserError(f"no such network file: {net}")


def fcd_route(raw: pd.DataFrame, route, net, mapping) -> tuple[pd.DataFrame, object]:
    """(raw, route to join) for an FCD log read through `mapping`: with `net` the log's own network
    (:class:`NetRoute`; ``start_lane_distance`` then follows the lanes when the log has no odometer), else the
    study's `route` after :func:`check_on_route`, else None (no route)."""
    if net is not None:
        nr, u = net_route(raw, net)
        if "odometer" not in raw.columns and "pos" in raw.columns:
            raw = raw.assign(start_lane_distance=u)  # along the lanes, not across the x/y chords of a bend
        return raw, nr
    if route is not None:
        check_on_route(raw, mapping, route)
    return raw, route


def _lanes(raw: pd.DataFrame) -> np.ndarray:
    if "lane" not in raw.columns:
        raise UserError("the log has no lane attribute (SUMO writes it by default): its route cannot be told")
    lanes = raw["lane"].astype("string").to_numpy(dtype=object, na_value=None)
    bad = [i for i, x in enumerate(lanes) if not x]
    if bad:
        raise UserError(f"column lane row {bad[0] + 1}: no lane")
    return lanes


def _edge(lane: str) -> str:
    return lane.rsplit("_", 1)[0]  # a SUMO lane id is <edge id>_<lane index>


def check_on_route(raw: pd.DataFrame, mapping, route) -> None:
    """UserError unless the log drives the study's route (see the module docstring)."""
    edges = tuple(mapping.route_edges) if mapping is not None else ()
    if not edges:
        raise UserError(f"the log's route is unknown: a SUMO FCD log is joined to route {route.name} only when the "
                        f"log mapping lists the route's SUMO edges ([log] route_edges); for a log of another "
                        f"network give that network with --net FILE")
    lanes = _lanes(raw)
    order = {e: i for i, e in enumerate(edges)}
    last = -1
    for i, lane in enumerate(lanes):
        if lane.startswith(":"):
            continue
        k = order.get(_edge(lane))
        if k is None:
            raise UserError(f"column lane row {i + 1}: lane {lane} is not on route {route.name} (SUMO edges "
                            f"{edges[0]} ... {edges[-1]}, [log] route_edges of {mapping.name}): the log is from "
                            f"another route; give its network with --net FILE")
        if k < last:
            raise UserError(f"column lane row {i + 1}: edge {_edge(lane)} after {edges[last]}, against the order of "
                            f"route {route.name}")
        if last < 0 and k != 0 and (ch := mapping.channel("s")) is not None and ch.column == "start_lane_distance":
            raise UserError(f"column lane row {i + 1}: the vehicle starts on edge {_edge(lane)}, but "
                            f"start_lane_distance is the route position only from the start of its first edge "
                            f"{edges[0]}")
        last = k


# ---------------------------------------------------------------------------------------------- own network
@dataclass(frozen=True)
class NetRoute:
    """One FCD log's route in its own SUMO network, sample by sample (row i of the log): what the import joins like
    a :class:`study.folder.route_file.RouteFile` (``join``, ``segments``, ``length``, ``name``, ``text``)."""

    name: str               # the network file's name (stored as drives.route)
    text: str               # identifies the network for the import's checksum: its name and sha256
    length: float           # m, the path's length along the lanes
    speed_limit: np.ndarray  # m/s
    segment: np.ndarray     # SUMO edge ids (object)
    tl_id: np.ndarray       # next light ahead (object, None after the last)
    d_tl: np.ndarray        # m to its stop line (NaN after the last)
    tl_state: np.ndarray    # green|yellow|red|None

    @property
    def segments(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.segment))

    def join(self, frame: pd.DataFrame, label: str = "column s", lights: bool = True,
             first_row: int = 0) -> tuple[pd.DataFrame, tuple[str, ...]]:
        """`frame` (row for row the log this route was built from) with speed_limit and segment added where
        absent, and (`lights`) tl_id, d_tl and tl_state when the log has no traffic-light column at all."""
        if first_row != 0 or len(frame) != self.speed_limit.size:
            raise ValueError("a NetRoute joins the whole log it was built from")
        wanted = [c for c in ("speed_limit", "segment") if c not in frame.columns]
        lights = lights and any(x is not None for x in self.tl_id) and \
            not {"tl_id", "tl_state", "d_tl"} & set(frame.columns)
        out = frame.copy()
        if "speed_limit" in wanted:
            out["speed_limit"] = self.speed_limit
        if "segment" in wanted:
            out["segment"] = pd.Categorical(self.segment, categories=list(self.segments))
        added = list(wanted)
        if lights:
            out["tl_id"] = pd.array(self.tl_id, dtype="string")
            out["tl_state"] = pd.array(self.tl_state, dtype="string")
            out["d_tl"] = self.d_tl
            added += ["tl_id", "tl_state", "d_tl"]
        return out, tuple(added)


def _read_net(path: Path):
    import sumolib

    try:
        net = sumolib.net.readNet(str(path), withInternal=True, withPrograms=True)
    except Exception as exc:  # not XML, not a network: one line
        raise UserError(f"{path.name}: not a readable SUMO network: {' '.join(str(exc).split())}") from None
    if not net.getEdges():
        raise UserError(f"{path.name}: not a SUMO network (no edges)")
    return net


def _chain(net, conn, to_edge) -> list:
    """The junction-internal lanes of `conn` in driving order (a turn may be split at an internal junction)."""
    out, via = [], conn.getViaLaneID()
    while via:
        lane = net.getLane(via)
        out.append(lane)
        nxt = [c for c in lane.getOutgoing() if c.getToLane().getEdge() is to_edge]
        via = nxt[0].getViaLaneID() if nxt else ""
    return out


def _edge_hops(a, b) -> list | None:
    """The edges from edge `a` to edge `b` (both included) over the network's connections, fewest first, with at
    most :data:`MAX_SKIPPED_EDGES` in between; None when there is no such way."""
    queue, prev = deque([a]), {a: None}
    while queue:
        e = queue.popleft()
        if e is b:
            hops = [e]
            while prev[hops[-1]] is not None:
                hops.append(prev[hops[-1]])
            return hops[::-1]
        depth, x = 0, e
        while prev[x] is not None:
            depth, x = depth + 1, prev[x]
        if depth > MAX_SKIPPED_EDGES:
            continue
        for nxt in e.getOutgoing():
            if nxt not in prev:
                prev[nxt] = e
                queue.append(nxt)
    return None


def _connection(net, from_lane, from_edge, to_edge, to_lane, seen_internal: set):
    """The connection by which the vehicle leaves `from_edge` for `to_edge`: the one through the junction lanes seen
    in the log, else from its lane to the lane it is seen on next, else from its lane, else the first."""
    conns = from_edge.getOutgoing().get(to_edge, [])

    def rank(c):
        via = {ln.getID() for ln in _chain(net, c, to_edge)}
        return (not (seen_internal and seen_internal <= via), c.getFromLane() is not from_lane,
                to_lane is not None and c.getToLane() is not to_lane, c.getFromLane().getIndex(),
                c.getToLane().getIndex())
    return min(conns, key=rank)


def _signal(net, tls_id: str, link: int, t: np.ndarray) -> np.ndarray:
    """The state (green|yellow|red|None) of link `link` of light `tls_id` at SUMO times `t` (s): from its program
    when that is the only one and static, else None throughout."""
    progs = list(net.getTLS(tls_id).getPrograms().values())
    out = np.full(t.size, None, dtype=object)
    if len(progs) != 1 or progs[0].getType() != "static":
        return out
    phases = progs[0].getPhases()
    dur = np.array([float(p.duration) for p in phases])
    ends = np.cumsum(dur)
    tau = np.mod(t - float(progs[0].getOffset()), ends[-1])
    k = np.minimum(np.searchsorted(ends, tau, side="right"), len(phases) - 1)
    states = np.array([SUMO_SIGNAL.get(p.state[link]) if link < len(p.state) else None for p in phases], dtype=object)
    return states[k]


def net_route(raw: pd.DataFrame, net_path) -> tuple[NetRoute, np.ndarray]:
    """The log's route in network `net_path` (see the module docstring) and each sample's position along its lanes
    (m, from the start of its first lane)."""
    path = Path(net_path)
    net = _read_net(path)
    lanes = _lanes(raw)
    pos = pd.to_numeric(raw["pos"], errors="coerce").to_numpy(dtype="float64") if "pos" in raw.columns else None
    if pos is None or not np.isfinite(pos).all():
        raise UserError("the log has no lane position (pos, SUMO writes it by default) in every row")
    obj = {}
    for i, lane in enumerate(lanes):
        if lane not in obj:
            try:
                obj[lane] = net.getLane(lane)
            except KeyError:
                raise UserError(f"column lane row {i + 1}: lane {lane} is not in network {path.name}: the log is "
                                f"not from this network") from None
    # runs of one lane; the normal ones carry the path, the junction-internal ones lie between them
    starts = np.flatnonzero(np.r_[True, lanes[1:] != lanes[:-1]])
    runs = [(int(a), int(b), lanes[a]) for a, b in zip(starts, np.r_[starts[1:], len(lanes)])]
    internal = [obj[r[2]].getEdge().getFunction() == "internal" for r in runs]
    if internal[0]:
        raise UserError(f"column lane row 1: the log starts inside a junction (lane {runs[0][2]}); it must start on "
                        f"a road of the network")
    u = np.empty(len(lanes))
    limit = np.empty(len(lanes))
    segment = np.empty(len(lanes), dtype=object)
    stops: list[tuple[float, str, int]] = []   # (stop line along the path, light, link index)
    off, cur = 0.0, obj[runs[0][2]]            # offset of the current normal lane, the lane
    where: dict[str, tuple] = {}               # junction lanes passed since: (offset, approach lane)
    pending: list[tuple[int, int, str]] = []   # junction-lane runs waiting for the next normal lane

    def place(run, lane_off, approach):
        a, b, _ = run
        u[a:b] = lane_off + pos[a:b]
        limit[a:b] = approach.getSpeed()
        segment[a:b] = approach.getEdge().getID()

    def cross(c, to_edge):
        """Leave the current lane by connection `c`: its light's stop line, its junction lanes; then on its toLane."""
        nonlocal off, cur
        if c.getTLSID():
            stops.append((off + cur.getLength(), c.getTLSID(), int(c.getTLLinkIndex())))
        s = off + cur.getLength()
        for ln in _chain(net, c, to_edge):
            where[ln.getID()] = (s, cur)
            s += ln.getLength()
        off, cur = s, c.getToLane()

    for run, inner in zip(runs, internal):
        lane = obj[run[2]]
        if inner:
            pending.append(run)
            continue
        where.clear()
        if lane.getEdge() is not cur.getEdge():
            hops = _edge_hops(cur.getEdge(), lane.getEdge())
            if hops is None:
                raise UserError(f"column lane row {run[0] + 1}: network {path.name} does not connect lane "
                                f"{cur.getID()} to lane {lane.getID()}: the log is not from this network")
            seen = {p[2] for p in pending}
            for k, (e1, e2) in enumerate(zip(hops[:-1], hops[1:])):
                cross(_connection(net, cur, e1, e2, lane if k == len(hops) - 2 else None, seen), e2)
        cur = lane  # also a lane change: the same road, the same offset (a SUMO edge's lanes share its length)
        for p in pending:
            if p[2] not in where:
                raise UserError(f"column lane row {p[0] + 1}: lane {p[2]} is not on the way to lane {lane.getID()} "
                                f"in network {path.name}")
            place(p, *where[p[2]])
        pending.clear()
        place(run, off, lane)
    if pending:  # the log ends inside a junction: by the connection of the last lane that passes there
        where.clear()
        seen = {p[2] for p in pending}
        conns = [c for c in cur.getOutgoing()
                 if seen <= {ln.getID() for ln in _chain(net, c, c.getToLane().getEdge())}]
        if not conns:
            p = pending[0]
            raise UserError(f"column lane row {p[0] + 1}: lane {p[2]} does not follow lane {cur.getID()} in network "
                            f"{path.name}")
        cross(conns[0], conns[0].getToLane().getEdge())
        for p in pending:
            place(p, *where[p[2]])
    length = max(float(u[-1]), off + cur.getLength())
    tl_id = np.full(len(lanes), None, dtype=object)
    d_tl = np.full(len(lanes), np.nan)
    tl_state = np.full(len(lanes), None, dtype=object)
    if stops:
        line = np.array([s for s, _, _ in stops])
        j = np.searchsorted(line, u, side="left")
        ahead = j < len(stops)
        t = pd.to_numeric(raw["sumo_time"] if "sumo_time" in raw.columns else raw["time"],
                          errors="coerce").to_numpy(dtype="float64")
        for k, (s, tls, link) in enumerate(stops):
            at = ahead & (j == k)
            tl_id[at] = tls
            d_tl[at] = s - u[at]
            tl_state[at] = _signal(net, tls, link, t[at])
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return NetRoute(path.name, f"sumo network\0{path.name}\0{digest}", length, limit, segment, tl_id, d_tl,
                    tl_state), u

"""The motorway scenario: its network (two lanes, acceleration and deceleration lanes), the same urban part as the
single-lane scenario, the ego's path and merge, traffic that overtakes the ego, and pruning that keeps every vehicle
that could still overtake it."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from pedas.constants import KMH, ROUTE_LENGTH
from pedas.network import build_network
from pedas.route_study import ego_connections, ego_edges, ego_path, study_route
from pedas.scenario import DEFAULT_SCENARIO, MOTORWAY, SCENARIOS, SINGLE_LANE, get_scenario

MAIN = ("h01m", "h02m", "h03", "h04m", "h05")  # main-carriageway edges without an extra lane
ACCELERATION = ("h01", "h02", "h04")  # begin with an acceleration lane (lane 0)
DECELERATION = {"h02d": "ramp_hoff1", "h04d": "ramp_hoff2"}  # end with a deceleration lane (lane 0)


@pytest.fixture(scope="module")
def net(tmp_path_factory):
    return build_network(build_dir=tmp_path_factory.mktemp("mw"), scenario=MOTORWAY)


def _lanes(net_file) -> dict[str, int]:
    root = ET.parse(net_file).getroot()
    return {e.get("id"): len(e.findall("lane")) for e in root.iter("edge") if e.get("function") != "internal"}


def _conns(net_file) -> set[tuple[str, str, int, int]]:
    root = ET.parse(net_file).getroot()
    return {(c.get("from"), c.get("to"), int(c.get("fromLane")), int(c.get("toLane"))) for c in root.iter("connection")
            if not c.get("from").startswith(":")}


def test_scenarios_by_name():
    assert DEFAULT_SCENARIO == MOTORWAY and set(SCENARIOS) == {MOTORWAY, SINGLE_LANE}
    assert get_scenario(None) is SCENARIOS[MOTORWAY]
    with pytest.raises(ValueError, match="unknown scenario 'nope' .*motorway"):
        get_scenario("nope")
    names = [p.name for p in get_scenario(MOTORWAY).sources]
    assert names == ["motorway.netccfg", "study.nod.xml", "motorway.nod.xml", "study.edg.xml", "motorway.edg.xml",
                     "motorway.con.xml", "study.tll.xml"]
    assert all(p.exists() for p in get_scenario(MOTORWAY).files)


def test_urban_connections_are_the_single_lane_scenarios():
    def urban(path):
        return {tuple(sorted(c.attrib.items())) for c in ET.parse(path).getroot().iter("connection")
                if c.get("from").startswith(("u", "x_"))}

    mw, sl = get_scenario(MOTORWAY), get_scenario(SINGLE_LANE)
    assert urban(mw.netccfg.parent / "motorway.con.xml") == urban(sl.netccfg.parent / "study.con.xml")
    assert len(urban(sl.netccfg.parent / "study.con.xml")) == 37  # the town and its ramp onto the highway


def test_two_lanes_with_acceleration_and_deceleration_lanes(net):
    lanes, conns = _lanes(net), _conns(net)
    assert all(lanes[e] == 2 for e in (*MAIN, "h00"))
    for e in ACCELERATION:  # three lanes; the right one ends (no connection onwards) after ~250 m
        assert lanes[e] == 3
        assert not any(c[0] == e and c[2] == 0 for c in conns)
    for e, ramp in DECELERATION.items():  # the right lane only leads to the off-ramp
        assert lanes[e] == 3
        assert {c[1] for c in conns if c[0] == e and c[2] == 0} == {ramp}
    root = ET.parse(net).getroot()
    length = {ln.get("id"): float(ln.get("length")) for ln in root.iter("lane")}
    assert all(240.0 <= length[f"{e}_0"] <= 300.0 for e in (*ACCELERATION, *DECELERATION))


def test_ego_path_merges_once_then_keeps_the_right_lane(net):
    edges = ego_edges(MOTORWAY)
    lanes = dict(zip(edges, (lane for lane, _ in ego_connections(net, edges))))
    assert lanes["r01"] == 0 and lanes["h01"] == 0  # on the acceleration lane ...
    leave_h01 = dict(zip(edges, (c for _, c in ego_connections(net, edges))))["h01"]
    assert leave_h01["fromLane"] == "1" and leave_h01["toLane"] == "0"  # ... leaves it by the adjacent lane
    n_lanes = _lanes(net)
    for e in edges[edges.index("h01m"):-1]:  # then the right lane of the main carriageway: lane 0 of two, 1 of three
        assert lanes[e] == n_lanes[e] - 2
    path = ego_path(net, edges)
    assert [p.lane_id for p in path if not p.internal][-1] == "h05_0"


def test_same_urban_route_and_a_smooth_feasible_highway(net):
    from pedas.dp import dp_reference

    mw, sl = study_route(net, scenario=MOTORWAY), study_route(scenario=SINGLE_LANE)
    assert mw.length == pytest.approx(ROUTE_LENGTH, abs=100.0)
    assert [(x.tl_id, x.s, x.phases, x.offset) for x in mw.lights] == \
        [(x.tl_id, x.s, x.phases, x.offset) for x in sl.lights]
    assert [(x.ss_id, x.s) for x in mw.stops] == [(x.ss_id, x.s) for x in sl.stops]
    urban = sl.segment == "urban"
    assert np.array_equal(mw.segment[:urban.sum()], sl.segment[:urban.sum()])
    assert np.array_equal(mw.speed_limit[:urban.sum()], sl.speed_limit[:urban.sum()])
    main = mw.v_min > 0
    # no curvature spike where the ego changes lane or a lane begins or ends: the curves are the single-lane ones
    assert mw.v_curve[main].min() == pytest.approx(sl.v_curve[sl.v_min > 0].min(), rel=0.05)
    assert mw.v_curve[mw.segment == "highway"].min() > 60.0 * KMH  # the ramp's junction is no sharp jog
    res = dp_reference(mw)  # feasible: the instructed 80 km/h can be held from the end of the acceleration lane
    held = res.s < mw.length - 500.0  # the DP drops the minimum where it brakes for the stop at the route's end
    assert np.all(mw.at(res.s[held], "v_min") <= res.v_dp[held] + 0.25 + 1e-9)


@pytest.mark.sumo
def test_ego_merges_keeps_its_lane_and_is_overtaken(net):
    """A plain ego (12 m/s in town, 25 m/s on the motorway, following a close leader) in the motorway traffic: it
    leaves the acceleration lane, stays in the right lane, vehicles pass it in the left lane, and no vehicle that
    reaches the two-lane part is ever pruned."""
    from pedas.traffic import EGO_ID, Traffic

    edges = ego_edges(MOTORWAY)
    right = {e: lane for e, (lane, _) in zip(edges, ego_connections(net, edges))}
    right[edges[-1]] = 0
    first_two_lane = edges.index("h01")
    passed, side, lanes_after_merge = set(), {}, set()
    with Traffic(5, net, scenario=MOTORWAY) as tr:
        ls = tr._ls
        assert tr._overtaking_from == first_two_lane
        assert all(tr._route_leave[ls.vehicle.getRouteID(v)] < first_two_lane for v in tr._join)
        tr.insert_ego()
        while not tr.ego_arrived():
            edge = ls.vehicle.getRoadID(EGO_ID)
            lead = tr.leader()
            v = 25.0 if edge.startswith("h") else 12.0
            tr.set_ego_speed(min(v, lead.v) if lead is not None and lead.gap < 30.0 else v)
            if edge in right and edges.index(edge) > edges.index("h01"):
                lanes_after_merge.add((edge, ls.vehicle.getLaneIndex(EGO_ID) - right[edge]))
                pos = ls.vehicle.getLanePosition(EGO_ID)
                for vid in ls.edge.getLastStepVehicleIDs(edge):  # left of the ego: behind it, then ahead of it
                    if vid != EGO_ID and ls.vehicle.getLaneIndex(vid) > right[edge]:
                        d = ls.vehicle.getLanePosition(vid) - pos
                        if side.get((vid, edge), 1.0) < 0.0 < d:
                            passed.add(vid)
                        side[(vid, edge)] = d
            tr.step()
    assert {d for _, d in lanes_after_merge} == {0}  # the right lane from the merge to the end
    assert len(passed) >= 5  # vehicles from behind overtook the ego in the left lane

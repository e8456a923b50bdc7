"""The study network: built from the plain-XML sources by netconvert, and the route description read from it (the
single-lane scenario's sources in data/network/; the motorway scenario's: tests/pedas/test_motorway.py)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from pedas.constants import HIGHWAY_MIN_SPEED, KMH, ROUTE_LENGTH
from pedas.network import SOURCES, build_network, source_hash
from pedas.route_study import EGO_EDGES, ego_path, study_route
from pedas.scenario import SINGLE_LANE


@pytest.fixture(scope="module")
def fresh_net(tmp_path_factory):
    """The network built from scratch into an empty build directory (as on a fresh clone)."""
    build = tmp_path_factory.mktemp("netbuild")
    return build_network(build_dir=build, scenario=SINGLE_LANE)


@pytest.fixture(scope="module")
def route(fresh_net):
    return study_route(fresh_net, scenario=SINGLE_LANE)


def test_build_from_scratch_is_cached_by_source_hash(fresh_net):
    assert fresh_net.exists() and fresh_net.stat().st_size > 10_000
    assert source_hash(scenario=SINGLE_LANE) in fresh_net.name
    mtime = fresh_net.stat().st_mtime_ns
    again = build_network(build_dir=fresh_net.parent, scenario=SINGLE_LANE)
    assert again == fresh_net and again.stat().st_mtime_ns == mtime  # reused, not rebuilt
    assert not [p for p in fresh_net.parent.iterdir() if p.name.startswith(".netconvert-")]  # no temp left


def test_changed_source_rebuilds_elsewhere(tmp_path, fresh_net):
    src = tmp_path / "src"
    src.mkdir()
    from pedas.paths import NETWORK_DIR

    for name in SOURCES:
        (src / name).write_bytes((NETWORK_DIR / name).read_bytes())
    assert source_hash(src) == source_hash(scenario=SINGLE_LANE)
    edg = src / "study.edg.xml"
    edg.write_text(edg.read_text().replace('id="h05" from="HOFF2" to="H_END" priority="10" numLanes="1" '
                                           'speed="33.3333"', 'id="h05" from="HOFF2" to="H_END" priority="10" '
                                           'numLanes="1" speed="27.7778"'))
    assert source_hash(src) != source_hash(scenario=SINGLE_LANE)
    net = build_network(source_dir=src, build_dir=tmp_path / "b")
    assert net.name != fresh_net.name
    assert study_route(net, scenario=SINGLE_LANE).speed_limit[-1] == pytest.approx(27.78, abs=0.01)


def test_missing_source_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="network source missing"):
        build_network(source_dir=tmp_path, build_dir=tmp_path / "b")


def test_concurrent_first_builds_agree(tmp_path):
    """Two processes building into the same empty directory at once: one file, both get its path."""
    code = ("import sys; from pedas.network import build_network; "
            "print(build_network(build_dir=sys.argv[1]))")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE, text=True,
                              env={**os.environ}) for _ in range(2)]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert outs[0] == outs[1]
    assert len(list(tmp_path.glob("*.net.xml"))) == 1


def test_route_length_lights_stops_and_highway_minimum(route):
    assert route.length == pytest.approx(ROUTE_LENGTH, abs=100.0)  # 13.2 km +- 0.1 (Sec. 4.3)
    assert len(route.lights) >= 7
    assert len(route.stops) >= 2
    urban = route.segment == "urban"
    hw = route.segment == "highway"
    # urban first, then highway
    assert urban[0] and hw[-1] and np.all(np.diff(hw.astype(int)) >= 0)
    assert all(route.at(x.s, "segment") == "urban" for x in (*route.lights, *route.stops))
    assert set(np.round(route.speed_limit[urban] / KMH).astype(int)) == {30, 50}
    main = route.v_min > 0
    assert set(np.round(route.speed_limit[main] / KMH).astype(int)) == {100, 120}
    assert np.all(route.v_min[main] == pytest.approx(HIGHWAY_MIN_SPEED))
    assert main.sum() * (route.s[1] - route.s[0]) > 7000.0  # the minimum holds on > 7 km of highway
    assert np.all(route.v_min[urban] == 0.0)


def test_route_has_turns_curves_and_elevation(route):
    urban = route.segment == "urban"
    hw = route.v_min > 0
    radius = 1.0 / np.maximum(np.abs(route.curvature), 1e-9)
    assert radius[urban].min() < 20.0  # turns at intersections
    assert ((radius[urban] > 40) & (radius[urban] < 150)).sum() > 100  # real curves between junctions
    assert radius[hw].min() < 700.0  # highway curves
    assert np.any(route.v_curve[hw] < route.speed_limit[hw])  # at least one highway curve limits the speed
    dz = route.z[hw].max() - route.z[hw].min()
    assert dz > 20.0  # an elevation profile, not a flat road
    assert np.abs(np.tan(route.grade)).max() < 0.06  # road design grades (<= 6 %)


def test_lights_run_fixed_time_programs(route):
    for tl in route.lights:
        assert {st for st, _ in tl.phases} == {"green", "yellow", "red"}
        assert 50.0 <= tl.cycle <= 100.0
        assert tl.state_at(123.4) == tl.state_at(123.4 + 7 * tl.cycle)  # periodic, deterministic


@pytest.mark.sumo
def test_route_matches_sumo_distances_and_signal_programs(fresh_net, route):
    """The route's stop-line positions equal SUMO's distance to the next light; the route's signal programs
    equal SUMO's states (reported one step later: the state in force during step t -> t + dt)."""
    import libsumo

    from pedas.constants import DT
    from pedas.network import ROUTES, VTYPES
    from pedas.paths import NETWORK_DIR

    libsumo.start(["sumo", "-n", str(fresh_net), "-r", str(NETWORK_DIR / ROUTES), "-a", str(NETWORK_DIR / VTYPES),
                   "--step-length", str(DT), "--step-method.ballistic", "true", "--no-step-log", "true",
                   "--xml-validation", "never", "--no-warnings", "true"])
    try:
        libsumo.vehicle.add("probe", "ego", typeID="ego", depart="0", departSpeed="0")
        libsumo.simulationStep()
        libsumo.vehicle.setSpeedMode("probe", 32)
        s_offset = libsumo.vehicle.getLanePosition("probe") - libsumo.vehicle.getDistance("probe")
        assert s_offset == pytest.approx(4.45, abs=0.2)  # the front bumper starts one vehicle length in
        checked_tl, checked_pos = 0, 0
        for _ in range(int(1400 / DT)):
            t = libsumo.simulation.getTime()
            for tl in route.lights:
                sumo_state = libsumo.trafficlight.getRedYellowGreenState(tl.tl_id)[0]
                assert {"G": "green", "y": "yellow", "r": "red"}[sumo_state] == tl.state_at(t - DT + 1e-9)
                checked_tl += 1
            if "probe" not in libsumo.vehicle.getIDList():
                break
            s = libsumo.vehicle.getDistance("probe") + s_offset
            nxt = libsumo.vehicle.getNextTLS("probe")
            if nxt:
                tl = route.next_light(s)
                assert nxt[0][0] == tl.tl_id
                assert nxt[0][2] == pytest.approx(tl.s - s, abs=0.05)
                checked_pos += 1
            libsumo.vehicle.setSpeed("probe", 15.0)
            libsumo.simulationStep()
        assert checked_pos > 1000 and checked_tl > 8000
        assert s == pytest.approx(route.length, abs=25.0)  # driven to (almost) the end of the route
    finally:
        libsumo.close()


def test_ego_path_is_the_route_edge_sequence(fresh_net):
    path = ego_path(fresh_net)
    edges = [p.lane_id.rsplit("_", 1)[0] for p in path if not p.internal]
    assert tuple(edges) == EGO_EDGES
    starts = np.array([p.s0 for p in path])
    assert np.all(np.diff(starts) > 0)

"""SUMO FCD as SUMO writes it (default options: no acceleration, vehicles departing later than time 0), on a network
that is not the study's route: the network's limits and lights with --net, refusal without it, acceleration and
time derived as documented (docs/drive_logs.md "SUMO floating-car data"). The network and the FCD are made by real
SUMO here (tests/sumo_two_edge.py)."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from study.logs.stored import drive_samples
from study.common.errors import UserError
from study.logs.fcd import derived_acceleration, likely_ego, read_fcd
from study.folder.logmap import load_mapping, parse_mapping
from study.store.store import Store
from tests.conftest import PAPER_STUDY
from tests.sumo_two_edge import build

TOWN_LANE = 392.8          # m: town_0 from x = 0 to the junction cut at x = 392.8 (netconvert's .net.xml)
KMH50, KMH80 = 13.89, 22.22   # m/s: the lanes' speed as netconvert writes it (2 decimals)


@pytest.fixture(scope="module")
def sumo_run(tmp_path_factory):
    """(network, FCD with SUMO's default attributes, FCD with --fcd-output.acceleration, tls states file)."""
    out = tmp_path_factory.mktemp("two_edge")
    net, fcd = build(out / "default", tls_states=True)
    _, fcd_acc = build(out / "acc", "--fcd-output.acceleration", "true")
    return net, fcd, fcd_acc, out / "default" / "tls.xml"


def add(db, pid="P001"):
    from study.store.studies import definition

    with Store.open(db) as st:
        st.insert("participants", {"participant_id": pid, "protocol": definition(st).protocol().name})


def snapshot(db):
    with Store.open(db) as st:
        return st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")


@pytest.mark.sumo
def test_default_fcd_imported_with_limits_from_its_own_network(cli, paper_db, sumo_run):
    """The issue's "Must show": SUMO's default FCD (no acceleration attribute) of another network imports with
    --net, its limits 50/80 km/h from that network, not the study route's."""
    net, fcd, _, _ = sumo_run
    assert "acceleration=" not in fcd.read_text()
    add(paper_db)
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego", "--net", net)
    assert r.code == 0, r.err
    raw = read_fcd(fcd, "ego")
    with Store.open(paper_db) as st:
        back = drive_samples(st, "P001", "baseline")
        row = st.df("SELECT route, meta FROM drives").iloc[0]
    town = back["segment"] == "town"
    assert set(back["segment"]) == {"town", "rural"}
    np.testing.assert_allclose(back.loc[town, "speed_limit"], KMH50)
    np.testing.assert_allclose(back.loc[~town, "speed_limit"], KMH80)
    # town samples are those on town_0 (and junction lanes after it, which keep the approach's limit)
    on = town.to_numpy()
    assert (raw.loc[on, "lane"] != "rural_0").all() and (raw.loc[~on, "lane"] == "rural_0").all()
    # time from the first sample: ego departs at SUMO time 5 s
    assert raw["sumo_time"].iloc[0] == 5.0 and back["t"].iloc[0] == 0.0
    np.testing.assert_allclose(back["t"], raw["sumo_time"] - 5.0)
    # acceleration derived: 0 at insertion, then SUMO's 2.6 m/s² from standstill (speeds 0, 2.6, 5.2)
    np.testing.assert_allclose(back["v"].iloc[:3], [0.0, 2.6, 5.2])
    np.testing.assert_allclose(back["a"].iloc[:3], [0.0, 2.6, 2.6])
    # s along the lanes (no odometer): on town_0 its pos; d_tl to the stop line at the end of town_0
    on_town = (raw["lane"] == "town_0").to_numpy()
    np.testing.assert_allclose(back.loc[on_town, "s"], raw.loc[on_town, "pos"])
    np.testing.assert_allclose(back.loc[on_town, "d_tl"] + back.loc[on_town, "s"], TOWN_LANE)
    assert (back.loc[on_town, "tl_id"] == "B").all() and back.loc[~town, "tl_id"].isna().all()
    meta = json.loads(row["meta"])
    assert row["route"] == "two.net.xml" and meta["net"] == "two.net.xml" and meta["derived"] == ["acceleration"]
    assert meta["from_route"] == ["speed_limit", "segment", "tl_id", "tl_state", "d_tl"]
    limits = back.groupby("segment", observed=True)["speed_limit"].first()
    print(f"\nimported {len(back)} samples; speed limits by segment (km/h): "
          f"{ {g: round(float(v) * 3.6, 2) for g, v in limits.items()} }")


@pytest.mark.sumo
def test_light_state_is_the_state_sumo_showed(sumo_run):
    """tl_state from the static program (offset 17 s) at SUMO's clock equals SUMO's own signal for the ego's link
    (town -> rural, link 3) at every sample before the stop line."""
    from study.logs.fcd_route import net_route

    net, fcd, _, tls = sumo_run
    raw = read_fcd(fcd, "ego")
    route, _ = net_route(raw, net)
    sumo = {float(m.group(1)): m.group(2) for m in re.finditer(r'time="([\d.]+)" id="B" [^>]*state="(\w+)"',
                                                               tls.read_text())}
    want = {"G": "green", "g": "green", "y": "yellow", "r": "red"}
    before = ~np.isnan(route.d_tl)
    states = [want[sumo[t][3]] for t in raw["sumo_time"][before]]
    assert list(route.tl_state[before]) == states
    assert {"green", "yellow", "red"} <= set(states)  # the ego meets every state of the program


@pytest.mark.sumo
def test_derived_acceleration_is_sumos(sumo_run):
    """The derived a (backward difference, 0 at insertion) agrees with SUMO's own --fcd-output.acceleration within
    the rounding of the file (speeds and accelerations to 0.01: 0.01 / 1 s + 0.005)."""
    _, fcd, fcd_acc, _ = sumo_run
    derived, recorded = read_fcd(fcd, "ego"), read_fcd(fcd_acc, "ego")
    assert derived.attrs["derived"] == ["acceleration"] and recorded.attrs["derived"] == []
    np.testing.assert_allclose(derived["speed"], recorded["speed"])
    np.testing.assert_allclose(derived["acceleration"], recorded["acceleration"], atol=0.0151)
    assert (recorded["acceleration"] < -1).any()  # braking for the red light is in it


def test_derived_acceleration_by_hand():
    t = np.array([0.0, 1.0, 1.5, 3.5])
    v = np.array([0.0, 2.0, 3.0, 1.0])
    np.testing.assert_allclose(derived_acceleration(t, v), [0.0, 2.0, 2.0, -1.0])
    np.testing.assert_allclose(derived_acceleration(t[:1], v[:1]), [0.0])


@pytest.mark.sumo
def test_fcd_of_another_network_refused_without_its_network(cli, paper_db, sumo_run):
    """Without --net the study route's limits (30/50 km/h) would be taken silently: refused, store unchanged."""
    _, fcd, _, _ = sumo_run
    add(paper_db)
    before = snapshot(paper_db)
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego")
    assert r.code == 2 and r.out == ""
    assert r.err.strip() == (f"pedas-study: error: {fcd}: column lane row 1: lane town_0 is not on route "
                             "study-13.2km (SUMO edges u01 ... h05, [log] route_edges of fcd_map.toml): the log is "
                             "from another route; give its network with --net FILE")
    assert snapshot(paper_db) == before


@pytest.mark.sumo
def test_wrong_network_and_misuse_of_net_refused(cli, paper_db, sumo_run, tmp_path):
    from pedas.network import build_network

    net, fcd, _, _ = sumo_run
    add(paper_db)
    before = snapshot(paper_db)
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego", "--net", build_network())
    assert r.code == 2 and r.err.strip() == (f"pedas-study: error: {fcd}: column lane row 1: lane town_0 is not in "
                                             f"network {build_network().name}: the log is not from this network")
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego", "--net", tmp_path / "none.net.xml")
    assert r.code == 2 and f"no such network file: {tmp_path / 'none.net.xml'}" in r.err
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net>")
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego", "--net", bad)
    assert r.code == 2 and "bad.net.xml: not a readable SUMO network" in r.err and len(r.err.splitlines()) == 1
    csv = tmp_path / "log.csv"
    csv.write_text("t,s,v\n0,0,0\n")
    r = cli("drive", "import", "P001", "baseline", csv, "--net", net)
    assert r.code == 2 and "--net is for SUMO FCD logs (this log is csv)" in r.err
    assert snapshot(paper_db) == before


@pytest.mark.sumo
def test_unknown_vehicle_lists_every_id_sorted_and_the_ego(sumo_run):
    _, fcd, _, _ = sumo_run
    ids = "car1, car2, car3, car4, car5, car6, car7, car8, car9, car10, ego"
    with pytest.raises(UserError) as exc:
        read_fcd(fcd, "eg0")
    assert str(exc.value) == (f"{fcd}: no vehicle 'eg0' in this FCD file; it holds 11 vehicles ({ids}; likely "
                              f"the ego: ego)")
    with pytest.raises(UserError) as exc:
        read_fcd(fcd)
    assert str(exc.value) == (f"{fcd} holds 11 vehicles ({ids}): name one with --vehicle (or [log] vehicle in the "
                              f"mapping); likely the ego: ego")


def test_likely_ego():
    assert likely_ego({"car1": 50, "Ego": 3}) == "Ego"
    assert likely_ego({"car1": 50, "ego_7": 3}) == "ego_7"
    assert likely_ego({"car1": 50, "car2": 80, "car10": 80}) == "car2"   # most samples, then natural order


def test_paper_mapping_lists_the_study_routes_edges():
    from pedas.route_study import ego_edges

    m = load_mapping((PAPER_STUDY / "fcd_map.toml").read_text(encoding="utf-8"), "fcd_map.toml")
    assert m.route_edges == ego_edges()


def test_route_edges_in_a_mapping():
    head = '[channels.t]\ncolumn = "time"\nunit = "s"\n[channels.v]\ncolumn = "speed"\nunit = "m/s"\n'
    _, problems = parse_mapping('[log]\nformat = "sumo-fcd"\nroute_edges = [":J0_0", "a"]\n' + head, "m.toml")
    assert problems == [(3, "log.route_edges", "must be a list of SUMO edge ids (text, not junction-internal ':' "
                                               "edges)")]
    _, problems = parse_mapping('[log]\nformat = "csv"\nroute_edges = ["a"]\n' + head, "m.toml")
    assert problems == [(3, "log.route_edges", "is for sumo-fcd logs only")]


def test_fcd_on_the_study_route_checked_by_its_edges():
    """Lanes off the declared edges, against their order, or a start after the first edge are refused; junction
    lanes are not checked; without declared edges the log's route is unknown."""
    from study.logs.fcd_route import check_on_route
    from study.folder.route_file import load_route

    route = load_route('[route]\nname = "r"\n[[sections]]\ns_from = 0\ns_to = 100\nspeed_limit = 10\n'
                       'segment = "x"\n', "route.toml")
    head = '[channels.t]\ncolumn = "time"\nunit = "s"\n[channels.v]\ncolumn = "speed"\nunit = "m/s"\n' \
           '[channels.s]\ncolumn = "start_lane_distance"\nunit = "m"\n'
    m = load_mapping('[log]\nformat = "sumo-fcd"\nroute_edges = ["a", "b#1", "c"]\n' + head, "m.toml")

    def lanes(*ids):
        return pd.DataFrame({"lane": list(ids)})

    check_on_route(lanes("a_0", ":J1_0_0", "b#1_1", "b#1_0", "c_0"), m, route)
    with pytest.raises(UserError, match=r"^column lane row 2: lane d_0 is not on route r \(SUMO edges a \.\.\. c"):
        check_on_route(lanes("a_0", "d_0"), m, route)
    with pytest.raises(UserError, match="^column lane row 3: edge a after c, against the order of route r$"):
        check_on_route(lanes("a_0", "c_0", "a_0"), m, route)
    with pytest.raises(UserError, match="^column lane row 1: the vehicle starts on edge b#1, but start_lane_distance"):
        check_on_route(lanes("b#1_0", "c_0"), m, route)
    no_edges = load_mapping('[log]\nformat = "sumo-fcd"\n' + head, "m.toml")
    with pytest.raises(UserError, match=r"^the log.s route is unknown: .* \(\[log\] route_edges\); .* --net FILE$"):
        check_on_route(lanes("a_0"), no_edges, route)
    with pytest.raises(UserError, match="^the log has no lane attribute"):
        check_on_route(pd.DataFrame({"x": [0.0]}), m, route)

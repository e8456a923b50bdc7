"""Pruning the traffic the ego can no longer meet: every vehicle removed is behind the ego or joins its route
where the ego has passed, as SUMO's own route distance says, and the ego's leader is the same before and after."""
from __future__ import annotations

import pytest

import pedas.traffic as traffic
from pedas.traffic import EGO_ID, Traffic

UNREACHABLE = -1e6  # getDrivingDistance answers about -2^30 for a position not ahead on the vehicle's route


def reachable(ls, edge: str, pos: float) -> bool:
    """SUMO: can the ego still reach (edge, pos) along its route?"""
    return ls.vehicle.getDrivingDistance(EGO_ID, edge, pos) > UNREACHABLE


def where_it_meets_the_route(tr, ls, vid: str, running: set[str]) -> tuple[str, float]:
    """The point of the ego's route a vehicle is at (on the route) or will first use (not yet on it)."""
    if vid in running:
        edge = ls.vehicle.getRoadID(vid)
        if edge in tr._ego_edges:
            return edge, float(ls.vehicle.getLanePosition(vid))
    edges = ls.vehicle.getRoute(vid)
    return next(e for e in edges if e in tr._ego_edges), 0.0


@pytest.mark.parametrize("seed", [3, 11])
def test_prune_removes_only_what_the_ego_cannot_meet(monkeypatch, seed):
    monkeypatch.setattr(traffic, "PRUNE_EVERY", 10**9)  # prune only when the test says so
    removed_total = 0
    with Traffic(seed) as tr:
        ls = tr._ls
        tr.insert_ego()
        for _ in range(12):
            for _ in range(250):  # 50 s: a plain driver, 10 m/s or the leader's speed when close
                lead = tr.leader()
                tr.set_ego_speed(min(10.0, lead.v) if lead and lead.gap < 25.0 else 10.0)
                tr.step()
                if tr.ego_arrived():
                    break
            if tr.ego_arrived():
                break
            running = set(ls.vehicle.getIDList())
            before = set(ls.vehicle.getLoadedIDList())
            meets = {vid: where_it_meets_the_route(tr, ls, vid, running) for vid in before if vid in tr._join}
            lead_before = tr.leader()
            n = tr.prune()
            gone = before - set(ls.vehicle.getLoadedIDList())
            assert len(gone) == n
            for vid in gone:
                edge, pos = meets[vid]
                assert not reachable(ls, edge, pos), f"{vid} at {edge}:{pos:.1f} is still ahead of the ego"
            lead_after = tr.leader()
            assert (lead_before and lead_before.veh_id) == (lead_after and lead_after.veh_id)
            # and nothing left on the route is behind the ego
            for vid in set(ls.vehicle.getIDList()) & set(tr._join):
                edge = ls.vehicle.getRoadID(vid)
                if edge in tr._ego_edges:
                    assert reachable(ls, edge, float(ls.vehicle.getLanePosition(vid))), f"{vid} left behind the ego"
            removed_total += n
    assert removed_total > 20  # the test exercised the pruning

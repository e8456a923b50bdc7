"""The drive loop's per-step exchange with SUMO: Traffic.observe / advance (subscriptions) give the very values of
the getters (time, ego_state, leader, ego_collided, ego_arrived), also right after a prune removed vehicles; and
the departures are added in the order of the departures frame."""
from __future__ import annotations

import random

import pandas as pd
import pytest

from pedas.scenario import SCENARIOS
from pedas.traffic import DEPARTURE_FIELDS, Traffic, departure_rows, load_demand

pytestmark = pytest.mark.sumo


@pytest.mark.parametrize("scenario", ["single-lane", "motorway"])
def test_observe_and_advance_are_the_getters(scenario):
    """A fast ego (15 m/s, SUMO's checks off) runs into and through the traffic, so that prunes remove the vehicle
    the subscription saw as its leader: observe must then ask SUMO again."""
    steps = refreshed = 0
    with Traffic(4, scenario=scenario) as tr:
        tr.insert_ego()
        tr.subscribe_ego()
        arrived = False
        while not arrived and steps < 3000:
            t, s, v, lead, collided = tr.observe()
            assert (t, (s, v), lead, collided) == (tr.time, tr.ego_state(), tr.leader(), tr.ego_collided())
            refreshed += tr._removed and lead is not None
            arrived = tr.advance(15.0)
            assert arrived == tr.ego_arrived()
            steps += 1
    assert steps > 1000 and refreshed > 0   # the check covered steps after a prune removed vehicles


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_departure_rows_are_the_frame_order(scenario):
    """Traffic.start adds departure_rows in their order; it is pandas' stable sort by (depart, veh_id), the order
    of the departures frame, whatever order the rows come in."""
    demand = load_demand(scenario=scenario)
    for seed in (0, 7):
        rows = departure_rows(seed, demand)
        shuffled = rows.copy()
        random.Random(seed).shuffle(shuffled)
        frame = pd.DataFrame(shuffled, columns=list(DEPARTURE_FIELDS)).sort_values(["depart", "veh_id"],
                                                                                   kind="stable")
        assert list(frame.itertuples(index=False, name=None)) == rows

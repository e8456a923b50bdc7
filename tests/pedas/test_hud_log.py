"""The HUD channels of a drive log (pedas.hud_log): a frame survives the round trip through its numbers, and the
unfollowed timer over a log is the controller's (hand-worked)."""
from __future__ import annotations

import math

import pytest

from pedas.hud_frame import FIG7
from pedas.hud_log import HUD_CHANNELS, channel_values, frame_from_channels, unfollowed_series


@pytest.mark.parametrize("sit", FIG7, ids=[s.key for s in FIG7])
def test_frame_round_trip_through_channels(sit):
    f = sit.frame()
    ch = channel_values(f)
    assert list(ch) == [name for name, _, _ in HUD_CHANNELS]
    assert frame_from_channels(ch, f.advice, f.arrow, f.in_band) == f


def test_channel_codes_hand_worked():
    h = {s.key: s for s in FIG7}["h"].frame()
    ch = channel_values(h)
    assert (ch["hud_countdown"], ch["hud_light"], ch["hud_icon"], ch["hud_tone"]) == (6.0, 1.0, 0.0, 0.0)
    assert math.isnan(channel_values({s.key: s for s in FIG7}["d"].frame())["hud_countdown"])


def test_unfollowed_series_hand_worked():
    # arrow down at samples 0-2, then none; constant speed, then braking at -1 m/s^2 between samples 3 and 4
    t = [0.0, 0.5, 1.0, 1.5, 2.0]
    v = [10.0, 10.0, 10.0, 10.0, 9.5]
    arrow = [-1, -1, -1, 0, -1]
    # k=0: previous arrow none -> 0; k=1,2: +0.5 each; k=3: arrow at 2 still down -> 1.5; k=4: arrow at 3 none -> 0
    assert unfollowed_series(t, v, arrow) == [0.0, 0.5, 1.0, 1.5, 0.0]
    assert unfollowed_series([0.0, 0.5], [10.0, 9.5], [-1, -1]) == [0.0, 0.0]    # -1 m/s^2: followed

"""Seeded 20 Hz simulator logs of the takeover study (studies/takeover): time in ms, speed in mph, distance in ft,
a takeover-request flag and a hands-on-wheel flag, as that lab's logger writes them.

A drive: automated driving at ~118 km/h; at 40 s the takeover request rises and stays on for 8 s; the driver's
hands reach the wheel after a takeover time drawn per participant and condition (longest without a warning, shortest
with the audiovisual one), then the driver slows to ~95 km/h past the obstacle. A familiarisation drive has no
request.
"""
from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pandas as pd

RATE_HZ = 20
DURATION_S = 75.0
TOR_AT_S = 40.0
#: mean takeover time (s) per condition: no warning, visual, audiovisual
TAKEOVER_S = {"none": 3.1, "visual": 2.5, "audiovisual": 1.9}
MPH = 0.44704          # m/s
FT = 0.3048            # m


def takeover_time(participant: str, condition: str) -> float:
    """The seeded takeover time (s) of a participant in a condition: the condition's mean plus a participant effect
    (sd 0.35 s) plus noise (sd 0.25 s), at least 0.8 s."""
    person = np.random.default_rng(zlib.crc32(participant.encode()))
    noise = np.random.default_rng(zlib.crc32(f"{participant}/{condition}".encode()))
    return max(0.8, TAKEOVER_S[condition] + person.normal(0, 0.35) + noise.normal(0, 0.25))


def make_log(participant: str, condition: str | None, duration_s: float = DURATION_S) -> pd.DataFrame:
    """One drive's log as the lab writes it (columns time_ms, speed_mph, dist_ft, tor, hands_on), `duration_s`
    long (at least 60 s: the request and the slowing down)."""
    rng = np.random.default_rng(zlib.crc32(f"log/{participant}/{condition}".encode()))
    t = np.arange(int(duration_s * RATE_HZ)) / RATE_HZ
    v = 118 / 3.6 + np.cumsum(rng.normal(0, 0.01, t.size))           # m/s, automated: nearly constant
    tor = np.zeros(t.size, dtype=int)
    hands = np.zeros(t.size, dtype=int)
    if condition is not None:
        tor[(t >= TOR_AT_S) & (t < TOR_AT_S + 8)] = 1
        grab = TOR_AT_S + takeover_time(participant, condition)
        hands[t >= grab] = 1
        slow = np.clip((t - grab) / 6, 0, 1)                        # manual: down to ~95 km/h over 6 s
        v = v - slow * (23 / 3.6)
    s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 / RATE_HZ)])
    return pd.DataFrame({"time_ms": np.round(t * 1000).astype(int), "speed_mph": np.round(v / MPH, 4),
                         "dist_ft": np.round(s / FT, 3), "tor": tor, "hands_on": hands})


def write_log(folder: Path, participant: str, condition: str | None, duration_s: float = DURATION_S) -> Path:
    path = Path(folder) / f"{participant}_{condition or 'familiarisation'}.csv"
    make_log(participant, condition, duration_s).to_csv(path, index=False)
    return path

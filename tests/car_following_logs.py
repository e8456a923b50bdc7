"""Seeded 20 Hz simulator logs of the car-following study (studies/car_following), as that lab's logger writes them:
time_s, speed_kmh, pos_m, lead_gap_m, lead_speed_kmh, steer_deg, brake_pct, throttle_pct, lane_offset_m,
lead_brake_event.

A drive: 180 s behind a lead vehicle at 22 m/s, a time gap drawn per participant and condition; at 90 s the lead
vehicle brakes hard (4 m/s^2 for 3 s, flag on for those 3 s) and speeds up again at 1 m/s^2. The driver releases the
accelerator after 0.6 of a brake reaction time drawn per participant and condition (shorter with the warning) and
brakes at the end of it (so the accelerator-to-brake transition takes the remaining 0.4);
the driver's speed is the lead vehicle's delayed by that time plus 0.3 s. The steering is two sines and a little noise;
the lateral position a slow sway with a known number of lane departures (the vehicle's edge over the lane boundary
for 1 s).
"""
from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pandas as pd

RATE_HZ = 20
DURATION_S = 180.0
LEAD_BRAKES_S = 90.0
LEAD_V = 22.0
#: mean brake reaction time (s) per condition
REACTION_S = {"no_warning": 1.35, "fcw": 0.95}
#: share of the brake reaction time that passes before the accelerator is released
RELEASE_SHARE = 0.6


def _rng(*parts: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32("/".join(parts).encode()))


def reaction_time(participant: str, condition: str) -> float:
    """The seeded brake reaction time (s): the condition's mean + a participant effect + noise, at least 0.5 s."""
    return max(0.5, REACTION_S[condition] + _rng(participant).normal(0, 0.15)
               + _rng(participant, condition, "rt").normal(0, 0.1))


def release_time(participant: str, condition: str) -> float:
    """When (s after the lead vehicle starts braking) the driver takes the foot off the accelerator: 0.6 of the
    brake reaction time, the rest being the move to the brake pedal."""
    return RELEASE_SHARE * reaction_time(participant, condition)


def time_gap(participant: str, condition: str) -> float:
    """The seeded time gap (s) of steady following."""
    return float(np.clip(1.6 + _rng(participant, condition, "gap").normal(0, 0.25), 1.0, 2.5))


def departures(participant: str, condition: str) -> int:
    """The number of 1 s lane departures in the drive (0-3)."""
    return int(_rng(participant, condition, "ld").integers(0, 4))


def lead_speed(t: np.ndarray) -> np.ndarray:
    v = np.full(t.shape, LEAD_V)
    braking = (t >= LEAD_BRAKES_S) & (t < LEAD_BRAKES_S + 3)
    v[braking] = LEAD_V - 4.0 * (t[braking] - LEAD_BRAKES_S)
    low = LEAD_V - 12.0
    again = t >= LEAD_BRAKES_S + 3
    v[again] = np.minimum(LEAD_V, low + 1.0 * (t[again] - LEAD_BRAKES_S - 3))
    return v


def make_log(participant: str, condition: str) -> pd.DataFrame:
    """One drive's log as the lab writes it (module docstring)."""
    rng = _rng("log", participant, condition)
    t = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    rt = reaction_time(participant, condition)
    vl = lead_speed(t)
    v = np.interp(t - rt - 0.3, t, vl, left=LEAD_V)
    s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 / RATE_HZ)])
    s_lead = time_gap(participant, condition) * LEAD_V + np.concatenate(
        [[0.0], np.cumsum((vl[1:] + vl[:-1]) / 2 / RATE_HZ)])
    gap = s_lead - s
    brake = np.where((t >= LEAD_BRAKES_S + rt) & (t < LEAD_BRAKES_S + rt + 4), 40.0, 0.0)
    throttle = np.where((t >= LEAD_BRAKES_S + release_time(participant, condition)) & (t < LEAD_BRAKES_S + rt + 6),
                        0.0, 20.0)
    phase = rng.uniform(0, 2 * np.pi)
    steer = (3 * np.sin(2 * np.pi * 0.05 * t + phase) + 1.5 * np.sin(2 * np.pi * 0.3 * t)
             + np.convolve(rng.normal(0, 0.3, t.size), np.ones(5) / 5, mode="same"))
    lat = 0.2 * np.sin(2 * np.pi * 0.02 * t + phase) + rng.normal(0, 0.02, t.size)
    for k in range(departures(participant, condition)):
        start = 20.0 + 45.0 * k
        lat[(t >= start) & (t < start + 1.0)] = 1.0          # the edge 1.9 m off the centre of a 3.5 m lane
    return pd.DataFrame({"time_s": np.round(t, 3), "speed_kmh": np.round(v * 3.6, 4), "pos_m": np.round(s, 3),
                         "lead_gap_m": np.round(gap, 3), "lead_speed_kmh": np.round(vl * 3.6, 4),
                         "steer_deg": np.round(steer, 4), "brake_pct": brake, "throttle_pct": throttle,
                         "lane_offset_m": np.round(lat, 4),
                         "lead_brake_event": ((t >= LEAD_BRAKES_S) & (t < LEAD_BRAKES_S + 3)).astype(int)})


def write_log(folder: Path, participant: str, condition: str) -> Path:
    path = Path(folder) / f"{participant}_{condition}.csv"
    make_log(participant, condition).to_csv(path, index=False)
    return path

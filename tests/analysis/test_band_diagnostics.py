"""The explanations of missed reproduction bands: chosen by the direction of the miss, numbers from the table."""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.drives.band_diagnostics import COLUMNS, why_missed
from analysis.drives.savings import BAND_HIGHWAY, BAND_OVERALL, BAND_RED, BAND_VIOLATION

DIAG = pd.DataFrame([
    (BAND_HIGHWAY, "v_highway", "mean speed on the highway", "km/h", 80.4, 79.9),
    (BAND_HIGHWAY, "lead_highway", "highway time with a leader within 100 m", "%", 91.6, 30.0),
    (BAND_HIGHWAY, "lead_slow_highway", "highway time with a leader within 100 m at <= 90 km/h (a lorry)", "%",
     85.2, 20.0),
    (BAND_VIOLATION, "drives_speeding", "drives above the limit at all (of 10)", "drives", 4, 1),
    (BAND_VIOLATION, "share_speeding", "distance above the limit, mean of drives", "%", 1.5, 0.02),
    (BAND_RED, "red_stops", "red stops, all drives", "stops", 50, 30),
    (BAND_RED, "queued", "red stops with a leader within 30 m (in a queue)", "%", 90.0, 80.0),
    (BAND_RED, "cf", "red stops with the car-following MPC in charge", "%", np.nan, 70.0),
], columns=COLUMNS)


def bands(**ours) -> pd.DataFrame:
    spec = {BAND_OVERALL: (5, 15), BAND_HIGHWAY: (0, np.inf), BAND_VIOLATION: (30, 60), BAND_RED: (40, 80)}
    return pd.DataFrame([{"band": b, "lo": lo, "hi": hi, "paper_value": 1.0, "our_value": ours[k],
                          "holds": lo <= ours[k] <= hi if b != BAND_HIGHWAY else ours[k] > 0}
                         for (b, (lo, hi)), k in zip(spec.items(), ("overall", "highway", "violation", "red"))])


def test_each_miss_in_the_expected_direction_is_explained_from_the_numbers():
    out = why_missed(bands(overall=7, highway=-3, violation=98, red=35), DIAG)
    assert len(out) == 3                                             # the overall band holds: nothing said
    hw, vio, red = out
    assert hw.startswith(f"*{BAND_HIGHWAY}*") and "80.4 km/h" in hw and "92 %" in hw and "85 % behind one" in hw
    assert vio.startswith(f"*{BAND_VIOLATION}*") and "4 baseline drives" in vio and "1 pEDAS drives (0.02 %)" in vio
    assert red.startswith(f"*{BAND_RED}*") and "stop at red 30 times (baseline 50)" in red and "70 %" in red


def test_a_miss_the_other_way_only_points_to_the_numbers():
    out = why_missed(bands(overall=7, highway=1, violation=10, red=90), DIAG)
    assert out == [f"*{BAND_VIOLATION}*: ours 10.00 %, paper 1.00 %; see the table above.",   # reductions in %
                   f"*{BAND_RED}*: ours 90.00 %, paper 1.00 %; see the table above."]

"""The bands of two traffic scenarios side by side: one tidy row per band (or diagnostic) and scenario, one table
column per scenario in the order given."""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.drives.band_diagnostics import COLUMNS
from analysis.drives.savings import BAND_HIGHWAY, BAND_OVERALL
from analysis.drives.scenario_comparison import (BAND_COLUMNS, DIAG_COLUMNS, bands_by_scenario, bands_table,
                                          diagnostics_table, write_comparison)


def scenario(overall: float, highway: float, v_hw: float, lead: float) -> tuple[pd.DataFrame, pd.DataFrame]:
    bands = pd.DataFrame([
        {"band": BAND_OVERALL, "lo": 5.0, "hi": 15.0, "paper_value": 9.8, "our_value": overall,
         "holds": 5.0 <= overall <= 15.0, "note": "n=3"},
        {"band": BAND_HIGHWAY, "lo": 0.0, "hi": np.inf, "paper_value": 6.4, "our_value": highway,
         "holds": highway > 0, "note": ""}])
    diag = pd.DataFrame([(BAND_HIGHWAY, "v_highway", "mean speed on the highway", "km/h", v_hw, 82.0),
                         (BAND_HIGHWAY, "lead_highway", "highway time with a leader within 100 m", "%", lead,
                          np.nan)], columns=COLUMNS)
    return bands, diag


PER = {"motorway": scenario(7.25, 1.5, 96.04, 41.0), "single-lane": scenario(6.3, -4.1, 80.1, 93.0)}


def test_tidy_frames_keep_every_band_per_scenario_in_order():
    bands, diag = bands_by_scenario(PER)
    assert list(bands.columns) == BAND_COLUMNS and list(diag.columns) == DIAG_COLUMNS
    assert bands["scenario"].tolist() == ["motorway", "motorway", "single-lane", "single-lane"]
    assert bands.set_index(["scenario", "band"]).loc[("single-lane", BAND_HIGHWAY), "our_value"] == -4.1
    assert diag.set_index(["scenario", "key"]).loc[("motorway", "v_highway"), "baseline"] == 96.04


def test_tables_have_a_column_per_scenario():
    bands, diag = bands_by_scenario(PER)
    header, rows = bands_table(bands, {"motorway": "motorway (default)"})
    assert header == ["Band", "Paper", "motorway (default)", "single-lane"]
    assert rows[0] == [BAND_OVERALL, "9.80", "7.25 (holds)", "6.30 (holds)"]
    assert rows[1] == [BAND_HIGHWAY, "6.40", "1.50 (holds)", "-4.10 (misses)"]
    header, rows = diagnostics_table(diag)
    assert header[3:] == ["motorway: baseline", "motorway: pEDAS", "single-lane: baseline", "single-lane: pEDAS"]
    assert rows[0][3:] == ["96.0", "82.0", "80.1", "82.0"]  # km/h with one decimal
    assert rows[1][3:] == ["41.00", "–", "93.00", "–"]  # NaN: not applicable


def test_written_files(tmp_path):
    files = write_comparison(tmp_path, PER)
    assert sorted(p.name for p in files) == sorted(f"{s}.{e}" for s in ("bands", "band_diagnostics")
                                                   for e in ("csv", "md", "tex"))
    assert pd.read_csv(tmp_path / "bands.csv").shape == (4, len(BAND_COLUMNS))
    assert (tmp_path / "bands.md").read_text().startswith("### Reproduction bands by traffic scenario")
    assert "-4.10 (misses)" in (tmp_path / "bands.md").read_text()

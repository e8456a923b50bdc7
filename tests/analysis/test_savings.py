"""Per-participant effects of pEDAS, the summary by style and the reproduction bands (analysis.drives.savings), with the
comparison the paper's study declares (studies/pedas_paper/kpis.toml)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from study.folder.kpi_spec import parse
from analysis.drives.savings import (participant_effects, objective_results, reduction_pct, reproduction_bands,
                              summarise)
from analysis.drives.tables import style_table
from tests.conftest import PAPER_STUDY

PAPER = parse((PAPER_STUDY / "kpis.toml").read_text(encoding="utf-8"))
STYLES = {"style": ["cautious", "normal", "sporty"]}


def kpi_rows(pid, cond, energy, urban, viol_share=0.1, red=2, green=3, jerk=1.0):
    """KPI rows (as store_kpis returns them) of one drive: overall energy + urban part."""
    base = {"participant_id": pid, "condition": cond, "drive_id": f"{pid}-{cond}", "violation_share": viol_share,
            "violation_events": 1, "red_stops": red, "tl_crossed_green": green, "tl_green_passes": green - 1,
            "tl_crossed": 5, "stops": red + 1,
            "rms_jerk": jerk, "mean_abs_a": 0.3, "mean_speed_mps": 12.0, "trip_time_s": 900.0}
    return [{**base, "segment": "urban", "energy_wh": urban},
            {**base, "segment": "highway", "energy_wh": energy - urban},
            {**base, "segment": "overall", "energy_wh": energy}]


def test_reduction_pct_and_zero_baseline():
    got = reduction_pct([100.0, 50.0, 0.0, 0.0, 4.0], [90.0, 60.0, 0.0, 2.0, 0.0])
    assert got[:2] == pytest.approx([10.0, -20.0])
    assert np.isnan(got[2]) and np.isnan(got[3])       # undefined against a baseline of 0
    assert got[4] == 100.0


def test_participant_effects_hand_worked():
    rows = (kpi_rows("P001", "baseline", 2000.0, 800.0, viol_share=0.20, red=4, jerk=2.0)
            + kpi_rows("P001", "pedas", 1800.0, 760.0, viol_share=0.10, red=1, jerk=1.5)
            + kpi_rows("P002", "baseline", 1000.0, 500.0, viol_share=0.0, red=0)
            + kpi_rows("P002", "pedas", 1100.0, 500.0, viol_share=0.05, red=1)
            + kpi_rows("P003", "baseline", 1000.0, 500.0))           # no pEDAS drive: not in the table
    per = participant_effects(pd.DataFrame(rows), PAPER.comparison,
                              pd.DataFrame({"style": {"P001": "normal", "P002": "sporty"}}))
    assert list(per["participant_id"]) == ["P001", "P002"]
    p1, p2 = per.iloc[0], per.iloc[1]
    assert p1["style"] == "normal"
    assert p1["saving_overall_pct"] == pytest.approx(10.0)            # (2000 - 1800) / 2000
    assert p1["saving_urban_pct"] == pytest.approx(5.0)               # (800 - 760) / 800
    assert p1["saving_highway_pct"] == pytest.approx(100 * (1200 - 1040) / 1200)
    assert p1["violation_reduction_pct"] == pytest.approx(50.0)
    assert p1["red_stop_reduction_pct"] == pytest.approx(75.0)
    assert p1["jerk_reduction_pct"] == pytest.approx(25.0)
    assert p2["saving_overall_pct"] == pytest.approx(-10.0)           # pEDAS used more energy
    assert np.isnan(p2["violation_reduction_pct"]) and np.isnan(p2["red_stop_reduction_pct"])


def test_summary_by_style_skips_undefined_and_pools_red_stops():
    per = pd.DataFrame({
        "participant_id": ["P001", "P002", "P003", "P004"], "style": ["normal", "normal", "sporty", "cautious"],
        "saving_overall_pct": [10.0, 20.0, 6.0, 2.0], "saving_urban_pct": [5.0, 7.0, 3.0, 1.0],
        "saving_highway_pct": [12.0, 25.0, 8.0, 3.0], "violation_reduction_pct": [50.0, np.nan, 40.0, 30.0],
        "red_stop_reduction_pct": [100.0, 50.0, np.nan, 0.0], "jerk_reduction_pct": [1.0, 2.0, 3.0, 4.0],
        "red_stops_baseline": [2, 2, 0, 1], "red_stops_pedas": [0, 1, 1, 1]})
    s = summarise(per, PAPER.comparison, STYLES).set_index(["style", "metric"])
    assert s.loc[("all", "saving_overall_pct"), "mean"] == pytest.approx(9.5)
    assert s.loc[("all", "saving_overall_pct"), "median"] == pytest.approx(8.0)
    assert s.loc[("normal", "saving_overall_pct"), "mean"] == pytest.approx(15.0)
    assert s.loc[("normal", "saving_overall_pct"), "n"] == 2
    assert s.loc[("all", "violation_reduction_pct"), "n"] == 3
    assert s.loc[("all", "violation_reduction_pct"), "mean"] == pytest.approx(40.0)
    assert s.loc[("all", "red_stop_reduction_pooled_pct"), "mean"] == pytest.approx(100 * (5 - 3) / 5)
    wide = style_table(summarise(per, PAPER.comparison, STYLES), PAPER.comparison).set_index("style")
    assert list(wide.index) == ["cautious", "normal", "sporty", "all"]
    assert wide.loc["sporty", "saving_highway_pct_mean"] == pytest.approx(8.0)
    assert wide.loc["all", "red_stop_reduction_pct_n"] == 3


def test_reproduction_bands_take_paper_values_from_published_data():
    from analysis.paper.published import value

    per = pd.DataFrame({
        "participant_id": ["P001", "P002"], "style": ["normal", "sporty"],
        "saving_overall_pct": [8.0, 12.0], "saving_urban_pct": [4.0, 6.0], "saving_highway_pct": [12.0, 14.0],
        "violation_reduction_pct": [20.0, 30.0], "red_stop_reduction_pct": [50.0, 70.0],
        "jerk_reduction_pct": [0.0, 0.0], "red_stops_baseline": [2, 2], "red_stops_pedas": [1, 1]})
    b = reproduction_bands(summarise(per, PAPER.comparison, STYLES)).set_index("band")
    assert list(b["holds"]) == [True, True, False, True]               # violations: 25 % < 30 %
    overall = b.iloc[0]
    assert overall["our_value"] == pytest.approx(10.0)
    assert overall["paper_value"] == value("energy_saving_mean", "overall", "all", table="kpi")
    assert b.iloc[1]["our_value"] == pytest.approx(13.0 - 5.0)


def test_objective_results_respect_exclusions(paper_db):
    from study.logs.importing import import_drive_frame
    from study.people.exclusions import exclude
    from study.people.participants import add_participant
    from study.store.store import Store

    def log(speed):
        t = np.arange(0, 60.0, 0.5)
        v = np.minimum(t, speed)
        s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * 0.5)])
        return pd.DataFrame({"t": t, "s": s, "v": v, "segment": np.where(t < 30, "urban", "highway"),
                             "speed_limit": 14.0})

    with Store.open(paper_db, actor="test") as st:
        for pid, style in (("P001", "normal"), ("P002", "sporty"), ("P003", "cautious")):
            add_participant(st, pid, style=style)
            import_drive_frame(st, pid, "baseline", log(16.0))
            import_drive_frame(st, pid, "pedas", log(13.0))
        exclude(st, "P002", "objective", "technical_issue")
        exclude(st, "P003", "subjective", "incomplete_survey")      # still in the objective analysis
        res = objective_results(st)
    assert list(res.per_participant["participant_id"]) == ["P001", "P003"]
    assert res.excluded == ["P002"] and res.incomplete == []
    assert set(res.kpis["participant_id"]) == {"P001", "P003"}
    assert (res.per_participant["saving_overall_pct"] > 0).all()
    assert (res.per_participant["violation_reduction_pct"] == 100.0).all()   # 16 m/s > 14 + 3 km/h; 13 is not


def test_reproduction_bands_without_published_values():
    from analysis.paper.published import load_published

    none = load_published().iloc[0:0]                               # a study without published values
    per = pd.DataFrame({"participant_id": ["P001"], "style": ["normal"], "saving_overall_pct": [20.0],
                        "saving_urban_pct": [5.0], "saving_highway_pct": [3.0], "violation_reduction_pct": [45.0],
                        "red_stop_reduction_pct": [np.nan], "jerk_reduction_pct": [0.0],
                        "red_stops_baseline": [0], "red_stops_pedas": [0]})
    b = reproduction_bands(summarise(per, PAPER.comparison, STYLES), published=none)
    assert b["paper_value"].isna().all()
    assert list(b["holds"]) == [False, False, True, False]         # 20 % > 15 %; highway < urban; no red stops

"""The sweep's analysis on synthetic points with a known answer: indices, ranking, the region of all four bands."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from SALib.sample import morris as morris_sample
from SALib.sample import sobol as sobol_sample

from analysis.sweep.design import BANDS, KPIS
from analysis.sweep.sensitivity import morris_indices, region, region_lines, sobol_indices, top_factors

FACTORS = (("a", 0.0, 1.0), ("b", 0.0, 2.0), ("c", 0.0, 1.0))
PROBLEM = {"num_vars": 3, "names": ["a", "b", "c"], "bounds": [[0.0, 1.0], [0.0, 2.0], [0.0, 1.0]]}
EDGES = {"overall": {"band": "overall band", "kpi": "saving_overall_pct", "lo": 5.0, "hi": 15.0},
         "highway": {"band": "highway band", "kpi": "highway_minus_urban_pp", "lo": 0.0, "hi": None},
         "violation": {"band": "violation band", "kpi": "violation_reduction_pct", "lo": 30.0, "hi": 60.0},
         "red": {"band": "red band", "kpi": "red_stop_reduction_pct", "lo": 40.0, "hi": 80.0}}


def _points(x: np.ndarray, phase: str) -> pd.DataFrame:
    """Every KPI depends on one factor only: the overall saving = 10 a, the red-stop reduction = 5 b, the rest
    constant."""
    df = pd.DataFrame(x, columns=["a", "b", "c"])
    df.insert(0, "phase", phase)
    df.insert(0, "point", np.arange(len(df)))
    for k in KPIS:
        df[k] = 3.0
    df["saving_overall_pct"] = 10.0 * df["a"]
    df["red_stop_reduction_pct"] = 5.0 * df["b"]
    return df


def test_morris_one_factor_kpi_ranks_that_factor_first():
    x = morris_sample.sample(PROBLEM, 6, num_levels=4, seed=1)
    ind = morris_indices(_points(x, "morris"), FACTORS, seed=1)
    over = ind[ind["kpi"] == "saving_overall_pct"].set_index("factor")
    # y = 10 a over a's whole range [0, 1]: every elementary effect is 10 (per unit of the scaled range)
    assert over.loc["a", "mu_star"] == pytest.approx(10.0)
    assert over.loc["a", "sigma"] == pytest.approx(0.0, abs=1e-9)
    assert over.loc[["b", "c"], "mu_star"].tolist() == pytest.approx([0.0, 0.0], abs=1e-12)
    red = ind[ind["kpi"] == "red_stop_reduction_pct"].set_index("factor")
    # y = 5 b over b's range [0, 2]: effect 10 per scaled unit
    assert red.loc["b", "mu_star"] == pytest.approx(10.0)
    assert red.loc[["a", "c"], "mu_star"].tolist() == pytest.approx([0.0, 0.0], abs=1e-12)
    # a constant KPI: every effect 0
    assert ind[ind["kpi"] == "saving_urban_pct"]["mu_star"].abs().max() == pytest.approx(0.0, abs=1e-12)
    assert top_factors(ind, 2) == ["a", "b"]
    assert top_factors(ind, 1) == ["a"]


def test_morris_undefined_kpi_gives_nan_not_a_number():
    x = morris_sample.sample(PROBLEM, 4, num_levels=4, seed=2)
    pts = _points(x, "morris")
    pts.loc[3, "violation_reduction_pct"] = np.nan
    ind = morris_indices(pts, FACTORS)
    assert ind[ind["kpi"] == "violation_reduction_pct"]["mu_star"].isna().all()
    assert ind[ind["kpi"] == "saving_overall_pct"]["mu_star"].notna().all()


def test_sobol_one_factor_kpi():
    x = sobol_sample.sample(PROBLEM, 64, calc_second_order=False, seed=3)
    ind = sobol_indices(_points(x, "sobol"), FACTORS, seed=3).set_index(["kpi", "factor"])
    over = ind.loc["saving_overall_pct"]
    assert over.loc["a", "ST"] == pytest.approx(1.0, abs=0.1)
    assert over.loc["a", "S1"] == pytest.approx(1.0, abs=0.15)
    # the other factors never change the output: their estimators are exactly 0
    assert over.loc[["b", "c"], "ST"].tolist() == pytest.approx([0.0, 0.0], abs=1e-12)
    assert over.loc[["b", "c"], "S1"].tolist() == pytest.approx([0.0, 0.0], abs=1e-12)
    assert ind.loc["saving_urban_pct", "ST"].isna().all()  # constant: no variance to split


def _band_points(values: list[dict]) -> pd.DataFrame:
    rows = []
    for i, v in enumerate(values):
        r = {"point": i, "phase": "morris", "a": v["a"], "b": v["b"], "c": 0.5, **{k: 0.0 for k in KPIS},
             **v["kpi"]}
        for key, e in EDGES.items():
            x, hi = r[e["kpi"]], np.inf if e["hi"] is None else e["hi"]
            r[f"holds_{key}"] = bool(x > 0) if key == "highway" else bool(e["lo"] <= x <= hi)
        r["holds_all"] = all(r[f"holds_{k}"] for k in EDGES)
        rows.append(r)
    return pd.DataFrame(rows)


META = {"bands": EDGES, "factors": [{"name": f, "lo": lo, "hi": hi} for f, lo, hi in FACTORS]}
GOOD = {"saving_overall_pct": 10.0, "highway_minus_urban_pp": 2.0, "violation_reduction_pct": 45.0,
        "red_stop_reduction_pct": 60.0}


def test_region_where_all_four_hold():
    pts = _band_points([{"a": 0.2, "b": 1.5, "kpi": GOOD},
                        {"a": 0.6, "b": 0.5, "kpi": GOOD},
                        {"a": 0.9, "b": 1.0, "kpi": {**GOOD, "saving_overall_pct": 20.0}},
                        {"a": 0.1, "b": 0.1, "kpi": {**GOOD, "violation_reduction_pct": 10.0}}])
    reg = region(pts, META)
    bands = reg[reg["item"] == "band"].set_index("name")["value"]
    assert bands.to_dict() == {"overall": 0.75, "highway": 1.0, "violation": 0.75, "red": 1.0}
    assert reg[reg["item"] == "all"]["value"].iloc[0] == 0.5
    fac = reg[reg["item"] == "factor"].set_index("name")
    # points 0 and 1 hold all four: a in [0.2, 0.6], b in [0.5, 1.5], c fixed at 0.5
    assert fac.loc["a", ["lo", "hi"]].tolist() == [0.2, 0.6]
    assert fac.loc["b", ["lo", "hi"]].tolist() == [0.5, 1.5]
    assert fac.loc["c", ["lo", "hi"]].tolist() == [0.5, 0.5]
    assert (reg["item"] != "closest").all()
    assert "a 0.2 to 0.6" in " ".join(region_lines(reg))


def test_region_none_hold_names_the_closest():
    pts = _band_points([
        # misses overall by 2 and violation by 5: 2 bands, distance 7
        {"a": 0.1, "b": 0.1, "kpi": {**GOOD, "saving_overall_pct": 3.0, "violation_reduction_pct": 65.0}},
        # misses red by 10: 1 band, distance 10
        {"a": 0.2, "b": 0.2, "kpi": {**GOOD, "red_stop_reduction_pct": 90.0}},
        # misses highway by 1 (-1 pp): 1 band, distance 1 -> closest
        {"a": 0.3, "b": 0.3, "kpi": {**GOOD, "highway_minus_urban_pp": -1.0}},
        # violation undefined: 1 band, infinitely far
        {"a": 0.4, "b": 0.4, "kpi": {**GOOD, "violation_reduction_pct": np.nan}}])
    reg = region(pts, META)
    assert reg[reg["item"] == "all"]["value"].iloc[0] == 0.0
    close = reg[reg["item"] == "closest"]
    assert close["point"].tolist() == [2, 1, 3]
    assert close["missed"].tolist() == [1, 1, 1]
    assert close["distance"].tolist() == [1.0, 10.0, np.inf]
    assert close["note"].iloc[2].endswith("misses violation (undefined)")
    assert close["note"].iloc[0] == "a=0.3, b=0.3, c=0.5; misses highway"
    assert "No design point meets all four bands" in " ".join(region_lines(reg))


def test_bands_keys_match_the_points_columns():
    assert set(BANDS) == set(EDGES)


def test_indices_are_reproducible_with_seed_0():
    """Seed 0 is a seed too (SALib's sobol.analyze would leave an int 0 unseeded)."""
    x = sobol_sample.sample(PROBLEM, 16, calc_second_order=False, seed=0)
    pts = _points(x, "sobol")
    pts["saving_urban_pct"] = pts["a"] + 2 * pts["b"] * pts["c"]
    a, b = sobol_indices(pts, FACTORS, seed=0), sobol_indices(pts, FACTORS, seed=0)
    pd.testing.assert_frame_equal(a, b)
    assert a["ST_conf"].notna().any()

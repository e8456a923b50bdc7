"""The report's sweep step: the committed sweep (data/sweep) re-analysed, beside the scenarios' bands, with its code
version checked against the current one."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd

from analysis.report.build import ReportConfig, skipped_reason, sweep_step
from analysis.drives.savings import BAND_HIGHWAY, BAND_OVERALL, BAND_RED, BAND_VIOLATION
from analysis.sweep.run import read_run
from analysis.sweep.sensitivity import indices, region

REPO = Path(__file__).resolve().parents[2]


def _bands(tmp: Path) -> None:
    rows = []
    for scenario, vals in (("motorway", (6.0, 1.0, 90.0, 50.0)), ("single-lane", (6.3, -4.1, 98.0, 39.0))):
        for band, v, holds in zip((BAND_OVERALL, BAND_HIGHWAY, BAND_VIOLATION, BAND_RED), vals,
                                  (True, vals[1] > 0, False, 40 <= vals[3] <= 80)):
            rows.append({"band": band, "scenario": scenario, "paper_value": 1.0, "our_value": v, "holds": holds,
                         "note": ""})
    (tmp / "scenarios").mkdir(parents=True)
    pd.DataFrame(rows).to_csv(tmp / "scenarios" / "bands.csv", index=False)


def test_sweep_step_recomputes_from_the_points_and_sets_the_bands_beside(tmp_path):
    cfg = ReportConfig(out=tmp_path / "rep", db=tmp_path / "s.duckdb")
    _bands(cfg.out)
    sweep_step(cfg)
    out = cfg.out / "sweep"
    for name in ("indices.csv", "indices.md", "indices.tex", "region.csv", "region.md", "region.tex", "sweep.md",
                 "bands.csv", "bands.md", "bands.tex", "figures/sweep_indices.png", "figures/sweep_indices.svg",
                 "figures/sweep_indices.pdf"):
        assert (out / name).exists(), name
    _, points, meta = read_run(REPO / "data" / "sweep")
    # recomputed from points.csv, not copied: the same frames as the analysis functions give
    pd.testing.assert_frame_equal(pd.read_csv(out / "indices.csv"), pd.read_csv(_csv(indices(points, meta))))
    pd.testing.assert_frame_equal(pd.read_csv(out / "region.csv"), pd.read_csv(_csv(region(points, meta))))
    md = (out / "bands.md").read_text()
    assert "motorway (default)" in md and "single-lane (previous)" in md and "Sweep: points where it holds" in md
    share = region(points, meta).set_index("name").loc["red", "value"]
    assert f"| {BAND_RED} | 1.00 | 50.00 (holds) | 39.00 (misses) | {100 * share:.0f} % |" in md
    text = (out / "sweep.md").read_text()
    assert meta["code_version"] in text and "What would have to be true" in text


def _csv(df: pd.DataFrame):
    import io

    from analysis.sweep.run import CSV

    buf = io.StringIO()
    df.to_csv(buf, **CSV)
    buf.seek(0)
    return buf


def test_sweep_step_says_when_the_sweep_is_stale_or_missing(tmp_path):
    sweep = tmp_path / "sweep-data"
    shutil.copytree(REPO / "data" / "sweep", sweep)
    meta = json.loads((sweep / "sweep.json").read_text())
    meta["code_version"] = "0000000000000000"
    (sweep / "sweep.json").write_text(json.dumps(meta))
    cfg = ReportConfig(out=tmp_path / "rep", db=tmp_path / "s.duckdb", sweep_dir=sweep)
    sweep_step(cfg)
    text = (cfg.out / "sweep" / "sweep.md").read_text()
    assert "0000000000000000" in text and "may be stale" in text
    assert not (cfg.out / "sweep" / "bands.md").exists()  # no drive analysis to set beside
    cfg = ReportConfig(out=tmp_path / "rep2", db=tmp_path / "s.duckdb", sweep_dir=tmp_path / "none")
    sweep_step(cfg)
    assert "no committed what-if sweep" in skipped_reason(cfg.out / "sweep")

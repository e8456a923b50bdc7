"""The report's cache goes beside its output folder unless --cache-dir says otherwise: an installed tool run from a
lab's folder writes nothing into the package."""
from __future__ import annotations

from pathlib import Path

from analysis.report.build import ReportConfig


def test_the_cache_defaults_to_beside_the_output_folder(tmp_path):
    cfg = ReportConfig(out=tmp_path / "lab" / "reports", db=tmp_path / "lab" / "study.duckdb")
    assert cfg.cache_dir == tmp_path / "lab" / ".report-cache"
    assert ReportConfig(out=tmp_path / "r", db=tmp_path / "s.duckdb", cache_dir=Path("/elsewhere")).cache_dir == \
        Path("/elsewhere")

"""The objective reproduction bands of the same reference cohort driven in several traffic scenarios, side by side.

Input per scenario: the ``bands.csv`` and ``band_diagnostics.csv`` that :func:`analysis.drives.analyze.analyze_drives`
writes for a store of simulated drives. Output: tidy frames (one row per band or diagnostic and scenario) and one
table each (Markdown and LaTeX) with a column per scenario, the first scenario given being the default.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

BAND_COLUMNS = ["band", "scenario", "paper_value", "our_value", "holds", "note"]
DIAG_COLUMNS = ["band", "key", "quantity", "unit", "scenario", "baseline", "pedas"]


def read_scenario(drives_dir: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(bands, diagnostics) of one scenario's drive analysis folder."""
    return pd.read_csv(drives_dir / "bands.csv"), pd.read_csv(drives_dir / "band_diagnostics.csv")


def bands_by_scenario(per_scenario: dict[str, tuple[pd.DataFrame, pd.DataFrame]]) -> tuple[pd.DataFrame,
                                                                                            pd.DataFrame]:
    """(bands, diagnostics) of every scenario in one tidy frame each (columns BAND_COLUMNS / DIAG_COLUMNS), in the
    order of `per_scenario` and of its bands."""
    bands = pd.concat([b.assign(scenario=name) for name, (b, _) in per_scenario.items()], ignore_index=True)
    diag = pd.concat([d.assign(scenario=name) for name, (_, d) in per_scenario.items()], ignore_index=True)
    return bands[BAND_COLUMNS], diag[DIAG_COLUMNS]


def _num(x: float, unit: str = "") -> str:
    if pd.isna(x):
        return "–"
    return f"{x:.0f}" if unit in ("drives", "stops") else f"{x:.1f}" if unit == "km/h" else f"{x:.2f}"


def bands_table(bands: pd.DataFrame, labels: dict[str, str] | None = None) -> tuple[list[str], list[list[str]]]:
    """(header, rows): Band | Paper | one column per scenario ("value (holds|misses)")."""
    names = list(dict.fromkeys(bands["scenario"]))
    labels = labels or {}
    rows = []
    for band, g in bands.groupby("band", sort=False):
        by = g.set_index("scenario")
        rows.append([band, _num(g["paper_value"].iloc[0])]
                    + [f"{_num(by.loc[n, 'our_value'])} ({'holds' if bool(by.loc[n, 'holds']) else 'misses'})"
                       if n in by.index else "–" for n in names])
    return ["Band", "Paper", *(labels.get(n, n) for n in names)], rows


def diagnostics_table(diag: pd.DataFrame, labels: dict[str, str] | None = None) -> tuple[list[str], list[list[str]]]:
    """(header, rows): Band | Quantity | Unit | baseline and pEDAS per scenario."""
    names = list(dict.fromkeys(diag["scenario"]))
    labels = labels or {}
    rows = []
    for _, g in diag.groupby("key", sort=False):
        by = g.set_index("scenario")
        first = g.iloc[0]
        cells = []
        for n in names:
            cells += [_num(by.loc[n, "baseline"], first.unit), _num(by.loc[n, "pedas"], first.unit)] \
                if n in by.index else ["–", "–"]
        rows.append([first.band, first.quantity, first.unit, *cells])
    head = [h for n in names for h in (f"{labels.get(n, n)}: baseline", f"{labels.get(n, n)}: pEDAS")]
    return ["Band", "Quantity", "Unit", *head], rows


def write_comparison(out: Path, per_scenario: dict[str, tuple[pd.DataFrame, pd.DataFrame]],
                     labels: dict[str, str] | None = None) -> list[Path]:
    """bands and band_diagnostics of the side-by-side comparison in `out`: the tidy frame as .csv, the table with
    a column per scenario as .md and .tex; the files."""
    from analysis.render import latex_table, markdown_table

    bands, diag = bands_by_scenario(per_scenario)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for stem, df, (header, rows), title in (
            ("bands", bands, bands_table(bands, labels), "Reproduction bands by traffic scenario"),
            ("band_diagnostics", diag, diagnostics_table(diag, labels), "Behind the bands, by traffic scenario")):
        df.to_csv(out / f"{stem}.csv", index=False, lineterminator="\n", float_format="%.12g")
        (out / f"{stem}.md").write_text(markdown_table(header, rows, title), encoding="utf-8")
        (out / f"{stem}.tex").write_text(latex_table(header, rows, title, label=f"tab:scenarios_{stem}"),
                                         encoding="utf-8")
        files += [out / f"{stem}.{ext}" for ext in ("csv", "md", "tex")]
    return files

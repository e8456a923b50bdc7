"""What the drives step writes about the study's shipped standard measures (docs/measures.md): the methods
sentences J2944 asks a report to carry, and the measures per region of interest (per drive, and by region and
condition as mean (SD) with n)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd


def methods_sentences(spec) -> list[str]:
    """One sentence per declared measure (:class:`study.folder.kpi_spec.MeasureKpi`): what it is, with the options
    used and its source; then one per region of interest."""
    out = [m.sentence() for m in spec.measures]
    if spec.regions:
        out.append("Regions of interest: " + "; ".join(f"{r.name}, {r.text()}" for r in spec.regions)
                   + ". A drive that does not reach a region (fewer than two samples in it) has no value there.")
    return out


def region_values(st, result) -> pd.DataFrame:
    """participant_id, condition, drive_id, region, one column per measure: the measures of every analysed drive
    (those of ``result.kpis``) in every declared region (NaN where the drive does not reach it)."""
    from analysis.drives.measures import measure_kpis

    spec = result.spec
    _, reg = measure_kpis(st.con, "drive_samples", spec.measures, spec.regions)
    drives = result.kpis[["participant_id", "condition", "drive_id"]].drop_duplicates()
    return drives.merge(reg, on="drive_id", how="inner").sort_values(["region", "condition", "participant_id"],
                                                                     kind="stable").reset_index(drop=True)


def region_summary(values: pd.DataFrame, spec) -> pd.DataFrame:
    """region, condition, then per measure n, mean and SD (n - 1) over the drives that reach the region."""
    rows = []
    regions = [r.name for r in spec.regions]
    for (region, condition), g in values.groupby(["region", "condition"], sort=False):
        row = {"region": region, "condition": condition}
        for m in spec.measures:
            x = g[m.name].dropna()
            row.update({f"{m.name}_n": len(x), f"{m.name}_mean": x.mean() if len(x) else np.nan,
                        f"{m.name}_sd": x.std(ddof=1) if len(x) > 1 else np.nan})
        rows.append(row)
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    return out.sort_values("region", key=lambda s: s.map(regions.index), kind="stable").reset_index(drop=True)


def _cells(summary: pd.DataFrame, spec) -> tuple[list[str], list[list[str]]]:
    header = ["Region", "Condition"] + [f"{m.heading} mean (SD), n" for m in spec.measures]

    def cell(row, m) -> str:
        n, mean, sd = int(row[f"{m.name}_n"]), row[f"{m.name}_mean"], row[f"{m.name}_sd"]
        if not n:
            return "–"
        d = spec.decimals(m.name)  # rounded for reading; region_summary.csv keeps the full value
        return f"{mean:.{d}f} ({'–' if np.isnan(sd) else f'{sd:.{d}f}'}), {n}"

    return header, [[r["region"], r["condition"]] + [cell(r, m) for m in spec.measures]
                     for _, r in summary.iterrows()]


def write_measure_tables(st, result, out_dir: str | Path) -> list[Path]:
    """regions.csv (per drive) and region_summary.{csv,md,tex} when the study declares measures and regions, and
    measures_methods.md (the methods sentences) when it declares measures; returns the paths written."""
    from analysis.drives.tables import kpi_markdown
    from analysis.render import latex_table

    spec = result.spec
    out = Path(out_dir)
    written = []
    if not spec.measures:
        return written
    methods = out / "measures_methods.md"
    methods.write_text("## Drive measures (methods)\n\n" + "\n\n".join(methods_sentences(spec)) + "\n",
                       encoding="utf-8")
    written.append(methods)
    if not spec.regions:
        return written
    values = region_values(st, result)
    values.to_csv(out / "regions.csv", index=False, float_format="%.12g")
    summary = region_summary(values, spec)
    summary.to_csv(out / "region_summary.csv", index=False, float_format="%.12g")
    header, rows = _cells(summary, spec)
    title = "Drive measures by region of interest, mean (SD), n drives"
    note = ("n counts the drives with a value: a drive that does not reach a region (or has no event there) has "
            "none, nor has one where the measure is undefined (e.g. no closing in on a lead vehicle for TTC).")
    (out / "region_summary.md").write_text(kpi_markdown(header, rows, title, (note,), text_columns=2),
                                           encoding="utf-8")
    (out / "region_summary.tex").write_text(latex_table(header, rows, title, (note,), "tab:measure_regions",
                                                        align="ll" + "r" * len(spec.measures)), encoding="utf-8")
    return written + [out / f for f in ("regions.csv", "region_summary.csv", "region_summary.md",
                                        "region_summary.tex")]

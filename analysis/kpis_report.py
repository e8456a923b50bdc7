"""`analyze drives`: the whole objective evaluation of a store into one directory — KPI and effect tables
(CSV/Markdown/LaTeX), the reproduction bands, Figures 9-12 and a short `objective.md` that links them."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.band_diagnostics import band_diagnostics, diagnostics_markdown
from analysis.figures_drives import write_figures
from analysis.savings import ObjectiveResult, objective_results, reproduction_bands
from analysis.tables_drives import bands_markdown, kpi_markdown, style_cells, style_table, write_tables


@dataclass
class DrivesReport:
    """What :func:`analyze_drives` produced."""
    result: ObjectiveResult
    bands: pd.DataFrame
    files: list[Path]
    figures: dict
    out: Path

    def text(self) -> str:
        r = self.result
        lines = [f"objective analysis: {r.n} participants with both drives "
                 f"({len(r.excluded)} excluded, {len(r.incomplete)} without a complete pair)"]
        h, rows = style_cells(style_table(r.summary))
        lines.append(kpi_markdown(h, rows, "By driving style, mean (median) %").rstrip())
        lines.append(bands_markdown(self.bands).rstrip())
        skipped = {k: v for k, v in self.figures.items() if isinstance(v, str)}
        for k, v in skipped.items():
            lines.append(f"{k} not drawn: {v}")
        lines.append(f"{len(self.files)} files in {self.out}")
        return "\n\n".join(lines)


def analyze_drives(st, out_dir: str | Path, participant: str = "P006", params=None) -> DrivesReport:
    """Compute KPIs, effects, summary and bands from the store ``st`` and write everything to ``out_dir``.
    A store without any drive is refused (ValueError) and nothing is written."""
    n_drives = st.con.execute("SELECT count(*) FROM drives").fetchone()[0]
    if not n_drives:
        raise ValueError("the store has no drives; import or simulate drives first")
    out = Path(out_dir)
    result = objective_results(st, params)
    bands = reproduction_bands(result.summary)
    files = write_tables(result, out)
    bands.to_csv(out / "bands.csv", index=False)
    diag = band_diagnostics(st, result, params)
    diag.to_csv(out / "band_diagnostics.csv", index=False, float_format="%.12g")
    files += [out / "bands.csv", out / "band_diagnostics.csv"]
    figures = write_figures(st, result, out / "figures", participant)
    for v in figures.values():
        if not isinstance(v, str):
            files.extend(v)
    rep = DrivesReport(result, bands, files, figures, out)
    md = ["# Objective evaluation", "",
          f"Participants with both drives: {result.n}. Excluded (objective scope): "
          f"{', '.join(result.excluded) or 'none'}. Without a complete pair: {', '.join(result.incomplete) or 'none'}.",
          "", (out / "style_table.md").read_text(encoding="utf-8"), bands_markdown(bands),
          diagnostics_markdown(diag), "## Figures", ""]
    for k, v in figures.items():
        md.append(f"- {k}: " + (f"not drawn ({v})" if isinstance(v, str)
                                 else ", ".join(f"[{p.name}](figures/{p.name})" for p in v)))
    (out / "objective.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    files.append(out / "objective.md")
    return rep

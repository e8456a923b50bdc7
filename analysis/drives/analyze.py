"""`analyze drives`: the whole objective evaluation of a store into one directory, as the study declares it
(study.folder.kpi_spec) — KPI and summary tables (CSV/Markdown/LaTeX); with a comparison the effect tables, Figures
9-12 and, where declared, the reproduction bands; a short `objective.md` that links them."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.drives.band_diagnostics import band_diagnostics, diagnostics_markdown
from analysis.drives.figures import write_figures
from analysis.drives.kpis import energy_note
from analysis.drives.measure_tables import write_measure_tables
from analysis.drives.paired import write_paired
from analysis.drives.savings import ObjectiveResult, objective_results, reproduction_bands, study_published
from analysis.drives.tables import (_summary_cells, _texts, bands_markdown, kpi_markdown, kpi_summary_table,
                                    style_cells, style_table, write_tables)


@dataclass
class DrivesReport:
    """What :func:`analyze_drives` produced (``bands`` None when the study declares none)."""
    result: ObjectiveResult
    bands: pd.DataFrame | None
    files: list[Path]
    figures: dict
    out: Path

    def text(self) -> str:
        r = self.result
        comparison = r.spec.comparison
        if comparison is None:
            lines = [f"objective analysis: {r.n} participants with drives ({len(r.excluded)} excluded)"]
            t = kpi_summary_table(r.summary)
            h, rows = _summary_cells(t, r.spec)
            lines.append(kpi_markdown(h, rows, "KPIs per drive, mean (SD)",
                                      text_columns=list(t.columns).index("n")).rstrip())
        else:
            lines = [f"objective analysis: {r.n} participants with both drives "
                     f"({len(r.excluded)} excluded, {len(r.incomplete)} without a complete pair)"]
            h, rows = style_cells(style_table(r.summary, comparison), comparison)
            title = _texts(comparison)["title"].split(",")[0].replace("Objective KPIs by", "By")
            lines.append(kpi_markdown(h, rows, f"{title}, mean (median) %").rstrip())
        if self.bands is not None:
            lines.append(bands_markdown(self.bands).rstrip())
        regions = self.out / "region_summary.md"
        if regions in self.files:
            lines.append(regions.read_text(encoding="utf-8").rstrip())
        note = energy_note(r.energy_sources)
        if note:
            lines.append(note)
        skipped = {k: v for k, v in self.figures.items() if isinstance(v, str)}
        for k, v in skipped.items():
            lines.append(f"{k} not drawn: {v}")
        lines.append(f"{len(self.files)} files in {self.out}")
        return "\n\n".join(lines)


def _write_participant_replay(st, out: Path, participant: str, comparison) -> Path | None:
    """The replay page of `participant`'s drives (analysis.drives.replay), the treatment drive first, as
    ``replay_<participant>.html``; None when the participant has no drive."""
    from analysis.drives.replay import write_replay

    conds = [r[0] for r in st.con.execute("SELECT condition FROM drives WHERE participant_id = ? ORDER BY condition",
                                          [participant]).fetchall()]
    if not conds:
        return None
    first = comparison.treatment if comparison is not None and comparison.treatment in conds else conds[0]
    return write_replay(st, participant, first, out / f"replay_{participant}.html")


def analyze_drives(st, out_dir: str | Path, participant: str | None = None, params=None) -> DrivesReport:
    """Compute the declared KPIs and summaries from the store ``st`` and write everything to ``out_dir``; with a
    comparison also the effects, the figures and (when declared) the reproduction bands. ``participant``: whose
    drives Figs. 11-12 and the replay page show (default: the comparison's declared ``participant``; none: not
    drawn). A store without any drive is refused (ValueError) and nothing is written."""
    n_drives = st.con.execute("SELECT count(*) FROM drives").fetchone()[0]
    if not n_drives:
        raise ValueError("the store has no drives; import or simulate drives first")
    out = Path(out_dir)
    result = objective_results(st, params)
    comparison = result.spec.comparison
    if participant is None and comparison is not None:
        participant = comparison.participant
    files = write_tables(result, out)
    measure_files = write_measure_tables(st, result, out)
    files += measure_files
    bands = diag = None
    if comparison is not None and comparison.bands:
        bands = reproduction_bands(result.summary, study_published(st))
        bands.to_csv(out / "bands.csv", index=False)
        diag = band_diagnostics(st, result, result.spec.params if params is None else params)
        diag.to_csv(out / "band_diagnostics.csv", index=False, float_format="%.12g")
        files += [out / "bands.csv", out / "band_diagnostics.csv"]
    figures = write_figures(st, result, out / "figures", participant)
    # paired tests, CIs and d_z of each compared KPI, the condition x group ANOVA, the paired plots
    files += write_paired(result, out)
    for v in figures.values():
        if not isinstance(v, str):
            files.extend(v)
    rep = DrivesReport(result, bands, files, figures, out)
    if comparison is None:
        md = ["# Objective evaluation", "",
              f"Participants with drives: {result.n}. Excluded (objective scope): {', '.join(result.excluded) or 'none'}.",
              "", (out / "kpi_table.md").read_text(encoding="utf-8")]
    else:
        md = ["# Objective evaluation", "",
              f"Participants with both drives: {result.n}. Excluded (objective scope): "
              f"{', '.join(result.excluded) or 'none'}. Without a complete pair: "
              f"{', '.join(result.incomplete) or 'none'}.", "", (out / "style_table.md").read_text(encoding="utf-8")]
        if bands is not None:
            md += [bands_markdown(bands), diagnostics_markdown(diag)]
        if (out / "paired.md").exists():
            md += [(out / "paired.md").read_text(encoding="utf-8")]
    md += [p.read_text(encoding="utf-8") for p in measure_files if p.suffix == ".md"]
    note = energy_note(result.energy_sources)
    if note:
        md += [note[0].upper() + note[1:] + ".", ""]
    if figures:
        md += ["## Figures", ""]
    for k, v in figures.items():
        md.append(f"- {k}: " + (f"not drawn ({v})" if isinstance(v, str)
                                 else ", ".join(f"[{p.name}](figures/{p.name})" for p in v)))
    replay = None if participant is None else _write_participant_replay(st, out, participant, comparison)
    if replay is not None:
        files.append(replay)
        md += ["", f"Replay of {participant}'s drives (the participant of Figs. 11-12): [{replay.name}]({replay.name})"]
    (out / "objective.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    files.append(out / "objective.md")
    return rep

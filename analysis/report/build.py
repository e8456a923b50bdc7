"""`pedas-study report`: every table and figure, the audit, the reproduction verdict and one HTML document
(`index.html`, analysis.report.document), in one run, for the study the store serves.

Two modes:

* **reference** (the default store `data/study.duckdb`, or `--reference`): build the store for the paper's study
  (`init --study studies/pedas_paper`) from `data/reference/` (the reference cohort with its protocol events and
  exclusions, the reconstructed survey), simulate the cohort's drives in SUMO, analyse, audit the paper and compare
  with its published values.
* **lab** (`--db my.duckdb` without `--reference`): analyse the lab's own store, for the study it serves
  (`study.store.studies.definition`), as it is; the paper comparison only with `--compare-paper`.

What the study or its store does not have is skipped with a stated reason instead of failing the run: no survey
answers (or no instrument or model file) -> no survey analysis; no drives -> no drive KPIs; no published values of
the paper -> no audit and no reproduction; conditions the simulator does not drive -> no simulation-core figures.
A step that skips writes its reason into `skipped.txt` of its folder; the document shows every reason.

Steps are cached by a hash of their inputs (data, parameters, code): a second run with nothing changed only re-renders
the document; changing one survey answer rebuilds the store (drives come from the drive cache) and reruns the analyses,
not the simulation. Progress goes to stderr per step with its time; a failing step is named and earlier outputs stay.
"""
from __future__ import annotations

import json
import shutil
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import pandas as pd

from analysis.render import write_table
from analysis.report.pipeline import Pipeline, Step, StepResult
from pedas.paths import NETWORK_DIR, REFERENCE_DIR, REPO_ROOT
from pedas.scenario import DEFAULT_SCENARIO, SINGLE_LANE
from study.common.errors import UserError

CODE = {name: REPO_ROOT / name for name in ("study", "pedas", "analysis")}
#: the one-line reason a step that skipped writes into its output folder
SKIPPED = "skipped.txt"


@dataclass
class ReportConfig:
    out: Path
    db: Path
    reference: bool = True
    compare_paper: bool = True
    participants: int | None = None   # reduced reference cohort (first N included participants), for quick runs
    workers: int | None = None
    scheduler: str | None = None
    seed: int = 0
    n_boot: int = 2000
    force: bool = False
    # step and drive cache; None: `.report-cache` beside the output folder (so an installed tool writes nothing into
    # its package: `make report` in a checkout gets <checkout>/.report-cache as before)
    cache_dir: Path | None = None
    reference_dir: Path = REFERENCE_DIR
    scenario: str = DEFAULT_SCENARIO  # the traffic scenario of the reference cohort's drives (pedas.scenario)
    # reference mode: the same cohort also driven in this scenario, its bands beside the default's (None: not)
    compare_scenario: str | None = SINGLE_LANE
    # the committed what-if sweep the report re-analyses (`make sweep`, docs/sweep.md)
    sweep_dir: Path = field(default_factory=lambda: REPO_ROOT / "data" / "sweep")

    def __post_init__(self) -> None:
        if self.cache_dir is None:
            self.cache_dir = Path(self.out).resolve().parent / ".report-cache"

    def comparison_db(self) -> Path:
        """The store of the comparison scenario's drives, beside `db`."""
        return self.db.with_name(f"{self.db.stem}-{self.compare_scenario}{self.db.suffix}")

    def compares(self) -> bool:
        """Reference mode with a comparison scenario other than the default."""
        return self.reference and self.compare_scenario not in (None, self.scenario)


@dataclass
class ReportResult:
    out: Path
    steps: list[StepResult]
    files: list[Path]
    verdict: dict
    skipped: dict[str, str] = field(default_factory=dict)   # part of the report -> why it was not produced


# ---------------------------------------------------------------------------------------------- step bodies
def _open_store(cfg: ReportConfig, read_only: bool = False):
    from study.store.store import Store

    return Store.open(cfg.db, actor="report", read_only=read_only)


def drive_data_digest(db: Path) -> str:
    """sha256 of the store's data the drive analyses read (:func:`analysis.report.bundle.table_hashes` without the
    survey's tables, :data:`study.folder.occasions.OCCASION_TABLES`; the drive samples by their drives' checksums):
    a survey answer entered or changed leaves it, so the drive steps stay cached. "missing" when the store does not
    exist (the step then says why)."""
    from analysis.report.bundle import table_hashes
    from study.folder.occasions import OCCASION_TABLES
    from study.store.store import Store

    if not db.exists():
        return "missing"
    with Store.open(db, actor="report", read_only=True) as st:
        return table_hashes(st, skip=frozenset({*OCCASION_TABLES, "drive_samples"}))["sha256"].iloc[-1]


def load_reference(st, ref_dir: Path = REFERENCE_DIR) -> None:
    """Load the reference study inputs into an open store: the paper's study (as `init --study
    studies/pedas_paper`; unchanged when the store already serves it, UserError when it serves another study),
    participants and protocol events with exclusions (`participants.csv`, `events.csv`) and the reconstructed
    survey (`survey.csv`), each import all or nothing."""
    from analysis.paper.published import PAPER_STUDY_DIR
    from analysis.paper.reference_cohort import Cohort, load_into_store
    from study.store.studies import register
    from study.survey.survey_import import import_survey

    register(st, PAPER_STUDY_DIR)
    participants = pd.read_csv(ref_dir / "participants.csv", dtype={"participant_id": str})
    events = pd.read_csv(ref_dir / "events.csv", dtype=str, keep_default_na=False)
    load_into_store(st, Cohort(participants, events, seed=-1))
    import_survey(st, ref_dir / "survey.csv")


def build_reference_store(cfg: ReportConfig, scenario: str | None = None, db: Path | None = None) -> None:
    """Create the store `db` (default `cfg.db`) from data/reference and the drives simulated in the traffic
    `scenario` (default `cfg.scenario`), written to a temporary file, then moved.

    With `cfg.participants`, only the first N participants of the objective sample are driven (a reduced cohort
    for quick runs); every participant and survey answer is loaded regardless.
    """
    from pedas.cohort import cohort_tasks, simulate_cohort
    from study.people.exclusions import included_participants
    from study.logs.simulated import participants_to_simulate, store_simulated
    from study.store.store import Store

    db = Path(db or cfg.db)
    tmp = db.with_name(db.name + ".building")
    for p in (tmp, tmp.with_name(tmp.name + ".wal")):
        p.unlink(missing_ok=True)
    with Store.open(tmp, actor="report") as st:
        load_reference(st, cfg.reference_dir)
        drivers = sorted(included_participants(st, "objective"))[:cfg.participants]
        # the same who-and-how as `simulate cohort`: tasks by participant id, baseline before pedas
        tasks = cohort_tasks(participants_to_simulate(st, drivers), base_seed=cfg.seed,
                             scenario=scenario or cfg.scenario)
        logs = simulate_cohort(tasks, workers=cfg.workers, scheduler=cfg.scheduler,
                               cache_dir=cfg.cache_dir / "drives")
        with st.transaction():
            store_simulated(st, tasks, logs)
    db.parent.mkdir(parents=True, exist_ok=True)
    for p in (db, db.with_name(db.name + ".wal")):
        p.unlink(missing_ok=True)
    tmp.replace(db)


@contextmanager
def _fresh_dir(out: Path) -> Iterator[Path]:
    """A new, empty folder beside `out` to write a step's outputs into; it replaces `out` only when the block
    ends without an error, so a failing step leaves its previous outputs as they were."""
    new = out.with_name(out.name + ".new")
    shutil.rmtree(new, ignore_errors=True)
    new.mkdir(parents=True)
    try:
        yield new
    except BaseException:
        shutil.rmtree(new, ignore_errors=True)
        raise
    shutil.rmtree(out, ignore_errors=True)
    new.replace(out)


def skipped_reason(folder: Path) -> str | None:
    """The reason a step gave for skipping (its folder's skipped.txt), None when it produced its outputs."""
    f = folder / SKIPPED
    return f.read_text(encoding="utf-8").strip() if f.is_file() else None


def survey_missing(st, study) -> str | None:
    """Why the store's survey cannot be analysed (no instrument, no model file, no answers), None when it can."""
    from analysis.survey.acceptance import responses_from_store

    if not study.instruments:
        return f"study {study.study_id} declares no survey instrument ([files] instrument)"
    if study.model is None:
        return f"study {study.study_id} declares no analysis model ([files] model)"
    if responses_from_store(st).empty:
        return "the store has no survey answers of included participants"
    return None


def _covariates(st, study, index) -> pd.DataFrame:
    """The covariate columns the study's regressions use, for the participants in `index` (none: no columns)."""
    from analysis.survey.acceptance import attributes_from_store, covariate_frame, covariates_of

    names = covariates_of(study)
    return covariate_frame(attributes_from_store(st) if names else None, study, names, index)[0]


def survey_step(cfg: ReportConfig) -> None:
    from analysis.survey.acceptance import analyze_store
    from analysis.survey.statistics_tables import write_survey_statistics
    from study.store.studies import definition

    with _open_store(cfg, read_only=True) as st:
        study = definition(st)
        reason = survey_missing(st, study)
        if reason is None:
            try:
                res, responses = analyze_store(st, n_boot=cfg.n_boot, seed=cfg.seed or 20240101)
            except (ValueError, UserError) as exc:
                # too few rows for the CFA, a singular covariance matrix, ...: the part is skipped with its reason,
                # the rest of the report still runs
                reason = f"the survey analysis (CFA, reliability, regressions) cannot run: {exc}"
        pca = None
        if reason is None:
            if paper_idioms(study):
                # Table 3 the way the paper's SPSS FACTOR reported it (first principal component per construct),
                # beside our CFA; only the loadings differ, so no bootstrap, and the CFA fits are the ones above
                pca, _ = analyze_store(st, n_boot=0, seed=cfg.seed or 20240101, loadings="pca", reuse=res)
            ext, ext_reason = _extended_survey(st, study, responses, cfg, res)
            covariates = _covariates(st, study, res.composites.index)
    with _fresh_dir(cfg.out / "survey") as out:
        if reason is not None:
            (out / SKIPPED).write_text(reason + "\n", encoding="utf-8")
            return
        res.write(out)
        responses.to_csv(out / "responses.csv", index=False)
        # fit with the RMSEA interval, regression diagnostics, the path diagram (analysis.survey.statistics_tables)
        write_survey_statistics(res, out, covariates)
        if pca is not None:
            write_table3_pca(pca, out / "pca")
        # the extended statistics (docs/acceptance_statistics.md) in survey/extended/
        if ext is not None:
            ext.write(out / "extended")
        else:
            (out / "extended").mkdir()
            (out / "extended" / SKIPPED).write_text(ext_reason + "\n", encoding="utf-8")


def within_step(cfg: ReportConfig) -> None:
    """within/: the within-subjects comparison the study declares ([within]; analysis.within), or the reason it
    could not run."""
    from analysis.within.analyze import analyze_store_within

    with _open_store(cfg, read_only=True) as st:
        try:
            res, data = analyze_store_within(st)
            reason = None
        except UserError as exc:
            reason = f"within-subjects comparison: {exc}"
    with _fresh_dir(cfg.out / "within") as out:
        if reason is not None:
            (out / SKIPPED).write_text(reason + "\n", encoding="utf-8")
            return
        res.write(out, data)


def paper_idioms(study) -> bool:
    """Whether the study asks for the paper's idioms (``[analysis] paper_idioms = true``: the principal-component
    Table 3, Table 5's "Step 1: Dependent Variable" rows); no other study's report shows them."""
    return bool(study.settings.get("analysis", {}).get("paper_idioms", False))


def write_table3_pca(pca, out: Path) -> None:
    """survey/pca/: loadings.csv, reliability.csv and table3.{md,tex,csv} of the analysis with PCA loadings."""
    from analysis.survey.acceptance import CSV_FLOAT, stable_frame
    from analysis.survey.tables import render_table

    out.mkdir(parents=True, exist_ok=True)
    for name in ("loadings", "reliability"):
        stable_frame(getattr(pca, name)).to_csv(out / f"{name}.csv", index=False, lineterminator="\n",
                                                float_format=CSV_FLOAT)
    for fmt in ("md", "tex", "csv"):
        (out / f"table3.{fmt}").write_text(render_table(pca, "table3", fmt), encoding="utf-8")


def _extended_survey(st, study, responses, cfg, survey=None):
    """(ExtendedAnalysis, None) of the store's answers, or (None, the one-line reason it could not run); it
    builds on the `survey` analysis of the same answers (its CFA) when given."""
    from analysis.survey.acceptance import attributes_from_store
    from analysis.survey.extended import analyze_extended

    try:
        # one process: the report holds the store open, and forking beside it buys ~1 s at most
        return analyze_extended(responses, study, attributes=attributes_from_store(st), n_boot=cfg.n_boot,
                                seed=cfg.seed or 20240101, workers=1, survey=survey), None
    except ValueError as exc:
        return None, f"extended statistics: {exc}"


def drives_step(cfg: ReportConfig) -> None:
    from analysis.drives.analyze import analyze_drives

    with _open_store(cfg, read_only=True) as st, _fresh_dir(cfg.out / "drives") as out:
        if st.one("SELECT count(*) FROM drives"):
            analyze_drives(st, out)
        else:
            (out / "objective.md").write_text("# Objective evaluation\n\nThe store has no drives.\n")
            (out / SKIPPED).write_text("the store has no drives, so there are no drive KPIs\n", encoding="utf-8")


def scenarios_step(cfg: ReportConfig) -> None:
    """scenarios/: the drive analysis of the comparison scenario's store (in a folder named after it) and the
    bands and their diagnostics of the default and the comparison scenario side by side."""
    from analysis.drives.analyze import analyze_drives
    from analysis.drives.scenario_comparison import read_scenario, write_comparison
    from study.store.store import Store

    with _fresh_dir(cfg.out / "scenarios") as out:
        with Store.open(cfg.comparison_db(), actor="report", read_only=True) as st:
            analyze_drives(st, out / cfg.compare_scenario)
        per = {cfg.scenario: read_scenario(cfg.out / "drives"),
               cfg.compare_scenario: read_scenario(out / cfg.compare_scenario)}
        write_comparison(out, per, labels={cfg.scenario: f"{cfg.scenario} (default)",
                                           cfg.compare_scenario: f"{cfg.compare_scenario} (previous)"})


def sweep_step(cfg: ReportConfig) -> None:
    """sweep/: the committed what-if sweep (cfg.sweep_dir) re-analysed from its points: indices, region (tidy,
    .md, .tex), figures/sweep_indices, sweep.md (its paragraph), and bands.* (the bands of the default and the
    comparison scenario beside the share of sweep points where each holds); skipped.txt without a sweep."""
    from analysis.render import latex_table, markdown_table
    from analysis.sweep.design import CSV
    from analysis.sweep.run import read_run
    from analysis.sweep.sensitivity import bands_beside, summary_lines, write_analysis
    from pedas.cohort import code_version

    with _fresh_dir(cfg.out / "sweep") as out:
        if not (cfg.sweep_dir / "points.csv").exists():
            (out / SKIPPED).write_text(f"no committed what-if sweep in {cfg.sweep_dir} (make sweep)\n",
                                       encoding="utf-8")
            return
        _, points, meta = read_run(cfg.sweep_dir)
        ind, reg = write_analysis(out, points, meta)
        (out / "sweep.md").write_text("\n".join(summary_lines(ind, reg, meta, code_version())) + "\n",
                                      encoding="utf-8")
        folder = cfg.out / "scenarios" if (cfg.out / "scenarios" / "bands.csv").exists() else cfg.out / "drives"
        if not (folder / "bands.csv").exists():
            return
        bands = pd.read_csv(folder / "bands.csv")
        if "scenario" not in bands:
            bands = bands.assign(scenario=cfg.scenario)
        labels = {cfg.scenario: f"{cfg.scenario} (default)"}
        if cfg.compares():
            labels[cfg.compare_scenario] = f"{cfg.compare_scenario} (previous)"
        tidy, header, rows = bands_beside(bands, reg, labels)
        title = "Reproduction bands by traffic scenario and across the what-if sweep"
        tidy.to_csv(out / "bands.csv", **CSV)
        (out / "bands.md").write_text(markdown_table(header, rows, title), encoding="utf-8")
        (out / "bands.tex").write_text(latex_table(header, rows, title, label="tab:sweep_bands"), encoding="utf-8")


def audit_step(cfg: ReportConfig) -> None:
    from analysis.paper.audit import write_audit

    with _fresh_dir(cfg.out / "paper") as out:
        write_audit(out)


def reproduction_step(cfg: ReportConfig) -> None:
    """reproduction.csv / .md: Tables 3-5 value by value (status per value), the Section 5.1 KPI bands of the
    simulated cohort beside the paper's numbers, and the audit findings that explain what cannot be met."""
    from types import SimpleNamespace

    from analysis.paper.audit import findings
    from analysis.paper.reproduction import render_markdown, reproduce

    if skipped_reason(cfg.out / "survey") is not None:  # nothing to compare: the document says why
        for name in ("reproduction.csv", "reproduction.md"):
            (cfg.out / name).unlink(missing_ok=True)
        return
    # from the files the survey and audit steps wrote: the comparison reruns when either changes
    survey = SimpleNamespace(**{name: pd.read_csv(cfg.out / "survey" / f"{name}.csv")
                                for name in ("descriptives", "loadings", "reliability", "correlations", "regressions")})
    audit = pd.read_csv(cfg.out / "paper" / "audit.csv")
    pca_dir = cfg.out / "survey" / "pca"
    pca = SimpleNamespace(loadings=pd.read_csv(pca_dir / "loadings.csv")) if pca_dir.exists() else None
    table = reproduce(survey, audit=audit, paper_procedure=pca)
    table.to_csv(cfg.out / "reproduction.csv", index=False, lineterminator="\n", float_format="%.12g")
    md = [render_markdown(table, source="the reference survey in the study store").rstrip(), ""]
    bands = cfg.out / "drives" / "bands.csv"
    md += ["# Objective evaluation (Section 5.1) of the simulated reference cohort", ""]
    if bands.exists():
        from analysis.drives.band_diagnostics import diagnostics_markdown, why_missed
        from analysis.drives.tables import bands_markdown

        bands_df = pd.read_csv(bands)
        diag = pd.read_csv(bands.with_name("band_diagnostics.csv"))
        md += [bands_markdown(bands_df).rstrip(), "",
               "The drives are simulated by virtual participants whose parameters were chosen for realism, not "
               "tuned to these bands; a band that does not hold is reported as such, with what lies behind it:", "",
               diagnostics_markdown(diag).rstrip(), ""]
        md += [line for w in why_missed(bands_df, diag) for line in (f"- {w}", "")]
        md += _scenarios_markdown(cfg)
        md += _sweep_markdown(cfg)
    else:
        md += ["No drives in the store.", ""]
    md += ["# Audit findings", "", "Published values that contradict other published values "
           "(details: [paper/audit.md](paper/audit.md)).", ""]
    md += [f"{int(r.finding)}. {r.title}" for r in findings(audit).itertuples()]
    (cfg.out / "reproduction.md").write_text("\n".join(md) + "\n", encoding="utf-8")


def _scenarios_markdown(cfg: ReportConfig) -> list[str]:
    """The reproduction document's lines on the comparison scenario: the bands side by side, the diagnostics,
    and why each band the comparison scenario misses is missed (nothing without a comparison)."""
    from analysis.drives.band_diagnostics import why_missed

    folder = cfg.out / "scenarios"
    if not cfg.compares() or not (folder / "bands.md").exists():
        return []
    sub = folder / cfg.compare_scenario
    md = [f"## The same cohort in the {cfg.compare_scenario} scenario", "",
          f"Traffic scenarios: docs/route_and_traffic.md. The cohort above drove the {cfg.scenario} scenario; the "
          f"same virtual participants (same seeds) drove the {cfg.compare_scenario} scenario:", "",
          (folder / "bands.md").read_text(encoding="utf-8").rstrip(), "",
          (folder / "band_diagnostics.md").read_text(encoding="utf-8").rstrip(), ""]
    missed = why_missed(pd.read_csv(sub / "bands.csv"), pd.read_csv(sub / "band_diagnostics.csv"))
    if missed:
        md += [f"In the {cfg.compare_scenario} scenario:", ""]
        md += [line for w in missed for line in (f"- {w}", "")]
    return md


def _sweep_markdown(cfg: ReportConfig) -> list[str]:
    """The reproduction document's lines on the what-if sweep: the bands beside the sweep, its paragraph."""
    folder = cfg.out / "sweep"
    if not (folder / "sweep.md").exists():
        return []
    md = ["## What would have to be true: the what-if sweep", ""]
    if (folder / "bands.md").exists():
        md += [(folder / "bands.md").read_text(encoding="utf-8").rstrip(), ""]
    return md + [(folder / "sweep.md").read_text(encoding="utf-8").rstrip(), "",
                 "Table and figure: [sweep/indices.md](sweep/indices.md), [sweep/region.md](sweep/region.md), "
                 "figures/sweep_indices.png.", ""]


def core_figures_step(cfg: ReportConfig) -> None:
    from pedas.figures_core import plot_all
    from pedas.route_study import study_route

    plot_all(cfg.out / "figures", route=study_route())


def study_figures_step(cfg: ReportConfig) -> None:
    from analysis.report.figures import participant_flow, plot_likert, plot_participant_flow
    from study.store.studies import definition

    figs = cfg.out / "figures"
    with _open_store(cfg, read_only=True) as st:
        flow = participant_flow(st)
        study = definition(st)
    plot_participant_flow(flow, figs)
    write_table(flow.frame(), cfg.out / "tables", "participant_flow", "Participant flow")
    responses = cfg.out / "survey" / "responses.csv"
    if responses.exists() and study.instruments:
        plot_likert(pd.read_csv(responses, dtype={"participant_id": str}), study.instrument(), figs)


_RAW_DATA = {"responses", "composites"}  # data files, not tables to render


def _audit_table(frame: pd.DataFrame, out: Path, stem: str) -> None:
    from analysis.paper.audit import write_table_files

    write_table_files(frame, out, stem)


#: (part folder, CSV stem) -> the writer of a table the part lays out itself from its CSV (header words, cells as
#: printed) where the CSV's folder holds no table files of it: the audit (its audit.md is a whole report)
OWN_LAYOUT = {("paper", "audit"): _audit_table}


def collect_step(cfg: ReportConfig) -> None:
    """Every table into tables/ (csv, md, tex) and every figure into figures/."""
    tables, figs = cfg.out / "tables", cfg.out / "figures"
    tables.mkdir(parents=True, exist_ok=True)
    figs.mkdir(parents=True, exist_ok=True)
    for sub in ("survey", "survey/pca", "survey/extended", "drives", "within", "scenarios", "sweep", "paper"):
        d = cfg.out / sub
        if not d.exists():
            continue
        prefix = sub.replace("/", "_")
        for f in sorted(d.glob("*.csv")):
            if f.stem in _RAW_DATA:
                continue
            # a part's own rendering (paper-shaped tables, the audit's table) wins over the generic one
            shaped = [f.with_suffix(ext) for ext in (".md", ".tex") if f.with_suffix(ext).exists()]
            if (sub, f.stem) in OWN_LAYOUT:
                OWN_LAYOUT[(sub, f.stem)](pd.read_csv(f), tables, f"{prefix}_{f.stem}")
            elif len(shaped) == 2:
                for g in [f, *shaped]:
                    shutil.copy2(g, tables / f"{prefix}_{g.name}")
            else:
                frame = pd.read_csv(f)
                if {"a", "b"} <= set(frame.columns) and frame["a"].dtype == object:
                    # a pair of constructs (HTMT, bootstrap intervals): "b" is not the coefficient B here
                    frame = frame.rename(columns={"a": "Construct 1", "b": "Construct 2"})
                write_table(frame, tables, f"{prefix}_{f.stem}", f"{sub}: {f.stem}")
        for f in sorted((d / "figures").glob("*")) if (d / "figures").exists() else []:
            shutil.copy2(f, figs / f.name)


# ---------------------------------------------------------------------------------------------- the study
def _verdict(out: Path) -> dict:
    rep = out / "reproduction.csv"
    if not rep.exists():
        return {}
    df = pd.read_csv(rep)
    return {"counts": df["status"].value_counts().to_dict(), "miss": int((df["status"] == "miss").sum())}


def report_study(cfg: ReportConfig):
    """The study the report is about: the paper's in reference mode (its store is built from it), else the one the
    lab's store serves (a store without a study -> UserError saying how to add one)."""
    if cfg.reference:
        from analysis.paper.published import paper_study

        return paper_study()
    from study.store.studies import definition

    with _open_store(cfg, read_only=True) as st:
        return definition(st)


def comparison_skip(cfg: ReportConfig, study) -> str | None:
    """Why the paper audit and reproduction do not run for `study` (None when they do)."""
    from analysis.paper.published import paper_study

    if "published" not in study.paths:
        return f"study {study.study_id} declares no published values to compare with ([files] published)"
    if study.study_id != paper_study().study_id:
        return (f"the reproduction compares the paper's Tables 3-5 with its published values; study "
                f"{study.study_id} is not the paper's study")
    if not cfg.compare_paper:
        return "the comparison with the paper was not asked for (--compare-paper)"
    return None


def core_figures_apply(study) -> bool:
    """Whether the simulation core's figures belong to `study`'s report: only to a study whose conditions the
    simulator drives. For any other study the part does not exist (no step, no section, no skip line)."""
    from study.logs.simulated import check_simulable

    try:
        check_simulable(study)
    except UserError:
        return False
    return True


def within_applies(study) -> bool:
    """Whether the study declares a within-subjects comparison ([within]); without one the part does not exist."""
    from study.folder.within_spec import within_spec

    return within_spec(study) is not None


def absent_parts(study) -> set[str]:
    """Parts of the document the study's declaration rules out, shown not even as skipped (their steps still say
    why in the command's output and the steps table): the survey analysis without an instrument or a model file,
    the audit and reproduction without published values."""
    out = set()
    if not study.instruments or study.model is None:
        out.add("survey")
    if "published" not in study.paths:
        out |= {"audit", "reproduction"}
    return out


def planned_skips(cfg: ReportConfig, study) -> dict[str, str]:
    """Parts of the report that the study's declaration rules out before anything runs: part -> reason."""
    out = {}
    reason = comparison_skip(cfg, study)
    if reason:
        out["audit"] = out["reproduction"] = reason
    return out


def data_skips(cfg: ReportConfig) -> dict[str, str]:
    """Parts skipped because the store lacks their data, as the steps recorded them: part -> reason."""
    out = {}
    for part in ("survey", "drives", "within"):
        reason = skipped_reason(cfg.out / part)
        if reason:
            out[part] = reason
    if "survey" in out:
        out.setdefault("reproduction", f"needs the survey analysis, which was skipped: {out['survey']}")
    return out


# ---------------------------------------------------------------------------------------------- the pipeline
def build_pipeline(cfg: ReportConfig, study=None) -> Pipeline:
    """The report's steps for `study` (default :func:`report_study`); parts its declaration rules out
    (:func:`planned_skips`) have no step."""
    from analysis.paper.published import PAPER_STUDY_DIR

    study = study if study is not None else report_study(cfg)
    skips = planned_skips(cfg, study)
    cache = cfg.cache_dir / ("report-" + ("reference" if cfg.reference else "lab"))
    pipe = Pipeline(cache)
    params = json.dumps({"participants": cfg.participants, "seed": cfg.seed, "n_boot": cfg.n_boot,
                         "db": str(cfg.db.resolve()), "out": str(cfg.out.resolve()), "scenario": cfg.scenario,
                         "compare_scenario": cfg.compare_scenario if cfg.compares() else None}, sort_keys=True)
    store_inputs: list = [cfg.db]
    if cfg.reference:
        from pedas.network import build_network

        sources = sorted(p for p in NETWORK_DIR.rglob("*") if p.suffix in (".xml", ".json", ".netccfg")
                         and NETWORK_DIR / "build" not in p.parents)
        scenarios = [cfg.scenario] + ([cfg.compare_scenario] if cfg.compares() else [])
        pipe.add(Step("network", lambda: [build_network(scenario=s) for s in scenarios],
                      inputs=[*sources, CODE["pedas"] / "network.py", CODE["pedas"] / "scenario.py", params]))
        # the store is built by this module and analysis.paper.reference_cohort besides study/ and pedas/, for the
        # paper's study folder
        store_code = [cfg.reference_dir, PAPER_STUDY_DIR, CODE["study"], CODE["pedas"], Path(__file__),
                      CODE["analysis"] / "paper" / "reference_cohort.py", params]
        pipe.add(Step("store", lambda: build_reference_store(cfg), after=["network"], outputs=[cfg.db],
                      inputs=store_code))
        if cfg.compares():
            pipe.add(Step("comparison store", lambda: build_reference_store(cfg, cfg.compare_scenario,
                                                                            cfg.comparison_db()),
                          after=["network"], outputs=[cfg.comparison_db()], inputs=store_code))
        store_inputs = []
    after_store = ["store"] if cfg.reference else []
    pipe.add(Step("survey", lambda: survey_step(cfg), outputs=[cfg.out / "survey"], after=after_store,
                  inputs=[*store_inputs, CODE["analysis"], params]))
    # the drive parts hash the store's drive data, not the store: a changed survey answer leaves them cached
    drive_code = [CODE["analysis"], CODE["study"], CODE["pedas"], params]
    pipe.add(Step("drives", lambda: drives_step(cfg), outputs=[cfg.out / "drives"],
                  inputs=[lambda: drive_data_digest(cfg.db), *drive_code]))
    if within_applies(study):
        pipe.add(Step("within", lambda: within_step(cfg), outputs=[cfg.out / "within"], after=after_store,
                      inputs=[*store_inputs, CODE["analysis"], params]))
    if cfg.compares():
        pipe.add(Step("scenarios", lambda: scenarios_step(cfg), outputs=[cfg.out / "scenarios"], after=["drives"],
                      inputs=[lambda: drive_data_digest(cfg.comparison_db()), *drive_code]))
    if cfg.reference:
        # the committed sweep, re-analysed; the simulation code's version says whether it is stale
        pipe.add(Step("sweep", lambda: sweep_step(cfg), outputs=[cfg.out / "sweep"],
                      after=["drives", *(["scenarios"] if cfg.compares() else [])],
                      inputs=[cfg.sweep_dir, CODE["analysis"], CODE["pedas"], *sources, params]))
    if "audit" not in skips:
        # the audit's bootstrap check of finding #8 runs on the shipped reconstruction
        pipe.add(Step("audit", lambda: audit_step(cfg), outputs=[cfg.out / "paper"],
                      inputs=[PAPER_STUDY_DIR, REFERENCE_DIR / "survey.csv", CODE["analysis"], params]))
        pipe.add(Step("reproduction", lambda: reproduction_step(cfg),
                      after=["survey", "drives", "audit", *(["scenarios"] if cfg.compares() else []),
                             *(["sweep"] if cfg.reference else [])],
                      outputs=[cfg.out / "reproduction.md", cfg.out / "reproduction.csv"],
                      inputs=[CODE["analysis"], params]))
    if core_figures_apply(study):
        pipe.add(Step("core figures", lambda: core_figures_step(cfg),
                      outputs=[cfg.out / "figures" / "aero_linearisation.png"],
                      inputs=[CODE["pedas"], params]))
    pipe.add(Step("study figures", lambda: study_figures_step(cfg), after=["survey", *after_store],
                  outputs=[cfg.out / "figures" / "participant_flow.png"],
                  inputs=[*store_inputs, CODE["analysis"], params]))
    pipe.add(Step("collect", lambda: collect_step(cfg), always=True))
    return pipe


def run_report(cfg: ReportConfig) -> ReportResult:
    """Run the pipeline for the report's study and render the document (index.html, analysis.report.document); returns
    what ran, what was skipped and why, and the reproduction verdict."""
    from analysis.report.document import render_document
    from analysis.report.manuscript import write_manuscript

    study = report_study(cfg)
    cfg.out.mkdir(parents=True, exist_ok=True)
    steps = build_pipeline(cfg, study).run(force=cfg.force)
    skipped = {**data_skips(cfg), **planned_skips(cfg, study)}  # a declared reason comes first
    with _open_store(cfg, read_only=True) as st:
        render_document(cfg.out, st, steps, skipped,
                        mode="reference study" if cfg.reference else "lab store", store_name=cfg.db.name,
                        core=core_figures_apply(study), absent=absent_parts(study))
    write_manuscript(cfg.out)  # the document's numbered tables and figures as Word and LaTeX
    files = sorted(p for p in cfg.out.rglob("*") if p.is_file())
    return ReportResult(cfg.out, steps, files, _verdict(cfg.out), skipped)

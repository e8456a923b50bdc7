"""`pedas-study report`: every table and figure, the audit, the reproduction verdict and an HTML index, in one run.

Two modes:

* **reference** (the default store `data/study.duckdb`, or `--reference`): build the store from `data/reference/` (the
  reference cohort with its protocol events and exclusions, the reconstructed survey), simulate the cohort's drives in
  SUMO, analyse, audit the paper and compare with its published values.
* **lab** (`--db my.duckdb` without `--reference`): analyse the lab's own store as it is; the paper comparison only with
  `--compare-paper`.

Steps are cached by a hash of their inputs (data, parameters, code): a second run with nothing changed only re-renders
the index; changing one survey answer rebuilds the store (drives come from the drive cache) and reruns the analyses,
not the simulation. Progress goes to stderr per step with its time; a failing step is named and earlier outputs stay.
"""
from __future__ import annotations

import html
import json
import shutil
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import pandas as pd

from analysis.pipeline import Pipeline, Step, StepResult
from analysis.render import write_table
from pedas.paths import NETWORK_DIR, PAPER_DIR, REFERENCE_DIR, REPO_ROOT

CODE = {name: REPO_ROOT / name for name in ("study", "pedas", "analysis")}


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
    cache_dir: Path = field(default_factory=lambda: REPO_ROOT / ".report-cache")
    reference_dir: Path = REFERENCE_DIR


@dataclass
class ReportResult:
    out: Path
    steps: list[StepResult]
    files: list[Path]
    verdict: dict


# ---------------------------------------------------------------------------------------------- step bodies
def _open_store(cfg: ReportConfig, read_only: bool = False):
    from study.store import Store

    return Store.open(cfg.db, actor="report", read_only=read_only)


def load_reference(st, ref_dir: Path = REFERENCE_DIR) -> None:
    """Load the reference study inputs into an open store: participants and protocol events with exclusions
    (`participants.csv`, `events.csv`) and the reconstructed survey (`survey.csv`), each import all or nothing."""
    from analysis.paper.reference_cohort import Cohort, load_into_store
    from study.survey_import import import_survey

    participants = pd.read_csv(ref_dir / "participants.csv", dtype={"participant_id": str})
    events = pd.read_csv(ref_dir / "events.csv", dtype=str, keep_default_na=False)
    load_into_store(st, Cohort(participants, events, seed=-1))
    import_survey(st, ref_dir / "survey.csv")


def build_reference_store(cfg: ReportConfig) -> None:
    """Create the store from data/reference and the simulated drives (written to a temporary file, then moved).

    With `cfg.participants`, only the first N participants of the objective sample are driven (a reduced cohort
    for quick runs); every participant and survey answer is loaded regardless.
    """
    from pedas.cohort import cohort_tasks, simulate_cohort
    from study.drives import import_drive_frame
    from study.exclusions import included_participants
    from study.store import Store

    tmp = cfg.db.with_name(cfg.db.name + ".building")
    for p in (tmp, tmp.with_name(tmp.name + ".wal")):
        p.unlink(missing_ok=True)
    with Store.open(tmp, actor="report") as st:
        load_reference(st, cfg.reference_dir)
        drivers = sorted(included_participants(st, "objective"))[:cfg.participants]
        people = st.df("SELECT participant_id, style FROM participants ORDER BY participant_id")
        people = people[people["participant_id"].isin(drivers)]
        logs = simulate_cohort(cohort_tasks(people, base_seed=cfg.seed), workers=cfg.workers,
                               scheduler=cfg.scheduler, cache_dir=cfg.cache_dir / "drives")
        with st.transaction():
            for (pid, condition), df in sorted(logs.items()):
                import_drive_frame(st, pid, condition, df, source="simulation", route="study_13k2")
    cfg.db.parent.mkdir(parents=True, exist_ok=True)
    for p in (cfg.db, cfg.db.with_name(cfg.db.name + ".wal")):
        p.unlink(missing_ok=True)
    tmp.replace(cfg.db)


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


def survey_step(cfg: ReportConfig) -> None:
    from analysis.acceptance import analyze_survey, responses_from_store

    with _open_store(cfg, read_only=True) as st:
        responses = responses_from_store(st)
    if responses.empty:
        raise ValueError("the store has no survey answers of included participants")
    res = analyze_survey(responses, n_boot=cfg.n_boot, seed=cfg.seed or 20240101)
    with _fresh_dir(cfg.out / "survey") as out:
        res.write(out)
        responses.to_csv(out / "responses.csv", index=False)


def drives_step(cfg: ReportConfig) -> None:
    from analysis.kpis_report import analyze_drives

    with _open_store(cfg, read_only=True) as st, _fresh_dir(cfg.out / "drives") as out:
        if st.one("SELECT count(*) FROM drives"):
            analyze_drives(st, out)
        else:
            (out / "objective.md").write_text("# Objective evaluation\n\nThe store has no drives.\n")


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

    # from the files the survey and audit steps wrote: the comparison reruns when either changes
    survey = SimpleNamespace(**{name: pd.read_csv(cfg.out / "survey" / f"{name}.csv")
                                for name in ("descriptives", "loadings", "reliability", "correlations", "regressions")})
    audit = pd.read_csv(cfg.out / "paper" / "audit.csv")
    table = reproduce(survey, audit=audit)
    table.to_csv(cfg.out / "reproduction.csv", index=False, lineterminator="\n", float_format="%.12g")
    md = [render_markdown(table, source="the reference survey in the study store").rstrip(), ""]
    bands = cfg.out / "drives" / "bands.csv"
    md += ["# Objective evaluation (Section 5.1) of the simulated reference cohort", ""]
    if bands.exists():
        from analysis.band_diagnostics import diagnostics_markdown, why_missed
        from analysis.tables_drives import bands_markdown

        bands_df = pd.read_csv(bands)
        diag = pd.read_csv(bands.with_name("band_diagnostics.csv"))
        md += [bands_markdown(bands_df).rstrip(), "",
               "The drives are simulated by virtual participants whose parameters were chosen for realism, not "
               "tuned to these bands; a band that does not hold is reported as such, with what lies behind it:", "",
               diagnostics_markdown(diag).rstrip(), ""]
        md += [line for w in why_missed(bands_df, diag) for line in (f"- {w}", "")]
    else:
        md += ["No drives in the store.", ""]
    md += ["# Audit findings", "", "Published values that contradict other published values "
           "(details: [paper/audit.md](paper/audit.md)).", ""]
    md += [f"{int(r.finding)}. {r.title}" for r in findings(audit).itertuples()]
    (cfg.out / "reproduction.md").write_text("\n".join(md) + "\n", encoding="utf-8")


def core_figures_step(cfg: ReportConfig) -> None:
    from pedas.figures_core import plot_all
    from pedas.route_study import study_route

    plot_all(cfg.out / "figures", route=study_route())


def study_figures_step(cfg: ReportConfig) -> None:
    from analysis.figures_study import participant_flow, plot_likert, plot_participant_flow
    from study.instrument import load_instrument

    figs = cfg.out / "figures"
    with _open_store(cfg, read_only=True) as st:
        flow = participant_flow(st)
    plot_participant_flow(flow, figs)
    write_table(flow.frame(), cfg.out / "tables", "participant_flow", "Participant flow")
    responses = cfg.out / "survey" / "responses.csv"
    if responses.exists():
        plot_likert(pd.read_csv(responses), load_instrument(), figs)


_RAW_DATA = {"responses", "composites"}  # data files, not tables to render


def collect_step(cfg: ReportConfig) -> None:
    """Every table into tables/ (csv, md, tex) and every figure into figures/."""
    tables, figs = cfg.out / "tables", cfg.out / "figures"
    tables.mkdir(parents=True, exist_ok=True)
    figs.mkdir(parents=True, exist_ok=True)
    for sub in ("survey", "drives", "paper"):
        d = cfg.out / sub
        if not d.exists():
            continue
        for f in sorted(d.glob("*.csv")):
            if f.stem in _RAW_DATA:
                continue
            # a part's own rendering (paper-shaped tables) wins over the generic one
            shaped = [f.with_suffix(ext) for ext in (".md", ".tex") if f.with_suffix(ext).exists()]
            if len(shaped) == 2:
                for g in [f, *shaped]:
                    shutil.copy2(g, tables / f"{sub}_{g.name}")
            else:
                write_table(pd.read_csv(f), tables, f"{sub}_{f.stem}", f"{sub}: {f.stem}")
        for f in sorted((d / "figures").glob("*")) if (d / "figures").exists() else []:
            shutil.copy2(f, figs / f.name)


# ---------------------------------------------------------------------------------------------- index
def _verdict(out: Path) -> dict:
    rep = out / "reproduction.csv"
    if not rep.exists():
        return {}
    df = pd.read_csv(rep)
    return {"counts": df["status"].value_counts().to_dict(), "miss": int((df["status"] == "miss").sum())}


def render_index(cfg: ReportConfig, steps: list[StepResult]) -> Path:
    """index.html linking every file, figures inline (relative paths: opens from the file system)."""
    out = cfg.out
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'><title>pEDAS study report</title>",
             "<style>body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
             "img{max-width:100%;border:1px solid #ddd;margin:.3em 0}figure{margin:1.2em 0}"
             "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2em .5em;font-size:.9em}"
             "code{background:#f4f4f4;padding:0 .2em}</style></head><body>",
             "<h1>pEDAS study report</h1>",
             f"<p>Mode: <b>{'reference study' if cfg.reference else 'lab store'}</b> · store <code>"
             f"{html.escape(cfg.db.name)}</code></p>"]
    verdict = _verdict(out)
    if verdict:
        counts = ", ".join(f"{k}: {v}" for k, v in sorted(verdict["counts"].items()))
        parts.append(f"<h2>Reproduction verdict</h2><p>{html.escape(counts)} — "
                     f"<a href='reproduction.md'>reproduction.md</a> · <a href='reproduction.csv'>csv</a></p>")
    for title, sub in (("Acceptance statistics", "survey"), ("Objective evaluation", "drives"),
                       ("Paper audit", "paper")):
        d = out / sub
        if d.exists():
            links = " · ".join(f"<a href='{sub}/{f.name}'>{html.escape(f.name)}</a>"
                               for f in sorted(d.iterdir()) if f.is_file())
            parts.append(f"<h2>{title}</h2><p>{links}</p>")
    tables = sorted((out / "tables").glob("*.md"))
    if tables:
        parts.append("<h2>Tables</h2><ul>")
        for t in tables:
            alts = " ".join(f"<a href='tables/{t.stem}{ext}'>{ext[1:]}</a>" for ext in (".csv", ".tex")
                            if (t.with_suffix(ext)).exists())
            parts.append(f"<li><a href='tables/{t.name}'>{html.escape(t.stem)}</a> {alts}</li>")
        parts.append("</ul>")
    figs = sorted((out / "figures").glob("*.png"))
    if figs:
        parts.append("<h2>Figures</h2>")
        for f in figs:
            parts.append(f"<figure><img src='figures/{f.name}' alt='{html.escape(f.stem)}'><figcaption>"
                         f"{html.escape(f.stem)} · <a href='figures/{f.stem}.pdf'>pdf</a></figcaption></figure>")
    parts.append("<h2>Steps</h2><table><tr><th>step</th><th>status</th><th>seconds</th></tr>")
    parts += [f"<tr><td>{s.name}</td><td>{s.status}</td><td>{s.seconds:.1f}</td></tr>" for s in steps]
    parts.append("</table></body></html>")
    path = out / "index.html"
    path.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------- the pipeline
def build_pipeline(cfg: ReportConfig) -> Pipeline:
    cache = cfg.cache_dir / ("report-" + ("reference" if cfg.reference else "lab"))
    pipe = Pipeline(cache)
    params = json.dumps({"participants": cfg.participants, "seed": cfg.seed, "n_boot": cfg.n_boot,
                         "db": str(cfg.db.resolve()), "out": str(cfg.out.resolve())}, sort_keys=True)
    store_inputs: list = [cfg.db]
    if cfg.reference:
        from pedas.network import build_network

        sources = sorted(p for p in NETWORK_DIR.iterdir() if p.suffix in (".xml", ".json", ".netccfg"))
        pipe.add(Step("network", lambda: build_network(), inputs=[*sources, CODE["pedas"] / "network.py"]))
        # the store is built by this module and analysis.paper.reference_cohort besides study/ and pedas/
        pipe.add(Step("store", lambda: build_reference_store(cfg), after=["network"], outputs=[cfg.db],
                      inputs=[cfg.reference_dir, CODE["study"], CODE["pedas"], Path(__file__),
                              CODE["analysis"] / "paper" / "reference_cohort.py", params]))
        store_inputs = []
    after_store = ["store"] if cfg.reference else []
    pipe.add(Step("survey", lambda: survey_step(cfg), outputs=[cfg.out / "survey"], after=after_store,
                  inputs=[*store_inputs, CODE["analysis"], params]))
    pipe.add(Step("drives", lambda: drives_step(cfg), outputs=[cfg.out / "drives"], after=after_store,
                  inputs=[*store_inputs, CODE["analysis"], params]))
    if cfg.compare_paper:
        pipe.add(Step("audit", lambda: audit_step(cfg), outputs=[cfg.out / "paper"],
                      inputs=[PAPER_DIR, CODE["analysis"], params]))
        pipe.add(Step("reproduction", lambda: reproduction_step(cfg), after=["survey", "drives", "audit"],
                      outputs=[cfg.out / "reproduction.md", cfg.out / "reproduction.csv"],
                      inputs=[CODE["analysis"], params]))
    pipe.add(Step("core figures", lambda: core_figures_step(cfg),
                  outputs=[cfg.out / "figures" / "aero_linearisation.png"],
                  inputs=[CODE["pedas"], params]))
    pipe.add(Step("study figures", lambda: study_figures_step(cfg), after=["survey", *after_store],
                  outputs=[cfg.out / "figures" / "participant_flow.png"],
                  inputs=[*store_inputs, CODE["analysis"], params]))
    pipe.add(Step("collect", lambda: collect_step(cfg), always=True))
    return pipe


def run_report(cfg: ReportConfig) -> ReportResult:
    """Run the pipeline and render index.html; returns what ran and the reproduction verdict."""
    cfg.out.mkdir(parents=True, exist_ok=True)
    steps = build_pipeline(cfg).run(force=cfg.force)
    render_index(cfg, steps)
    files = sorted(p for p in cfg.out.rglob("*") if p.is_file())
    return ReportResult(cfg.out, steps, files, _verdict(cfg.out))

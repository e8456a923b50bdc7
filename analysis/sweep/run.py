"""The what-if sweep (docs/sweep.md): the reduced cohort drives every design point; each point's drives give the
paper's objective KPIs and reproduction bands exactly as the report computes them.

Run: the Morris phase's drives (every point x person x condition) go to :func:`pedas.cohort.simulate_cohort` in one
call (one progress bar, every worker busy); the Morris indices choose the Sobol phase's factors, whose drives follow
in a second call. Every drive is cached by its inputs, so a killed sweep reruns only the drives it had not finished.

Per point, the drives are imported into a temporary store of the paper's study (the same import and KPI definition
as the report's reference store) and go through :func:`analysis.drives.savings.participant_effects`,
:func:`~analysis.drives.savings.summarise` and :func:`~analysis.drives.savings.reproduction_bands`.
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import pandas as pd

from analysis.sweep.design import (BANDS, CSV, MORRIS_LEVELS, SweepSpec, check_spec, cohort, morris_design,
                                   sobol_design, whatif_of)


def point_id(point: int, slot: int) -> str:
    """The participant id a reference person drives under in design point `point` (the study's id pattern
    P<digits>; ids are not part of a drive's cache key, so the same person and settings hit the same drive)."""
    return f"P{point:05d}{slot:03d}"


def point_tasks(design: pd.DataFrame, people: pd.DataFrame, spec: SweepSpec) -> list:
    """Both drives of every person at every design point: DriveTasks of :func:`pedas.cohort.cohort_tasks` (person
    seed from the reference id and the sweep seed, the point's what-if), renamed to :func:`point_id`."""
    from pedas.cohort import cohort_tasks

    slot = {pid: i for i, pid in enumerate(people["participant_id"])}
    tasks = []
    for row in design.to_dict("records"):
        base = cohort_tasks(people[["participant_id", "style"]], base_seed=spec.seed, scenario=spec.scenario,
                            whatif=whatif_of(row))
        tasks += [replace(t, participant_id=point_id(int(row["point"]), slot[t.participant_id])) for t in base]
    return tasks


def count_cached(tasks, cache_dir) -> int:
    """How many of `tasks` are in the drive cache already."""
    from pedas.cohort import is_cached

    return sum(is_cached(t, cache_dir) for t in tasks)


def point_effects(design: pd.DataFrame, people: pd.DataFrame, tasks: list, logs: dict) -> pd.DataFrame:
    """Every design point's people, one row each: ``point``, then the columns of
    :func:`analysis.drives.savings.participant_effects` (both drives' KPIs side by side, the reductions). A person
    with a failed drive (missing from `logs`) has no row."""
    from analysis.drives.kpis import store_kpis
    from analysis.drives.savings import participant_effects
    from analysis.paper.published import PAPER_STUDY_DIR
    from study.people.participants import add_participant
    from study.logs.simulated import store_simulated
    from study.store.store import Store
    from study.store.studies import register

    attrs = [c for c in people.columns if c != "participant_id"]
    with tempfile.TemporaryDirectory() as tmp, Store.open(Path(tmp) / "sweep.duckdb", actor="sweep") as st:
        register(st, PAPER_STUDY_DIR)
        for point in design["point"]:
            for slot, person in enumerate(people.to_dict("records")):
                add_participant(st, point_id(int(point), slot),
                                {a: person[a] for a in attrs if pd.notna(person[a])})
        done = [t for t in tasks if (t.participant_id, t.condition) in logs]
        with st.transaction():
            store_simulated(st, done, logs)
        kpis = store_kpis(st, spec=_paper_spec())
    frames = []
    for point in design["point"]:
        per = participant_effects(kpis[kpis["participant_id"].isin(_ids(point, people))], _paper_spec().comparison)
        per.insert(0, "point", int(point))
        frames.append(per)
    return pd.concat(frames, ignore_index=True)


def point_row(per: pd.DataFrame, n_failed: int = 0) -> tuple[dict, dict]:
    """One design point from its people's rows of :func:`point_effects`: (the KPIS, ``n_violation`` and ``n_red``
    (people whose violation / red-stop reduction is defined: the baseline drive has some), ``n_failed``,
    ``holds_<band>`` per band and ``holds_all``; the bands' edges: key -> band, kpi, lo, hi, hi None = no upper
    edge), through :func:`~analysis.drives.savings.summarise` and
    :func:`~analysis.drives.savings.reproduction_bands` under the paper study's comparison."""
    from analysis.drives.savings import BAND_HIGHWAY, reproduction_bands, summarise

    summary = summarise(per.drop(columns="point"), _paper_spec().comparison, {})
    bands = reproduction_bands(summary).set_index("band")
    mean = summary.set_index("metric")
    row: dict = {}
    for k in ("saving_overall_pct", "saving_urban_pct", "saving_highway_pct"):
        row[k] = float(mean.loc[k, "mean"])
    row["highway_minus_urban_pp"] = float(bands.loc[BAND_HIGHWAY, "our_value"])
    for k in ("violation_reduction_pct", "red_stop_reduction_pct"):
        row[k] = float(mean.loc[k, "mean"])
    row["n_violation"] = int(mean.loc["violation_reduction_pct", "n"])
    row["n_red"] = int(mean.loc["red_stop_reduction_pct", "n"])
    row["n_failed"] = n_failed
    edges = {}
    for key, (band, kpi) in BANDS.items():
        row[f"holds_{key}"] = bool(bands.loc[band, "holds"])
        hi = float(bands.loc[band, "hi"])
        edges[key] = {"band": band, "kpi": kpi, "lo": float(bands.loc[band, "lo"]),
                      "hi": hi if hi != float("inf") else None}  # None: no upper edge (plain JSON)
    row["holds_all"] = all(row[f"holds_{k}"] for k in BANDS)
    return row, edges


@lru_cache(maxsize=1)
def _paper_spec():
    """The KPIs and comparison the paper study's KPI file declares (the study the temporary store of
    :func:`point_effects` serves)."""
    from analysis.paper.published import PAPER_STUDY_DIR
    from study.folder.definition import load
    from study.folder.kpi_spec import study_spec

    return study_spec(load(PAPER_STUDY_DIR, units=False))


def _ids(point, people: pd.DataFrame) -> set[str]:
    """The participant ids of `people` at design point `point` (:func:`point_id`)."""
    return {point_id(int(point), slot) for slot in range(len(people))}


def point_kpis(design: pd.DataFrame, people: pd.DataFrame, tasks: list, logs: dict) -> pd.DataFrame:
    """The points frame: the design's columns, then per point :func:`point_row` of its people, with
    ``n_failed`` the drives that failed (missing from `logs`: their person is left out of the point's KPIs); the
    bands' edges in ``attrs['bands']``."""
    per = point_effects(design, people, tasks, logs)
    rows, edges = [], {}
    for point in design["point"]:
        ids = _ids(point, people)
        failed = sum(t.participant_id in ids and (t.participant_id, t.condition) not in logs for t in tasks)
        row, edges = point_row(per[per["point"] == int(point)], failed)
        rows.append({"point": int(point), **row})
    out = design.merge(pd.DataFrame(rows), on="point", how="left")
    out.attrs["bands"] = edges
    return out


def drive_points(design, people, spec, workers=None, scheduler=None, client=None, cache_dir=None,
                 progress=True, echo=None, failures: list | None = None) -> tuple[list, dict]:
    """Drive every point of `design` (one simulate_cohort call): (the DriveTasks, their logs by (participant id,
    condition)). A drive that fails (pedas.drive.DriveError) does not stop the sweep: it has no log, and is
    appended to `failures` as a dict (point, participant, seed, style, condition, kind, message)."""
    from pedas.cohort import default_cache_dir, simulate_cohort

    cdir = Path(cache_dir or default_cache_dir())
    echo = echo or (lambda text: print(text, flush=True))  # flushed: the line comes before the progress bar
    tasks = point_tasks(design, people, spec)
    phase = design["phase"].iloc[0]
    echo(f"{phase}: {len(design)} points x {len(people)} people x 2 conditions = {len(tasks)} drives, "
         f"{count_cached(tasks, cdir)} already cached")
    failed: list = []
    logs = simulate_cohort(tasks, workers=workers, scheduler=scheduler, client=client, cache_dir=cdir,
                           progress=progress, failures=failed)
    for task, exc in failed:
        echo(f"drive failed: {exc}")
        if failures is not None:
            failures.append({"participant": task.participant_id, "seed": task.seed, "style": task.style,
                             "condition": task.condition, "kind": exc.kind, "message": str(exc)})
    return tasks, logs


def simulate_points(design, people, spec, workers=None, scheduler=None, client=None, cache_dir=None,
                    progress=True, echo=None, failures: list | None = None) -> pd.DataFrame:
    """Drive every point of `design` (:func:`drive_points`) and return its points frame (:func:`point_kpis`); a
    failed drive is counted in its point's ``n_failed``."""
    tasks, logs = drive_points(design, people, spec, workers, scheduler, client, cache_dir, progress, echo, failures)
    return point_kpis(design, people, tasks, logs)


def run_sweep(spec: SweepSpec, out: Path, workers=None, scheduler=None, client=None, cache_dir=None,
              progress=True, echo=None) -> dict:
    """Design, drive and analyse a sweep; write design.csv, points.csv, sweep.json and the analysis
    (:func:`analysis.sweep.sensitivity.write_analysis`) into `out`; return sweep.json's content."""
    from analysis.sweep.sensitivity import morris_indices, top_factors, write_analysis
    from pedas.cohort import code_version

    check_spec(spec)
    t0 = time.perf_counter()
    people = cohort(spec)
    design = morris_design(spec)
    failures: list[dict] = []
    points = simulate_points(design, people, spec, workers, scheduler, client, cache_dir, progress, echo, failures)
    edges = points.attrs["bands"]
    sobol_factors: list[str] = []
    if spec.sobol_n:
        sobol_factors = top_factors(morris_indices(points, spec.factors), spec.top)
        more = sobol_design(spec, sobol_factors, start=len(design))
        design = pd.concat([design, more], ignore_index=True)
        points = pd.concat([points, simulate_points(more, people, spec, workers, scheduler, client, cache_dir,
                                                    progress, echo, failures)], ignore_index=True)
    meta = {
        "factors": [{"name": f, "lo": lo, "hi": hi} for f, lo, hi in spec.factors],
        "sobol_factors": sobol_factors, "trajectories": spec.trajectories, "morris_levels": MORRIS_LEVELS,
        "sobol_n": spec.sobol_n, "top": spec.top, "seed": spec.seed, "scenario": spec.scenario,
        "participants_per_style": spec.participants, "styles": list(spec.styles),
        "cohort": list(people["participant_id"]), "points": len(design),
        "drives": 2 * len(design) * len(people), "bands": edges, "failures": failures,
        "code_version": code_version(),
        "wall_s": round(time.perf_counter() - t0, 1),
        # the local pool's size as simulate_cohort chooses it (None on a Dask cluster)
        "workers": None if (scheduler or client) else int(workers or os.cpu_count() or 1),
        "scheduler": scheduler or ("distributed client" if client is not None else None),
    }
    write_run(out, design, points, meta)
    write_analysis(out, points, meta)
    return meta


def write_run(out: Path, design: pd.DataFrame, points: pd.DataFrame, meta: dict) -> list[Path]:
    """design.csv, points.csv and sweep.json in `out` (the sweep's data; the analysis is recomputed from them)."""
    out.mkdir(parents=True, exist_ok=True)
    design.to_csv(out / "design.csv", **CSV)
    points.to_csv(out / "points.csv", **CSV)
    (out / "sweep.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return [out / "design.csv", out / "points.csv", out / "sweep.json"]


def read_run(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """(design, points, meta) of a sweep folder written by :func:`write_run`."""
    design = pd.read_csv(folder / "design.csv")
    points = pd.read_csv(folder / "points.csv")
    meta = json.loads((folder / "sweep.json").read_text(encoding="utf-8"))
    return design, points, meta


def spec_of(meta: dict) -> SweepSpec:
    """The SweepSpec a sweep.json describes."""
    return SweepSpec(factors=tuple((f["name"], f["lo"], f["hi"]) for f in meta["factors"]),
                     trajectories=meta["trajectories"], sobol_n=meta["sobol_n"], top=meta["top"],
                     participants=meta["participants_per_style"], styles=tuple(meta["styles"]),
                     scenario=meta["scenario"], seed=meta["seed"])


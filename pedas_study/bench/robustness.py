"""Robustness sweep (`pedas-study bench robustness`): many simulated drives, every failure counted by kind instead
of stopping the run.

The design is person seeds x styles x conditions x traffic seeds; every combination is one drive of
:func:`pedas.drive.drive` on the study route. A drive that raises :class:`pedas.drive.DriveError` is counted
under the error's ``kind`` (collision, red_light, stop_sign, backwards, standstill, timeout); any other exception
under ``exception:<TypeName>``. Any failure is a bug in the driver model, the controller or the drive loop:
the sweep exists to find them, so it runs to the end and reports them all.

Drives run on a local process pool ('spawn' context, as :mod:`pedas.cohort`) because libsumo runs one
simulation per process; each worker runs its drives one at a time. Nothing is cached: a sweep always
simulates.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from itertools import count, islice, product
from multiprocessing import get_context
from typing import Callable, NamedTuple, Sequence

import pandas as pd

from pedas.vocabulary import CONDITIONS, STYLES

COLUMNS = ("seed", "style", "condition", "traffic_seed", "ok", "kind", "message", "duration_s", "steps", "wall_s")


class SweepTask(NamedTuple):
    """One drive of the sweep: person seed, style, condition and the (resolved) traffic seed."""

    seed: int
    style: str
    condition: str
    traffic_seed: int

    def label(self) -> str:
        """The drive's name in messages (the wording of the drive loop's own errors)."""
        from pedas.drive import drive_name

        return drive_name(self.seed, self.style, self.condition, self.traffic_seed)


def sweep_tasks(seeds: Sequence[int], styles: Sequence[str] = STYLES, conditions: Sequence[str] = CONDITIONS,
                traffic_seeds: Sequence[int | None] | None = None) -> list[SweepTask]:
    """The design, sorted: seeds x styles x conditions x traffic seeds.

    A traffic seed None stands for the person seed (as in :func:`pedas.drive.drive`); ``traffic_seeds=None``
    means ``(None,)``. Combinations that resolve to the same drive are run once.
    """
    tseeds = (None,) if traffic_seeds is None else tuple(traffic_seeds)
    tasks = {SweepTask(int(s), str(st), str(c), int(s if ts is None else ts))
             for s, st, c, ts in product(seeds, styles, conditions, tseeds)}
    return sorted(tasks)


def traffic_design(seeds: Sequence[int], k: int) -> tuple[int | None, ...]:
    """K traffic seeds per person: the person's own (None) and the K-1 smallest positive integers that are no
    person seed of the sweep (so every person meets K different traffics; the extra ones are shared)."""
    if k < 1:
        raise ValueError("the number of traffic seeds must be >= 1")
    taken = {int(s) for s in seeds}
    return (None,) + tuple(islice((t for t in count(1) if t not in taken), k - 1))


def run_one(task: SweepTask, drive_fn: Callable | None = None, net_file: str | None = None) -> dict:
    """Run one drive in the calling process; its row of the sweep table (never raises for a failed drive).

    drive_fn: a callable with the signature of :func:`pedas.drive.drive` (default: that function, imported
    here so that a worker resolves it itself); it must be a top-level function to reach a spawned worker.
    """
    from pedas.drive import DriveError

    if drive_fn is None:
        from pedas.drive import drive as drive_fn
    row = dict(task._asdict(), ok=False, kind=None, message=None, duration_s=float("nan"), steps=pd.NA)
    kw = {"traffic_seed": task.traffic_seed} | ({"net_file": net_file} if net_file else {})
    t0 = time.perf_counter()
    try:
        df = drive_fn(task.seed, task.style, task.condition, **kw)
    except DriveError as exc:
        kind = str(exc.kind)
        if kind == DriveError.kind and exc.__cause__ is not None:  # the drive loop wrapped an unexpected error
            kind = f"exception:{type(exc.__cause__).__name__}"
        row.update(kind=kind, message=_name(task, exc))
    except Exception as exc:  # an unexpected error is a failure of this drive, not of the sweep
        row.update(kind=f"exception:{type(exc).__name__}", message=_name(task, exc))
    else:
        info = df.attrs.get("drive", {})
        row.update(ok=True, kind="ok", duration_s=float(info.get("duration_s", df["t"].iloc[-1])),
                   steps=int(info.get("steps", len(df))))
    row["wall_s"] = time.perf_counter() - t0
    return row


def _name(task: SweepTask, exc: BaseException) -> str:
    """One-line message naming the drive; kept as is when the error names it already (the drive loop's do)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if text.startswith(task.label()) else f"{task.label()}: {text}"


def robustness_sweep(seeds: Sequence[int], styles: Sequence[str] = STYLES, conditions: Sequence[str] = CONDITIONS,
                     traffic_seeds: Sequence[int | None] | None = None, workers: int | None = None,
                     progress: bool = True, drive_fn: Callable | None = None) -> pd.DataFrame:
    """Run the design of :func:`sweep_tasks`; one row per drive with the columns of ``COLUMNS``.

    Rows are sorted by (seed, style, condition, traffic_seed), whatever the completion order. ``ok`` is True
    for a drive that reached the end of the route; ``kind`` is "ok" or the failure kind; ``message`` the
    failure in one line (None when ok); ``duration_s`` simulated drive time (s, NaN on failure); ``steps``
    simulation steps; ``wall_s`` wall-clock time of the drive call in its worker (s; the first drive of a
    worker includes the per-process setup of route and DP reference). ``df.attrs['wall_s']`` is the wall time
    of the whole sweep (s) and ``df.attrs['workers']`` the pool size.

    workers: processes (default: CPU count, at most the number of drives); drive_fn: see :func:`run_one`.
    """
    from tqdm import tqdm

    tasks = sweep_tasks(seeds, styles, conditions, traffic_seeds)
    if not tasks:
        raise ValueError("the sweep has no drives (empty seeds, styles or conditions)")
    unknown = sorted({t.condition for t in tasks} - set(CONDITIONS)) + sorted({t.style for t in tasks} - set(STYLES))
    if unknown:
        raise ValueError(f"unknown style or condition {unknown[0]!r} (styles: {'|'.join(STYLES)}; conditions: "
                         f"{'|'.join(CONDITIONS)})")
    if workers is not None and workers < 1:
        raise ValueError("workers must be >= 1")
    n = max(1, min(int(workers or os.cpu_count() or 1), len(tasks)))
    net_file = None
    if drive_fn is None:  # build the network once here, not racing in every worker
        from pedas.network import build_network

        net_file = str(build_network())
    rows: list[dict] = []
    t0 = time.perf_counter()
    with tqdm(total=len(tasks), desc="drives", unit="drive", disable=not progress) as bar, \
            ProcessPoolExecutor(max_workers=n, mp_context=get_context("spawn")) as pool:
        futs = {pool.submit(run_one, t, drive_fn, net_file): t for t in tasks}
        for fut in as_completed(futs):
            try:
                rows.append(fut.result())
            except Exception as exc:  # the worker itself died (e.g. a crash inside SUMO): still one row
                task = futs[fut]
                rows.append(dict(task._asdict(), ok=False, kind=f"exception:{type(exc).__name__}",
                                 message=_name(task, exc), duration_s=float("nan"), steps=pd.NA,
                                 wall_s=float("nan")))
            bar.set_postfix(failures=sum(not r["ok"] for r in rows), refresh=False)
            bar.update(1)
    df = pd.DataFrame(rows, columns=list(COLUMNS)).sort_values(["seed", "style", "condition", "traffic_seed"])
    df = df.reset_index(drop=True).astype({"ok": bool, "steps": "Int64", "duration_s": float, "wall_s": float})
    df.attrs.update(wall_s=time.perf_counter() - t0, workers=n)
    return df


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Failures by kind: columns kind, failures, share (of all drives); most frequent first.

    When every drive passed there is one row ``kind="none", failures=0`` so that a report always shows the
    failure count."""
    bad = df.loc[~df["ok"], "kind"]
    if bad.empty:
        return pd.DataFrame({"kind": ["none"], "failures": [0], "share": [0.0]})
    counts = bad.value_counts().rename_axis("kind").reset_index(name="failures")
    counts = counts.sort_values(["failures", "kind"], ascending=[False, True]).reset_index(drop=True)
    counts["share"] = counts["failures"] / len(df)
    return counts


def wall_time(df: pd.DataFrame) -> dict:
    """Wall-clock figures of a sweep (s): the whole sweep, the sum, median and maximum of the drives, and the
    median per condition ({'sweep', 'drives_sum', 'median', 'max', 'median_by_condition'})."""
    w = df["wall_s"].astype(float)
    return {"sweep": float(df.attrs.get("wall_s", float("nan"))), "drives_sum": float(w.sum()),
            "median": float(w.median()), "max": float(w.max()),
            "median_by_condition": {str(k): float(v) for k, v in w.groupby(df["condition"]).median().items()}}

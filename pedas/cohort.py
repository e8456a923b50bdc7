"""Simulate a cohort: many (participant, condition) drives in worker processes, cached by their inputs.

libsumo runs one simulation per process, so drives run in separate worker processes: a local process pool
('spawn' context) by default, or the workers of a Dask distributed cluster (``scheduler=ADDRESS``). Within one
process drives are serialised by a lock, so a Dask worker with several threads stays correct.

Every result is cached under ``cache_dir`` (default ``.report-cache/drives`` in the checkout, or
``$PEDAS_DRIVE_CACHE``) by a hash of its inputs: the task (seed, style, condition, traffic seed) and the
simulation code and network sources. A rerun with nothing changed reads the cache and starts no worker.
"""
from __future__ import annotations

import hashlib
import json
import os
import threading
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from functools import lru_cache
from multiprocessing import get_context
from pathlib import Path

import pandas as pd

from pedas.paths import NETWORK_DIR, REPO_ROOT
from pedas.scenario import DEFAULT_SCENARIO
from pedas.whatif import WhatIf

_SUMO_LOCK = threading.Lock()  # one libsumo simulation per process


@dataclass(frozen=True)
class DriveTask:
    """One drive to simulate: who (participant id, person seed, style), which condition, which traffic, and the
    what-if settings that differ from the scenario's (:meth:`pedas.whatif.WhatIf.items`)."""

    participant_id: str
    seed: int
    style: str
    condition: str
    traffic_seed: int | None = None
    scenario: str = DEFAULT_SCENARIO
    whatif: tuple[tuple[str, float], ...] = ()


def default_cache_dir() -> Path:
    """``$PEDAS_DRIVE_CACHE`` or ``.report-cache/drives`` in the checkout."""
    env = os.environ.get("PEDAS_DRIVE_CACHE")
    return Path(env) if env else REPO_ROOT / ".report-cache" / "drives"


@lru_cache(maxsize=1)
def code_version() -> str:
    """Hash of everything a simulated drive depends on: the simulation modules and the network/traffic sources."""
    h = hashlib.sha256()
    pkg = Path(__file__).resolve().parent
    # every module, compiled kernel source and data file of the simulation core: a list of names would miss the next
    # new module
    for p in sorted([*pkg.glob("*.py"), *pkg.glob("*.c"), *pkg.glob("*.h"), *pkg.glob("*.json")]):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    # every network and traffic source of every scenario (not the built networks)
    for p in sorted(q for q in NETWORK_DIR.rglob("*") if q.is_file() and NETWORK_DIR / "build" not in q.parents):
        h.update(str(p.relative_to(NETWORK_DIR)).encode())
        h.update(p.read_bytes())
    try:
        from importlib.metadata import version

        # the solvers a drive's plans come from
        for dist in ("eclipse-sumo", "osqp", "daqp"):
            h.update(version(dist).encode())
    except Exception:  # pragma: no cover
        pass
    return h.hexdigest()[:16]


def task_key(task: DriveTask) -> str:
    """Cache key of a task: hash of its fields (not the participant id: the same person drives the same) and
    :func:`code_version`."""
    fields = {k: v for k, v in asdict(task).items() if k != "participant_id"}
    blob = json.dumps({"task": fields, "code": code_version()}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def participant_seed(participant_id: str, base_seed: int = 0) -> int:
    """The person seed of a participant id under a cohort seed (stable across runs and machines)."""
    digest = hashlib.sha256(f"{int(base_seed)}:{participant_id}".encode()).digest()
    return int.from_bytes(digest[:4], "big") & 0x7FFFFFFF


def _cache_paths(cache_dir: Path, key: str) -> tuple[Path, Path]:
    return cache_dir / f"{key}.parquet", cache_dir / f"{key}.json"


def is_cached(task: DriveTask, cache_dir: Path | None = None) -> bool:
    """Whether the drive of `task` is in the cache (both of its files), without reading it."""
    return all(p.exists() for p in _cache_paths(Path(cache_dir or default_cache_dir()), task_key(task)))


def load_cached(task: DriveTask, cache_dir: Path | None = None, key: str | None = None) -> pd.DataFrame | None:
    """The cached drive log of `task`, or None."""
    data, meta = _cache_paths(Path(cache_dir or default_cache_dir()), key or task_key(task))
    if not (data.exists() and meta.exists()):
        return None
    df = pd.read_parquet(data)
    df.attrs["drive"] = json.loads(meta.read_text())
    return df


def _store_cached(key: str, df: pd.DataFrame, cache_dir: Path) -> None:
    cache_dir.mkdir(parents=True, exist_ok=True)
    data, meta = _cache_paths(cache_dir, key)
    info = dict(df.attrs.get("drive", {}))
    plain = df.copy()
    plain.attrs = {}
    for path, write in ((data, lambda p: plain.to_parquet(p, index=False)),
                        (meta, lambda p: p.write_text(json.dumps(info, sort_keys=True, default=str)))):
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        write(tmp)
        os.replace(tmp, path)  # atomic: a concurrent reader sees a complete file or none


def run_task(task: DriveTask, cache_dir: str | None = None, key: str | None = None) -> pd.DataFrame:
    """Simulate one task (in the calling process) unless cached; store it in the cache. Worker entry point.

    `key`: the cache key computed by the caller (so that parent and worker agree on it)."""
    from pedas.drive import DriveError, drive

    cdir = Path(cache_dir) if cache_dir else default_cache_dir()
    key = key or task_key(task)
    hit = load_cached(task, cdir, key)
    if hit is not None:
        return hit
    with _SUMO_LOCK:
        try:
            df = drive(task.seed, task.style, task.condition, traffic_seed=task.traffic_seed,
                       scenario=task.scenario, whatif=WhatIf.from_items(task.whatif))
        except DriveError as exc:  # the message names the drive; add whose it is
            raise exc.named(task.participant_id) from None
    _store_cached(key, df, cdir)
    return df


def _run_task_keyed(task: DriveTask, cache_dir: str | None, key: str) -> tuple[DriveTask, pd.DataFrame]:
    return task, run_task(task, cache_dir, key)


def simulate_cohort(tasks: list[DriveTask], workers: int | None = None, scheduler: str | None = None,
                    cache_dir: str | Path | None = None, progress: bool = True,
                    client=None, failures: list | None = None) -> dict[tuple[str, str], pd.DataFrame]:
    """Run all `tasks`; {(participant_id, condition): drive log}.

    workers: size of the local process pool (default: CPU count, at most the number of tasks); scheduler: address
    of a Dask distributed scheduler to run on instead (or pass a ``distributed.Client`` as `client`); cached
    tasks are read without starting any worker. A drive that fails (a :class:`pedas.drive.DriveError`, e.g. a
    SafetyViolation) raises here, unless `failures` is a list: then ``(task, error)`` is appended to it, the
    drive is missing from the result, and the other drives go on (a failure is not cached: a rerun tries again).
    """
    from tqdm import tqdm

    cdir = Path(cache_dir or default_cache_dir())
    out: dict[tuple[str, str], pd.DataFrame] = {}
    # tasks not in the cache, by key: tasks with the same key (two sweep points with the same settings, two people
    # with the same seed and style) are the same drive, simulated once
    todo: dict[str, list[DriveTask]] = {}
    for task in tasks:
        key = task_key(task)
        hit = load_cached(task, cdir, key)
        if hit is not None:
            out[(task.participant_id, task.condition)] = hit
        else:
            todo.setdefault(key, []).append(task)
    bar = tqdm(total=len(tasks), initial=len(out), desc="drives", unit="drive", disable=not progress)
    try:
        if not todo:
            return out
        if scheduler is not None or client is not None:
            from distributed import Client
            from distributed import as_completed as dask_completed

            own = client is None
            cl = client or Client(scheduler)
            try:
                futs = {cl.submit(_run_task_keyed, same[0], str(cdir), key, pure=False): same
                        for key, same in todo.items()}
                for fut in dask_completed(futs):
                    _collect(futs[fut], fut.result, out, failures)
                    bar.update(len(futs[fut]))
            finally:
                if own:
                    cl.close()
        else:
            n = max(1, min(int(workers or os.cpu_count() or 1), len(todo)))
            with ProcessPoolExecutor(max_workers=n, mp_context=get_context("spawn")) as pool:
                futs = {pool.submit(_run_task_keyed, same[0], str(cdir), key): same for key, same in todo.items()}
                for fut in as_completed(futs):
                    _collect(futs[fut], fut.result, out, failures)
                    bar.update(len(futs[fut]))
    finally:
        bar.close()
    return out


def _collect(same: list[DriveTask], result, out: dict, failures: list | None) -> None:
    """Put a finished drive (`result()`) into `out` for every task of its key (`same`), or its DriveError into
    `failures` once per task (re-raised when that is None)."""
    from pedas.drive import DriveError

    try:
        _, df = result()
    except DriveError as exc:
        if failures is None:
            raise
        failures.append((same[0], exc))
        failures.extend((task, exc.named(f"{task.participant_id} (the same drive as {same[0].participant_id})"))
                        for task in same[1:])
        return
    for i, task in enumerate(same):
        out[(task.participant_id, task.condition)] = df if i == 0 else df.copy()


def cohort_tasks(participants: pd.DataFrame, base_seed: int = 0,
                 conditions: tuple[str, ...] = ("baseline", "pedas"),
                 scenario: str = DEFAULT_SCENARIO, whatif: WhatIf | None = None) -> list[DriveTask]:
    """Tasks for a participants frame (participant_id, style): both conditions per person, same person seed and
    traffic in both, in the traffic `scenario` with the `whatif` settings. A missing style is simulated as
    'normal'."""
    items = (whatif or WhatIf()).items()
    tasks = []
    for row in participants.itertuples(index=False):
        style = row.style if isinstance(row.style, str) and row.style else "normal"
        seed = participant_seed(row.participant_id, base_seed)
        for cond in conditions:
            tasks.append(DriveTask(row.participant_id, seed, style, cond, scenario=scenario, whatif=items))
    return tasks

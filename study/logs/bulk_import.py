"""Many drive logs at once (``drive import --from MANIFEST``, ``drive import --dir DIR --pattern PATTERN``): the end
of a lab's day, every log of every participant copied from the simulator.

All or nothing, in three steps on one store opening:

1. **Check the list**: each row names a registered participant, a condition of the study or a drive phase without
   one (:func:`study.logs.importing.drive_target`) that the participant has entered
   (:func:`study.logs.importing.phase_mismatch`), and an existing file; no drive twice.
2. **Read every file** (:func:`study.logs.importing.read_log`: mapping, units, route, plausibility), in parallel on
   the machine's cores (worker processes that hold no store), with a progress bar.
3. **Store** them in one transaction, each as ``drive import`` stores one (unchanged when the same log is stored,
   ``replace`` needed for a different one).

A problem in any step is collected, not raised at once: the command lists every problem of every file (its line in
the manifest, or the file, and the reason) and stores nothing (:class:`study.common.bulk_rows.BadRows`).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from study.common.bulk_rows import BadRow, BadRows, BulkRows, cell, check_columns, read_table
from study.common.errors import UserError, shown

#: columns of a manifest: participant_id, the drive (condition or phase) and the file are required
MANIFEST_COLUMNS = ("participant_id", "condition", "file", "mapping", "format", "vehicle")
#: the placeholders of a file-name pattern
PLACEHOLDERS = ("participant", "condition")


@dataclass(frozen=True)
class BulkItem:
    """One log to import: where it was named (manifest line, or 0 for a folder), participant, the drive
    (condition or drive phase), the file and how to read it."""

    line: int
    participant_id: str
    drive: str
    path: Path
    mapping: str | None = None
    fmt: str | None = None
    vehicle: str | None = None

    def where(self) -> str:
        return f"line {self.line}: {shown(self.path)}" if self.line else shown(self.path)


def manifest_items(path: str | Path, ignore: Iterable[str] = ()) -> list[BulkItem]:
    """The rows of a manifest CSV: participant_id (or participant), condition (or phase: a drive phase without a
    condition), file (relative to the manifest's folder), and optionally mapping (a log mapping file, 'none' = a
    canonical log), format (csv | parquet | sumo-fcd), vehicle (of a SUMO FCD file)."""
    path = Path(path)
    table = read_table(path, tuple(ignore))
    rename = {"participant": "participant_id", "phase": "condition"}
    columns = [rename.get(c, c) for c in table.columns]
    if len(set(columns)) != len(columns):
        raise UserError(f"{shown(path)}: give participant or participant_id, condition or phase, not both")
    rows = [(line, {rename.get(k, k): v for k, v in row.items()}) for line, row in table.rows]
    check_columns(BulkRows(columns, rows), shown(path), MANIFEST_COLUMNS[:3], MANIFEST_COLUMNS[3:])
    base = path.parent
    out = []
    for line, row in rows:
        file = cell(row["file"]) or ""
        out.append(BulkItem(line, cell(row["participant_id"]) or "", cell(row["condition"]) or "",
                            (base / file) if file else Path(""), cell(row.get("mapping")), cell(row.get("format")),
                            cell(row.get("vehicle"))))
    return out


def pattern_regex(pattern: str) -> re.Pattern:
    """A file-name pattern (``{participant}_{condition}.csv``) as a regular expression; each placeholder matches
    a run of characters without a path separator, the rest literally. Both placeholders are required."""
    parts = re.split(r"(\{[^{}]*\})", pattern)
    names = [p[1:-1] for p in parts if p.startswith("{") and p.endswith("}")]
    unknown = [n for n in names if n not in PLACEHOLDERS]
    if unknown or sorted(names) != sorted(PLACEHOLDERS):
        raise UserError(f"--pattern {pattern!r}: use each of {{participant}} and {{condition}} once (e.g. "
                        f"\"{{participant}}_{{condition}}.csv\"){'; unknown: ' + ', '.join(unknown) if unknown else ''}")
    rx = "".join(f"(?P<{p[1:-1]}>[^/]+?)" if p.startswith("{") else re.escape(p) for p in parts)
    return re.compile(rx + r"\Z")


def folder_items(folder: str | Path, pattern: str) -> tuple[list[BulkItem], list[str]]:
    """(the files of `folder` whose name matches `pattern`, in name order; the names of the other files)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"no such folder: {shown(folder)}")
    rx = pattern_regex(pattern)
    items, other = [], []
    for path in sorted(p for p in folder.iterdir() if p.is_file()):
        m = rx.match(path.name)
        if m:
            items.append(BulkItem(0, m["participant"], m["condition"], path))
        else:
            other.append(path.name)
    if not items:
        raise UserError(f"no file in {shown(folder)} matches {pattern!r}")
    return items, other


# ---------------------------------------------------------------------------------------------- reading in workers
def _read(study, item: BulkItem, force: str | None) -> tuple[str, Any]:
    """(ok, ReadLog) or (error, reason) of one file: run in a worker process."""
    from study.logs.importing import read_log

    try:
        return "ok", read_log(study, item.path, item.mapping, item.fmt, item.vehicle, force, whole=True)
    except UserError as exc:
        return "error", str(exc)
    except Exception as exc:  # noqa: BLE001  an unreadable file is one line of the listing, not a crash
        return "error", f"{shown(item.path)}: cannot read: {' '.join(str(exc).split())}"


def _init_worker() -> None:
    from study.common.units import units

    units()   # the unit registry, built once per worker (mapped logs convert their units with it)


def workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:   # not on Linux
        return max(1, os.cpu_count() or 1)


def read_all(study, items: list[BulkItem], force: str | None, jobs: int | None = None,
             tick: Callable[[], None] | None = None) -> list[tuple[str, Any]]:
    """:func:`_read` of every item, in item order, on `jobs` worker processes (default: :func:`workers`; 1 =
    in this process). `tick` is called as each file is done."""
    jobs = min(jobs or workers(), len(items)) or 1
    if jobs == 1:
        _init_worker()
        out = []
        for item in items:
            out.append(_read(study, item, force))
            if tick:
                tick()
        return out
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # forkserver: the workers start from a clean process (not a fork of one holding the store's connection and
    # DuckDB's threads), with the import machinery loaded once
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["study.logs.importing"])
    results: list[tuple[str, Any] | None] = [None] * len(items)
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker) as pool:
        futures = {pool.submit(_read, study, item, force): k for k, item in enumerate(items)}
        for fut in as_completed(futures):
            results[futures[fut]] = fut.result()
            if tick:
                tick()
    return results  # type: ignore[return-value]


# ---------------------------------------------------------------------------------------------- the import
@dataclass(frozen=True)
class BulkResult:
    imported: int
    replaced: int
    unchanged: int
    samples: int
    participants: int
    results: tuple


def import_many(st, items: list[BulkItem], source: str, replace: bool = False, force: str | None = None,
                jobs: int | None = None, progress: Callable[[int], Callable[[], None]] | None = None) -> BulkResult:
    """Import every log of `items` into the store `st`, all or nothing (module docstring). `source` names the list
    in the refusal (``FILE: N bad row(s)``). `progress(n)` returns the function called as each of the n files is
    read. Any problem -> :class:`BadRows` naming each (file or manifest line, participant, reason)."""
    from study.logs.importing import _force_reason, drive_target, phase_mismatch, store_read_log
    from study.people.participants import require
    from study.store.studies import definition

    force = _force_reason(force)
    study = definition(st)
    bad: list[tuple[int, BadRow]] = []   # (the item's place in the list, the problem)
    targets: dict[int, tuple[str | None, str | None, str | None]] = {}
    seen: dict[tuple[str, str], str] = {}
    for k, item in enumerate(items):
        try:
            if not item.participant_id:
                raise UserError("no participant")
            if not item.drive:
                raise UserError("no condition or drive phase")
            if not str(item.path) or not item.path.is_file():
                raise UserError(f"no such file: {shown(item.path)}")
            require(st, item.participant_id)
            condition, phase = drive_target(st, item.participant_id, item.drive)
            key = (item.participant_id, condition or phase)
            if key in seen:
                raise UserError(f"the {key[1]} drive of {key[0]} is also {seen[key]}")
            seen[key] = item.where()
            mismatch = phase_mismatch(st, item.participant_id, condition, phase)
            if mismatch and not force:
                raise UserError(mismatch)
            targets[k] = (condition, phase, mismatch)
        except UserError as exc:
            bad.append((k, BadRow(item.line, item.participant_id, _with_file(item, str(exc)))))
    readable = [k for k in range(len(items)) if k in targets]
    tick = progress(len(readable)) if progress else None
    logs = dict(zip(readable, read_all(study, [items[k] for k in readable], force, jobs, tick)))
    for k, (status, value) in logs.items():
        if status == "error":
            bad.append((k, BadRow(items[k].line, items[k].participant_id, _with_file(items[k], value))))
    if bad:
        raise BadRows(source, [b for _, b in sorted(bad, key=lambda kb: kb[0])])
    done = []
    with st.transaction():
        for k in readable:
            condition, phase, mismatch = targets[k]
            try:
                done.append(store_read_log(st, items[k].participant_id, condition, phase, logs[k][1], force,
                                           mismatch, replace))
            except UserError as exc:
                bad.append((k, BadRow(items[k].line, items[k].participant_id, _with_file(items[k], str(exc)))))
        if bad:
            raise BadRows(source, [b for _, b in bad])
    count = {s: sum(1 for r in done if r.status == s) for s in ("imported", "replaced", "unchanged")}
    return BulkResult(count["imported"], count["replaced"], count["unchanged"],
                      sum(r.n_samples for r in done if r.status != "unchanged"),
                      len({r.participant_id for r in done}), tuple(done))


def _with_file(item: BulkItem, reason: str) -> str:
    """The reason, naming the file as given (once)."""
    name = shown(item.path)
    return reason if name in reason else f"{name}: {reason}"

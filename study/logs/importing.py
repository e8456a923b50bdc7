"""Drive logs: validation and import of simulator logs and of simulated drives (DataFrames).

A drive log has one row per sample with SI units (see docs/contracts.md "Drive log" and docs/drive_logs.md):
required ``t`` s, ``s`` m, ``v`` m/s, ``segment`` (a label of the study's route), ``speed_limit`` m/s; optional
``a``, ``grade``, ``ft``, ``fb``, ``p_batt``, ``tl_id``, ``tl_state``, ``d_tl``, ``leader_gap``, ``leader_v``,
``v_advice``, ``controller``, ``hud_arrow``, ``hud_in_band``, ``warning``.

A lab's own log (CSV, Parquet or SUMO FCD XML, its own column names and units) is read through a log mapping
(:mod:`study.folder.logmap`; the study's ``[files] log_mapping`` or ``--map FILE``), which may also keep extra channels
(stored as DOUBLE columns of ``drive_samples``, registered in ``drive_channels``). The study's route
(:mod:`study.folder.route_file`, ``[files] route``) supplies speed limits, segment labels and the next traffic light by
position when the log lacks them. Imported logs pass plausibility checks (distance from the integral of v dt
against s, sampling interval) that ``force=REASON`` may override, recorded in ``drives.meta``.

Energy: a log's own battery power (``p_batt``, or a mapped power channel) is stored as measured; the vehicle model
(:mod:`pedas.power`) fills ``ft``, ``fb`` and ``p_batt`` only when the study declares it (``[drives]
energy_model``); otherwise ``p_batt`` stays NULL. ``drives.meta`` records ``energy_source``.

An import is one transaction: the ``drives`` row (audited) and all its samples are stored together or not
at all. Re-importing the same content is a no-op; different content for a (participant, condition) that
already has a drive needs ``replace=True`` (audited as delete + insert).

Memory: a canonical CSV or Parquet log is never held whole. It is read in chunks of :data:`CHUNK_ROWS` rows twice,
first to check it (:func:`_prepare_file`: the problem reported is the one the whole log gives), then inside the
transaction to store it, its rows streamed into ``drive_samples`` by one INSERT while DuckDB's memory is held to
:data:`IMPORT_MEMORY`. A mapped log, a SUMO FCD file and a DataFrame are checked whole (:func:`_prepare`) and stored
the same way.
"""
from __future__ import annotations

import hashlib
import json
import time
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pandas as pd

from study.common.errors import UserError, check_choice, escaped, shown
from study.common.file_checks import register_file_check
from study.common.toml_lines import line_of
from study.folder import logmap, route_file
from study.folder.definition import STUDY_FILE
from study.folder.drive_columns import (
    COLUMNS,
)
from study.logs import fcd_route
from study.logs.reading import (
    _CSV_TYPES,
    file_checksum,
    frame_checksum,
    log_format,
    read_drive_file,
)
from study.logs.validation import (
    CHECK_LENGTH,
    CHECK_ROUTE,
    Plausibility,
    _first,
    _numeric,
    _Problem,
    _row,
    _validate,
    plausibility,
    validate_drive,
)

SOURCES = ("import", "simulation")
#: vehicle models a study may declare as [drives] energy_model: name -> what drives.meta says it used
ENERGY_MODELS = {"nissan_leaf": "Nissan Leaf parameters"}
ENERGY_MEASURED = "measured"          # p_batt from the log
ENERGY_SIMULATED = "simulated"        # p_batt of a simulated drive whose caller did not name its model
ENERGY_UNAVAILABLE = "unavailable"    # no power in the log and no model declared: p_batt is NULL
#: rows per chunk of a canonical CSV or Parquet log imported in chunks (a few tens of MB of memory per chunk, the
#: computed columns and the Arrow copy included)
CHUNK_ROWS = 50_000
#: DuckDB's memory limit while an import writes its samples (:mod:`study.common.duck_memory`): the rows stream to the file
IMPORT_MEMORY = "128MB"


@dataclass(frozen=True)
class DriveImport:
    """What an import did. status: imported | unchanged | replaced."""

    drive_id: int
    participant_id: str
    condition: str
    status: str
    n_samples: int
    checksum: str
    seconds: float
    ignored_columns: tuple[str, ...] = ()
    filled_columns: tuple[str, ...] = field(default=())
    channels: tuple[str, ...] = ()          # extra channels stored with the samples
    energy_source: str | None = None
    overridden: tuple[str, ...] = ()        # plausibility problems imported anyway (force)
    phase: str | None = None                # a drive phase without a condition (then `condition` names it too)

    @property
    def rows_per_second(self) -> float:
        return self.n_samples / self.seconds if self.seconds > 0 else float("inf")


@dataclass(frozen=True)
class LogSummary:
    """What storing a validated log needs before its samples: ``n`` samples, the validated ``columns`` (canonical
    order), the first and last ``t`` (s) and ``s`` (m), and whether ``p_batt`` has a value anywhere
    (``has_power``)."""

    n: int
    columns: tuple[str, ...]
    t: tuple[float, float]
    s: tuple[float, float]
    has_power: bool

    @classmethod
    def of(cls, frame: pd.DataFrame) -> "LogSummary":
        t, s = frame["t"].to_numpy(dtype="float64"), frame["s"].to_numpy(dtype="float64")
        return cls(len(frame), tuple(frame.columns), (t[0], t[-1]), (s[0], s[-1]),
                   "p_batt" in frame.columns and bool(frame["p_batt"].notna().any()))


@dataclass(frozen=True)
class PreparedDrive:
    """A log ready to be stored: mapped, joined to the study's route, validated and checked (:func:`_prepare`,
    :func:`_prepare_file`).

    * ``frame``: the validated drive log, the known columns in canonical order (:data:`COLUMNS`) in SI units
      (t s, s m, v and speed_limit m/s, a m/s², ft and fb N, p_batt W, grade rad, d_tl and leader_gap m); None for a
      log file validated in chunks, which ``stream`` reads and validates again while it is stored.
    * ``extras``: the extra channels of the log mapping, one float column each in its stored unit
      (:attr:`study.folder.logmap.Channel.stored_unit`), row for row with ``frame``; None without a mapping.
    * ``labels``: canonical column -> how messages name it (e.g. ``"v (column speed_kmh, km/h)"``); empty without a
      mapping (messages then say "column <name>").
    * ``ignored``: source columns that were not read (neither mapped nor canonical).
    * ``joined``: the columns added from the route (speed_limit, segment, tl_id, d_tl), in that order.
    * ``s_integrated``: True when the position s (m) was integrated from v dt (a mapped log without a position).
    * ``overridden``: the plausibility problems imported anyway (``force``), one line each.
    * ``channels``: the extra channels (:class:`study.folder.logmap.Channel`) whose values ``extras`` holds; () without a
      mapping.
    * ``summary``: length, columns and ends of the validated log (:class:`LogSummary`; taken from ``frame`` when
      not given).
    * ``stream``: for a log validated in chunks, a function that yields the validated log again in consecutive
      chunks (same columns as ``summary.columns``); None when ``frame`` holds the log.
    """

    frame: pd.DataFrame | None
    extras: pd.DataFrame | None
    labels: dict[str, str]
    ignored: tuple[str, ...]
    joined: tuple[str, ...]
    s_integrated: bool
    overridden: tuple[str, ...]
    channels: tuple = ()
    summary: LogSummary | None = None
    stream: Callable[[], Iterator[pd.DataFrame]] | None = None

    def __post_init__(self) -> None:
        if self.summary is None:
            object.__setattr__(self, "summary", LogSummary.of(self.frame))

    def chunks(self) -> Iterator[pd.DataFrame]:
        """The validated log in consecutive chunks: ``frame`` as the only one, or the chunks of ``stream``."""
        return iter([self.frame]) if self.stream is None else self.stream()


@dataclass(frozen=True)
class DriveRecord:
    """One drive to store for (participant, condition) (:func:`_store_drive`): the ``drives`` row and its samples.

    * ``participant_id``, ``condition``: whose drive, in which condition of the study.
    * ``prepared``: the samples and what preparing them found (:class:`PreparedDrive`).
    * ``checksum``: sha256 (hex) that identifies the content: of the file (with mapping and route when used) or of
      the validated frame (:func:`frame_checksum`); the same checksum again is a no-op.
    * ``source``: one of :data:`SOURCES` ('import' of a log, 'simulation').
    * ``route``: the route name stored with the drive (``drives.route``), None when none.
    * ``file_name``: the imported file's name (``drives.file_name``), None for a frame.
    * ``seed``: the random seed of a simulated drive, None otherwise.
    * ``meta``: JSON-serialisable settings for ``drives.meta`` (``energy_source`` is added unless given).
    * ``replace``: replace a stored drive of different content for (participant, condition) instead of refusing.
    * ``started``: :func:`time.perf_counter` when the import began (s); :attr:`DriveImport.seconds` counts from it.
    * ``progress``: called with one line per step of a long import, or None.
    """

    participant_id: str
    condition: str
    prepared: PreparedDrive
    checksum: str
    source: str
    started: float
    route: str | None = None
    file_name: str | None = None
    seed: int | None = None
    meta: dict | None = None
    replace: bool = False
    progress: Callable[[str], None] | None = None
    phase: str | None = None


# ---------------------------------------------------------------------------------------------- drive phases
def drive_target(st, participant_id: str, name: str) -> tuple[str | None, str | None]:
    """(condition, phase) of the drive `name` names: a condition of the study -> (name, None); else a drive phase
    without a condition (familiarisation, practice) of the participant's protocol (any protocol of the study for
    an unknown participant) -> (None, name), stored with condition NULL and that phase. Else UserError."""
    from study.store.studies import definition

    study = definition(st)
    if name in study.condition_names:
        return name, None
    try:
        from study.people.protocol import protocol_of

        protos = [protocol_of(st, participant_id)]
    except UserError:
        protos = list(study.protocols.values())
    free = list(dict.fromkeys(ph.name for pr in protos for ph in pr.steps if ph.drive and ph.condition is None))
    if name in free:
        return None, name
    also = f"; drive phases without a condition: {', '.join(free)}" if free else ""
    raise UserError(f"unknown condition {name!r} (study {study.study_id}: {'|'.join(study.condition_names)}{also})")


def phase_mismatch(st, participant_id: str, condition: str | None, phase: str | None) -> str | None:
    """Why a log of `condition` (or of the drive `phase` without one) does not belong to a drive phase the participant
    has entered (in progress, completed or aborted: a log is often copied after the session), or None when it does.
    A phase not yet entered (also after an abort that ended the participant's protocol before it) is named with the
    phases the participant did enter. A participant without recorded phases is not checked (a lab that does not
    record the protocol)."""
    from study.people.protocol import protocol_of

    entered = st.con.execute("SELECT phase, outcome FROM phase_events WHERE participant_id = ? ORDER BY seq",
                             [participant_id]).fetchall()
    if not entered:
        return None
    proto = protocol_of(st, participant_id)
    steps = {p.name: p for p in proto.steps}

    def belongs(step) -> bool:
        return step.drive and ((step.condition == condition) if condition is not None
                               else (step.condition is None and step.name == phase))

    if any(name in steps and belongs(steps[name]) for name, _ in entered):
        return None
    target = next((p.name for p in proto.steps if belongs(p)), None)
    want = (f"{condition} ({target})" if condition is not None and target else condition) if condition is not None \
        else f"the drive phase {phase}"
    done = ", ".join(name if outcome == "completed" else f"{name} ({outcome.replace('_', ' ')})"
                     for name, outcome in entered)
    return f"{participant_id} has not entered the drive of {want}; phases entered: {done}"


# ---------------------------------------------------------------------------------------------- study settings
def energy_model(study) -> str | None:
    """The vehicle model a study declares for computing energy ([drives] energy_model), None when none."""
    return study.settings.get("drives", {}).get("energy_model")


def _check_study(study, problems) -> None:
    """[drives] of study.toml: only known keys; energy_model one of ENERGY_MODELS."""
    drives = study.settings.get("drives")
    if drives is None:
        return
    if not isinstance(drives, dict):
        problems.add(STUDY_FILE, None, "drives", "must be a table")
        return
    text = study.files.get(STUDY_FILE, "")
    for key, value in drives.items():
        if key != "energy_model":
            problems.add(STUDY_FILE, line_of(text, key, "drives"), f"drives.{key}", "unknown key (known: "
                                                                                   "energy_model)")
        elif value not in ENERGY_MODELS:
            problems.add(STUDY_FILE, line_of(text, key, "drives"), "drives.energy_model",
                         f"unknown vehicle model {value!r} (known: {', '.join(ENERGY_MODELS)})")


register_file_check(_check_study)


# ---------------------------------------------------------------------------------------------- import
def _fill(frame: pd.DataFrame, model: str | None) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """Compute absent optional columns: the acceleration a from the trace always; the forces ft, fb and the
    battery power p_batt only with a declared vehicle model (pedas.power.fill_drive_columns)."""
    before = set(frame.columns)
    if model is None:
        if "a" in frame.columns:
            return frame, ()
        out = frame.copy()
        out["a"] = np.gradient(frame["v"].to_numpy(dtype=float), frame["t"].to_numpy(dtype=float))
        return out[[c for c in COLUMNS if c in out.columns]], ("a",)
    from pedas.power import fill_drive_columns

    filled = fill_drive_columns(frame)
    if filled is None:
        filled = frame
    new = tuple(c for c in COLUMNS if c in filled.columns and c not in before)
    return filled[[c for c in COLUMNS if c in filled.columns]], new


def _filled(chunks: Iterator[pd.DataFrame], model: str | None,
            drop_power: bool) -> Iterator[tuple[pd.DataFrame, tuple[str, ...]]]:
    """Each validated chunk with the absent computed columns (:func:`_fill`) and their names; `drop_power`: without
    an empty ``p_batt``. Each chunk is computed together with the samples next to it, so that a (central
    differences of v over t, np.gradient) is the one of the whole log, and the rest follows sample by sample."""
    def fill(before, chunk, after):
        parts = [p for p in (before, chunk, after) if p is not None]
        if len(parts) == 1:
            return _fill(chunk, model)
        out, filled = _fill(pd.concat(parts, ignore_index=True), model)
        lo = 0 if before is None else 1
        return out.iloc[lo:lo + len(chunk)].reset_index(drop=True), filled

    before = pending = None
    for chunk in chunks:
        if drop_power and "p_batt" in chunk.columns:
            chunk = chunk.drop(columns="p_batt")
        if pending is not None:
            yield fill(before, pending, chunk.iloc[:1])
            before = pending.iloc[-1:]
        pending = chunk
    if pending is not None:
        yield fill(before, pending, None)


def _energy(has_power: bool, study, source: str) -> tuple[str | None, str]:
    """(model to fill with or None, energy_source for drives.meta); `has_power`: the log has a battery power."""
    model = energy_model(study)
    if has_power:
        return model, (ENERGY_MEASURED if source == "import" else ENERGY_SIMULATED)
    if model is not None:
        return model, f"modelled ({ENERGY_MODELS[model]})"
    return None, ENERGY_UNAVAILABLE


def _store_channels(st, channels: tuple) -> None:
    """Register new extra channels (drive_channels) and add their DOUBLE columns to drive_samples."""
    for ch in channels:
        unit = ch.stored_unit
        have = st.one("SELECT unit FROM drive_channels WHERE channel = ?", [ch.name])
        if have is None:
            st.con.execute(f'ALTER TABLE drive_samples ADD COLUMN "{ch.name}" DOUBLE')
            st._columns.pop("drive_samples", None)  # the cached column list no longer holds
            from study.store.audit_trail import utcnow

            st.insert("drive_channels", {"channel": ch.name, "unit": unit, "description": ch.description or None,
                                         "added_at": utcnow()})
        elif have != unit:
            raise UserError(f"channel {ch.name} is stored in {have}, this log mapping gives it in {unit}: "
                            f"add to = \"{have}\" to its [channels.{ch.name}]")


#: Arrow types of the columns of drive_samples that are not DOUBLE (the extra channels are DOUBLE)
_ARROW_TYPES = {"drive_id": "int64", "idx": "int32", "segment": "string", "tl_id": "string", "tl_state": "string",
                "controller": "string", "hud_arrow": "int8", "hud_in_band": "bool", "warning": "bool"}


def _insert_samples(st, frames: Iterator[pd.DataFrame]) -> None:
    """Insert the sample frames (drive_id, idx and the columns of drive_samples, the same in each) into
    drive_samples with one INSERT that reads them as a stream of Arrow batches: DuckDB writes the rows as they come
    (one statement's bulk path; many small INSERTs kept every chunk's rows in memory until the commit). A problem
    raised while the frames are made (a file changed meanwhile) is raised as it is."""
    import itertools

    import duckdb
    import pyarrow as pa

    def arrow_type(col: str):
        kind = _ARROW_TYPES.get(col, "double")
        # text as a dictionary: the validated columns are categoricals of a few labels (5x faster than strings)
        return pa.dictionary(pa.int32(), pa.string()) if kind == "string" else pa.type_for_alias(kind)

    first = next(frames)
    schema = pa.schema([(c, arrow_type(c)) for c in first.columns])
    failed: list[BaseException] = []

    def batches():
        try:
            for df in itertools.chain([first], frames):
                yield from pa.Table.from_pandas(df, schema=schema, preserve_index=False).to_batches()
        except BaseException as exc:  # DuckDB reports it as an Arrow stream error: keep the original
            failed.append(exc)
            raise

    view = f"_samples_{id(first)}"
    cols = ", ".join(f'"{c}"' for c in schema.names)
    st.con.register(view, pa.RecordBatchReader.from_batches(schema, batches()))
    try:
        st._write(f'INSERT INTO drive_samples ({cols}) SELECT {cols} FROM "{view}"', [], "drive_samples")
    except Exception:
        if failed:
            raise failed[0] from None
        raise
    finally:
        try:
            st.con.unregister(view)
        except duckdb.Error:  # an aborted transaction refuses it; the name is not used again
            pass


def _store_drive(st, drive: DriveRecord) -> DriveImport:
    """Store `drive` in one transaction (the audited ``drives`` row and all its samples, written chunk by chunk), or
    find it stored."""
    from study.people.participants import require
    from study.store.studies import definition

    participant_id, condition, checksum, source = drive.participant_id, drive.condition, drive.checksum, drive.source
    prep, progress, t0 = drive.prepared, drive.progress, drive.started
    log, extras, channels, ignored = prep.summary, prep.extras, prep.channels, prep.ignored
    study = definition(st)
    phase = drive.phase
    if phase is None:
        study.check_condition(condition)
    label = condition if phase is None else phase   # what messages and the result call the drive
    check_choice("source", source, SOURCES)
    # an empty power column is no measurement: it is dropped and the model (if any) fills it
    model, energy_source = _energy(log.has_power, study, source)
    meta = dict(drive.meta or {})
    meta.setdefault("energy_source", energy_source)
    from study.common.duck_memory import bounded

    try:
        with bounded(st.con, IMPORT_MEMORY), st.transaction():
            require(st, participant_id)
            have = st.con.execute("SELECT drive_id, checksum, file_name FROM drives WHERE participant_id = ? "
                                  "AND condition IS NOT DISTINCT FROM ? AND phase IS NOT DISTINCT FROM ?",
                                  [participant_id, None if phase else condition, phase]).fetchone()
            if have and have[1] == checksum:
                return DriveImport(int(have[0]), participant_id, label, "unchanged", log.n, checksum,
                                   time.perf_counter() - t0, ignored, energy_source=meta["energy_source"],
                                   phase=phase)
            if source == "import":
                twin = st.con.execute("SELECT participant_id, coalesce(condition, phase) FROM drives "
                                      "WHERE checksum = ?", [checksum]).fetchone()
                if twin:
                    raise UserError(f"this log is already stored as the {twin[1]} drive of {twin[0]}")
            if have and not drive.replace:
                raise UserError(f"{participant_id} already has a {label} drive"
                                f"{' from ' + have[2] if have[2] else ''} with different content; "
                                f"use --replace to replace it")
            if channels:
                _store_channels(st, channels)
            status = "imported"
            if have:
                st.con.execute("DELETE FROM drive_samples WHERE drive_id = ?", [have[0]])
                st.delete("drives", {"drive_id": int(have[0])})
                status = "replaced"
            row = st.insert("drives", {
                "participant_id": participant_id, "condition": None if phase else condition, "phase": phase,
                "source": source, "route": drive.route,
                "checksum": checksum, "n_samples": log.n, "file_name": drive.file_name,
                "duration_s": float(log.t[1] - log.t[0]), "distance_m": float(log.s[1] - log.s[0]),
                "seed": drive.seed, "meta": json.dumps(meta, sort_keys=True, default=str)})
            drive_id = int(row["drive_id"])
            if progress:
                progress(f"writing {log.n} samples of drive {drive_id} ({participant_id} {label})")
            filled: list[tuple[str, ...]] = []

            def samples() -> Iterator[pd.DataFrame]:
                done = 0
                for chunk, computed in _filled(prep.chunks(), model, drop_power=not log.has_power):
                    filled[:] = [computed]
                    out = chunk.copy()
                    out.insert(0, "idx", np.arange(done, done + len(chunk), dtype=np.int32))
                    out.insert(0, "drive_id", np.full(len(chunk), drive_id, dtype=np.int64))
                    for ch in channels:
                        out[ch.name] = extras[ch.name].to_numpy(dtype="float64")[done:done + len(chunk)]
                    done += len(chunk)
                    yield out

            _insert_samples(st, samples())
            if progress:
                progress("committing")
    finally:
        if channels:  # a rolled-back ALTER TABLE leaves a stale cached column list otherwise
            st._columns.pop("drive_samples", None)
    return DriveImport(drive_id, participant_id, label, status, log.n, checksum,
                       time.perf_counter() - t0, ignored, filled[0], tuple(ch.name for ch in channels),
                       meta["energy_source"], prep.overridden, phase)


def _mapping_for(study, path: Path, fmt: str, mapping) -> logmap.Mapping | None:
    """The log mapping that reads this file: `mapping` = a Mapping, a file path, "none" (a canonical log) or
    None (the study's [files] log_mapping when it reads this format; else the file is a canonical log)."""
    if isinstance(mapping, logmap.Mapping):
        m = mapping
    elif mapping is None:
        text = study.text("log_mapping")
        if text is None:
            return None
        m = logmap.load_mapping(text, study.paths["log_mapping"])
        return m if m.format == fmt else None
    elif str(mapping) == "none":
        return None
    else:
        mp = Path(mapping)
        if not mp.is_file():
            raise UserError(f"no such log mapping file: {mp}")
        m = logmap.load_mapping(mp.read_text(encoding="utf-8"), mp.name)
    if m.format != fmt:
        raise UserError(f"log mapping {m.name} reads {m.format} files, {shown(path)} is {fmt}")
    return m


def _prepare(raw: pd.DataFrame, mapping: logmap.Mapping | None, route: route_file.RouteFile | None,
             source: str, force: str | None) -> PreparedDrive:
    """Map, join to the route, validate and check a raw log; returns the pieces the store needs."""
    extras, labels, ignored = None, {}, ()
    s_integrated = False
    if mapping is not None:
        frame, extras, labels, ignored = logmap.apply_mapping(raw, mapping)
        for ch in mapping.extras:
            x = extras[ch.name].to_numpy(dtype="float64")
            i = _first(np.isinf(x))
            if i is not None:
                raise UserError(f"channel {ch.label} row {_row(i)}: {x[i]} is not finite")
    else:
        frame = raw
    if mapping is not None and "s" not in frame.columns:
        # a mapped log without a position: s is the distance travelled (trapezoidal integral of v dt)
        t = _numeric(frame, "t", f"channel {labels['t']}" if "t" in labels else None)
        v = _numeric(frame, "v", f"channel {labels['v']}" if "v" in labels else None)
        frame = frame.assign(s=np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]))
        labels = {**labels, "s": "s (integrated from v)"}
        s_integrated = True
    joined: tuple[str, ...] = ()
    if route is not None and "s" in frame.columns:
        # a lab's mapped log gets the next light by position; canonical logs and simulated drives carry their own
        frame, joined = route.join(frame, f"channel {labels['s']}" if "s" in labels else "column s",
                                   lights=mapping is not None)
    for col in ("speed_limit", "segment"):
        if col not in frame.columns and mapping is not None:
            raise UserError(f"the log has no {col}: map it in {mapping.name} or declare a route in the study "
                            f"([files] route)")
    valid, more_ignored = validate_drive(frame, labels, route.segments if route is not None else None)
    if mapping is None:
        ignored = more_ignored
    overridden: tuple[str, ...] = ()
    if source == "import":
        problems = plausibility(valid, labels, mapping.rate_hz if mapping else None,
                                mapping.max_gap_s if mapping else logmap.DEFAULT_MAX_GAP_S,
                                mapping.distance_tolerance if mapping else logmap.DEFAULT_DISTANCE_TOLERANCE,
                                s_integrated, route.length if route is not None else None)
        if problems and not force:
            raise UserError(f"{problems[0]} (if this is right, import with --force REASON)")
        overridden = tuple(problems)
    return PreparedDrive(frame=valid, extras=extras, labels=labels, ignored=ignored, joined=joined,
                         s_integrated=s_integrated, overridden=overridden,
                         channels=mapping.extras if mapping is not None else ())


# ---------------------------------------------------------------------------------------------- streamed import
class _Unreadable(UserError):
    """The file cannot be read as a table (reported as it is, without the file name in front twice)."""


def _read_chunks(path: Path, kind: str) -> Iterator[pd.DataFrame]:
    """A canonical CSV or Parquet log in consecutive chunks of :data:`CHUNK_ROWS` rows, each typed as
    :func:`read_drive_file` types the whole file (pandas' CSV reader, Parquet's own types), at least one chunk (empty
    for a file without rows); an unreadable file -> UserError."""
    try:
        if kind == "parquet":
            import pyarrow.parquet as pq

            f = pq.ParquetFile(path)
            empty = True
            for batch in f.iter_batches(batch_size=CHUNK_ROWS):
                if batch.num_rows:
                    empty = False
                    yield batch.to_pandas()
            if empty:
                yield f.schema_arrow.empty_table().to_pandas()
            return
        with pd.read_csv(path, dtype=_CSV_TYPES, low_memory=False, chunksize=CHUNK_ROWS) as reader:
            yield from reader
    except UserError:
        raise
    except Exception as exc:  # unreadable file: one line
        raise _Unreadable(f"cannot read {shown(path)}: {' '.join(str(exc).split())}") from exc


def _log_chunks(path: Path, kind: str, route: route_file.RouteFile | None) -> Iterator[tuple]:
    """Each chunk of a canonical log file joined to the route (speed_limit and segment where absent) and validated
    (:func:`_validate` with the rows counted across the chunks): (rows, validated chunk or None, its problem
    (:class:`_Problem`) or None, ignored columns, columns joined from the route)."""
    carry: dict = {}
    row0 = 0
    for raw in _read_chunks(path, kind):
        valid, problem, ignored, joined = None, None, (), ()
        try:
            frame = raw
            if route is not None and "s" in raw.columns:
                frame, joined = route.join(raw, "column s", lights=False, first_row=row0)
            valid, ignored = _validate(frame, None, route.segments if route is not None else None, row0, carry)
        except _Problem as exc:
            problem = exc
        except UserError as exc:  # the route's: a position off the route, checked before the values
            problem = _Problem(str(exc), CHECK_ROUTE)
        yield len(raw), valid, problem, ignored, joined
        row0 += len(raw)


def _prepare_file(path: Path, kind: str, route: route_file.RouteFile | None, force: str | None) -> PreparedDrive:
    """:func:`_prepare` of a canonical CSV or Parquet log file read in chunks (memory for a few chunks, not for the
    log): every check of :func:`validate_drive` and :func:`plausibility`, with the problem the whole log would
    give. The samples are not kept: the prepared drive reads and validates the file again while it is stored."""
    best: _Problem | None = None
    check = Plausibility(route_length=route.length if route is not None else None)
    n, columns, ignored, joined, has_power = 0, (), (), (), False
    t, s = [None, None], [None, None]
    with closing(_log_chunks(path, kind, route)) as chunks:
        for rows, valid, problem, ign, jn in chunks:
            if n == 0:
                ignored, joined = ign, jn
            n += rows
            if problem is not None and (best is None or problem.check < best.check):
                best = problem
                if best.check == CHECK_ROUTE:  # nothing comes before it
                    break
            if best is not None or valid is None or not len(valid):
                continue
            columns = tuple(valid.columns)
            if t[0] is None:
                t[0], s[0] = valid["t"].iloc[0], valid["s"].iloc[0]
            t[1], s[1] = valid["t"].iloc[-1], valid["s"].iloc[-1]
            has_power = has_power or ("p_batt" in valid.columns and bool(valid["p_batt"].notna().any()))
            check.add(valid)
    if n < 2 and (best is None or best.check > CHECK_LENGTH):
        best = _Problem(f"a drive log needs at least 2 samples, this one has {n}", CHECK_LENGTH)
    if best is not None:
        raise best
    problems = check.problems()
    if problems and not force:
        raise UserError(f"{problems[0]} (if this is right, import with --force REASON)")
    summary = LogSummary(n, columns, (t[0], t[1]), (s[0], s[1]), has_power)
    return PreparedDrive(frame=None, extras=None, labels={}, ignored=ignored, joined=joined, s_integrated=False,
                         overridden=tuple(problems), summary=summary,
                         stream=lambda: _validated_again(path, kind, route, summary))


def _validated_again(path: Path, kind: str, route: route_file.RouteFile | None,
                     summary: LogSummary) -> Iterator[pd.DataFrame]:
    """The validated chunks of a log file that :func:`_prepare_file` found valid; a file that has changed since
    -> UserError (the import's transaction then stores nothing)."""
    n, last = 0, None
    with closing(_log_chunks(path, kind, route)) as chunks:
        for rows, valid, problem, _, _ in chunks:
            n += rows
            if problem is not None:
                raise UserError(f"{shown(path)} changed while it was being imported: {problem}")
            if len(valid):
                last = (valid["t"].iloc[-1], valid["s"].iloc[-1])
                yield valid
    if n != summary.n or last != (summary.t[1], summary.s[1]):
        raise UserError(f"{shown(path)} changed while it was being imported")


def _force_reason(force: str | None) -> str | None:
    if force is None:
        return None
    if not isinstance(force, str) or not force.strip():
        raise UserError("--force needs a reason (recorded with the drive)")
    return force.strip()


@dataclass(frozen=True)
class ReadLog:
    """A drive log file read, mapped and checked, ready to store: the prepared log, its checksum, the
    ``drives.meta`` it brings (format, mapping, units, ...), the route name of the study and the file's name."""

    prepared: PreparedDrive
    checksum: str
    meta: dict[str, Any]
    route: str | None
    file_name: str


def read_log(study, path: str | Path, mapping: Any = None, fmt: str | None = None, vehicle: str | None = None,
             force: str | None = None, net: str | Path | None = None, whole: bool = False,
             progress: Callable[[str], None] | None = None) -> ReadLog:
    """Read, map and check a drive log file of `study` (a StudyDefinition) without a store: what
    :func:`import_drive_file` stores, and what a bulk import (:mod:`study.logs.bulk_import`) reads in parallel.
    `whole`: read a canonical CSV or Parquet log whole rather than in chunks (a result that can cross processes).
    Every problem -> UserError starting with the file name as given."""
    t0 = time.perf_counter()
    path = Path(path)
    kind = log_format(path, fmt)
    m = _mapping_for(study, path, kind, mapping)
    fcd_route.check_net_option(net, kind, m)
    rfile = route_file.study_route(study)
    derived: list[str] = []
    vehicle = vehicle or (m.vehicle if m is not None else None)
    if not path.exists():
        raise UserError(f"no such file: {shown(path)}")
    if m is None and kind in ("csv", "parquet") and not whole:  # a canonical log: read in chunks, never whole
        try:
            prep = _prepare_file(path, kind, rfile, force)
        except _Unreadable:
            raise
        except UserError as exc:
            raise UserError(f"{shown(path)}: {exc}") from None
        if progress:
            progress(f"read {prep.summary.n} rows from {path.name}")
    else:  # a mapped log (units, integrated positions, lights by position) or SUMO FCD: read whole
        raw = read_drive_file(path, kind, vehicle)
        derived = [c for c in raw.attrs.get("derived", ()) if m is not None and c in {ch.column for ch in m.channels}]
        if progress:
            progress(f"read {len(raw)} rows from {path.name}")
        try:
            if kind == "sumo-fcd" and m is not None:  # its own network (--net), or the study's route it drives
                raw, rfile = fcd_route.fcd_route(raw, rfile, net, m)
            prep = _prepare(raw, m, rfile, "import", force)
        except UserError as exc:
            raise UserError(f"{shown(path)}: {exc}") from None
    checksum = file_checksum(path)
    if m is not None or prep.joined or prep.s_integrated:
        h = hashlib.sha256(f"file\0{checksum}\0".encode())
        h.update(f"mapping\0{m.text if m is not None else ''}\0vehicle\0{vehicle or ''}\0".encode())
        h.update(f"route\0{rfile.text if rfile is not None and prep.joined else ''}".encode())
        checksum = h.hexdigest()
    meta: dict[str, Any] = {"format": kind}
    if m is not None:
        meta["log_mapping"] = m.name
        meta["units"] = {c.name: c.unit for c in m.channels if c.unit is not None}
    if vehicle:
        meta["vehicle"] = vehicle
    if net is not None:
        meta["net"] = Path(net).name
    if derived:
        meta["derived"] = derived
    if prep.joined:
        meta["from_route"] = list(prep.joined)
    if prep.s_integrated:
        meta["s"] = "integrated from v"
    meta["read_s"] = time.perf_counter() - t0
    return ReadLog(prep, checksum, meta, rfile.name if rfile is not None else None, path.name)


def store_read_log(st, participant_id: str, condition: str | None, phase: str | None, log: ReadLog,
                   force: str | None, mismatch: str | None, replace: bool = False, route: str | None = None,
                   progress: Callable[[str], None] | None = None, started: float | None = None) -> DriveImport:
    """Store a :class:`ReadLog` as the drive (participant, condition or phase) in one transaction (joining the
    caller's): the forced reason and the overridden phase mismatch go into ``drives.meta``."""
    meta = {k: v for k, v in log.meta.items() if k != "read_s"}
    if force is not None:
        meta["forced"] = {"reason": force,
                          "overridden": list(log.prepared.overridden) + ([mismatch] if mismatch else [])}
    t0 = started if started is not None else time.perf_counter() - log.meta.get("read_s", 0.0)
    try:
        r = _store_drive(st, DriveRecord(participant_id, condition, log.prepared, log.checksum, "import", t0,
                                         route=route or log.route, file_name=log.file_name, meta=meta,
                                         replace=replace, progress=progress, phase=phase))
        return replace_overridden(r, mismatch)
    except UserError as exc:
        if str(exc).startswith("channel "):
            raise UserError(f"{log.file_name}: {exc}") from None
        raise


#: characters of a client's file name kept with an uploaded drive (``drives.file_name``): a file system's 255
ORIGINAL_NAME_MAX = 255


def client_file_name(name: str) -> str:
    r"""A file name as a client sent it, kept as the drive's ``file_name`` and shown in messages, never used as a
    path: its last part (after the last ``/`` or ``\``: a browser may send the client's folder, which names its
    user), control and invisible format characters escaped (``\r``, ``\x07``, ``\u202e``: the name stays one line
    and reads as it is), at most :data:`ORIGINAL_NAME_MAX` characters (a longer one cut, ending in "…")."""
    import unicodedata

    base = str(name).replace("\\", "/").rsplit("/", 1)[-1]
    text = "".join(escaped(c) if unicodedata.category(c) == "Cc" else f"\\u{ord(c):04x}"
                   if unicodedata.category(c) == "Cf" else c for c in base)
    return text if len(text) <= ORIGINAL_NAME_MAX else text[:ORIGINAL_NAME_MAX - 1] + "…"


def import_drive_file(st, participant_id: str, condition: str, path: str | Path, replace: bool = False,
                      route: str | None = None, progress: Callable[[str], None] | None = None,
                      mapping: Any = None, fmt: str | None = None, vehicle: str | None = None,
                      force: str | None = None, net: str | Path | None = None,
                      original_name: str | None = None) -> DriveImport:
    """Read, map, check and import a drive log file (CSV, Parquet or SUMO FCD) for (participant, condition).

    `mapping`: None = the study's log mapping when it reads this format (else the file is a canonical log),
    "none" = a canonical log, or a mapping file path / :class:`study.folder.logmap.Mapping`. `fmt` overrides the format
    taken from the file name; `vehicle` picks the vehicle of an FCD file, `net` its SUMO network (limits and lights
    from there instead of the study's route: :mod:`study.logs.fcd_route`). `force` = a reason to import despite
    plausibility problems (recorded in drives.meta) and despite :func:`phase_mismatch` (a log for a drive phase the
    participant has not entered: refused without it). `condition` is a condition of the study or a
    drive phase without one (:func:`drive_target`). `route` names the route stored with the drive (default: the
    study's route file's name). Checksum: sha256 of the file; of file, mapping and route when those were used.
    Every problem of the log is one line starting with the file name. A canonical CSV or Parquet log (no mapping) is
    read in chunks of :data:`CHUNK_ROWS` rows, twice (validated, then stored), so that its size does not bound the
    memory; a mapped or SUMO FCD log is read whole (:func:`read_log`). `original_name`: the name the file had on the
    client (an upload saved under a name of the server's): stored as ``drives.file_name`` and named in messages
    instead of `path`, as :func:`client_file_name` keeps it.
    """
    from dataclasses import replace as replaced

    from study.store.studies import definition

    study = definition(st)  # first: parsing a stored study (its model file) is not part of the import's time
    t0 = time.perf_counter()
    force = _force_reason(force)
    condition, phase = drive_target(st, participant_id, condition)
    mismatch = phase_mismatch(st, participant_id, condition, phase)
    if mismatch and not force:
        raise UserError(f"{mismatch}; import with --force REASON to store it anyway")
    name = client_file_name(original_name) if original_name else ""
    if name and progress is not None:
        saved, report = Path(path).name, progress

        def progress(line: str) -> None:  # every step names the lab's file, not the saved one
            report(line.replace(saved, name))
    try:
        log = read_log(study, path, mapping, fmt, vehicle, force, net, progress=progress)
    except UserError as exc:
        if not name:
            raise
        raise UserError(str(exc).replace(shown(path), name)) from None
    if name:
        log = replaced(log, file_name=name)
    return store_read_log(st, participant_id, condition, phase, log, force, mismatch, replace, route, progress, t0)


def import_drive_frame(st, participant_id: str, condition: str, df: pd.DataFrame, source: str = "simulation",
                       route: str | None = None, replace: bool = False, seed: int | None = None,
                       meta: dict | None = None, file_name: str | None = None,
                       progress: Callable[[str], None] | None = None, force: str | None = None) -> DriveImport:
    """Validate and store a drive given as a canonical DataFrame (e.g. a simulated drive).

    The checksum is :func:`frame_checksum` of the validated frame, so storing the same frame again is a no-op.
    The HUD channels of :data:`pedas.hud_log.HUD_CHANNELS` (all or none) are kept as extra channels and counted in
    the checksum (:mod:`study.logs.hud_channels`); other columns outside the format are ignored.
    `seed` and `meta` (JSON-serialisable settings) are kept on the drives row for reproducibility, with
    ``energy_source`` added unless `meta` names it. Source 'import' frames get the plausibility checks.
    """
    from study.store.studies import definition

    study = definition(st)
    t0 = time.perf_counter()
    force = _force_reason(force)
    condition, phase = drive_target(st, participant_id, condition)
    rfile = route_file.study_route(study)
    prep = _prepare(df, None, rfile, source, force)
    from dataclasses import replace as _with

    from study.logs.hud_channels import hud_extras, with_channels

    extras, hud = hud_extras(df)   # what the HUD showed (docs/hud.md): kept as extra channels, not ignored
    if hud:
        prep = _with(prep, extras=extras, channels=hud, ignored=tuple(c for c in prep.ignored if c not in extras))
    meta = dict(meta) if meta is not None else {}
    if prep.joined:
        meta["from_route"] = list(prep.joined)
    if force is not None:
        meta["forced"] = {"reason": force, "overridden": list(prep.overridden)}
    checksum = with_channels(frame_checksum(prep.frame), prep.extras, prep.channels)
    return _store_drive(st, DriveRecord(participant_id, condition, prep, checksum, source, t0,
                                        route=route, file_name=file_name, seed=seed, meta=meta, replace=replace,
                                        progress=progress, phase=phase))


def replace_overridden(r: DriveImport, mismatch: str | None) -> DriveImport:
    """`r` with the phase mismatch a forced import overrode listed after its plausibility problems."""
    from dataclasses import replace

    return r if not mismatch or r.status == "unchanged" else replace(r, overridden=r.overridden + (mismatch,))



"""Drive logs: validation and import of simulator logs and of simulated drives (DataFrames).

A drive log has one row per sample with SI units (see docs/contracts.md "Drive log" and docs/drive_logs.md):
required ``t`` s, ``s`` m, ``v`` m/s, ``segment`` (a label of the study's route), ``speed_limit`` m/s; optional
``a``, ``grade``, ``ft``, ``fb``, ``p_batt``, ``tl_id``, ``tl_state``, ``d_tl``, ``leader_gap``, ``leader_v``,
``v_advice``, ``controller``, ``hud_arrow``, ``hud_in_band``, ``warning``.

A lab's own log (CSV, Parquet or SUMO FCD XML, its own column names and units) is read through a log mapping
(:mod:`study.logmap`; the study's ``[files] log_mapping`` or ``--map FILE``), which may also keep extra channels
(stored as DOUBLE columns of ``drive_samples``, registered in ``drive_channels``). The study's route
(:mod:`study.route_file`, ``[files] route``) supplies speed limits, segment labels and the next traffic light by
position when the log lacks them. Imported logs pass plausibility checks (distance from the integral of v dt
against s, sampling interval) that ``force=REASON`` may override, recorded in ``drives.meta``.

Energy: a log's own battery power (``p_batt``, or a mapped power channel) is stored as measured; the vehicle model
(:mod:`pedas.power`) fills ``ft``, ``fb`` and ``p_batt`` only when the study declares it (``[drives]
energy_model``); otherwise ``p_batt`` stays NULL. ``drives.meta`` records ``energy_source``.

An import is one transaction: the ``drives`` row (audited) and all its samples are stored together or not
at all. Re-importing the same content is a no-op; different content for a (participant, condition) that
already has a drive needs ``replace=True`` (audited as delete + insert).
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from study import logmap, route_file
from study.definition import STUDY_FILE
from study.drive_columns import BOOL_OPTIONAL, COLUMNS, FLOAT_OPTIONAL, REQUIRED, TEXT_OPTIONAL
from study.errors import UserError, check_choice
from study.file_checks import register_file_check
from study.toml_lines import line_of

SOURCES = ("import", "simulation")
V_MAX = 70.0            # m/s, upper plausibility bound of speed and speed limit (252 km/h)
SEGMENT_MAX = route_file.SEGMENT_MAX
#: vehicle models a study may declare as [drives] energy_model: name -> what drives.meta says it used
ENERGY_MODELS = {"nissan_leaf": "Nissan Leaf parameters"}
ENERGY_MEASURED = "measured"          # p_batt from the log
ENERGY_SIMULATED = "simulated"        # p_batt of a simulated drive whose caller did not name its model
ENERGY_UNAVAILABLE = "unavailable"    # no power in the log and no model declared: p_batt is NULL
MIN_CHECK_DISTANCE = 50.0   # m: the distance check starts once v dt or s has covered this much
DISTANCE_SLACK = 5.0        # m: absolute slack of the distance check (start-up, rounding of positions)
RATE_TOLERANCE = 0.05       # relative: median time step vs the mapping's rate_hz
SAMPLING_S = (0.01, 1.0)    # s: plausible median sampling interval of a simulator log (100 Hz .. 1 Hz)
#: plausible magnitudes for a passenger car (docs/drive_logs.md gives the sources): column -> (bound, unit, what)
MAGNITUDES = {
    "p_batt": (1.0e6, "W", "battery power"),     # 1 MW: above every series-production passenger EV but hypercars
    "ft": (5.0e4, "N", "traction force"),        # 50 kN > 3500 kg (licence B) x 9.81 m/s^2 x tyre friction 1.2
    "fb": (5.0e4, "N", "braking force"),
}
#: ratios of the integral of v dt to s that a unit mix-up produces, and what it means
_UNIT_MIXUPS = ((3.6, "a speed in km/h read as m/s"), (1 / 3.6, "a speed in m/s read as km/h"),
                (1.609344, "a speed in mph read as km/h"), (1 / 1.609344, "a speed in km/h read as mph"),
                (2.2369363, "a speed in mph read as m/s"), (1 / 2.2369363, "a speed in m/s read as mph"),
                (1000.0, "a time in ms read as s"), (0.001, "a time in s read as ms"),
                (3.2808399, "a position in m read as ft"), (1 / 3.2808399, "a position in ft read as m"))
_TRUE = {"true", "1", "t", "yes", "y", "1.0"}
_FALSE = {"false", "0", "f", "no", "n", "0.0"}


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

    @property
    def rows_per_second(self) -> float:
        return self.n_samples / self.seconds if self.seconds > 0 else float("inf")


@dataclass(frozen=True)
class PreparedDrive:
    """A log ready to be stored: mapped, joined to the study's route, validated and checked (:func:`_prepare`).

    * ``frame``: the validated drive log, the known columns in canonical order (:data:`COLUMNS`) in SI units
      (t s, s m, v and speed_limit m/s, a m/s², ft and fb N, p_batt W, grade rad, d_tl and leader_gap m).
    * ``extras``: the extra channels of the log mapping, one float column each in its stored unit
      (:attr:`study.logmap.Channel.stored_unit`), row for row with ``frame``; None without a mapping.
    * ``labels``: canonical column -> how messages name it (e.g. ``"v (column speed_kmh, km/h)"``); empty without a
      mapping (messages then say "column <name>").
    * ``ignored``: source columns that were not read (neither mapped nor canonical).
    * ``joined``: the columns added from the route (speed_limit, segment, tl_id, d_tl), in that order.
    * ``s_integrated``: True when the position s (m) was integrated from v dt (a mapped log without a position).
    * ``overridden``: the plausibility problems imported anyway (``force``), one line each.
    * ``channels``: the extra channels (:class:`study.logmap.Channel`) whose values ``extras`` holds; () without a
      mapping.
    """

    frame: pd.DataFrame
    extras: pd.DataFrame | None
    labels: dict[str, str]
    ignored: tuple[str, ...]
    joined: tuple[str, ...]
    s_integrated: bool
    overridden: tuple[str, ...]
    channels: tuple = ()


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


# ---------------------------------------------------------------------------------------------- validation
def _row(i: int) -> int:
    """Rows are reported 1-based, counting data rows (a CSV header is not a row)."""
    return int(i) + 1


def _numeric(df: pd.DataFrame, col: str, name: str | None = None) -> np.ndarray:
    """Column as float64; a non-number names column (`name`, default "column <col>") and row."""
    name = name or f"column {col}"
    s = df[col]
    if pd.api.types.is_bool_dtype(s) or not (pd.api.types.is_numeric_dtype(s) or s.dtype == object
                                              or pd.api.types.is_string_dtype(s)):
        raise UserError(f"{name} must be numeric (dtype {s.dtype})")
    if pd.api.types.is_numeric_dtype(s):
        return s.to_numpy(dtype="float64", na_value=np.nan)
    conv = pd.to_numeric(s, errors="coerce")
    bad = conv.isna() & s.notna() & (s.astype("string").str.strip() != "")
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(f"{name} row {_row(i)}: {s.iloc[i]!r} is not a number")
    return conv.to_numpy(dtype="float64", na_value=np.nan)


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _text(df: pd.DataFrame, col: str, allowed: tuple[str, ...] | None, required: bool, name: str | None = None,
          max_length: int | None = None) -> pd.Categorical:
    """Column as a categorical of stripped text (NaN = missing), checked against `allowed` (and `max_length`).

    Works on the distinct values (pd.factorize) because logs have millions of rows but a handful of values.
    """
    name = name or f"column {col}"
    codes, uniques = pd.factorize(df[col], use_na_sentinel=True)
    labels = np.array([str(u).strip() for u in uniques] + [None], dtype=object)  # index -1 -> None
    labels[[i for i, u in enumerate(labels[:-1]) if u == ""]] = None
    missing = np.flatnonzero(pd.isna(labels[:-1]))
    if required:
        bad_missing = (codes == -1) | np.isin(codes, missing)
        i = _first(bad_missing)
        if i is not None:
            raise UserError(f"{name} row {_row(i)}: missing value")
    if allowed is not None:
        bad = [k for k, u in enumerate(labels[:-1]) if u is not None and u not in allowed]
        if bad:
            i = _first(np.isin(codes, bad))
            raise UserError(f"{name} row {_row(i)}: {labels[codes[i]]!r} is not one of {'|'.join(allowed)}")
    if max_length is not None:
        bad = [k for k, u in enumerate(labels[:-1]) if u is not None and len(u) > max_length]
        if bad:
            i = _first(np.isin(codes, bad))
            raise UserError(f"{name} row {_row(i)}: {labels[codes[i]][:20]!r}... is longer than {max_length} "
                            f"characters")
    # a categorical keeps the few distinct strings once (DuckDB stores it as text on insert)
    cats = sorted({u for u in labels[:-1] if u is not None})
    pos = np.array([cats.index(u) if u is not None else -1 for u in labels[:-1]] + [-1], dtype=np.int64)
    return pd.Categorical.from_codes(pos[codes], categories=cats)


def _bool(df: pd.DataFrame, col: str, name: str | None = None) -> pd.arrays.BooleanArray:
    name = name or f"column {col}"
    s = df[col]
    if pd.api.types.is_bool_dtype(s):
        return pd.array(s, dtype="boolean")
    if pd.api.types.is_numeric_dtype(s):
        vals = s.to_numpy(dtype="float64", na_value=np.nan)
    else:
        codes, uniques = pd.factorize(s, use_na_sentinel=True)
        low = [str(u).strip().lower() for u in uniques]
        table = np.array([1.0 if u in _TRUE else 0.0 if u in _FALSE else np.nan if u == "" else 2.0
                          for u in low] + [np.nan])
        vals = table[codes]
    bad = ~np.isnan(vals) & ~np.isin(vals, (0.0, 1.0))
    if bad.any():
        i = _first(bad)
        raise UserError(f"{name} row {_row(i)}: {s.iloc[i]!r} is not a boolean (0/1, true/false)")
    mask = np.isnan(vals)
    return pd.arrays.BooleanArray(np.where(mask, False, vals == 1.0), mask)


def validate_drive(df: pd.DataFrame, labels: dict[str, str] | None = None,
                   segments: tuple[str, ...] | None = None) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """Check a drive log and return (normalised frame with the known columns in canonical order, ignored columns).

    Rules (the first violation is reported as one line naming column and 1-based row): required columns
    present; at least 2 samples; no missing value in a required column; numeric columns numeric and finite;
    0 <= v <= 70 m/s; 0 < speed_limit <= 70 m/s; t strictly increasing; s non-decreasing; segment a label of
    at most 64 characters (one of `segments` when given: the labels of the study's route); optional columns typed
    (tl_state green|yellow|red, controller rt|cf|none, hud_arrow -1|0|1, hud_in_band/warning boolean, the rest
    numbers) — missing values allowed there. `labels` names mapped channels in messages (default "column <c>").
    """
    if not isinstance(df, pd.DataFrame):
        raise UserError("a drive log must be a table")
    labels = labels or {}

    def lab(col: str) -> str:
        return f"channel {labels[col]}" if col in labels else f"column {col}"

    df = df.reset_index(drop=True)
    df.columns = [str(c).strip() for c in df.columns]
    dup = df.columns[df.columns.duplicated()].tolist()
    if dup:
        raise UserError(f"column {dup[0]} appears twice")
    for col in REQUIRED:
        if col not in df.columns:
            raise UserError(f"missing required column {col!r} (required: {', '.join(REQUIRED)})")
    if len(df) < 2:
        raise UserError(f"a drive log needs at least 2 samples, this one has {len(df)}")
    out: dict[str, Any] = {}
    for col in ("t", "s", "v", "speed_limit"):
        x = _numeric(df, col, lab(col))
        i = _first(~np.isfinite(x))
        if i is not None:
            what = "missing value (NaN)" if np.isnan(x[i]) else f"{x[i]} is not finite"
            raise UserError(f"{lab(col)} row {_row(i)}: {what}")
        out[col] = x
    out["segment"] = _text(df, "segment", segments, required=True, name=lab("segment"), max_length=SEGMENT_MAX)
    v = out["v"]
    i = _first((v < 0) | (v > V_MAX))
    if i is not None:
        raise UserError(f"{lab('v')} row {_row(i)}: speed {v[i]:g} m/s outside 0..{V_MAX:g} m/s")
    lim = out["speed_limit"]
    i = _first((lim <= 0) | (lim > V_MAX))
    if i is not None:
        raise UserError(f"{lab('speed_limit')} row {_row(i)}: {lim[i]:g} m/s outside (0, {V_MAX:g}] m/s "
                        f"(speed limits are in m/s, not km/h)")
    dt = np.diff(out["t"])
    i = _first(dt <= 0)
    if i is not None:
        raise UserError(f"{lab('t')} row {_row(i + 1)}: time step {dt[i]:g} s is not positive "
                        f"(t={out['t'][i + 1]:g} after {out['t'][i]:g})")
    ds = np.diff(out["s"])
    i = _first(ds < 0)
    if i is not None:
        raise UserError(f"{lab('s')} row {_row(i + 1)}: distance decreases ({out['s'][i + 1]:g} m after "
                        f"{out['s'][i]:g} m)")
    for col in FLOAT_OPTIONAL:
        if col in df.columns:
            x = _numeric(df, col, lab(col))
            i = _first(np.isinf(x))
            if i is not None:
                raise UserError(f"{lab(col)} row {_row(i)}: {x[i]} is not finite")
            out[col] = x
    for col, allowed in TEXT_OPTIONAL.items():
        if col in df.columns:
            out[col] = _text(df, col, allowed, required=False, name=lab(col))
    if "hud_arrow" in df.columns:
        x = _numeric(df, "hud_arrow", lab("hud_arrow"))
        i = _first(~np.isnan(x) & ~np.isin(x, (-1.0, 0.0, 1.0)))
        if i is not None:
            raise UserError(f"{lab('hud_arrow')} row {_row(i)}: {x[i]:g} is not one of -1|0|1")
        mask = np.isnan(x)
        out["hud_arrow"] = pd.arrays.IntegerArray(np.where(mask, 0, x).astype(np.int8), mask)
    for col in BOOL_OPTIONAL:
        if col in df.columns:
            out[col] = _bool(df, col, lab(col))
    frame = pd.DataFrame({c: out[c] for c in COLUMNS if c in out})
    ignored = tuple(c for c in df.columns if c not in COLUMNS)
    return frame, ignored


# ---------------------------------------------------------------------------------------------- reading
def log_format(path: str | Path, fmt: str | None = None) -> str:
    """The format of a drive log file: `fmt` when given, else from the name (.csv/.csv.gz/.txt, .parquet/.pq,
    .xml/.xml.gz = SUMO FCD)."""
    if fmt is not None:
        return check_choice("format", fmt, logmap.FORMATS)
    name = Path(path).name.lower()
    if name.endswith((".parquet", ".pq")):
        return "parquet"
    if name.endswith((".csv", ".csv.gz", ".txt")):
        return "csv"
    if name.endswith((".xml", ".xml.gz")):
        return "sumo-fcd"
    raise UserError(f"{Path(path).name}: unknown drive log format (use .csv, .parquet or SUMO FCD .xml, "
                    f"or --format)")


def read_drive_file(path: str | Path, fmt: str | None = None, vehicle: str | None = None) -> pd.DataFrame:
    """Read a CSV, Parquet or SUMO FCD drive log as it is (mapping and validation are separate)."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    kind = log_format(path, fmt)
    try:
        if kind == "sumo-fcd":
            from study.fcd import read_fcd

            return read_fcd(path, vehicle)
        if kind == "parquet":
            return pd.read_parquet(path)
        return pd.read_csv(path, dtype={"tl_id": "string", "segment": "string", "tl_state": "string",
                                        "controller": "string"}, low_memory=False)
    except UserError:
        raise
    except Exception as exc:  # unreadable file: one line
        raise UserError(f"cannot read {path.name}: {' '.join(str(exc).split())}") from exc


def file_checksum(path: str | Path) -> str:
    """sha256 (hex) of the file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def frame_checksum(df: pd.DataFrame) -> str:
    """sha256 (hex) of a canonical serialisation of a validated drive frame: for each known column in
    canonical order its name, then float64 little-endian bytes (numbers) or, for text and booleans, the
    distinct values in order of first appearance followed by each row's int64 code (-1 = missing)."""
    h = hashlib.sha256()
    for col in COLUMNS:
        if col not in df.columns:
            continue
        s = df[col]
        h.update(f"\x1e{col}\x1d".encode())
        if isinstance(s.dtype, pd.CategoricalDtype) or not pd.api.types.is_numeric_dtype(s) \
                or pd.api.types.is_bool_dtype(s):
            codes, uniques = pd.factorize(s.astype(object), use_na_sentinel=True)
            h.update("\x1f".join(str(u) for u in uniques).encode("utf-8") + b"\x1d")
            h.update(np.ascontiguousarray(codes.astype("<i8")).tobytes())
        else:
            h.update(np.ascontiguousarray(s.to_numpy(dtype="<f8", na_value=np.nan)).tobytes())
    return h.hexdigest()


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


# ---------------------------------------------------------------------------------------------- plausibility
def plausibility(frame: pd.DataFrame, labels: dict[str, str] | None = None, rate_hz: float | None = None,
                 max_gap_s: float = logmap.DEFAULT_MAX_GAP_S,
                 tolerance: float = logmap.DEFAULT_DISTANCE_TOLERANCE, s_integrated: bool = False,
                 route_length: float | None = None) -> list[str]:
    """Problems of a validated log that suggest a unit or timing error (each one line naming channel and row).

    * sampling: the median time step lies in :data:`SAMPLING_S` (0.01-1 s) and agrees with `rate_hz` (when given)
      within 5 %; no step exceeds `max_gap_s`;
    * magnitudes: battery power and forces within :data:`MAGNITUDES` (a passenger car);
    * distance: the integral of v dt since the first sample and the advance of s agree within `tolerance`
      (relative) + 5 m, checked from the first 50 m on: a speed in km/h read as m/s is off by 3.6 at any speed;
      a log without s (integrated from v) must not be longer than the route.
    """
    labels = labels or {}

    def lab(col: str) -> str:
        return f"channel {labels[col]}" if col in labels else f"column {col}"

    out = []
    t, s, v = (frame[c].to_numpy(dtype="float64") for c in ("t", "s", "v"))
    dt = np.diff(t)
    if rate_hz is not None and dt.size:
        med, want = float(np.median(dt)), 1.0 / rate_hz
        if abs(med / want - 1.0) > RATE_TOLERANCE:
            out.append(f"{lab('t')} rows 1-{len(t)}: median sampling interval {med:.6g} s, but the log mapping "
                       f"declares {rate_hz:g} Hz ({want:.6g} s){_hint(med / want)}")
    if dt.size and not out:  # the declared rate's message says more
        med, (lo, hi) = float(np.median(dt)), SAMPLING_S
        if not lo <= med <= hi:
            unit = (": looks like a time in ms read as s" if lo <= med / 1000 <= hi else
                    ": looks like a time in s read as ms" if lo <= med * 1000 <= hi else "")
            out.append(f"{lab('t')} rows 1-{len(t)}: median sampling interval {med:.6g} s outside {lo:g}-{hi:g} s"
                       f"{unit}")
    for col, (bound, unit, what) in MAGNITUDES.items():
        if col in frame.columns:
            x = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype="float64", na_value=np.nan)
            i = _first(np.abs(x) > bound)
            if i is not None:
                out.append(f"{lab(col)} row {_row(i)}: {what} {x[i]:g} {unit} beyond ±{bound:g} {unit} "
                           f"(implausible for a passenger car)")
    i = _first(dt > max_gap_s)
    if i is not None:
        out.append(f"{lab('t')} row {_row(i + 1)}: gap of {dt[i]:g} s after t = {t[i]:g} s (largest allowed "
                   f"{max_gap_s:g} s, [log] max_gap_s of the log mapping)")
    travelled = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    if s_integrated:
        if route_length is not None and travelled[-1] > route_length * (1 + tolerance) + DISTANCE_SLACK:
            out.append(f"{lab('v')} row {len(v)}: the integral of v dt is {travelled[-1]:,.0f} m, longer than "
                       f"the route ({route_length:,.0f} m){_hint(travelled[-1] / route_length)}")
        return out
    advanced = s - s[0]
    big = np.maximum(travelled, advanced)
    bad = (big >= MIN_CHECK_DISTANCE) & (np.abs(travelled - advanced) > tolerance * big + DISTANCE_SLACK)
    i = _first(bad)
    if i is not None:
        ratio = travelled[i] / advanced[i] if advanced[i] > 0 else float("inf")
        out.append(f"{lab('v')} row {_row(i)}: the integral of v dt since row 1 is {travelled[i]:,.0f} m but "
                   f"{lab('s')} advanced {advanced[i]:,.0f} m (ratio {ratio:.3g}, allowed 1 ± {tolerance:g})"
                   f"{_hint(ratio)}")
    return out


def _hint(ratio: float) -> str:
    for r, what in _UNIT_MIXUPS:
        if np.isfinite(ratio) and abs(ratio / r - 1.0) < 0.05:
            return f": looks like {what}"
    return ""


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


def _energy(frame: pd.DataFrame, study, source: str) -> tuple[str | None, str]:
    """(model to fill with or None, energy_source for drives.meta)."""
    has_power = "p_batt" in frame.columns and frame["p_batt"].notna().any()
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
            from study.audit_trail import utcnow

            st.insert("drive_channels", {"channel": ch.name, "unit": unit, "description": ch.description or None,
                                         "added_at": utcnow()})
        elif have != unit:
            raise UserError(f"channel {ch.name} is stored in {have}, this log mapping gives it in {unit}: "
                            f"add to = \"{have}\" to its [channels.{ch.name}]")


def _store_drive(st, drive: DriveRecord) -> DriveImport:
    """Store `drive` in one transaction (the audited ``drives`` row and all its samples), or find it stored."""
    from study.participants import require
    from study.studies import definition

    participant_id, condition, checksum, source = drive.participant_id, drive.condition, drive.checksum, drive.source
    prep, progress, t0 = drive.prepared, drive.progress, drive.started
    frame, extras, channels, ignored = prep.frame, prep.extras, prep.channels, prep.ignored
    study = definition(st)
    study.check_condition(condition)
    check_choice("source", source, SOURCES)
    if "p_batt" in frame.columns and frame["p_batt"].isna().all():
        frame = frame.drop(columns="p_batt")  # an empty power column is no measurement
    model, energy_source = _energy(frame, study, source)
    meta = dict(drive.meta or {})
    meta.setdefault("energy_source", energy_source)
    try:
        with st.transaction():
            require(st, participant_id)
            have = st.con.execute("SELECT drive_id, checksum, file_name FROM drives WHERE participant_id = ? "
                                  "AND condition = ?", [participant_id, condition]).fetchone()
            if have and have[1] == checksum:
                return DriveImport(int(have[0]), participant_id, condition, "unchanged", len(frame), checksum,
                                   time.perf_counter() - t0, ignored, energy_source=meta["energy_source"])
            if source == "import":
                twin = st.con.execute("SELECT participant_id, condition FROM drives WHERE checksum = ?",
                                      [checksum]).fetchone()
                if twin:
                    raise UserError(f"this log is already stored as the {twin[1]} drive of {twin[0]}")
            if have and not drive.replace:
                raise UserError(f"{participant_id} already has a {condition} drive"
                                f"{' from ' + have[2] if have[2] else ''} with different content; "
                                f"use --replace to replace it")
            frame, filled = _fill(frame, model)
            if channels:
                _store_channels(st, channels)
            status = "imported"
            if have:
                st.con.execute("DELETE FROM drive_samples WHERE drive_id = ?", [have[0]])
                st.delete("drives", {"drive_id": int(have[0])})
                status = "replaced"
            t = frame["t"].to_numpy()
            s = frame["s"].to_numpy()
            row = st.insert("drives", {
                "participant_id": participant_id, "condition": condition, "source": source, "route": drive.route,
                "checksum": checksum, "n_samples": len(frame), "file_name": drive.file_name,
                "duration_s": float(t[-1] - t[0]), "distance_m": float(s[-1] - s[0]), "seed": drive.seed,
                "meta": json.dumps(meta, sort_keys=True, default=str)})
            drive_id = int(row["drive_id"])
            samples = frame.copy()
            samples.insert(0, "idx", np.arange(len(frame), dtype=np.int32))
            samples.insert(0, "drive_id", np.full(len(frame), drive_id, dtype=np.int64))
            for ch in channels:
                samples[ch.name] = extras[ch.name].to_numpy(dtype="float64")
            if progress:
                progress(f"writing {len(frame)} samples of drive {drive_id} ({participant_id} {condition})")
            # DuckDB scans an Arrow table faster than pandas' nullable/categorical columns (about 1.3x measured)
            import pyarrow as pa

            st.insert_df("drive_samples", pa.Table.from_pandas(samples, preserve_index=False))
            if progress:
                progress("committing")
    finally:
        if channels:  # a rolled-back ALTER TABLE leaves a stale cached column list otherwise
            st._columns.pop("drive_samples", None)
    return DriveImport(drive_id, participant_id, condition, status, len(frame), checksum,
                       time.perf_counter() - t0, ignored, filled, tuple(ch.name for ch in channels),
                       meta["energy_source"], prep.overridden)


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
        raise UserError(f"log mapping {m.name} reads {m.format} files, {path.name} is {fmt}")
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


def _force_reason(force: str | None) -> str | None:
    if force is None:
        return None
    if not isinstance(force, str) or not force.strip():
        raise UserError("--force needs a reason (recorded with the drive)")
    return force.strip()


def import_drive_file(st, participant_id: str, condition: str, path: str | Path, replace: bool = False,
                      route: str | None = None, progress: Callable[[str], None] | None = None,
                      mapping: Any = None, fmt: str | None = None, vehicle: str | None = None,
                      force: str | None = None) -> DriveImport:
    """Read, map, check and import a drive log file (CSV, Parquet or SUMO FCD) for (participant, condition).

    `mapping`: None = the study's log mapping when it reads this format (else the file is a canonical log),
    "none" = a canonical log, or a mapping file path / :class:`study.logmap.Mapping`. `fmt` overrides the format
    taken from the file name; `vehicle` picks the vehicle of an FCD file. `force` = a reason to import despite
    plausibility problems (recorded in drives.meta). `route` names the route stored with the drive (default: the
    study's route file's name). Checksum: sha256 of the file; of file, mapping and route when those were used.
    Every problem of the log is one line starting with the file name.
    """
    from study.studies import definition

    study = definition(st)  # first: parsing a stored study (its model file) is not part of the import's time
    t0 = time.perf_counter()
    path = Path(path)
    force = _force_reason(force)
    study.check_condition(condition)
    kind = log_format(path, fmt)
    m = _mapping_for(study, path, kind, mapping)
    rfile = route_file.study_route(study)
    vehicle = vehicle or (m.vehicle if m is not None else None)
    raw = read_drive_file(path, kind, vehicle)
    if progress:
        progress(f"read {len(raw)} rows from {path.name}")
    try:
        prep = _prepare(raw, m, rfile, "import", force)
    except UserError as exc:
        raise UserError(f"{path.name}: {exc}") from None
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
    if prep.joined:
        meta["from_route"] = list(prep.joined)
    if prep.s_integrated:
        meta["s"] = "integrated from v"
    if force is not None:
        meta["forced"] = {"reason": force, "overridden": list(prep.overridden)}
    route = route or (rfile.name if rfile is not None else None)
    try:
        return _store_drive(st, DriveRecord(participant_id, condition, prep, checksum, "import", t0, route=route,
                                            file_name=path.name, meta=meta, replace=replace, progress=progress))
    except UserError as exc:
        if str(exc).startswith("channel "):
            raise UserError(f"{path.name}: {exc}") from None
        raise


def import_drive_frame(st, participant_id: str, condition: str, df: pd.DataFrame, source: str = "simulation",
                       route: str | None = None, replace: bool = False, seed: int | None = None,
                       meta: dict | None = None, file_name: str | None = None,
                       progress: Callable[[str], None] | None = None, force: str | None = None) -> DriveImport:
    """Validate and store a drive given as a canonical DataFrame (e.g. a simulated drive).

    The checksum is :func:`frame_checksum` of the validated frame, so storing the same frame again is a no-op.
    `seed` and `meta` (JSON-serialisable settings) are kept on the drives row for reproducibility, with
    ``energy_source`` added unless `meta` names it. Source 'import' frames get the plausibility checks.
    """
    from study.studies import definition

    study = definition(st)
    t0 = time.perf_counter()
    force = _force_reason(force)
    study.check_condition(condition)
    rfile = route_file.study_route(study)
    prep = _prepare(df, None, rfile, source, force)
    meta = dict(meta) if meta is not None else {}
    if prep.joined:
        meta["from_route"] = list(prep.joined)
    if force is not None:
        meta["forced"] = {"reason": force, "overridden": list(prep.overridden)}
    return _store_drive(st, DriveRecord(participant_id, condition, prep, frame_checksum(prep.frame), source, t0,
                                        route=route, file_name=file_name, seed=seed, meta=meta, replace=replace,
                                        progress=progress))


def drive_samples(st, participant_id: str, condition: str, channels: bool | list[str] = False) -> pd.DataFrame:
    """The samples of one drive in order (columns of the drive-log format, then the extra `channels`: True = all
    registered ones, or a list of names); unknown drive or channel -> UserError."""
    drive_id = st.one("SELECT drive_id FROM drives WHERE participant_id = ? AND condition = ?",
                      [participant_id, condition])
    if drive_id is None:
        raise UserError(f"{participant_id} has no {condition} drive")
    known = list_channels(st)["channel"].tolist()
    if channels is True:
        extra = known
    elif channels:
        extra = list(channels)
        for name in extra:
            if name not in known:
                raise UserError(f"unknown drive channel {name!r} (stored: {', '.join(known) or 'none'})")
    else:
        extra = []
    cols = ", ".join(list(COLUMNS) + [f'"{c}"' for c in extra])
    return st.df(f"SELECT {cols} FROM drive_samples WHERE drive_id = ? ORDER BY idx", [drive_id])


def list_channels(st) -> pd.DataFrame:
    """The extra channels stored with drive samples: channel, unit, description, added_at."""
    return st.df("SELECT channel, unit, description, added_at FROM drive_channels ORDER BY channel")


def list_drives(st) -> pd.DataFrame:
    return st.df("SELECT drive_id, participant_id, condition, source, route, n_samples, duration_s, distance_m, "
                 "file_name, checksum, created_at FROM drives ORDER BY participant_id, condition")

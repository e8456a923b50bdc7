"""Drive logs: validation and import of simulator logs (CSV or Parquet) and of simulated drives (DataFrames).

A drive log has one row per sample with SI units (see docs/contracts.md and docs/store.md):
required ``t`` s, ``s`` m, ``v`` m/s, ``segment`` urban|highway, ``speed_limit`` m/s; optional ``a``, ``grade``,
``ft``, ``fb``, ``p_batt``, ``tl_id``, ``tl_state``, ``d_tl``, ``leader_gap``, ``leader_v``, ``v_advice``,
``controller``, ``hud_arrow``, ``hud_in_band``, ``warning``. Optional columns that can be computed from the
trace (a, ft, fb, p_batt) are filled by ``pedas.power.fill_drive_columns`` when absent.

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

from pedas.vocabulary import CONDITIONS, SEGMENTS
from study.errors import UserError, check_choice

SOURCES = ("import", "simulation")
REQUIRED = ("t", "s", "v", "segment", "speed_limit")
TL_STATES = ("green", "yellow", "red")
CONTROLLERS = ("rt", "cf", "none")
FLOAT_OPTIONAL = ("a", "grade", "ft", "fb", "p_batt", "d_tl", "leader_gap", "leader_v", "v_advice")
TEXT_OPTIONAL = {"tl_id": None, "tl_state": TL_STATES, "controller": CONTROLLERS}
BOOL_OPTIONAL = ("hud_in_band", "warning")
COLUMNS = REQUIRED + ("a", "grade", "ft", "fb", "p_batt", "tl_id", "tl_state", "d_tl", "leader_gap", "leader_v",
                      "v_advice", "controller", "hud_arrow", "hud_in_band", "warning")
V_MAX = 70.0            # m/s, upper plausibility bound of speed and speed limit (252 km/h)
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

    @property
    def rows_per_second(self) -> float:
        return self.n_samples / self.seconds if self.seconds > 0 else float("inf")


# ---------------------------------------------------------------------------------------------- validation
def _row(i: int) -> int:
    """Rows are reported 1-based, counting data rows (a CSV header is not a row)."""
    return int(i) + 1


def _numeric(df: pd.DataFrame, col: str) -> np.ndarray:
    """Column as float64; a non-number names column and row."""
    s = df[col]
    if pd.api.types.is_bool_dtype(s) or not (pd.api.types.is_numeric_dtype(s) or s.dtype == object
                                              or pd.api.types.is_string_dtype(s)):
        raise UserError(f"column {col} must be numeric (dtype {s.dtype})")
    if pd.api.types.is_numeric_dtype(s):
        return s.to_numpy(dtype="float64", na_value=np.nan)
    conv = pd.to_numeric(s, errors="coerce")
    bad = conv.isna() & s.notna() & (s.astype("string").str.strip() != "")
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(f"column {col} row {_row(i)}: {s.iloc[i]!r} is not a number")
    return conv.to_numpy(dtype="float64", na_value=np.nan)


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _text(df: pd.DataFrame, col: str, allowed: tuple[str, ...] | None, required: bool) -> pd.Categorical:
    """Column as a categorical of stripped text (NaN = missing), checked against `allowed`.

    Works on the distinct values (pd.factorize) because logs have millions of rows but a handful of values.
    """
    codes, uniques = pd.factorize(df[col], use_na_sentinel=True)
    labels = np.array([str(u).strip() for u in uniques] + [None], dtype=object)  # index -1 -> None
    labels[[i for i, u in enumerate(labels[:-1]) if u == ""]] = None
    missing = np.flatnonzero(pd.isna(labels[:-1]))
    if required:
        bad_missing = (codes == -1) | np.isin(codes, missing)
        i = _first(bad_missing)
        if i is not None:
            raise UserError(f"column {col} row {_row(i)}: missing value")
    if allowed is not None:
        bad = [k for k, u in enumerate(labels[:-1]) if u is not None and u not in allowed]
        if bad:
            i = _first(np.isin(codes, bad))
            raise UserError(f"column {col} row {_row(i)}: {labels[codes[i]]!r} is not one of {'|'.join(allowed)}")
    # a categorical keeps the few distinct strings once (DuckDB stores it as text on insert)
    cats = sorted({u for u in labels[:-1] if u is not None})
    pos = np.array([cats.index(u) if u is not None else -1 for u in labels[:-1]] + [-1], dtype=np.int64)
    return pd.Categorical.from_codes(pos[codes], categories=cats)


def _bool(df: pd.DataFrame, col: str) -> pd.arrays.BooleanArray:
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
        raise UserError(f"column {col} row {_row(i)}: {s.iloc[i]!r} is not a boolean (0/1, true/false)")
    mask = np.isnan(vals)
    return pd.arrays.BooleanArray(np.where(mask, False, vals == 1.0), mask)


def validate_drive(df: pd.DataFrame) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """Check a drive log and return (normalised frame with the known columns in canonical order, ignored columns).

    Rules (the first violation is reported as one line naming column and 1-based row): required columns
    present; at least 2 samples; no missing value in a required column; numeric columns numeric and finite;
    0 <= v <= 70 m/s; 0 < speed_limit <= 70 m/s; t strictly increasing; s non-decreasing; segment in
    urban|highway; optional columns typed (tl_state green|yellow|red, controller rt|cf|none, hud_arrow -1|0|1,
    hud_in_band/warning boolean, the rest numbers) — missing values allowed there.
    """
    if not isinstance(df, pd.DataFrame):
        raise UserError("a drive log must be a table")
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
        x = _numeric(df, col)
        i = _first(~np.isfinite(x))
        if i is not None:
            what = "missing value (NaN)" if np.isnan(x[i]) else f"{x[i]} is not finite"
            raise UserError(f"column {col} row {_row(i)}: {what}")
        out[col] = x
    out["segment"] = _text(df, "segment", SEGMENTS, required=True)
    v = out["v"]
    i = _first((v < 0) | (v > V_MAX))
    if i is not None:
        raise UserError(f"column v row {_row(i)}: speed {v[i]:g} m/s outside 0..{V_MAX:g} m/s")
    lim = out["speed_limit"]
    i = _first((lim <= 0) | (lim > V_MAX))
    if i is not None:
        raise UserError(f"column speed_limit row {_row(i)}: {lim[i]:g} m/s outside (0, {V_MAX:g}] m/s "
                        f"(speed limits are in m/s, not km/h)")
    dt = np.diff(out["t"])
    i = _first(dt <= 0)
    if i is not None:
        raise UserError(f"column t row {_row(i + 1)}: time step {dt[i]:g} s is not positive "
                        f"(t={out['t'][i + 1]:g} after {out['t'][i]:g})")
    ds = np.diff(out["s"])
    i = _first(ds < 0)
    if i is not None:
        raise UserError(f"column s row {_row(i + 1)}: distance decreases ({out['s'][i + 1]:g} m after "
                        f"{out['s'][i]:g} m)")
    for col in FLOAT_OPTIONAL:
        if col in df.columns:
            x = _numeric(df, col)
            i = _first(np.isinf(x))
            if i is not None:
                raise UserError(f"column {col} row {_row(i)}: {x[i]} is not finite")
            out[col] = x
    for col, allowed in TEXT_OPTIONAL.items():
        if col in df.columns:
            out[col] = _text(df, col, allowed, required=False)
    if "hud_arrow" in df.columns:
        x = _numeric(df, "hud_arrow")
        i = _first(~np.isnan(x) & ~np.isin(x, (-1.0, 0.0, 1.0)))
        if i is not None:
            raise UserError(f"column hud_arrow row {_row(i)}: {x[i]:g} is not one of -1|0|1")
        mask = np.isnan(x)
        out["hud_arrow"] = pd.arrays.IntegerArray(np.where(mask, 0, x).astype(np.int8), mask)
    for col in BOOL_OPTIONAL:
        if col in df.columns:
            out[col] = _bool(df, col)
    frame = pd.DataFrame({c: out[c] for c in COLUMNS if c in out})
    ignored = tuple(c for c in df.columns if c not in COLUMNS)
    return frame, ignored


# ---------------------------------------------------------------------------------------------- reading
def read_drive_file(path: str | Path) -> pd.DataFrame:
    """Read a CSV (.csv, .csv.gz) or Parquet (.parquet, .pq) drive log as it is (validation is separate)."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    name = path.name.lower()
    try:
        if name.endswith((".parquet", ".pq")):
            return pd.read_parquet(path)
        if name.endswith((".csv", ".csv.gz", ".txt")):
            return pd.read_csv(path, dtype={"tl_id": "string", "segment": "string", "tl_state": "string",
                                            "controller": "string"}, low_memory=False)
    except UserError:
        raise
    except Exception as exc:  # unreadable file: one line
        raise UserError(f"cannot read {path.name}: {' '.join(str(exc).split())}") from exc
    raise UserError(f"{path.name}: unknown drive log format (use .csv or .parquet)")


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


# ---------------------------------------------------------------------------------------------- import
def _fill(frame: pd.DataFrame) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """Compute the absent optional columns that follow from the trace (pedas.power.fill_drive_columns)."""
    try:
        from pedas.power import fill_drive_columns
    except ImportError:  # the simulation core is optional for the store; columns stay NULL
        return frame, ()
    before = set(frame.columns)
    filled = fill_drive_columns(frame)
    if filled is None:
        filled = frame
    new = tuple(c for c in COLUMNS if c in filled.columns and c not in before)
    return filled[[c for c in COLUMNS if c in filled.columns]], new


def _store_drive(st, participant_id: str, condition: str, frame: pd.DataFrame, checksum: str, source: str,
                 route: str | None, file_name: str | None, replace: bool, seed: int | None,
                 meta: dict | None, ignored: tuple[str, ...], t0: float,
                 progress: Callable[[str], None] | None) -> DriveImport:
    from study.participants import require

    check_choice("condition", condition, CONDITIONS)
    check_choice("source", source, SOURCES)
    with st.transaction():
        require(st, participant_id)
        have = st.con.execute("SELECT drive_id, checksum, file_name FROM drives WHERE participant_id = ? "
                              "AND condition = ?", [participant_id, condition]).fetchone()
        if have and have[1] == checksum:
            return DriveImport(int(have[0]), participant_id, condition, "unchanged", len(frame), checksum,
                               time.perf_counter() - t0, ignored)
        if source == "import":
            twin = st.con.execute("SELECT participant_id, condition FROM drives WHERE checksum = ?",
                                  [checksum]).fetchone()
            if twin:
                raise UserError(f"this log is already stored as the {twin[1]} drive of {twin[0]}")
        if have and not replace:
            raise UserError(f"{participant_id} already has a {condition} drive"
                            f"{' from ' + have[2] if have[2] else ''} with different content; "
                            f"use --replace to replace it")
        frame, filled = _fill(frame)
        status = "imported"
        if have:
            st.con.execute("DELETE FROM drive_samples WHERE drive_id = ?", [have[0]])
            st.delete("drives", {"drive_id": int(have[0])})
            status = "replaced"
        t = frame["t"].to_numpy()
        s = frame["s"].to_numpy()
        row = st.insert("drives", {
            "participant_id": participant_id, "condition": condition, "source": source, "route": route,
            "checksum": checksum, "n_samples": len(frame), "file_name": file_name,
            "duration_s": float(t[-1] - t[0]), "distance_m": float(s[-1] - s[0]), "seed": seed,
            "meta": json.dumps(meta, sort_keys=True, default=str) if meta is not None else None})
        drive_id = int(row["drive_id"])
        samples = frame.copy()
        samples.insert(0, "idx", np.arange(len(frame), dtype=np.int32))
        samples.insert(0, "drive_id", np.full(len(frame), drive_id, dtype=np.int64))
        if progress:
            progress(f"writing {len(frame)} samples of drive {drive_id} ({participant_id} {condition})")
        # DuckDB scans an Arrow table faster than pandas' nullable/categorical columns (about 1.3x measured)
        import pyarrow as pa

        st.insert_df("drive_samples", pa.Table.from_pandas(samples, preserve_index=False))
        if progress:
            progress("committing")
    return DriveImport(drive_id, participant_id, condition, status, len(frame), checksum,
                       time.perf_counter() - t0, ignored, filled)


def import_drive_file(st, participant_id: str, condition: str, path: str | Path, replace: bool = False,
                      route: str | None = None, progress: Callable[[str], None] | None = None) -> DriveImport:
    """Validate and import a CSV/Parquet drive log for (participant, condition); checksum = sha256 of the file."""
    t0 = time.perf_counter()
    path = Path(path)
    raw = read_drive_file(path)
    if progress:
        progress(f"read {len(raw)} rows from {path.name}")
    frame, ignored = validate_drive(raw)
    return _store_drive(st, participant_id, condition, frame, file_checksum(path), "import", route, path.name,
                        replace, None, None, ignored, t0, progress)


def import_drive_frame(st, participant_id: str, condition: str, df: pd.DataFrame, source: str = "simulation",
                       route: str | None = None, replace: bool = False, seed: int | None = None,
                       meta: dict | None = None, file_name: str | None = None,
                       progress: Callable[[str], None] | None = None) -> DriveImport:
    """Validate and store a drive given as a DataFrame (e.g. a simulated drive).

    The checksum is :func:`frame_checksum` of the validated frame, so storing the same frame again is a no-op.
    `seed` and `meta` (JSON-serialisable settings) are kept on the drives row for reproducibility.
    """
    t0 = time.perf_counter()
    frame, ignored = validate_drive(df)
    return _store_drive(st, participant_id, condition, frame, frame_checksum(frame), source, route, file_name,
                        replace, seed, meta, ignored, t0, progress)


def drive_samples(st, participant_id: str, condition: str) -> pd.DataFrame:
    """The samples of one drive in order (columns of the drive-log format); unknown drive -> UserError."""
    drive_id = st.one("SELECT drive_id FROM drives WHERE participant_id = ? AND condition = ?",
                      [participant_id, condition])
    if drive_id is None:
        raise UserError(f"{participant_id} has no {condition} drive")
    cols = ", ".join(COLUMNS)
    return st.df(f"SELECT {cols} FROM drive_samples WHERE drive_id = ? ORDER BY idx", [drive_id])


def list_drives(st) -> pd.DataFrame:
    return st.df("SELECT drive_id, participant_id, condition, source, route, n_samples, duration_s, distance_m, "
                 "file_name, checksum, created_at FROM drives ORDER BY participant_id, condition")

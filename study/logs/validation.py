"""Checks of a drive log in the canonical columns (docs/contracts.md "Drive log"): the columns' types and ranges
(:func:`validate_drive`) and the plausibility checks an import may override with ``force=REASON``
(:func:`plausibility`: distance from the integral of v dt against s, sampling interval, magnitudes)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from study.common.errors import UserError
from study.common.numbers import column_floats
from study.folder import logmap, route_file
from study.folder.drive_columns import (
    BOOL_OPTIONAL,
    COLUMNS,
    FLOAT_OPTIONAL,
    REQUIRED,
    TEXT_OPTIONAL,
)

V_MAX = 70.0            # m/s, upper plausibility bound of speed and speed limit (252 km/h)
SEGMENT_MAX = route_file.SEGMENT_MAX
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


# ---------------------------------------------------------------------------------------------- validation
def _row(i: int) -> int:
    """Rows are reported 1-based, counting data rows (a CSV header is not a row)."""
    return int(i) + 1


class _Problem(UserError):
    """A problem :func:`validate_drive` reports, with the position of its check in the order of the checks
    (`check`): a log validated in chunks reports the problem of the earliest check that fails in any chunk, at the
    first chunk where it fails, which is what the whole log validated at once reports."""

    def __init__(self, message: str, check: int) -> None:
        super().__init__(message)
        self.check = check


#: positions in the order of the checks of the problems outside the rows' values
CHECK_ROUTE, CHECK_HEADER, CHECK_LENGTH = -1, 0, 1


def _numeric(df: pd.DataFrame, col: str, name: str | None = None, first_row: int = 0) -> np.ndarray:
    """Column as float64; a non-number names column (`name`, default "column <col>") and row (`first_row`: the
    log's 0-based row of the frame's first row)."""
    name = name or f"column {col}"
    s = df[col]
    if pd.api.types.is_bool_dtype(s) or not (pd.api.types.is_numeric_dtype(s) or s.dtype == object
                                              or pd.api.types.is_string_dtype(s)):
        raise UserError(f"{name} must be numeric (dtype {s.dtype})")
    return column_floats(s, lambda i: f"{name} row {_row(first_row + i)}")


def _first(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _text(df: pd.DataFrame, col: str, allowed: tuple[str, ...] | None, required: bool, name: str | None = None,
          max_length: int | None = None, first_row: int = 0) -> pd.Categorical:
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
            raise UserError(f"{name} row {_row(first_row + i)}: missing value")
    if allowed is not None:
        bad = [k for k, u in enumerate(labels[:-1]) if u is not None and u not in allowed]
        if bad:
            i = _first(np.isin(codes, bad))
            raise UserError(f"{name} row {_row(first_row + i)}: {labels[codes[i]]!r} is not one of "
                            f"{'|'.join(allowed)}")
    if max_length is not None:
        bad = [k for k, u in enumerate(labels[:-1]) if u is not None and len(u) > max_length]
        if bad:
            i = _first(np.isin(codes, bad))
            raise UserError(f"{name} row {_row(first_row + i)}: {labels[codes[i]][:20]!r}... is longer than "
                            f"{max_length} characters")
    # a categorical keeps the few distinct strings once (DuckDB stores it as text on insert)
    cats = sorted({u for u in labels[:-1] if u is not None})
    pos = np.array([cats.index(u) if u is not None else -1 for u in labels[:-1]] + [-1], dtype=np.int64)
    return pd.Categorical.from_codes(pos[codes], categories=cats)


def _bool(df: pd.DataFrame, col: str, name: str | None = None, first_row: int = 0) -> pd.arrays.BooleanArray:
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
        raise UserError(f"{name} row {_row(first_row + i)}: {s.iloc[i]!r} is not a boolean (0/1, true/false)")
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
    return _validate(df, labels, segments)


def _validate(df: pd.DataFrame, labels: dict[str, str] | None = None, segments: tuple[str, ...] | None = None,
              first_row: int | None = None, carry: dict | None = None) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """:func:`validate_drive` of the whole log (`first_row` None) or of one chunk of it: `first_row` is the log's
    0-based row of the chunk's first row (messages name the log's rows; the length is checked for the whole log by
    the caller); `carry` holds the last t and s of the previous chunk (``carry["t"]``, ``carry["s"]``, None for the
    first) for the checks across the chunks' border and receives this chunk's. Problems raise :class:`_Problem`."""
    if not isinstance(df, pd.DataFrame):
        raise _Problem("a drive log must be a table", CHECK_HEADER)
    labels = labels or {}
    whole, row0 = first_row is None, first_row or 0
    carry = {} if carry is None else carry
    before = (carry.get("t"), carry.get("s"))
    carry["t"] = carry["s"] = None  # until this chunk's t and s are numbers

    def lab(col: str) -> str:
        return f"channel {labels[col]}" if col in labels else f"column {col}"

    df = df.reset_index(drop=True)
    df.columns = [str(c).strip() for c in df.columns]
    dup = df.columns[df.columns.duplicated()].tolist()
    if dup:
        raise _Problem(f"column {dup[0]} appears twice", CHECK_HEADER)
    for col in REQUIRED:
        if col not in df.columns:
            raise _Problem(f"missing required column {col!r} (required: {', '.join(REQUIRED)})", CHECK_HEADER)
    if whole and len(df) < 2:
        raise _Problem(f"a drive log needs at least 2 samples, this one has {len(df)}", CHECK_LENGTH)
    step = CHECK_LENGTH  # each check below is the next one in the order
    out: dict[str, Any] = {}
    try:
        for col in ("t", "s", "v", "speed_limit"):
            step += 1
            x = _numeric(df, col, lab(col), row0)
            step += 1
            i = _first(~np.isfinite(x))
            if i is not None:
                what = "missing value (NaN)" if np.isnan(x[i]) else f"{x[i]} is not finite"
                raise UserError(f"{lab(col)} row {_row(row0 + i)}: {what}")
            out[col] = x
            if col == "s":
                carry["t"], carry["s"] = (out["t"][-1], out["s"][-1]) if len(x) else before
        step += 1
        out["segment"] = _text(df, "segment", segments, required=True, name=lab("segment"),
                               max_length=SEGMENT_MAX, first_row=row0)
        step += 1
        v = out["v"]
        i = _first((v < 0) | (v > V_MAX))
        if i is not None:
            raise UserError(f"{lab('v')} row {_row(row0 + i)}: speed {v[i]:g} m/s outside 0..{V_MAX:g} m/s")
        step += 1
        lim = out["speed_limit"]
        i = _first((lim <= 0) | (lim > V_MAX))
        if i is not None:
            raise UserError(f"{lab('speed_limit')} row {_row(row0 + i)}: {lim[i]:g} m/s outside (0, {V_MAX:g}] m/s "
                            f"(speed limits are in m/s, not km/h)")
        # the steps between rows, the one across the border to the previous chunk included
        base = row0 - 1 if before[0] is not None else row0   # the log's row of t[0] below
        t = out["t"] if before[0] is None else np.concatenate([[before[0]], out["t"]])
        s = out["s"] if before[1] is None else np.concatenate([[before[1]], out["s"]])
        step += 1
        dt = np.diff(t)
        i = _first(dt <= 0)
        if i is not None:
            raise UserError(f"{lab('t')} row {_row(base + i + 1)}: time step {dt[i]:g} s is not positive "
                            f"(t={t[i + 1]:g} after {t[i]:g})")
        step += 1
        ds = np.diff(s)
        i = _first(ds < 0)
        if i is not None:
            raise UserError(f"{lab('s')} row {_row(base + i + 1)}: distance decreases ({s[i + 1]:g} m after "
                            f"{s[i]:g} m)")
        for col in FLOAT_OPTIONAL:
            step += 1
            if col in df.columns:
                x = _numeric(df, col, lab(col), row0)
                i = _first(np.isinf(x))
                if i is not None:
                    raise UserError(f"{lab(col)} row {_row(row0 + i)}: {x[i]} is not finite")
                out[col] = x
        for col, allowed in TEXT_OPTIONAL.items():
            step += 1
            if col in df.columns:
                out[col] = _text(df, col, allowed, required=False, name=lab(col), first_row=row0)
        step += 1
        if "hud_arrow" in df.columns:
            x = _numeric(df, "hud_arrow", lab("hud_arrow"), row0)
            i = _first(~np.isnan(x) & ~np.isin(x, (-1.0, 0.0, 1.0)))
            if i is not None:
                raise UserError(f"{lab('hud_arrow')} row {_row(row0 + i)}: {x[i]:g} is not one of -1|0|1")
            mask = np.isnan(x)
            out["hud_arrow"] = pd.arrays.IntegerArray(np.where(mask, 0, x).astype(np.int8), mask)
        for col in BOOL_OPTIONAL:
            step += 1
            if col in df.columns:
                out[col] = _bool(df, col, lab(col), row0)
    except _Problem:
        raise
    except UserError as exc:
        raise _Problem(str(exc), step) from None
    frame = pd.DataFrame({c: out[c] for c in COLUMNS if c in out})
    ignored = tuple(c for c in df.columns if c not in COLUMNS)
    return frame, ignored


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
    check = Plausibility(labels, rate_hz, max_gap_s, tolerance, s_integrated, route_length)
    check.add(frame)
    return check.problems()


class Plausibility:
    """:func:`plausibility` of a validated log given in consecutive chunks (:meth:`add`), with the same problems as
    for the whole log (:meth:`problems`): the time steps are kept for their median (8 bytes a sample); the integral
    of v dt runs on across the chunks in the same order of additions."""

    def __init__(self, labels: dict[str, str] | None = None, rate_hz: float | None = None,
                 max_gap_s: float = logmap.DEFAULT_MAX_GAP_S,
                 tolerance: float = logmap.DEFAULT_DISTANCE_TOLERANCE, s_integrated: bool = False,
                 route_length: float | None = None) -> None:
        self.labels = labels or {}
        self.rate_hz, self.max_gap_s, self.tolerance = rate_hz, max_gap_s, tolerance
        self.s_integrated, self.route_length = s_integrated, route_length
        self.n = 0
        self.steps: list[np.ndarray] = []
        self.last: tuple[float, float] | None = None       # t, v of the previous chunk's last row
        self.s0: float | None = None
        self.travelled = 0.0                               # integral of v dt up to the last row added (m)
        self.magnitude: dict[str, str] = {}
        self.gap: str | None = None
        self.distance: str | None = None

    def lab(self, col: str) -> str:
        return f"channel {self.labels[col]}" if col in self.labels else f"column {col}"

    def add(self, frame: pd.DataFrame) -> None:
        if not len(frame):
            return
        row0 = self.n
        t, s, v = (frame[c].to_numpy(dtype="float64") for c in ("t", "s", "v"))
        for col, (bound, unit, what) in MAGNITUDES.items():
            if col in frame.columns and col not in self.magnitude:
                x = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype="float64", na_value=np.nan)
                i = _first(np.abs(x) > bound)
                if i is not None:
                    self.magnitude[col] = (f"{self.lab(col)} row {_row(row0 + i)}: {what} {x[i]:g} {unit} beyond "
                                           f"±{bound:g} {unit} (implausible for a passenger car)")
        # with the previous chunk's last row in front, the steps are those of the whole log
        base = row0 - 1 if self.last is not None else row0
        if self.last is not None:
            t, v = np.concatenate([[self.last[0]], t]), np.concatenate([[self.last[1]], v])
        dt = np.diff(t)
        self.steps.append(dt)
        i = _first(dt > self.max_gap_s)
        if i is not None and self.gap is None:
            self.gap = (f"{self.lab('t')} row {_row(base + i + 1)}: gap of {dt[i]:g} s after t = {t[i]:g} s (largest "
                        f"allowed {self.max_gap_s:g} s, [log] max_gap_s of the log mapping)")
        # the running sum continues the previous chunk's in the same order of additions (np.cumsum is sequential)
        travelled = np.cumsum(np.concatenate([[self.travelled], 0.5 * (v[1:] + v[:-1]) * dt]))
        if self.last is None:
            self.s0 = float(s[0])
        else:
            travelled = travelled[1:]
        self.travelled = float(travelled[-1])
        self.last = (float(t[-1]), float(v[-1]))
        self.n += len(frame)
        if self.s_integrated or self.distance is not None:
            return
        advanced = s - self.s0
        big = np.maximum(travelled, advanced)
        tol = self.tolerance
        bad = (big >= MIN_CHECK_DISTANCE) & (np.abs(travelled - advanced) > tol * big + DISTANCE_SLACK)
        i = _first(bad)
        if i is not None:
            ratio = travelled[i] / advanced[i] if advanced[i] > 0 else float("inf")
            self.distance = (f"{self.lab('v')} row {_row(row0 + i)}: the integral of v dt since row 1 is "
                             f"{travelled[i]:,.0f} m but {self.lab('s')} advanced {advanced[i]:,.0f} m (ratio "
                             f"{ratio:.3g}, allowed 1 ± {tol:g}){_hint(ratio)}")

    def problems(self) -> list[str]:
        """The problems, in the order :func:`plausibility` lists them."""
        out = []
        dt = np.concatenate(self.steps) if self.steps else np.zeros(0)
        self.steps = [dt]  # one array (the chunks' copies go), partitioned in place by the median: the steps of a
        med = float(np.median(dt, overwrite_input=True)) if dt.size else float("nan")  # long log are 8 bytes/sample
        if self.rate_hz is not None and dt.size:
            want = 1.0 / self.rate_hz
            if abs(med / want - 1.0) > RATE_TOLERANCE:
                out.append(f"{self.lab('t')} rows 1-{self.n}: median sampling interval {med:.6g} s, but the log "
                           f"mapping declares {self.rate_hz:g} Hz ({want:.6g} s){_hint(med / want)}")
        if dt.size and not out:  # the declared rate's message says more
            lo, hi = SAMPLING_S
            if not lo <= med <= hi:
                unit = (": looks like a time in ms read as s" if lo <= med / 1000 <= hi else
                        ": looks like a time in s read as ms" if lo <= med * 1000 <= hi else "")
                out.append(f"{self.lab('t')} rows 1-{self.n}: median sampling interval {med:.6g} s outside "
                           f"{lo:g}-{hi:g} s{unit}")
        out += [self.magnitude[c] for c in MAGNITUDES if c in self.magnitude]
        if self.gap is not None:
            out.append(self.gap)
        if self.s_integrated:
            length = self.route_length
            if length is not None and self.n and self.travelled > length * (1 + self.tolerance) + DISTANCE_SLACK:
                out.append(f"{self.lab('v')} row {self.n}: the integral of v dt is {self.travelled:,.0f} m, longer "
                           f"than the route ({length:,.0f} m){_hint(self.travelled / length)}")
        elif self.distance is not None:
            out.append(self.distance)
        return out


def _hint(ratio: float) -> str:
    for r, what in _UNIT_MIXUPS:
        if np.isfinite(ratio) and abs(ratio / r - 1.0) < 0.05:
            return f": looks like {what}"
    return ""



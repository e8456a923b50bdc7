"""Log mapping: how a simulator's own drive log (its column names and units) becomes the canonical drive log.

A mapping is a TOML file (``[files] log_mapping`` of a study, or ``drive import --map FILE``; docs/drive_logs.md)::

    [log]
    format = "csv"              # csv | parquet | sumo-fcd: the files this mapping reads
    rate_hz = 60                # optional: the logger's sampling rate, checked against the time channel
    max_gap_s = 1.0             # optional: largest allowed time step (s), default 1 s
    distance_tolerance = 0.10   # optional: allowed relative difference of the integral of v dt and of s
    vehicle = "ego"             # sumo-fcd: the vehicle (or drive import --vehicle)
    route_edges = ["u01", ...]  # sumo-fcd: the SUMO edges of the study's route in driving order (study.logs.fcd_route)

    [channels.v]                # a canonical channel (docs/contracts.md "Drive log") ...
    column = "speed_kmh"        # ... read from this source column
    unit = "km/h"               # unit of the source column; converted to the channel's SI unit with pint
    scale = 1.0                 # optional: value = raw * scale + offset, in `unit`, before the conversion
    offset = 0.0

    [channels.lat_pos]          # any other name: an extra channel, stored as a DOUBLE column of drive_samples
    column = "lat_pos_m"
    unit = "m"                  # stored in this unit (or in `to`, when given)
    description = "lateral position from the lane centre, left positive"

Unknown units (anything pint does not define) and units of the wrong dimension (a speed in kW) are refused.
A grade in % or per mille is a slope (rise/run) and becomes an angle in rad (atan), a grade in deg/rad is an angle.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
import pandas as pd

from study.common.errors import UserError
from study.common.file_checks import register_file_check
from study.common.numbers import column_floats
from study.common.toml_lines import raise_first_problem, read_toml
from study.common.units import convert_values, parse_unit
from study.folder.drive_columns import COLUMNS

FORMATS = ("csv", "parquet", "sumo-fcd")
#: SI unit of each numeric canonical channel (the unit it is stored in)
CANONICAL_UNITS = {"t": "s", "s": "m", "v": "m/s", "speed_limit": "m/s", "a": "m/s^2", "grade": "rad",
                   "ft": "N", "fb": "N", "p_batt": "W", "d_tl": "m", "leader_gap": "m", "leader_v": "m/s",
                   "v_advice": "m/s"}
#: canonical channels that are not numbers: mapped by renaming only (no unit)
CANONICAL_TEXT = ("segment", "tl_id", "tl_state", "controller", "hud_arrow", "hud_in_band", "warning")
CHANNEL_NAME = re.compile(r"^[a-z][a-z0-9_]{0,62}$")
RESERVED = ("drive_id", "idx")       # columns of drive_samples that are not channels
DEFAULT_MAX_GAP_S = 1.0
DEFAULT_DISTANCE_TOLERANCE = 0.10
_LOG_KEYS = ("format", "vehicle", "rate_hz", "max_gap_s", "distance_tolerance", "name", "route_edges")
_CHANNEL_KEYS = ("column", "unit", "scale", "offset", "description", "to")
_SLOPE_UNITS = ("percent", "permille")   # grade given as rise/run, not as an angle


def canonical_names() -> tuple[str, ...]:
    return tuple(COLUMNS) + RESERVED


@lru_cache(maxsize=1)
def sql_keywords() -> frozenset[str]:
    """DuckDB's keywords (any category): not usable as channel (column) names."""
    import duckdb

    con = duckdb.connect()
    try:
        return frozenset(r[0].lower() for r in con.execute("SELECT keyword_name FROM duckdb_keywords()").fetchall())
    finally:
        con.close()


def check_channel_name(name: str) -> str:
    """`name` if it can be an extra channel (a new column of drive_samples), else UserError saying why."""
    if not isinstance(name, str) or not CHANNEL_NAME.match(name):
        raise UserError(f"channel name {name!r} must be lower-case letters, digits and _, starting with a letter "
                        f"(at most 63 characters)")
    if name in canonical_names():
        raise UserError(f"channel name {name!r} is a column of the drive log itself")
    if name in sql_keywords():
        raise UserError(f"channel name {name!r} is an SQL keyword; choose another name (e.g. {name}_value)")
    return name


@dataclass(frozen=True)
class Channel:
    """One mapped channel: the canonical or extra `name`, its source `column`, source `unit`, `scale`/`offset`."""

    name: str
    column: str
    unit: str | None
    scale: float = 1.0
    offset: float = 0.0
    description: str = ""
    to: str | None = None

    @property
    def extra(self) -> bool:
        return self.name not in CANONICAL_UNITS and self.name not in CANONICAL_TEXT

    @property
    def stored_unit(self) -> str | None:
        """Unit of the stored values: SI for canonical channels, `to` or the source unit for extra channels."""
        if self.name in CANONICAL_UNITS:
            return CANONICAL_UNITS[self.name]
        return self.to or self.unit

    @property
    def label(self) -> str:
        """How messages name this channel: canonical name, source column and unit."""
        unit = f", {self.unit}" if self.unit else ""
        return f"{self.name} (column {self.column}{unit})"


@dataclass(frozen=True)
class Mapping:
    """A parsed log mapping (see the module docstring)."""

    name: str
    format: str
    channels: tuple[Channel, ...]
    vehicle: str | None = None
    route_edges: tuple[str, ...] = ()   # sumo-fcd: the SUMO edges of the study's route, in driving order
    rate_hz: float | None = None
    max_gap_s: float = DEFAULT_MAX_GAP_S
    distance_tolerance: float = DEFAULT_DISTANCE_TOLERANCE
    text: str = field(default="", repr=False)

    def channel(self, name: str) -> Channel | None:
        return next((c for c in self.channels if c.name == name), None)

    @property
    def extras(self) -> tuple[Channel, ...]:
        return tuple(c for c in self.channels if c.extra)


# ---------------------------------------------------------------------------------------------- parsing
def _line(text: str, table: str, key: str | None = None) -> int | None:
    """1-based line of `[table]` (or of `key = ...` inside it); for ``channels.X`` also ``X = {...}`` in
    ``[channels]``. None when not found."""
    lines = text.splitlines()
    parts = table.split(".")
    hdr = re.compile(r"^\s*\[\s*" + r"\s*\.\s*".join(rf'"?{re.escape(p)}"?' for p in parts) + r"\s*\]\s*(#.*)?$")
    start = next((i for i, ln in enumerate(lines) if hdr.match(ln)), None)
    if start is None and len(parts) == 2:
        parent = _line(text, parts[0])
        if parent is not None:
            inline = re.compile(rf'^\s*"?{re.escape(parts[1])}"?\s*=')
            for i in range(parent, len(lines)):
                if re.match(r"^\s*\[", lines[i]):
                    break
                if inline.match(lines[i]):
                    return i + 1
        return None
    if start is None:
        return None
    if key is None:
        return start + 1
    pat = re.compile(rf"^\s*{re.escape(key)}\s*=")
    for i in range(start + 1, len(lines)):
        if re.match(r"^\s*\[", lines[i]):
            break
        if pat.match(lines[i]):
            return i + 1
    return start + 1


def parse_mapping(text: str, name: str) -> tuple[Mapping | None, list[tuple[int | None, str, str]]]:
    """Parse a mapping text; returns (mapping or None, problems as (line, field, message))."""
    data, problems = read_toml(text)
    if data is None:
        return None, problems
    for key in data:
        if key not in ("log", "channels"):
            problems.append((_line(text, key), key, "unknown table (use [log] and [channels.NAME])"))
    log = data.get("log", {})
    if not isinstance(log, dict):
        problems.append((None, "log", "must be a table"))
        log = {}
    for key in log:
        if key not in _LOG_KEYS:
            problems.append((_line(text, "log", key), f"log.{key}", f"unknown key (known: {', '.join(_LOG_KEYS)})"))
    fmt = log.get("format", "csv")
    if fmt not in FORMATS:
        problems.append((_line(text, "log", "format"), "log.format", f"{fmt!r} is not one of {'|'.join(FORMATS)}"))
    vehicle = log.get("vehicle")
    if vehicle is not None and not isinstance(vehicle, str):
        problems.append((_line(text, "log", "vehicle"), "log.vehicle", "must be a vehicle id (text)"))
    route_edges = log.get("route_edges", [])
    if not isinstance(route_edges, list) or not all(isinstance(e, str) and e and not e.startswith(":")
                                                    for e in route_edges):
        problems.append((_line(text, "log", "route_edges"), "log.route_edges",
                         "must be a list of SUMO edge ids (text, not junction-internal ':' edges)"))
        route_edges = []
    elif route_edges and fmt != "sumo-fcd":
        problems.append((_line(text, "log", "route_edges"), "log.route_edges", "is for sumo-fcd logs only"))

    def positive(key: str, default: float | None) -> float | None:
        v = log.get(key, default)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0 or not math.isfinite(v):
            problems.append((_line(text, "log", key), f"log.{key}", "must be a positive number"))
            return default
        return float(v)

    rate = positive("rate_hz", None)
    gap = positive("max_gap_s", DEFAULT_MAX_GAP_S)
    tol = positive("distance_tolerance", DEFAULT_DISTANCE_TOLERANCE)
    if tol is not None and tol >= 1:
        problems.append((_line(text, "log", "distance_tolerance"), "log.distance_tolerance",
                         "is a fraction (0.1 = 10 %), must be below 1"))

    raw_channels = data.get("channels", {})
    if not isinstance(raw_channels, dict) or not raw_channels:
        problems.append((_line(text, "channels"), "channels", "declare at least [channels.t] and [channels.v]"))
        raw_channels = {}
    channels: list[Channel] = []
    columns: dict[str, str] = {}
    for cname, spec in raw_channels.items():
        where = _line(text, f"channels.{cname}")
        fld = f"channels.{cname}"
        if not isinstance(spec, dict):
            problems.append((where, fld, "must be a table with column and unit"))
            continue
        for key in spec:
            if key not in _CHANNEL_KEYS:
                problems.append((_line(text, fld, key) or where, f"{fld}.{key}",
                                 f"unknown key (known: {', '.join(_CHANNEL_KEYS)})"))
        column = spec.get("column")
        if not isinstance(column, str) or not column:
            problems.append((where, f"{fld}.column", "names the source column (text)"))
            continue
        if column in columns:
            problems.append((_line(text, fld, "column") or where, f"{fld}.column",
                             f"column {column!r} is already mapped to channel {columns[column]}"))
        columns[column] = cname
        text_channel = cname in CANONICAL_TEXT
        if cname not in CANONICAL_UNITS and not text_channel:
            try:
                check_channel_name(cname)
            except UserError as exc:
                problems.append((where, fld, str(exc)))
                continue
        unit = spec.get("unit")
        scale, offset = spec.get("scale", 1.0), spec.get("offset", 0.0)
        for key, val in (("scale", scale), ("offset", offset)):
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                problems.append((_line(text, fld, key) or where, f"{fld}.{key}", "must be a number"))
        if scale == 0:
            problems.append((_line(text, fld, "scale") or where, f"{fld}.scale", "must not be 0"))
        to = spec.get("to")
        if text_channel:
            if unit is not None or to is not None or "scale" in spec or "offset" in spec:
                problems.append((where, fld, f"{cname} is not a number: map it by column only (no unit)"))
            channels.append(Channel(cname, column, None, description=str(spec.get("description", ""))))
            continue
        try:
            u = parse_unit(unit)
            if cname in CANONICAL_UNITS:
                if to is not None:
                    raise UserError(f"'to' is for extra channels; {cname} is always stored in "
                                    f"{CANONICAL_UNITS[cname]}")
                target = parse_unit(CANONICAL_UNITS[cname])
                if u.dimension != target.dimension:
                    raise UserError(f"unit {unit!r} is not a unit of {CANONICAL_UNITS[cname]} "
                                    f"({cname} needs {_dimension_word(target)})")
            elif to is not None:
                tu = parse_unit(to)
                if tu.dimension != u.dimension:
                    raise UserError(f"cannot convert {unit!r} to {to!r} (different dimensions)")
        except UserError as exc:
            problems.append((_line(text, fld, "unit") or where, f"{fld}.unit", str(exc)))
            continue
        channels.append(Channel(cname, column, unit.strip(), float(scale) if _isnum(scale) else 1.0,
                                float(offset) if _isnum(offset) else 0.0, str(spec.get("description", "")),
                                to.strip() if isinstance(to, str) else None))
    names = {c.name for c in channels}
    for need in ("t", "v"):
        if raw_channels and need not in raw_channels:
            problems.append((_line(text, "channels"), f"channels.{need}",
                             f"missing: every log needs {'time' if need == 't' else 'speed'} ({need})"))
    if problems:
        return None, problems
    return Mapping(name=str(log.get("name", name)), format=fmt, channels=tuple(c for c in channels if c.name in names),
                   vehicle=vehicle, route_edges=tuple(route_edges), rate_hz=rate, max_gap_s=gap or DEFAULT_MAX_GAP_S,
                   distance_tolerance=tol or DEFAULT_DISTANCE_TOLERANCE, text=text), []


def _isnum(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _dimension_word(u) -> str:
    return {"[time]": "a time", "[length]": "a length", "[length] / [time]": "a speed",
            "[length] / [time] ** 2": "an acceleration", "dimensionless": "an angle or ratio",
            "[mass] * [length] / [time] ** 2": "a force",
            "[mass] * [length] ** 2 / [time] ** 3": "a power"}.get(u.dimension_text, u.dimension_text)


def load_mapping(text: str, name: str) -> Mapping:
    """Parse a mapping; the first problem -> UserError ``name:line: field: message``."""
    mapping, problems = parse_mapping(text, name)
    raise_first_problem(name, problems)
    return mapping


# ---------------------------------------------------------------------------------------------- applying
def convert(values: np.ndarray, unit: str, target: str, channel: str = "") -> np.ndarray:
    """`values` (float64) from `unit` to `target`; a grade in %/per mille is a slope and becomes atan(slope) rad."""
    u = parse_unit(unit)
    if channel == "grade" and u.name in _SLOPE_UNITS:
        return np.arctan(convert_values(values, u, parse_unit("dimensionless")))
    return convert_values(values, u, parse_unit(target))


def _numbers(raw: pd.DataFrame, col: str, label: str) -> np.ndarray:
    return column_floats(raw[col], lambda i: f"channel {label} row {i + 1}")


def apply_mapping(raw: pd.DataFrame, mapping: Mapping) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, str],
                                                                   tuple[str, ...]]:
    """The raw log as (canonical frame in SI units, extra channels frame, {channel: label for messages},
    unmapped source columns). A mapped column missing from the log -> UserError naming it."""
    raw = raw.reset_index(drop=True)
    raw.columns = [str(c).strip() for c in raw.columns]
    missing = [c for c in mapping.channels if c.column not in raw.columns]
    if missing:
        c = missing[0]
        raise UserError(f"the log has no column {c.column!r} (mapped to channel {c.name} by {mapping.name}; "
                        f"its columns: {', '.join(map(str, raw.columns[:12]))}"
                        f"{', ...' if len(raw.columns) > 12 else ''})")
    canon: dict[str, Any] = {}
    extra: dict[str, np.ndarray] = {}
    labels: dict[str, str] = {}
    for c in mapping.channels:
        labels[c.name] = c.label
        if c.unit is None:
            canon[c.name] = raw[c.column]
            continue
        x = _numbers(raw, c.column, c.label)
        if c.scale != 1.0 or c.offset != 0.0:
            x = x * c.scale + c.offset
        if c.extra:
            extra[c.name] = convert(x, c.unit, c.to, c.name) if c.to else x
        else:
            canon[c.name] = convert(x, c.unit, CANONICAL_UNITS[c.name], c.name)
    used = {c.column for c in mapping.channels}
    ignored = tuple(str(c) for c in raw.columns if c not in used)
    return pd.DataFrame(canon), pd.DataFrame(extra, index=pd.RangeIndex(len(raw))), labels, ignored


# ---------------------------------------------------------------------------------------------- study check
def _check_study(study, problems) -> None:
    """[files] log_mapping parses; when it maps neither speed_limit nor segment the study must declare a route."""
    rel = study.paths.get("log_mapping")
    if not rel or rel not in study.files:
        return
    mapping, found = parse_mapping(study.files[rel], rel)
    for line, fld, msg in found:
        problems.add(rel, line, fld, msg)
    if mapping is None:
        return
    if study.paths.get("route") is None:
        for need in ("speed_limit", "segment"):
            if mapping.channel(need) is None:
                problems.add(rel, _line(study.files[rel], "channels"), f"channels.{need}",
                             "not mapped and the study declares no route ([files] route) to join it from")
                break


register_file_check(_check_study, units=True)

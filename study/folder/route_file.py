"""Route file: a study's route as sections (speed limit, free segment label), traffic lights and stop signs by
position, and the join of a drive log to it by the position s (docs/drive_logs.md).

    [route]
    name = "lk-5km"           # stored with each drive (drives.route)
    speed_unit = "km/h"       # unit of the speed limits below (default m/s); a section may give its own
    position_unit = "m"       # unit of s_from, s_to and s (default m)

    [[sections]]              # contiguous: the first starts at 0, each starts where the one before ends
    s_from = 0
    s_to = 1500
    speed_limit = 50
    segment = "town"          # any label; KPIs are reported per label

    [[lights]]                # traffic lights by the position of their stop line
    id = "TL1"
    s = 620
    phases = [["green", 30], ["yellow", 3], ["red", 27]]   # optional: fixed-time plan, s
    offset = 0                                             # optional: time (s) at which the first phase starts

    [[stops]]                 # stop signs by the position of their stop line
    id = "STOP1"
    s = 4600

At import the log's samples get ``speed_limit`` (m/s) and ``segment`` of the section that contains their s when the
log lacks them, and a log read through a mapping without any traffic-light column gets ``tl_id``/``d_tl`` (the next
light at or ahead of s, m to its stop line).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pedas.route_toml import Light, Stop
from study.common.errors import UserError
from study.common.file_checks import register_file_check
from study.common.toml_lines import line_of, raise_first_problem, read_toml
from study.common.units import conversion_factor, parse_unit

SEGMENT_MAX = 64
LIGHT_STATES = ("green", "yellow", "red")
_ROUTE_KEYS = ("name", "speed_unit", "position_unit", "description")
_SECTION_KEYS = ("s_from", "s_to", "speed_limit", "segment", "speed_unit", "label")
EPS = 1e-6   # m: positions this close to the route's ends count as on the route (float sums of lane lengths)


@dataclass(frozen=True)
class RouteFile:
    """A parsed route: sections [s_from, s_to) in m with speed_limit in m/s and a segment label; lights; stops."""

    name: str
    s_from: np.ndarray
    s_to: np.ndarray
    speed_limit: np.ndarray
    segment: tuple[str, ...]
    lights: tuple[Light, ...] = ()
    stops: tuple[Stop, ...] = ()
    text: str = field(default="", repr=False)

    @property
    def length(self) -> float:
        return float(self.s_to[-1])

    @property
    def segments(self) -> tuple[str, ...]:
        """The segment labels in order of first appearance along the route."""
        return tuple(dict.fromkeys(self.segment))

    def join(self, frame: pd.DataFrame, label: str = "column s", lights: bool = True,
             first_row: int = 0) -> tuple[pd.DataFrame, tuple[str, ...]]:
        """`frame` (with s in m) with speed_limit and segment added from the route where absent, and (`lights`)
        tl_id and d_tl when the log has no traffic-light column at all; returns (frame, added columns).
        A sample outside the route -> UserError naming its row (`label` names the position column; `first_row` is
        the 0-based row of the log that `frame` starts with, when it is a chunk of a log)."""
        wanted = [c for c in ("speed_limit", "segment") if c not in frame.columns]
        lights = lights and bool(self.lights) and not {"tl_id", "tl_state", "d_tl"} & set(frame.columns)
        if not wanted and not lights:
            return frame, ()
        s = pd.to_numeric(frame["s"], errors="coerce").to_numpy(dtype="float64", na_value=np.nan)
        # a position off the route has no limit or segment; for the lights alone it just has no light ahead
        bad = ~np.isfinite(s) | (((s < -EPS) | (s > self.length + EPS)) if wanted else False)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise UserError(f"{label} row {first_row + i + 1}: position {s[i]:g} m is outside route {self.name} "
                            f"(0–{self.length:g} m){' (missing value)' if not np.isfinite(s[i]) else ''}")
        out = frame.copy()
        k = np.clip(np.searchsorted(self.s_from, s, side="right") - 1, 0, len(self.s_from) - 1)
        added = []
        if "speed_limit" in wanted:
            out["speed_limit"] = self.speed_limit[k]
            added.append("speed_limit")
        if "segment" in wanted:
            cats = list(self.segments)
            codes = np.array([cats.index(g) for g in self.segment], dtype=np.int64)[k]
            out["segment"] = pd.Categorical.from_codes(codes, categories=cats)
            added.append("segment")
        if lights:
            ls = np.array([tl.s for tl in self.lights])
            j = np.searchsorted(ls, s, side="left")
            ahead = j < len(ls)
            ids = np.array([tl.id for tl in self.lights] + [None], dtype=object)
            out["tl_id"] = pd.array(ids[j], dtype="string")
            out["d_tl"] = np.where(ahead, ls[np.minimum(j, len(ls) - 1)] - s, np.nan)
            added += ["tl_id", "d_tl"]
        return out, tuple(added)


# ---------------------------------------------------------------------------------------------- parsing
def _line(text: str, table: str, nth: int = 0, key: str | None = None) -> int | None:
    """1-based line of the nth `[table]` / `[[table]]` header, or of `key = ...` inside it."""
    return line_of(text, key or "", table, nth)


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def parse_route(text: str, name: str) -> tuple[RouteFile | None, list[tuple[int | None, str, str]]]:
    """Parse a route text; returns (route or None, problems as (line, field, message))."""
    data, problems = read_toml(text)
    if data is None:
        return None, problems
    for key in data:
        if key not in ("route", "sections", "lights", "stops"):
            problems.append((_line(text, key), key, "unknown table (use [route], [[sections]], [[lights]], "
                                                     "[[stops]])"))
    head = data.get("route", {})
    if not isinstance(head, dict):
        head = {}
    for key in head:
        if key not in _ROUTE_KEYS:
            problems.append((_line(text, "route", key=key), f"route.{key}",
                             f"unknown key (known: {', '.join(_ROUTE_KEYS)})"))
    rname = head.get("name")
    if not isinstance(rname, str) or not rname.strip():
        problems.append((_line(text, "route"), "route.name", "needs a name (text)"))
        rname = name

    def unit_factor(unit: Any, target: str, where: int | None, fld: str) -> float | None:
        try:
            u = parse_unit(unit)
            t = parse_unit(target)
            if u.dimension != t.dimension:
                raise UserError(f"unit {unit!r} is not a unit of {target}")
            return conversion_factor(u, t)
        except UserError as exc:
            problems.append((where, fld, str(exc)))
            return None

    speed_f = unit_factor(head.get("speed_unit", "m/s"), "m/s", _line(text, "route", key="speed_unit"),
                          "route.speed_unit")
    pos_f = unit_factor(head.get("position_unit", "m"), "m", _line(text, "route", key="position_unit"),
                        "route.position_unit")
    pos_f = pos_f or 1.0

    sections = data.get("sections", [])
    if not isinstance(sections, list) or not sections:
        problems.append((_line(text, "route"), "sections", "declare at least one [[sections]]"))
        sections = []
    s_from, s_to, limits, labels = [], [], [], []
    for k, sec in enumerate(sections):
        fld = f"sections[{k}]"
        where = _line(text, "sections", k)
        if not isinstance(sec, dict):
            problems.append((where, fld, "must be a table"))
            continue
        for key in sec:
            if key not in _SECTION_KEYS:
                problems.append((_line(text, "sections", k, key), f"{fld}.{key}",
                                 f"unknown key (known: {', '.join(_SECTION_KEYS[:5])})"))
        a, b, lim, seg = sec.get("s_from"), sec.get("s_to"), sec.get("speed_limit"), sec.get("segment")
        if not (_number(a) and _number(b)) or not b > a:
            problems.append((where, fld, "needs numbers s_from < s_to"))
            continue
        f = speed_f if "speed_unit" not in sec else unit_factor(
            sec["speed_unit"], "m/s", _line(text, "sections", k, "speed_unit"), f"{fld}.speed_unit")
        if not _number(lim) or not lim > 0:
            problems.append((_line(text, "sections", k, "speed_limit"), f"{fld}.speed_limit",
                             "needs a positive number"))
            continue
        if not isinstance(seg, str) or not seg.strip() or seg != seg.strip() or len(seg) > SEGMENT_MAX:
            problems.append((_line(text, "sections", k, "segment"), f"{fld}.segment",
                             f"needs a label (text of 1 to {SEGMENT_MAX} characters)"))
            continue
        if f is None:
            continue
        v = float(lim) * f
        if v > 70.0:
            problems.append((_line(text, "sections", k, "speed_limit"), f"{fld}.speed_limit",
                             f"{lim:g} is {v:g} m/s, above 70 m/s: check speed_unit"))
            continue
        if s_to and abs(float(a) * pos_f - s_to[-1]) > EPS:
            problems.append((_line(text, "sections", k, "s_from"), f"{fld}.s_from", f"must equal s_to of the section before "
                                                      f"({s_to[-1] / pos_f:g}): sections are contiguous"))
        if not s_to and float(a) != 0.0:
            problems.append((_line(text, "sections", k, "s_from"), f"{fld}.s_from", "the first section starts at 0"))
        s_from.append(float(a) * pos_f)
        s_to.append(float(b) * pos_f)
        limits.append(v)
        labels.append(seg)
    length = s_to[-1] if s_to else 0.0

    def objects(table: str, extra_ok: tuple[str, ...]) -> list[dict]:
        out = []
        items = data.get(table, [])
        if not isinstance(items, list):
            problems.append((_line(text, table), table, f"use [[{table}]] tables"))
            return out
        seen = set()
        for k, obj in enumerate(items):
            fld = f"{table}[{k}]"
            where = _line(text, table, k)
            if not isinstance(obj, dict) or not isinstance(obj.get("id"), str) or not _number(obj.get("s")):
                problems.append((where, fld, "needs an id (text) and a position s"))
                continue
            for key in obj:
                if key not in ("id", "s") + extra_ok:
                    problems.append((_line(text, table, k, key), f"{fld}.{key}", "unknown key"))
            pos = float(obj["s"]) * pos_f
            if s_to and not -EPS <= pos <= length + EPS:
                problems.append((_line(text, table, k, "s"), f"{fld}.s",
                                 f"{obj['s']:g} lies outside the route (0–{length / pos_f:g})"))
            if obj["id"] in seen:
                problems.append((where, f"{fld}.id", f"{obj['id']!r} declared twice"))
            seen.add(obj["id"])
            out.append({**obj, "s": pos, "_k": k})
        return out

    lights = []
    for obj in objects("lights", ("phases", "offset")):
        k, fld = obj["_k"], f"lights[{obj['_k']}]"
        phases = obj.get("phases", [])
        ok = isinstance(phases, list) and all(
            isinstance(p, list) and len(p) == 2 and p[0] in LIGHT_STATES and _number(p[1]) and p[1] > 0
            for p in phases)
        if not ok:
            problems.append((_line(text, "lights", k, "phases"), f"{fld}.phases",
                             f"a list of [state, seconds] with state {'|'.join(LIGHT_STATES)} and seconds > 0"))
            phases = []
        if not _number(obj.get("offset", 0.0)):
            problems.append((_line(text, "lights", k, "offset"), f"{fld}.offset", "must be a number (s)"))
        lights.append(Light(obj["id"], obj["s"], tuple((str(p), float(d)) for p, d in phases),
                            float(obj.get("offset", 0.0)) if _number(obj.get("offset", 0.0)) else 0.0))
    stops = [Stop(obj["id"], obj["s"]) for obj in objects("stops", ())]
    if problems:
        return None, problems
    return RouteFile(rname.strip(), np.array(s_from), np.array(s_to), np.array(limits), tuple(labels),
                     tuple(sorted(lights, key=lambda x: x.s)), tuple(sorted(stops, key=lambda x: x.s)), text), []


def load_route(text: str, name: str) -> RouteFile:
    """Parse a route; the first problem -> UserError ``name:line: field: message``."""
    route, problems = parse_route(text, name)
    raise_first_problem(name, problems)
    return route


def study_route(study) -> RouteFile | None:
    """The route a study declares ([files] route), None when it declares none."""
    text = study.text("route")
    return None if text is None else load_route(text, study.paths["route"])


# ---------------------------------------------------------------------------------------------- study check
def _check_study(study, problems) -> None:
    rel = study.paths.get("route")
    if not rel or rel not in study.files:
        return
    for line, fld, msg in parse_route(study.files[rel], rel)[1]:
        problems.add(rel, line, fld, msg)


register_file_check(_check_study, units=True)

"""The drive KPIs a study declares: the file ``[files] kpis = "kpis.toml"`` of its folder (docs/kpis.md).

    builtins = ["time", "violations"]       which built-in KPI groups to report (table BUILTINS)
    group_by = ["condition"]                 summaries by condition and/or declared participant attributes
    channels = ["lat_pos"]                   extra DOUBLE channels of the drive log the SQL KPIs read

    [violations]  tolerance = "none" | "absolute" (km_h = 5) | "relative" (percent = 3) | "german"; min_event_s
    [stops]       v_stop, v_moving (m/s);  [red_stops] distance_m (m)
    [sql]         name = "aggregate expression" or {sql = "...", per_segment = true, unit = "m", label = "...",
                  decimals = 2} (decimals: shown with, 0-10; default those of its unit)
                  or {query = "SELECT ... FROM samples ...", per_segment, unit, label}: a full read-only query
    [events]      name = {from = "condition", to = "condition", statistic = "first" | "mean" | "max" | "count",
                  per_segment, unit, label}: the time from a rising edge of `from` to the next sample where `to` holds
    [measures]    name = {measure = "steering_reversal_rate", gap_deg = 2.0, per_segment, label}: a shipped
                  standard measure (study.folder.measure_library, docs/measures.md) with its options
    [regions]     name = {s_from, s_to} | {t_from, t_to} | {segment = "..."} | {event = "channel", before_s,
                  after_s}: regions of interest, each measure computed in each
    [comparison]  control, treatment (conditions), bands; [comparison.columns] / .reductions / .pooled

:func:`parse` turns the text into a :class:`KpiSpec` and reports every problem with file, line and field; the check
registered with :func:`study.folder.definition.register_file_check` runs it (and cross-checks conditions and attributes) in
every ``study check`` and every load of a study. A study without a KPI file gets :data:`DEFAULT_SPEC`. Which vehicle
model may supply the power of a drive that logged none is the study's ``[drives] energy_model`` (study.toml, the
same declaration the drive import uses); without one such a drive's energy is unavailable.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from typing import Any

from pedas.constants import KMH
from study.common.file_checks import register_file_check
from study.common.problems import Problem, StudyError
from study.common.toml_lines import line_of
from study.folder.kpi_fields import KPI_FIELDS, SAMPLE_COLUMNS, KpiParams
from study.folder.kpi_query import check_condition, check_query, trial_connection

#: built-in KPI groups -> their output columns (study.folder.kpi_fields.KPI_FIELDS), in output order
BUILTINS: dict[str, tuple[str, ...]] = {
    "time": ("distance_m", "trip_time_s", "mean_speed_mps"),
    "energy": ("energy_wh", "wh_per_km"),
    "violations": ("violation_distance_m", "violation_share", "violation_events"),
    "traffic_lights": ("tl_crossed", "tl_crossed_green", "tl_crossed_yellow", "tl_crossed_red", "tl_green_passes"),
    "red_stops": ("red_stops",),
    "stops": ("stops",),
    "jerk": ("rms_jerk", "mean_abs_a"),
}
TOLERANCES = ("none", "absolute", "relative", "german")
ENERGY_MODELS = {"nissan_leaf": "modelled (Nissan Leaf parameters)", "none": None}
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_RESERVED = {"participant_id", "condition", "phase", "drive_id", "segment", "n_intervals", "overall", "all"}
_KEYS = {"builtins", "group_by", "channels", "violations", "stops", "red_stops", "sql", "events", "measures", "regions",
         "comparison"}
#: how an event KPI sums up several events of one drive (or segment); docs/kpis.md says why "first" is the default
STATISTICS = ("first", "mean", "max", "count")


def _heading(name: str, label: str, unit: str) -> str:
    """'Label (unit)' of a declared KPI for rendered tables (the name when it has no label)."""
    text = label or name
    return f"{text} ({unit})" if unit else text


@dataclass(frozen=True)
class SqlKpi:
    """A user KPI over the samples of a drive (and of each segment when ``per_segment``): with ``query`` False,
    ``sql`` is one DuckDB aggregate expression (computed in the built-ins' grouped pass); with ``query`` True, ``sql``
    is a full read-only query over the relation ``samples`` (that drive's or segment's rows in idx order) returning
    one row with one number (checked by :func:`study.folder.kpi_query.check_query`)."""

    name: str
    sql: str
    per_segment: bool = False
    unit: str = ""
    label: str = ""
    query: bool = False
    decimals: int | None = None    # shown with (None: those of its unit)

    @property
    def heading(self) -> str:
        return _heading(self.name, self.label, self.unit)


@dataclass(frozen=True)
class EventKpi:
    """Time (s) from an event to the next response in a drive: ``start`` and ``end`` are conditions per sample
    (a boolean or 0/1 channel, or a boolean SQL expression; checked by :func:`study.folder.kpi_query.check_condition`).

    An event is a rising edge of ``start``: a sample where it holds and held not at the sample before (the drive's
    first sample is none: its onset was not logged). Its time is t(first sample at or after the edge where ``end``
    holds) - t(edge), NULL when ``end`` never holds again. ``statistic``: ``first`` (the first event's time),
    ``mean`` / ``max`` (over the events with a response) or ``count`` (the number of events). NULL without an event
    (``count``: 0, and NULL where ``from`` is NULL at every sample: not logged). A NULL condition at a sample counts
    as false. Per segment, an event belongs to the segment of its edge (the left-point rule of the intervals)."""

    name: str
    start: str
    end: str
    statistic: str = "first"
    per_segment: bool = False
    unit: str = "s"
    label: str = ""
    decimals: int | None = None    # shown with (None: those of its unit)

    @property
    def heading(self) -> str:
        return _heading(self.name, self.label, self.unit)


@dataclass(frozen=True)
class MeasureKpi:
    """A shipped standard measure (:data:`study.folder.measure_library.MEASURES`) with the study's options (defaults
    filled in, as sorted (key, value) pairs), computed per drive (and per segment when ``per_segment``) and per
    region of interest by :mod:`analysis.drives.measures`."""

    name: str
    measure: str
    options: tuple[tuple[str, Any], ...] = ()
    per_segment: bool = False
    unit: str = ""
    label: str = ""
    decimals: int | None = None    # shown with (None: those of its unit)

    @property
    def heading(self) -> str:
        return _heading(self.name, self.label, self.unit)

    @property
    def opts(self) -> dict[str, Any]:
        return dict(self.options)

    @property
    def channels(self) -> tuple[str, ...]:
        from study.folder.measure_library import MEASURES

        return MEASURES[self.measure].channels_of(self.opts)

    def sentence(self) -> str:
        """The methods sentence of this measure with its options (J2944's reporting requirement)."""
        from study.folder.measure_library import MEASURES

        return MEASURES[self.measure].sentence(self.opts, self.label)


#: kinds of region of interest -> their keys (the first are required)
REGION_KINDS = {"position": (("s_from", "s_to"), ()), "time": (("t_from", "t_to"), ()),
                "segment": (("segment",), ()), "event": (("event",), ("before_s", "after_s"))}


@dataclass(frozen=True)
class Region:
    """A region of interest of every drive: samples with ``s_from <= s < s_to`` (m, ``position``), with
    ``t_from <= t - t0 < t_to`` (s from the drive's first sample, ``time``), of route ``segment``, or from
    ``before_s`` before to ``after_s`` after the first rising edge of channel ``event`` (``event``). A drive with
    fewer than two samples in it (it does not reach the region, or has no event) has no value there (NULL)."""

    name: str
    kind: str
    lo: float = 0.0
    hi: float = 0.0
    segment: str = ""
    event: str = ""

    def text(self) -> str:
        if self.kind == "position":
            return f"route position {self.lo:g} m to {self.hi:g} m"
        if self.kind == "time":
            return f"{self.lo:g} s to {self.hi:g} s after the start of the drive"
        if self.kind == "segment":
            return f"route segment {self.segment}"
        return f"{self.lo:g} s before to {self.hi:g} s after the first onset of {self.event}"


@dataclass(frozen=True)
class Comparison:
    """Paired drives of each participant: ``control`` vs ``treatment`` condition.

    ``columns``: per-participant column template -> (KPI, segment); ``{condition}`` in the template is replaced by the
    condition's name, else ``_<condition>`` is appended. ``reductions``: name -> (KPI, segment), 100 (control -
    treatment) / control. ``pooled``: name -> KPI (overall), the reduction of the sums over participants.
    ``bands``: print the paper's reproduction bands beside the summary. ``labels``: reduction -> column label of
    the summary table (only labelled reductions appear there); ``table``: title, note and participant_title of the
    rendered tables. ``participant``: the participant whose drives Figs. 11-12 and the replay page show (None:
    those are drawn only for a participant named on the command line)."""

    control: str
    treatment: str
    bands: bool = False
    columns: tuple[tuple[str, str, str], ...] = ()
    reductions: tuple[tuple[str, str, str], ...] = ()
    pooled: tuple[tuple[str, str], ...] = ()
    labels: tuple[tuple[str, str], ...] = ()
    table: tuple[tuple[str, str], ...] = ()
    participant: str | None = None

    def column(self, template: str, condition: str) -> str:
        return template.replace("{condition}", condition) if "{condition}" in template else f"{template}_{condition}"


#: decimals a KPI is shown with for reading (rendered tables, printed lines), by its unit; the CSV files and the
#: store keep full precision. A unit not listed: 3. (A 20 Hz time is a multiple of 0.05 s: 2 decimals.)
DECIMALS = {"m": 1, "km": 3, "s": 2, "min": 2, "m/s": 2, "km/h": 1, "m/s^2": 2, "m/s2": 2, "%": 1, "Wh": 1,
            "kWh": 3, "Wh/km": 1, "W": 0, "kW": 2, "N": 0, "deg": 1, "rad": 3, "1": 3, "": 3}
#: the most decimals a KPI may declare (``decimals = ...`` of an [sql], [events] or [measures] entry)
MAX_DECIMALS = 10
#: the unit of each built-in KPI column (docs/kpis.md); counts and shares are dimensionless ("")
BUILTIN_UNITS = {"energy_wh": "Wh", "distance_m": "m", "trip_time_s": "s", "mean_speed_mps": "m/s",
                 "wh_per_km": "Wh/km", "violation_distance_m": "m", "violation_share": "", "violation_events": "",
                 "tl_crossed": "", "tl_crossed_green": "", "tl_crossed_yellow": "", "tl_crossed_red": "",
                 "tl_green_passes": "", "red_stops": "", "stops": "", "rms_jerk": "m/s³", "mean_abs_a": "m/s²"}
#: the units of other columns by their name's ending (reductions in %, columns per condition)
_SUFFIX_UNITS = (("_pct", "%"), ("_mps", "m/s"), ("_kmh", "km/h"), ("_wh_per_km", "Wh/km"), ("_wh", "Wh"),
                 ("_m", "m"), ("_s", "s"))


@dataclass(frozen=True)
class KpiSpec:
    """What a study's KPI file declares (module docstring); thresholds in SI units."""

    builtins: tuple[str, ...] = tuple(BUILTINS)
    group_by: tuple[str, ...] = ("condition",)
    channels: tuple[str, ...] = ()
    energy_model: str = "none"
    tolerance: str = "none"
    tol_abs: float = 0.0            # m/s
    tol_rel: float = 0.0            # share of the limit
    min_event_s: float = 1.0
    v_stop: float = 0.5
    v_moving: float = 2.0
    red_stop_dist: float = 50.0
    sql: tuple[SqlKpi, ...] = ()
    comparison: Comparison | None = None
    attributes: tuple[str, ...] = field(default=())   # group_by without "condition"
    events: tuple[EventKpi, ...] = ()
    measures: tuple[MeasureKpi, ...] = ()
    regions: tuple[Region, ...] = ()

    @property
    def user_kpis(self) -> tuple:
        """The study's own KPIs in output order: the [sql] ones, then the [events] ones, then the [measures]."""
        return (*self.sql, *self.events, *self.measures)

    @property
    def measure_channels(self) -> tuple[str, ...]:
        """The channels the declared measures and regions read."""
        chans = [c for m in self.measures for c in m.channels] + [r.event for r in self.regions if r.event]
        return tuple(dict.fromkeys(chans))

    @property
    def columns(self) -> tuple[str, ...]:
        """Output KPI columns: the declared built-ins in the order of :data:`KPI_FIELDS`, then the SQL KPIs, then
        the event KPIs."""
        declared = {c for b in self.builtins for c in BUILTINS[b]}
        return tuple(c for c in KPI_FIELDS if c in declared) + tuple(k.name for k in self.user_kpis)

    @property
    def headings(self) -> dict[str, str]:
        """Column -> how rendered tables name it: 'Label (unit)' for the study's own KPIs, the name for built-ins."""
        return {k.name: k.heading for k in self.user_kpis}

    def unit(self, column: str) -> str:
        """The unit of KPI `column` as declared: a study KPI's ``unit`` ([sql], [events]; a [measures] entry's from
        the measure library), a built-in's from :data:`BUILTIN_UNITS`, another column's from its name's ending
        (``saving_urban_pct``: %); "" for a dimensionless one (a count, a share, a score).

        >>> from study.folder.kpi_spec import DEFAULT_SPEC
        >>> DEFAULT_SPEC.unit("wh_per_km"), DEFAULT_SPEC.unit("red_stops"), DEFAULT_SPEC.unit("saving_urban_pct")
        ('Wh/km', '', '%')
        """
        kpi = next((k for k in self.user_kpis if k.name == column), None)
        if kpi is not None:
            return kpi.unit
        if column in BUILTIN_UNITS:
            return BUILTIN_UNITS[column]
        return next((u for end, u in _SUFFIX_UNITS if column.endswith(end)), "")

    def decimals(self, column: str) -> int:
        """Decimals `column` is shown with for reading: a declared KPI's own ``decimals``, else :data:`DECIMALS` of
        its unit (:meth:`unit`; counts without decimals)."""
        kpi = next((k for k in self.user_kpis if k.name == column), None)
        if kpi is not None and kpi.decimals is not None:
            return kpi.decimals
        if kpi is None and column.endswith(("_events", "_stops", "n_intervals")):
            return 0
        return DECIMALS.get(self.unit(column), 3)

    @property
    def params(self):
        """The thresholds as :class:`study.folder.kpi_fields.KpiParams`."""
        return KpiParams(tol_abs=self.tol_abs, tol_rel=self.tol_rel, min_event_s=self.min_event_s,
                         v_stop=self.v_stop, v_moving=self.v_moving, red_stop_dist=self.red_stop_dist)

    @property
    def energy_source_model(self) -> str | None:
        """The label of the vehicle model that fills missing battery power, None when energy is measured only."""
        return ENERGY_MODELS[self.energy_model] if "energy" in self.builtins else None

    def tolerance_text(self) -> str:
        if self.tolerance == "none":
            return "no tolerance"
        if self.tolerance == "absolute":
            return f"{self.tol_abs / KMH:g} km/h"
        if self.tolerance == "relative":
            return f"{100 * self.tol_rel:g} % of the limit"
        return "max(3 km/h, 3 % of the limit) (German enforcement rule)"


DEFAULT_SPEC = KpiSpec()


class KpiSpecProblems(list):
    """(line, field, message) triples of one KPI file."""

    def add(self, line: int | None, fld: str, message: str) -> None:
        self.append((line, fld, message))


def parse(text: str, problems: KpiSpecProblems | None = None, attributes: dict[str, Any] | None = None,
          conditions: tuple[str, ...] | None = None, mapped: tuple[str, set] | None = None) -> KpiSpec | None:
    """Parse a KPI file; problems go to ``problems`` (line, field, message); None when there is any.

    ``attributes`` (name -> study.folder.definition.Attribute) and ``conditions`` (declared names), when given, are checked
    against the grouping and the comparison; ``mapped`` = (log mapping file, its extra channels), when given, must
    hold every declared channel."""
    probs = problems if problems is not None else KpiSpecProblems()
    n0 = len(probs)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        probs.add(int(m.group(1)) if m else None, "", f"not valid TOML: {exc}")
        return None
    for key in data:
        if key not in _KEYS:
            probs.add(line_of(text, key) or line_of(text, "", key), key, f"unknown key (known: {', '.join(sorted(_KEYS))})")

    builtins = data.get("builtins", list(BUILTINS))
    if not isinstance(builtins, list) or not all(isinstance(b, str) for b in builtins):
        probs.add(line_of(text, "builtins"), "builtins", "must be a list of names")
        builtins = []
    for b in builtins:
        if b not in BUILTINS:
            probs.add(line_of(text, "builtins"), "builtins", f"{b!r} is not a built-in KPI ({', '.join(BUILTINS)})")

    channels = data.get("channels", [])
    if not isinstance(channels, list) or not all(isinstance(c, str) and _NAME.match(c) for c in channels):
        probs.add(line_of(text, "channels"), "channels", "must be a list of channel names (lower-case letters, digits, _)")
        channels = []
    for c in channels:
        if c in SAMPLE_COLUMNS:
            probs.add(line_of(text, "channels"), "channels", f"{c!r} is a standard drive-log column, not an extra channel")
        elif mapped is not None and c not in mapped[1]:
            extras = ", ".join(sorted(set(mapped[1]) - set(SAMPLE_COLUMNS)))
            # a channel the SQL KPIs read must come from the study's simulator logs
            probs.add(line_of(text, "channels"), "channels", f"{c!r} is not an extra channel of the log mapping "
                                                           f"{mapped[0]} ({extras or 'none'})")

    group_by = data.get("group_by", ["condition"])
    if not isinstance(group_by, list) or not all(isinstance(g, str) for g in group_by):
        probs.add(line_of(text, "group_by"), "group_by", "must be a list of names")
        group_by = []
    for g in group_by:
        if g != "condition" and attributes is not None and g not in attributes:
            probs.add(line_of(text, "group_by"), "group_by",
                      f"{g!r} is neither 'condition' nor a declared participant attribute "
                      f"({', '.join(attributes) or 'none declared'})")
    if len(set(group_by)) != len(group_by):
        probs.add(line_of(text, "group_by"), "group_by", "a grouping is named twice")

    spec: dict[str, Any] = {}

    viol = _table(data, "violations", text, probs)
    _unknown(viol, {"tolerance", "km_h", "percent", "min_event_s"}, "violations", text, probs)
    tol = viol.get("tolerance", "none")
    spec["tolerance"] = tol
    need = {"absolute": "km_h", "relative": "percent"}.get(tol)
    if tol not in TOLERANCES:
        probs.add(line_of(text, "tolerance", "violations"), "violations.tolerance",
                  f"{tol!r} is not one of {'|'.join(TOLERANCES)}")
    elif need and need not in viol:
        probs.add(line_of(text, "tolerance", "violations"), f"violations.{need}",
                  f"a {tol} tolerance needs {need} (e.g. {need} = {5 if need == 'km_h' else 3})")
    for key in ("km_h", "percent"):
        if key in viol and key != need and tol in TOLERANCES:
            probs.add(line_of(text, key, "violations"), f"violations.{key}", f"not used by tolerance {tol!r}")
    km_h = _number(viol, "km_h", 0.0, "violations", text, probs, lo=0.0)
    percent = _number(viol, "percent", 0.0, "violations", text, probs, lo=0.0)
    spec["tol_abs"] = {"absolute": km_h * KMH, "german": 3.0 * KMH}.get(tol, 0.0)
    spec["tol_rel"] = {"relative": percent / 100.0, "german": 0.03}.get(tol, 0.0)
    spec["min_event_s"] = _number(viol, "min_event_s", 1.0, "violations", text, probs, lo=0.0)

    stops = _table(data, "stops", text, probs)
    _unknown(stops, {"v_stop", "v_moving"}, "stops", text, probs)
    spec["v_stop"] = _number(stops, "v_stop", 0.5, "stops", text, probs, lo=0.0)
    spec["v_moving"] = _number(stops, "v_moving", 2.0, "stops", text, probs, lo=0.0)
    if spec["v_moving"] < spec["v_stop"]:
        probs.add(line_of(text, "v_moving", "stops"), "stops.v_moving", "must not be below v_stop")
    red = _table(data, "red_stops", text, probs)
    _unknown(red, {"distance_m"}, "red_stops", text, probs)
    spec["red_stop_dist"] = _number(red, "distance_m", 50.0, "red_stops", text, probs, lo=0.0)

    sql_kpis = _sql_kpis(_table(data, "sql", text, probs), text, probs, tuple(channels))
    event_kpis = _event_kpis(_table(data, "events", text, probs), text, probs, tuple(channels),
                             {k.name for k in sql_kpis})
    measures = _measures(_table(data, "measures", text, probs), text, probs, mapped,
                         {k.name for k in (*sql_kpis, *event_kpis)})
    regions = _regions(_table(data, "regions", text, probs), text, probs, mapped)
    comparison = _comparison(_table(data, "comparison", text, probs), text, probs, conditions,
                             tuple(b for b in builtins if b in BUILTINS), [*sql_kpis, *event_kpis, *measures])
    if len(probs) > n0:
        return None
    return KpiSpec(builtins=tuple(b for b in BUILTINS if b in builtins), group_by=tuple(group_by),
                   channels=tuple(channels), sql=tuple(sql_kpis), comparison=comparison,
                   attributes=tuple(g for g in group_by if g != "condition"), events=tuple(event_kpis),
                   measures=tuple(measures), regions=tuple(regions), **spec)


def _table(data: dict, key: str, text: str, probs: KpiSpecProblems) -> dict:
    v = data.get(key, {})
    if not isinstance(v, dict):
        probs.add(line_of(text, key), key, "must be a table ([" + key + "])")
        return {}
    return v


def _unknown(tbl: dict, known: set, section: str, text: str, probs: KpiSpecProblems) -> None:
    for k in tbl:
        if k not in known and not isinstance(tbl[k], dict):
            probs.add(line_of(text, k, section), f"{section}.{k}", f"unknown key (known: {', '.join(sorted(known))})")


def _number(tbl: dict, key: str, default: float, section: str, text: str, probs: KpiSpecProblems,
            lo: float | None = None) -> float:
    v = tbl.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v:
        probs.add(line_of(text, key, section), f"{section}.{key}", f"must be a number, not {v!r}")
        return default
    if lo is not None and v < lo:
        probs.add(line_of(text, key, section), f"{section}.{key}", f"must be >= {lo:g}, not {v:g}")
        return default
    return float(v)


def _entry_line(text: str, section: str, name: str, key: str | None = None) -> int | None:
    """Line of KPI ``name`` of ``section``: its ``[section.name]`` table (its ``key`` line when given) or its
    ``name = {...}`` line."""
    if line_of(text, "", f"{section}.{name}") is not None:
        return line_of(text, key, f"{section}.{name}") if key else line_of(text, "", f"{section}.{name}")
    return line_of(text, name, section) or line_of(text, f'"{name}"', section)


def _common(raw: dict, name: str, line, fld: str, probs: KpiSpecProblems, known: tuple[str, ...],
            taken: set[str], text: str = "") -> bool:
    """The checks every user KPI shares (its keys, name, per_segment, unit, label and decimals); True when it may be
    used."""
    bad = set(raw) - set(known)
    if bad:
        probs.add(line, fld, f"unknown key(s) {', '.join(sorted(bad))} (known: {', '.join(known)})")
    if not _NAME.match(name) or name in _RESERVED or name in KPI_FIELDS:
        probs.add(line, fld, "a KPI name is lower-case letters, digits and _, and not a built-in column")
        return False
    if name in taken:
        probs.add(line, fld, "a KPI of this name is declared twice ([sql] and [events] share one namespace)")
        return False
    if not isinstance(raw.get("per_segment", False), bool):
        probs.add(line, f"{fld}.per_segment", "must be true or false")
        return False
    for key in ("unit", "label"):
        if key in raw and not isinstance(raw[key], str):
            probs.add(line, f"{fld}.{key}", "must be a text")
            return False
    dec = raw.get("decimals", 0)
    if isinstance(dec, bool) or not isinstance(dec, int) or not 0 <= dec <= MAX_DECIMALS:
        section, _, entry = fld.partition(".")
        probs.add(_entry_line(text, section, entry, "decimals") or line, f"{fld}.decimals",
                  f"must be a whole number from 0 to {MAX_DECIMALS}, not {dec!r}")
        return False
    return True


def _sql_kpis(tbl: dict, text: str, probs: KpiSpecProblems, channels: tuple[str, ...]) -> list[SqlKpi]:
    out = []
    for name, raw in tbl.items():
        line = _entry_line(text, "sql", name)
        fld = f"sql.{name}"
        if isinstance(raw, str):
            raw = {"sql": raw}
        if not isinstance(raw, dict) or ("sql" in raw) == ("query" in raw):
            probs.add(line, fld, 'needs either an aggregate expression (sql = "stddev_samp(lat_pos)") or a query '
                                 '(query = "SELECT ... FROM samples")')
            continue
        key = "query" if "query" in raw else "sql"
        if not isinstance(raw[key], str) or not raw[key].strip():
            probs.add(line, fld, f"{key} must be a non-empty text")
            continue
        if not _common(raw, name, line, fld, probs, (key, "per_segment", "unit", "label", "decimals"), set(), text):
            continue
        error = check_query(raw["query"], channels) if key == "query" else check_sql(raw["sql"], channels)
        if error:
            probs.add(_entry_line(text, "sql", name, key) or line, fld, error)
            continue
        out.append(SqlKpi(name, raw[key].strip(), bool(raw.get("per_segment", False)), str(raw.get("unit", "")),
                          str(raw.get("label", name)), query=key == "query", decimals=raw.get("decimals")))
    return out


def _event_kpis(tbl: dict, text: str, probs: KpiSpecProblems, channels: tuple[str, ...],
                taken: set[str]) -> list[EventKpi]:
    out = []
    for name, raw in tbl.items():
        line = _entry_line(text, "events", name)
        fld = f"events.{name}"
        if not isinstance(raw, dict):
            probs.add(line, fld, 'must be a table, e.g. {from = "takeover_request", to = "hands_on"}')
            continue
        if not _common(raw, name, line, fld, probs,
                       ("from", "to", "statistic", "per_segment", "unit", "label", "decimals"), taken, text):
            continue
        statistic = raw.get("statistic", "first")
        if statistic not in STATISTICS:
            probs.add(_entry_line(text, "events", name, "statistic") or line, f"{fld}.statistic",
                      f"{statistic!r} is not one of {'|'.join(STATISTICS)}")
            continue
        ok = True
        for key in ("from", "to"):
            error = check_condition(raw.get(key), channels) if key in raw else \
                f'needs a condition, e.g. {key} = "{"takeover_request" if key == "from" else "hands_on"}"'
            if error:
                probs.add(_entry_line(text, "events", name, key) or line, f"{fld}.{key}", error)
                ok = False
        if ok:
            unit = raw.get("unit", "" if statistic == "count" else "s")
            out.append(EventKpi(name, raw["from"].strip(), raw["to"].strip(), statistic,
                                bool(raw.get("per_segment", False)), str(unit), str(raw.get("label", name)),
                                raw.get("decimals")))
    return out


def _missing_channel(channel: str, mapped: tuple[str, set] | None) -> str | None:
    """A reason when the log mapping (``mapped``: its file, its channel names) does not supply ``channel``."""
    from study.folder.measure_library import ALWAYS_PRESENT

    if mapped is None or channel in ALWAYS_PRESENT or channel in mapped[1]:
        return None
    return f"needs channel {channel!r}, which the log mapping {mapped[0]} does not map"


#: the keys of a [measures] entry beside ``measure`` that are no option of the measure
_MEASURE_KEYS = ("per_segment", "label", "decimals")


def _measures(tbl: dict, text: str, probs: KpiSpecProblems, mapped, taken: set[str]) -> list[MeasureKpi]:
    from study.folder.measure_library import MEASURES, resolve

    out = []
    for name, raw in tbl.items():
        line = _entry_line(text, "measures", name)
        fld = f"measures.{name}"
        if not isinstance(raw, dict) or not isinstance(raw.get("measure"), str):
            probs.add(line, fld, 'must be a table naming a shipped measure, e.g. {measure = "sdlp"}')
            continue
        measure = MEASURES.get(raw["measure"])
        if measure is None:
            probs.add(_entry_line(text, "measures", name, "measure") or line, f"{fld}.measure",
                      f"{raw['measure']!r} is not a shipped measure ({', '.join(sorted(MEASURES))})")
            continue
        common = {k: v for k, v in raw.items() if k in _MEASURE_KEYS}
        if not _common(common, name, line, fld, probs, _MEASURE_KEYS, taken, text):
            continue
        opts, problems = resolve(measure, {k: v for k, v in raw.items() if k not in ("measure", *_MEASURE_KEYS)})
        for key, reason in problems:
            probs.add(_entry_line(text, "measures", name, key) or line, f"{fld}.{key}", reason)
        missing = [r for r in (_missing_channel(c, mapped) for c in measure.channels_of(opts)) if r]
        for reason in missing[:1]:
            probs.add(line, fld, reason)
        if problems or missing:
            continue
        taken.add(name)
        out.append(MeasureKpi(name, measure.name, tuple(sorted(opts.items())), bool(raw.get("per_segment", False)),
                              measure.unit_of(opts), str(raw.get("label", measure.title)), raw.get("decimals")))
    return out


def _regions(tbl: dict, text: str, probs: KpiSpecProblems, mapped) -> list[Region]:
    out = []
    for name, raw in tbl.items():
        line = _entry_line(text, "regions", name)
        fld = f"regions.{name}"
        kinds = [k for k, (req, _) in REGION_KINDS.items() if isinstance(raw, dict) and req[0] in raw]
        if not _NAME.match(name) or len(kinds) != 1:
            probs.add(line, fld, "a region is a name (lower-case letters, digits, _) = one of {s_from, s_to}, "
                                 "{t_from, t_to}, {segment = \"...\"} or {event = \"channel\", before_s, after_s}")
            continue
        kind = kinds[0]
        req, opt = REGION_KINDS[kind]
        bad = set(raw) - set(req) - set(opt)
        if bad:
            probs.add(line, fld, f"unknown key(s) {', '.join(sorted(bad))} for a {kind} region "
                                 f"(keys: {', '.join(req + opt)})")
            continue
        if kind == "segment":
            if not isinstance(raw["segment"], str) or not raw["segment"]:
                probs.add(line, f"{fld}.segment", "must name a route segment")
                continue
            out.append(Region(name, kind, segment=raw["segment"]))
            continue
        if kind == "event":
            reason = "must name a 0/1 channel" if not isinstance(raw["event"], str) or not _NAME.match(raw["event"]) \
                else _missing_channel(raw["event"], mapped)
            nums = [raw.get("before_s", 0.0), raw.get("after_s", 10.0)]
        else:
            missing = [k for k in req if k not in raw]
            reason = f"needs {' and '.join(missing)}" if missing else None
            nums = [raw.get(k, 0.0) for k in req]
        if reason is None and not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                                      for x in nums):
            reason = "its bounds must be numbers"
        elif reason is None and kind != "event" and nums[1] <= nums[0]:
            reason = f"{req[1]} must be above {req[0]}"
        elif reason is None and kind == "event" and (nums[0] < 0 or nums[1] <= 0):
            reason = "before_s must be >= 0 and after_s > 0"
        if reason:
            probs.add(line, fld, reason)
            continue
        out.append(Region(name, kind, float(nums[0]), float(nums[1]), event=raw.get("event", "")))
    return out


# a sub-query, a window or a second statement is no aggregate over the drive's samples
_FORBIDDEN = re.compile(r";|--|/\*|\b(select|from|over|window)\b", re.IGNORECASE)


def check_sql(sql: str, channels: tuple[str, ...] = ()) -> str | None:
    """None when ``sql`` is one aggregate expression over the sample columns and ``channels`` (tried on an empty
    typed table: it must aggregate every row of a group into one value); else a one-line reason."""
    import duckdb

    if _FORBIDDEN.search(sql):
        return "must be one aggregate expression (no ;, comments, SELECT, FROM or window functions)"
    con = trial_connection(channels)   # only `samples`, no file access
    try:
        try:
            con.execute(f"SELECT drive_id, ({sql})::DOUBLE FROM samples GROUP BY drive_id").fetchall()
        except duckdb.Error as exc:
            msg = " ".join(str(exc).split())
            if "must appear in the GROUP BY" in msg or "aggregate function" in msg.lower():
                return f"{sql!r} is not an aggregate over the samples (e.g. avg(x), stddev_samp(x))"
            if "not found" in msg.lower() and "column" in msg.lower():
                return (f"{sql!r} reads an unknown column ({msg[:160]}); an extra channel must be listed in "
                        f"channels = [...]")
            return f"{sql!r}: {msg[:200]}"
        # an aggregate cannot stand beside a plain column without GROUP BY; a constant (or a plain expression)
        # can, and is no KPI of the drive
        try:
            con.execute(f"SELECT drive_id, ({sql})::DOUBLE FROM samples").fetchall()
            return f"{sql!r} is not an aggregate over the samples (e.g. avg(x), stddev_samp(x))"
        except duckdb.Error:
            pass
    finally:
        con.close()
    return None


def _kpi_ref(raw: Any, builtin_cols: set, sql_names: set) -> tuple[str, str] | str:
    """'kpi' or 'kpi@segment' -> (kpi, segment); a reason string when bad."""
    if not isinstance(raw, str):
        return "must name a KPI, e.g. \"energy_wh@urban\""
    kpi, _, seg = raw.partition("@")
    seg = seg or "overall"
    if kpi not in builtin_cols and kpi not in sql_names:
        return f"{kpi!r} is not a declared KPI column"
    return kpi, seg


def _comparison(tbl: dict, text: str, probs: KpiSpecProblems, conditions: tuple[str, ...] | None,
                builtins: tuple[str, ...], sql_kpis: list[SqlKpi]) -> Comparison | None:
    if not tbl:
        return None
    _unknown(tbl, {"control", "treatment", "bands", "participant"}, "comparison", text, probs)
    table = tbl.get("table", {})
    if not isinstance(table, dict) or not all(isinstance(v, str) for v in table.values()):
        probs.add(line_of(text, "", "comparison.table"), "comparison.table", "must be a table of texts")
        table = {}
    _unknown(table, {"title", "note", "participant_title"}, "comparison.table", text, probs)
    c, t = tbl.get("control"), tbl.get("treatment")
    for key, v in (("control", c), ("treatment", t)):
        if not isinstance(v, str):
            probs.add(line_of(text, key, "comparison"), f"comparison.{key}", "must name a condition")
        elif conditions is not None and v not in conditions:
            probs.add(line_of(text, key, "comparison"), f"comparison.{key}",
                      f"{v!r} is not a declared condition ({'|'.join(conditions)})")
    if isinstance(c, str) and c == t:
        probs.add(line_of(text, "treatment", "comparison"), "comparison.treatment", "must differ from the control")
    bands = tbl.get("bands", False)
    if not isinstance(bands, bool):
        probs.add(line_of(text, "bands", "comparison"), "comparison.bands", "must be true or false")
    who = tbl.get("participant")
    if who is not None and (not isinstance(who, str) or not who.strip()):
        probs.add(line_of(text, "participant", "comparison"), "comparison.participant", "must be a participant id")
        who = None
    cols = {col for b in builtins for col in BUILTINS[b]}
    names = {k.name for k in sql_kpis}
    parts: dict[str, list] = {}
    labels = []
    for sub in ("columns", "reductions", "pooled"):
        part = tbl.get(sub, {})
        parts[sub] = []
        if not isinstance(part, dict):
            probs.add(line_of(text, sub, "comparison"), f"comparison.{sub}", "must be a table")
            continue
        for name, raw in part.items():
            if sub == "reductions" and isinstance(raw, dict):   # {kpi = "...", label = "..."}
                if isinstance(raw.get("label"), str):
                    labels.append((name, raw["label"]))
                raw = raw.get("kpi")
            ref = _kpi_ref(raw, cols, names)
            line = line_of(text, name, f"comparison.{sub}") or line_of(text, f'"{name}"', f"comparison.{sub}")
            if isinstance(ref, str):
                probs.add(line, f"comparison.{sub}.{name}", ref)
            elif sub == "pooled" and ref[1] != "overall":
                probs.add(line, f"comparison.{sub}.{name}", "a pooled reduction sums whole drives (no @segment)")
            else:
                parts[sub].append((name, *ref) if sub != "pooled" else (name, ref[0]))
    for name, kpi in parts["pooled"]:
        if not any(k == kpi and seg == "overall" for _, k, seg in parts["columns"]):
            probs.add(line_of(text, name, "comparison.pooled"), f"comparison.pooled.{name}",
                      f"{kpi} must also be one of [comparison.columns] (the pooled sums are taken from there)")
    if not isinstance(c, str) or not isinstance(t, str):
        return None
    return Comparison(control=c, treatment=t, bands=bool(bands), columns=tuple(parts["columns"]),
                      reductions=tuple(parts["reductions"]), pooled=tuple(parts["pooled"]), labels=tuple(labels),
                      table=tuple(table.items()), participant=who)


# ------------------------------------------------------------------------------------------ the study's KPIs
def study_spec(study) -> KpiSpec:
    """The KPIs a :class:`study.folder.definition.StudyDefinition` declares (:data:`DEFAULT_SPEC` without a KPI file)."""
    drives = study.settings.get("drives", {})
    model = drives.get("energy_model") if isinstance(drives, dict) else None
    model = model if model in ENERGY_MODELS else "none"
    text = study.text("kpis")
    if text is None:
        return replace(DEFAULT_SPEC, energy_model=model)
    probs = KpiSpecProblems()
    spec = parse(text, probs, {a.name: a for a in study.attributes}, study.condition_names)
    if spec is None:
        raise StudyError([Problem(study.paths["kpis"], ln, f, m) for ln, f, m in probs])
    return replace(spec, energy_model=model)


def _check_study(study, problems) -> None:
    """The check run by every study parse: the KPI file against the study's attributes and conditions."""
    rel = study.paths.get("kpis")
    if rel is None or rel not in study.files:
        return
    probs = KpiSpecProblems()
    mapped = None
    mapping_rel = study.paths.get("log_mapping")
    if mapping_rel in study.files:
        from study.folder.logmap import parse_mapping

        mapping, _ = parse_mapping(study.files[mapping_rel], mapping_rel)  # its own check reports its problems
        if mapping is not None:
            mapped = (mapping_rel, {c.name for c in mapping.channels})
    parse(study.files[rel], probs, {a.name: a for a in study.attributes}, study.condition_names, mapped)
    for line, fld, message in probs:
        problems.add(rel, line, fld, message)


register_file_check(_check_study, units=True)  # it parses the log mapping, whose units pint reads

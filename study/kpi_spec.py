"""The drive KPIs a study declares: the file ``[files] kpis = "kpis.toml"`` of its folder (docs/kpis.md).

    builtins = ["time", "violations"]       which built-in KPI groups to report (table BUILTINS)
    group_by = ["condition"]                 summaries by condition and/or declared participant attributes
    channels = ["lat_pos"]                   extra DOUBLE channels of the drive log the SQL KPIs read

    [violations]  tolerance = "none" | "absolute" (km_h = 5) | "relative" (percent = 3) | "german"; min_event_s
    [stops]       v_stop, v_moving (m/s);  [red_stops] distance_m (m)
    [sql]         name = "aggregate expression" or {sql = "...", per_segment = true, unit = "m", label = "..."}
    [comparison]  control, treatment (conditions), bands; [comparison.columns] / .reductions / .pooled

:func:`parse` turns the text into a :class:`KpiSpec` and reports every problem with file, line and field; the check
registered with :func:`study.definition.register_file_check` runs it (and cross-checks conditions and attributes) in
every ``study check`` and every load of a study. A study without a KPI file gets :data:`DEFAULT_SPEC`. Which vehicle
model may supply the power of a drive that logged none is the study's ``[drives] energy_model`` (study.toml, the
same declaration the drive import uses); without one such a drive's energy is unavailable.
"""
from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field, replace
from typing import Any

from pedas.constants import KMH
from study.file_checks import register_file_check
from study.kpi_fields import KPI_FIELDS, SAMPLE_COLUMNS, KpiParams
from study.problems import Problem, StudyError
from study.toml_lines import line_of

#: built-in KPI groups -> their output columns (study.kpi_fields.KPI_FIELDS), in output order
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
_RESERVED = {"participant_id", "condition", "drive_id", "segment", "n_intervals", "overall", "all"}
_KEYS = {"builtins", "group_by", "channels", "violations", "stops", "red_stops", "sql", "comparison"}


@dataclass(frozen=True)
class SqlKpi:
    """A user KPI: a DuckDB aggregate over the samples of a drive (and of each segment when ``per_segment``)."""

    name: str
    sql: str
    per_segment: bool = False
    unit: str = ""
    label: str = ""


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

    @property
    def columns(self) -> tuple[str, ...]:
        """Output KPI columns: the declared built-ins in the order of :data:`KPI_FIELDS`, then the SQL KPIs."""
        declared = {c for b in self.builtins for c in BUILTINS[b]}
        return tuple(c for c in KPI_FIELDS if c in declared) + tuple(k.name for k in self.sql)

    @property
    def params(self):
        """The thresholds as :class:`study.kpi_fields.KpiParams`."""
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

    ``attributes`` (name -> study.definition.Attribute) and ``conditions`` (declared names), when given, are checked
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
            # a channel the SQL KPIs read must come from the study's simulator logs
            probs.add(line_of(text, "channels"), "channels", f"{c!r} is not an extra channel of the log mapping "
                                                           f"{mapped[0]} ({', '.join(sorted(mapped[1])) or 'none'})")

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
    comparison = _comparison(_table(data, "comparison", text, probs), text, probs, conditions,
                             tuple(b for b in builtins if b in BUILTINS), sql_kpis)
    if len(probs) > n0:
        return None
    return KpiSpec(builtins=tuple(b for b in BUILTINS if b in builtins), group_by=tuple(group_by),
                   channels=tuple(channels), sql=tuple(sql_kpis), comparison=comparison,
                   attributes=tuple(g for g in group_by if g != "condition"), **spec)


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


def _sql_kpis(tbl: dict, text: str, probs: KpiSpecProblems, channels: tuple[str, ...]) -> list[SqlKpi]:
    out = []
    for name, raw in tbl.items():
        line = line_of(text, name, "sql")
        fld = f"sql.{name}"
        if isinstance(raw, str):
            raw = {"sql": raw}
        if not isinstance(raw, dict) or not isinstance(raw.get("sql"), str) or not raw["sql"].strip():
            probs.add(line, fld, 'needs an aggregate expression, e.g. sdlp = "stddev_samp(lat_pos)"')
            continue
        bad = set(raw) - {"sql", "per_segment", "unit", "label"}
        if bad:
            probs.add(line, fld, f"unknown key(s) {', '.join(sorted(bad))} (known: sql, per_segment, unit, label)")
        if not _NAME.match(name) or name in _RESERVED or name in KPI_FIELDS:
            probs.add(line, fld, "a KPI name is lower-case letters, digits and _, and not a built-in column")
            continue
        if not isinstance(raw.get("per_segment", False), bool):
            probs.add(line, f"{fld}.per_segment", "must be true or false")
            continue
        error = check_sql(raw["sql"], channels)
        if error:
            probs.add(line, fld, error)
            continue
        out.append(SqlKpi(name, raw["sql"].strip(), bool(raw.get("per_segment", False)), str(raw.get("unit", "")),
                          str(raw.get("label", name))))
    return out


# a sub-query, a window or a second statement is no aggregate over the drive's samples
_FORBIDDEN = re.compile(r";|--|/\*|\b(select|from|over|window)\b", re.IGNORECASE)


def check_sql(sql: str, channels: tuple[str, ...] = ()) -> str | None:
    """None when ``sql`` is one aggregate expression over the sample columns and ``channels`` (tried on an empty
    typed table: it must aggregate every row of a group into one value); else a one-line reason."""
    import duckdb

    if _FORBIDDEN.search(sql):
        return "must be one aggregate expression (no ;, comments, SELECT, FROM or window functions)"
    cols = {**SAMPLE_COLUMNS, **{c: "DOUBLE" for c in channels}}
    con = duckdb.connect()
    try:
        con.execute("CREATE TABLE samples (" + ", ".join(f'"{c}" {t}' for c, t in cols.items()) + ")")
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
    """The KPIs a :class:`study.definition.StudyDefinition` declares (:data:`DEFAULT_SPEC` without a KPI file)."""
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
        from study.logmap import parse_mapping

        mapping, _ = parse_mapping(study.files[mapping_rel], mapping_rel)  # its own check reports its problems
        if mapping is not None:
            mapped = (mapping_rel, {c.name for c in mapping.extras})
    parse(study.files[rel], probs, {a.name: a for a in study.attributes}, study.condition_names, mapped)
    for line, fld, message in probs:
        problems.add(rel, line, fld, message)


register_file_check(_check_study)

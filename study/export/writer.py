"""Export of the store for SPSS, R and Python: every table as CSV, Parquet or SPSS ``.sav``.

Besides the tables, a wide survey file per instrument (``survey_wide_<instrument>``: one row per participant,
one column per item, the final answers) is written, because that is the file an analyst opens in SPSS, and, when the
study declares scores, ``scores`` (every score per participant and occasion, :func:`study.survey.scores.score_table`).
``participants`` carries the study's declared attributes as columns (``study.people.participants.participant_attributes``;
the long ``participant_attributes`` table is written as well). A ``manifest.json`` lists the files, their row
counts, the schema version and what was left out.

``.sav`` files carry variable labels and value labels taken from the store's study: an attribute's ``label``
(study.toml), a choice attribute written as codes 1..k labelled with its choices, a numeric attribute that a choice
item of the codebook fills labelled with that item's choices, condition and segment names coded in the order the
study declares them; a survey item's wording and its anchors or point labels looked up per (instrument, item_id)
in the ``items`` table, so two instrument versions that reuse an item id keep their own wording. Enumerations
of the store itself (scope, reason, outcome, ...) are coded 1..k as well; booleans 0/1 with labels no/yes.

``deidentify=True`` keeps only what is needed for analysis under the pseudonymous participant IDs: an attribute
for which study.toml declares bands (``[export.bands]``, e.g. ``age = ["16-24", "25-34", "65+"]``) is written as
its band (column ``<attribute>_band`` or the declared ``column``) instead of the exact value — numeric and choice
attributes without declared bands are written as they are, free-text attributes are dropped; every timestamp
``<col>`` of a participant's row becomes ``<col>_s``, seconds after that participant's first recorded event (the
earliest timestamp of any of their rows, usually the registration), and a timestamp of no participant is dropped;
free text that can carry names is dropped (notes, people's names: entered_by, actor, ...; source file names, the
route name, free-text answers and resolutions, the reason given for a forced import, the drive log's checksum
that leads back to the raw file); the audit log (which repeats exact values), the long attribute table,
appointments, survey link tokens and drafts and any table this module does not know are left out (listed in the
manifest). docs/store.md ("Exports") lists what stays and why.

Streaming: a table is written by DuckDB as it reads it (``COPY (SELECT ...) TO file``, CSV or Parquet, DuckDB's
memory held to :data:`EXPORT_MEMORY`), so an export of millions of drive samples needs DuckDB's buffers, not memory
for the table; the de-identified columns are SQL expressions of the same SELECT (:func:`table_sql`). Only the small
per-participant files are built as DataFrames (``participants`` with its typed attributes, the wide survey files,
and ``drives`` when de-identified, whose JSON ``meta`` is rewritten in Python). A ``.sav`` file is written by
pyreadstat from one whole DataFrame (pyreadstat cannot append), so a ``.sav`` export holds each table,
``drive_samples`` included, in memory once.
"""
from __future__ import annotations

import json
import re
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from study.common.errors import UserError, check_choice
from study.common.file_checks import register_file_check

FORMATS = ("csv", "parquet", "sav")
#: the file of every declared score per participant and occasion
SCORES = "scores"

#: enumerations of the store itself (not of a study): coded 1..k in .sav files
ENUMS: dict[str, tuple[str, ...]] = {
    "scope": ("all", "objective", "subjective"),
    "reason": ("motion_sickness", "technical_issue", "incomplete_survey", "withdrawn", "other"),
    "outcome": ("in_progress", "completed", "aborted"),
    "tl_state": ("green", "yellow", "red"),
    "controller": ("rt", "cf", "none"),
    "action": ("insert", "update", "delete"),
}
# `source` means different things in drives and survey_submissions: per table.
TABLE_ENUMS: dict[str, dict[str, tuple[str, ...]]] = {
    "drives": {"source": ("import", "simulation")},
    "survey_submissions": {"source": ("web", "import", "entry")},
}
NUMERIC_LABELS: dict[str, dict[int, str]] = {
    "hud_arrow": {-1: "slow down", 0: "keep speed", 1: "speed up"},
}
LABELS: dict[str, str] = {
    "participant_id": "Pseudonymous participant ID",
    "protocol": "Study protocol",
    "study_version": "Version of the study definition at registration",
    "created_at": "Recorded at (UTC)",
    "created_at_s": "Recorded at (s after the participant's first event)",
    "started_at_s": "Phase start (s after the participant's first event)",
    "ended_at_s": "Phase end (s after the participant's first event)",
    "entered_at_s": "Entered at (s after the participant's first event)",
    "submitted_at_s": "Submitted at (s after the participant's first event)",
    "resolved_at_s": "Resolved at (s after the participant's first event)",
    "assigned_at_s": "Order assigned at (s after the participant's first event)",
    "attribute": "Participant attribute",
    "phase": "Protocol phase",
    "seq": "Position of the phase in the protocol",
    "started_at": "Phase start (UTC)",
    "ended_at": "Phase end (UTC)",
    "outcome": "Phase outcome",
    "note": "Note",
    "scope": "Exclusion scope",
    "reason": "Exclusion reason",
    "drive_id": "Drive ID",
    "condition": "Drive condition",
    "source": "Data source",
    "route": "Route",
    "checksum": "SHA-256 of the drive log",
    "n_samples": "Number of samples",
    "file_name": "Imported file name",
    "duration_s": "Drive duration (s)",
    "distance_m": "Drive distance (m)",
    "seed": "Random seed of a simulated drive",
    "meta": "Simulation settings (JSON)",
    "idx": "Sample index within the drive",
    "t": "Time (s)",
    "s": "Distance along the route (m)",
    "v": "Speed (m/s)",
    "segment": "Road segment",
    "speed_limit": "Speed limit (m/s)",
    "a": "Acceleration (m/s^2)",
    "grade": "Road grade (rad)",
    "ft": "Traction force (N)",
    "fb": "Braking force (N)",
    "p_batt": "Battery power (W)",
    "tl_id": "Next traffic light ahead",
    "tl_state": "State of the next traffic light",
    "d_tl": "Distance to the next stop line (m)",
    "leader_gap": "Gap to the preceding vehicle (m)",
    "leader_v": "Speed of the preceding vehicle (m/s)",
    "v_advice": "Advised speed (m/s)",
    "controller": "Active MPC (rt = reference tracking, cf = car following)",
    "hud_arrow": "HUD arrow (-1 slow down, 0 keep, 1 speed up)",
    "hud_in_band": "Speed within the HUD band",
    "warning": "Auditory warning active",
    "instrument": "Survey instrument",
    "occasion": "Questionnaire occasion (the protocol phase answered in)",
    "item_id": "Survey item",
    "entry_round": "Data entry round",
    "value": "Answer (scale value)",
    "text": "Answer (free text)",
    "entered_by": "Entered by",
    "entered_at": "Entered at (UTC)",
    "at": "Time of the change (UTC)",
    "actor": "Who made the change",
    "action": "Kind of change",
    "table_name": "Table changed",
    "row_key": "Key of the changed row (JSON)",
    "old": "Old values (JSON)",
    "new": "New values (JSON)",
}
# Deidentified export: tables kept (others are left out) and columns dropped wherever they occur.
DEIDENTIFIED_TABLES = ("participants", "phase_events", "exclusions", "drives", "drive_samples", "instruments",
                       "items", "responses", "survey_submissions", "survey_resolutions", "order_assignments")
IDENTIFYING_COLUMNS = ("note", "entered_by", "submitted_by", "resolved_by", "issued_by", "actor", "file_name",
                       "created_by", "email", "phone", "name",
                       "route", "text", "checksum")  # free text (--route, answers), a hash of the raw file
RELATIVE = "_s"  # suffix of a timestamp column made relative to the participant's first event
WIDE = "survey_wide_"  # file name prefix of the wide survey file of an instrument
#: DuckDB's memory limit while a CSV or Parquet export runs: COPY streams within it, a sort spills to disk beyond it
EXPORT_MEMORY = "400MB"
_BAND = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*(?:-\s*(\d+(?:\.\d+)?)|(\+))\s*$")


@dataclass(frozen=True)
class ExportResult:
    outdir: Path
    files: dict[str, int]          # file name -> rows
    skipped: tuple[str, ...]       # tables left out


@dataclass(frozen=True)
class Part:
    """One file of an export: `name` (the file name without extension) and either `sql`, a SELECT over the store
    that DuckDB writes as it reads it, or `frame`, a small DataFrame built in Python."""

    name: str
    sql: str | None = None
    frame: pd.DataFrame | None = None


@dataclass(frozen=True)
class Bands:
    """Declared bands of one numeric attribute: `column` replaces it in a deidentified export; `bands` are
    (low, high, label) with inclusive bounds (high None = open, "65+")."""

    attribute: str
    column: str
    bands: tuple[tuple[float, float | None, str], ...]

    def apply(self, values: pd.Series) -> pd.Series:
        """The band label of each value (None when missing or in no band)."""
        num = pd.to_numeric(values, errors="coerce")
        out = pd.Series([None] * len(values), index=values.index, dtype=object)
        for lo, hi, label in self.bands:
            inside = (num >= lo) if hi is None else (num >= lo) & (num <= hi)
            out[inside.fillna(False).astype(bool)] = label
        return out


@dataclass
class Vocabulary:
    """What the .sav files of one store say about its columns (built from the store's study and items)."""

    enums: dict[str, tuple[str, ...]] = field(default_factory=dict)        # text column -> categories 1..k
    labels: dict[str, str] = field(default_factory=dict)                   # column -> variable label
    values: dict[str, dict[int, str]] = field(default_factory=dict)        # numeric column -> value labels
    items: dict[str, tuple[dict[str, str], dict[str, dict[int, str]]]] = field(default_factory=dict)
    title: str = "study"                                                   # file label prefix


def declared_bands(study) -> list[Bands]:
    """The bands study.toml declares under ``[export.bands]``: ``attr = ["16-24", ..., "65+"]`` or
    ``attr = { column = "name", bands = [...] }``; a band list that is not ascending and disjoint, or names an
    attribute that is not numeric -> UserError naming study.toml."""
    raw = (study.settings.get("export") or {}).get("bands") or {}
    where = "study.toml: export.bands"
    if not isinstance(raw, dict):
        raise UserError(f"{where}: must be a table of attribute = [bands]")
    out = []
    for name, spec in raw.items():
        column, labels = f"{name}_band", spec
        if isinstance(spec, dict):
            column, labels = spec.get("column", column), spec.get("bands")
        try:
            a = study.attribute(name)
        except UserError as exc:
            raise UserError(f"{where}.{name}: {exc}") from None
        if a.type not in ("integer", "number"):
            raise UserError(f"{where}.{name}: only a numeric attribute can be banded ({name} is {a.type})")
        if not isinstance(column, str) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", column):
            raise UserError(f"{where}.{name}.column: {column!r} is not a column name")
        if not isinstance(labels, list) or not labels or not all(isinstance(b, str) for b in labels):
            raise UserError(f"{where}.{name}: give the bands as a list of texts like \"16-24\" or \"65+\"")
        bands, prev = [], None
        for k, b in enumerate(labels):
            m = _BAND.match(b)
            if not m or (m.group(3) and k != len(labels) - 1):
                raise UserError(f"{where}.{name}: {b!r} is not a band (\"LOW-HIGH\", the last may be \"LOW+\")")
            lo, hi = float(m.group(1)), None if m.group(3) else float(m.group(2))
            if (hi is not None and hi < lo) or (prev is not None and lo <= prev):
                raise UserError(f"{where}.{name}: bands must be ascending and must not overlap ({b!r})")
            prev = hi
            bands.append((lo, hi, b.strip()))
        out.append(Bands(name, column, tuple(bands)))
    return out


def _check_study(study, problems) -> None:
    """`study check` hook: the [export] bands must be usable."""
    try:
        declared_bands(study)
    except UserError as exc:
        problems.add("study.toml", None, "export.bands", str(exc).split(": ", 2)[-1])


register_file_check(_check_study)


def _study_of(st):
    """The store's study, or None for a store without one (its tables are still exported)."""
    from study.store.studies import definition

    try:
        return definition(st)
    except UserError:
        return None


def participants_frame(st, study) -> pd.DataFrame:
    """The participants table with one typed column per declared attribute after participant_id."""
    from study.people.participants import participant_attributes

    base = st.df("SELECT * FROM participants ORDER BY participant_id")
    if study is None:
        return base
    attrs = participant_attributes(st)
    return attrs.merge(base, on="participant_id", how="left")[list(attrs.columns) + list(base.columns[1:])]


def _columns(st, table: str) -> list[tuple[str, str]]:
    """(name, DuckDB type) of each column of `table`, in order."""
    return [(r[0], r[1]) for r in st.con.execute(
        "SELECT column_name, data_type FROM duckdb_columns() WHERE table_name = ? AND schema_name = 'main' "
        "ORDER BY column_index", [table]).fetchall()]


def _is_time(sql_type: str) -> bool:
    return sql_type.startswith("TIMESTAMP")


def origins_sql(st, tables) -> str:
    """SELECT participant_id, origin: each participant's first recorded event, the earliest timestamp of any of their
    rows in `tables` (the origin of the relative times of a deidentified export)."""
    parts = []
    for t in tables:
        cols = _columns(st, t)
        if any(c == "participant_id" for c, _ in cols):
            parts += [f'SELECT participant_id, "{c}" AS event_at FROM "{t}"' for c, typ in cols if _is_time(typ)]
    if not parts:
        return "SELECT NULL::VARCHAR AS participant_id, NULL::TIMESTAMP AS origin WHERE false"
    return ("SELECT participant_id, min(event_at) AS origin FROM (" + " UNION ALL ".join(parts) + ") "
            "WHERE participant_id IS NOT NULL AND event_at IS NOT NULL GROUP BY participant_id")


def first_events(st, tables) -> pd.Series:
    """participant_id -> the first recorded event (:func:`origins_sql`), for the tables built in Python."""
    return st.df(origins_sql(st, tables)).set_index("participant_id")["origin"]


def _seconds_after(col: str) -> str:
    """SQL of the seconds from the row's participant's origin (``o.origin``) to ``t.<col>``, the same double as
    pandas' ``(t - origin).dt.total_seconds()``: whole seconds plus the microsecond residual / 1e6. The difference is
    never negative (the origin is the earliest of these times), so integer division and remainder are floor ones."""
    d = f'(epoch_us(t."{col}") - epoch_us(o.origin))'
    return f"(CAST({d} // 1000000 AS DOUBLE) + CAST({d} % 1000000 AS DOUBLE) / 1e6)"


def samples_in_order(st) -> bool:
    """True when ``drive_samples`` is stored in (drive_id, idx) order, so that scanning it is that order: each drive's
    rows are one run of row ids in sample order (idx = row id - the drive's first row id) and the runs follow each
    other by drive_id. Imports and simulations store a drive in one append, so this holds unless two drives were
    logged live at the same time; then the export sorts."""
    return st.one("""
        WITH r AS (SELECT drive_id, min(rowid) AS lo, max(rowid) AS hi, count(*) AS n FROM drive_samples
                   GROUP BY drive_id)
        SELECT (SELECT count(*) FROM drive_samples s JOIN r USING (drive_id) WHERE s.idx <> s.rowid - r.lo)
             + (SELECT count(*) FROM r WHERE hi - lo + 1 <> n)
             + (SELECT count(*) FROM (SELECT hi, lead(lo) OVER (ORDER BY drive_id) AS next_lo FROM r)
                WHERE next_lo <= hi) = 0""")


def hidden_columns(st, study) -> dict[str, set[str]]:
    """Columns of the store that an export leaves out because they carry nothing for this store, so that a study
    keeps the files it had before they existed: the ``occasion`` of the survey tables when the study has one
    questionnaire occasion (:func:`study.folder.occasions.several`), ``drives.phase`` when no drive outside the conditions
    is stored (docs/store.md, "Exports")."""
    from study.folder.occasions import OCCASION_TABLES, several

    hide: dict[str, set[str]] = {}
    if study is None or not several(study):
        for t in OCCASION_TABLES:
            hide[t] = {"occasion"}
    if not st.one("SELECT count(*) FROM drives WHERE phase IS NOT NULL"):
        hide["drives"] = {"phase"}
    return hide


def table_sql(st, table: str, deidentify: bool = False, origins: str | None = None,
              hide: set[str] | frozenset = frozenset()) -> str:
    """The SELECT that exports `table`: every column as stored (``drive_samples`` ordered by drive and sample: the
    stored order when :func:`samples_in_order`, else sorted); deidentified (:data:`IDENTIFYING_COLUMNS` left out,
    each timestamp ``<col>`` of a participant's row as ``<col>_s`` seconds after the participant's first event from
    `origins` (:func:`origins_sql`), other timestamps left out) in the table's row order; the columns `hide`
    (:func:`hidden_columns`) left out."""
    order = ""
    if table == "drive_samples" and not samples_in_order(st):  # a sort of millions of rows: only when needed
        order = ' ORDER BY t."drive_id", t."idx"'
    if not deidentify:
        if hide:
            shown = ", ".join(f't."{c}"' for c, _ in _columns(st, table) if c not in hide)
            return f'SELECT {shown} FROM "{table}" t{order}'
        return f'SELECT * FROM "{table}" t{order}'
    cols = [(c, typ) for c, typ in _columns(st, table) if c not in hide]
    per_person = any(c == "participant_id" for c, _ in cols)
    select, relative = [], False
    for c, typ in cols:
        if c in IDENTIFYING_COLUMNS:
            continue
        if _is_time(typ):
            if per_person and origins is not None:
                select.append(f'{_seconds_after(c)} AS "{c}{RELATIVE}"')
                relative = True
            continue
        select.append(f't."{c}"')
    source = f'"{table}" t'
    if relative:  # the join must not reorder the rows: they keep the table's order (its rowid)
        source += f" LEFT JOIN ({origins}) o ON o.participant_id = t.participant_id"
        order = order or (" ORDER BY t.rowid" if table != "drive_samples" else "")
    return f"SELECT {', '.join(select) or 'NULL AS _empty'} FROM {source}{order}"


def relative_times(df: pd.DataFrame, origins: pd.Series | None) -> pd.DataFrame:
    """Each timestamp column ``<col>`` replaced in place by ``<col>_s``: seconds after the row's participant's first
    event (`origins`, :func:`first_events`); without a participant_id column or origins the timestamps are
    dropped."""
    df = df.copy()
    for col in [c for c in df.columns if pd.api.types.is_datetime64_any_dtype(df[c])]:
        if "participant_id" in df.columns and origins is not None:
            origin = pd.to_datetime(df["participant_id"].map(origins))
            df.insert(df.columns.get_loc(col), col + RELATIVE, (df[col] - origin).dt.total_seconds())
        df = df.drop(columns=col)
    return df


def _without_reason(meta):
    """drives.meta without the free-text reason of a forced import (the overridden problems stay)."""
    if not isinstance(meta, str):
        return meta
    m = json.loads(meta)
    if isinstance(m.get("forced"), dict):
        m["forced"] = {k: v for k, v in m["forced"].items() if k != "reason"}
    return json.dumps(m, sort_keys=True)


def deidentify_table(table: str, df: pd.DataFrame, bands: list[Bands] | tuple = (), origins: pd.Series | None = None,
                     text_attributes: tuple[str, ...] = ()) -> pd.DataFrame:
    """The deidentified form of one table (see module docstring); `bands` from :func:`declared_bands`, `origins`
    from :func:`first_events` (None: timestamps are dropped), `text_attributes` the study's free-text attributes."""
    df = df.copy()
    if table == "participants":
        for b in bands:
            if b.attribute in df:
                df.insert(df.columns.get_loc(b.attribute), b.column, b.apply(df[b.attribute]))
                df = df.drop(columns=b.attribute)
        df = df.drop(columns=[c for c in text_attributes if c in df])
    if "meta" in df.columns:
        df["meta"] = df["meta"].map(_without_reason)
    df = relative_times(df, origins)
    return df.drop(columns=[c for c in IDENTIFYING_COLUMNS if c in df.columns])


def survey_wide(st, instrument: str) -> pd.DataFrame:
    """Final answers, one row per participant and one column per item (``study.survey.answers.final_responses``)."""
    from study.survey.answers import final_responses

    return final_responses(st, instrument)


def collect(st, deidentify: bool = False) -> tuple[list[Part], tuple[str, ...]]:
    """The files to export, in order: every table (or the deidentified set) and the wide survey file(s), and the
    tables left out. A table is a SQL part unless it needs Python (``participants`` with its attributes, a table
    with ``meta`` when deidentified); the wide files are frames."""
    study = _study_of(st)
    bands = declared_bands(study) if (deidentify and study is not None) else []
    tables, skipped = [], []
    for table in st.tables():
        (skipped if deidentify and table not in DEIDENTIFIED_TABLES else tables).append(table)
    origins = origins_sql(st, tables) if deidentify else None
    text_attributes = tuple(a.name for a in study.attributes if a.type == "text") if study is not None else ()
    hide = hidden_columns(st, study)
    parts: list[Part] = []
    by_frame = None
    for table in tables:
        framed = table == "participants" or (deidentify and any(c == "meta" for c, _ in _columns(st, table)))
        if not framed:
            parts.append(Part(table, sql=table_sql(st, table, deidentify, origins, hide.get(table, set()))))
            continue
        df = participants_frame(st, study) if table == "participants" else st.df(f'SELECT * FROM "{table}"')
        df = df.drop(columns=[c for c in hide.get(table, ()) if c in df.columns])
        if deidentify:
            if by_frame is None:
                by_frame = first_events(st, tables)
            df = deidentify_table(table, df, bands, by_frame, text_attributes)
        parts.append(Part(table, frame=df))
    instruments = [r[0] for r in st.con.execute("SELECT DISTINCT instrument FROM responses ORDER BY 1").fetchall()]
    if not instruments:
        instruments = [r[0] for r in st.con.execute("SELECT instrument FROM instruments ORDER BY 1").fetchall()]
    for ins in instruments:
        try:
            wide = survey_wide(st, ins)
        except (UserError, ValueError, KeyError):  # a codebook no stored study version declares: the long
            skipped.append(f"{WIDE}{ins}")         # responses table is still exported
            continue
        if deidentify:  # attribute items repeat the participants' exact attributes: those are in participants;
            from study.survey.answers import (  # free-text answers can carry names
                attribute_items,
                instrument_of,
            )

            spec = instrument_of(st, ins)
            text_items = [i for i, kind in spec.items["response_type"].items() if kind == "text"]
            wide = wide.drop(columns=[c for c in list(attribute_items(spec)) + text_items if c in wide.columns])
        parts.append(Part(f"{WIDE}{ins}", frame=wide))
    scores = score_part(st)
    if scores is not None:
        parts.append(scores)
    return parts, tuple(skipped)


def score_part(st) -> Part | None:
    """The ``scores`` file: every declared score per participant and occasion (:func:`study.survey.scores.score_table`);
    None when the study declares no score. Scores carry no names or exact attributes, so the de-identified export
    keeps them as they are."""
    from study.survey.scores import score_table

    df = score_table(st)
    return Part(SCORES, frame=df) if len(df.columns) > 1 else None


def write_scores(st, outdir: str | Path, formats: tuple[str, ...]) -> dict[Path, int]:
    """Write the ``scores`` file (:func:`score_part`) to `outdir` in each of `formats`; {path: rows}. A study that
    declares no score -> UserError."""
    outdir = Path(outdir)
    for fmt in formats:
        check_choice("format", fmt, FORMATS)
    if outdir.exists() and not outdir.is_dir():
        raise UserError(f"{outdir} exists and is not a directory")
    part = score_part(st)
    if part is None:
        raise UserError("the study declares no score ([[scores]] in study.toml, docs/survey.md \"Scores\")")
    voc = vocabulary(st) if "sav" in formats else None
    outdir.mkdir(parents=True, exist_ok=True)
    written = {}
    for fmt in formats:
        path = outdir / f"{SCORES}.{fmt}"
        tmp = path.with_name(path.name + ".partial")
        written[path] = _write(st, fmt, part, tmp, voc)
        tmp.replace(path)
    return written


# ---------------------------------------------------------------------------------------------- SPSS
def _item_labels(st) -> dict[str, tuple[dict[str, str], dict[str, dict[int, str]]]]:
    """Per instrument: (variable labels = item wording, value labels = every point's or choice's label when the
    codebook gives them, else the two anchors of a scale), looked up per (instrument, item_id) in `items`."""
    from study.folder.instrument import parse_choices

    items = st.df("SELECT instrument, item_id, text, scale_min, scale_max, anchor_low, anchor_high, choices "
                  "FROM items ORDER BY instrument, position")
    out: dict[str, tuple[dict[str, str], dict[str, dict[int, str]]]] = {}
    for r in items.itertuples(index=False):
        var, val = out.setdefault(r.instrument, ({}, {}))
        var[r.item_id] = str(r.text)[:250]
        try:
            labs = parse_choices(r.choices) if isinstance(r.choices, str) else {}
        except ValueError:
            labs = {}
        if not labs and pd.notna(r.scale_min) and pd.notna(r.scale_max):
            if isinstance(r.anchor_low, str) and r.anchor_low:
                labs[int(r.scale_min)] = r.anchor_low
            if isinstance(r.anchor_high, str) and r.anchor_high:
                labs[int(r.scale_max)] = r.anchor_high
        if labs:
            val[r.item_id] = labs
    return out


def vocabulary(st) -> Vocabulary:
    """Labels and codes of the store's study and items for the .sav files (see the module docstring)."""
    from study.survey.answers import attribute_items

    voc = Vocabulary(enums=dict(ENUMS), labels=dict(LABELS), values=dict(NUMERIC_LABELS), items=_item_labels(st))
    study = _study_of(st)
    if study is None:
        return voc
    voc.title = study.study_id
    from study.folder.scores import study_scores

    for spec in study_scores(study):
        voc.labels.setdefault(spec.name, spec.label or spec.name)
    voc.enums["condition"] = study.condition_names
    voc.labels["condition"] = ("Drive condition (" + "; ".join(f"{c.name} = {c.label}" for c in study.conditions)
                               + ")")[:250]
    if study.text("route") is not None:
        from study.folder.route_file import study_route

        voc.enums["segment"] = tuple(dict.fromkeys(study_route(study).segments))
    for a in study.attributes:
        voc.labels[a.name] = a.label or a.name
        if a.type == "choice":
            voc.enums[a.name] = a.choices
    for b in declared_bands(study):
        voc.labels[b.column] = f"{voc.labels.get(b.attribute, b.attribute)} (band)"
        voc.enums[b.column] = tuple(label for _, _, label in b.bands)
    # a numeric attribute filled by a choice item: that item's choices label the numbers
    for ins in study.instruments.values():
        for item, name in attribute_items(ins).items():
            attr = next((a for a in study.attributes if a.name == name), None)
            if attr is not None and attr.type in ("integer", "number") and ins.choices(item):
                voc.values.setdefault(name, ins.choices(item))
    return voc


def to_spss_frame(table: str, df: pd.DataFrame, voc: Vocabulary | None = None, instrument: str | None = None):
    """(frame with SPSS-friendly types, variable labels, value labels, measures) for pyreadstat.write_sav.

    `instrument` names the instrument of a wide survey frame: its items' labels come from that instrument."""
    voc = voc or Vocabulary(enums=dict(ENUMS), labels=dict(LABELS), values=dict(NUMERIC_LABELS))
    item_var, item_val = voc.items.get(instrument, ({}, {})) if instrument else ({}, {})
    out = pd.DataFrame(index=df.index)
    var_labels: dict[str, str] = {}
    val_labels: dict[str, dict] = {}
    measure: dict[str, str] = {}
    enums = {**voc.enums, **TABLE_ENUMS.get(table, {})}
    for col in df.columns:
        s = df[col]
        var_labels[col] = item_var.get(col) or voc.labels.get(col, col)
        if col in enums and col != "participant_id" and not pd.api.types.is_numeric_dtype(s):
            codes = {v: i for i, v in enumerate(enums[col], start=1)}
            unknown = set(s.dropna().unique()) - set(codes)
            if unknown:  # a value the label set does not know: keep the text rather than lose it
                out[col] = s.astype(object).where(s.notna(), "").astype(str)
                continue
            out[col] = s.map(codes).astype("float64")
            val_labels[col] = {float(i): v for v, i in codes.items()}
            measure[col] = "ordinal" if col.endswith("_band") else "nominal"
        elif pd.api.types.is_bool_dtype(s) or (s.dtype == object and s.dropna().map(type).eq(bool).all()
                                                and s.notna().any()):
            out[col] = s.astype("float64")
            val_labels[col] = {0.0: "no", 1.0: "yes"}
            measure[col] = "nominal"
        elif pd.api.types.is_datetime64_any_dtype(s):
            out[col] = s.dt.tz_localize(None) if getattr(s.dt, "tz", None) is not None else s
        elif pd.api.types.is_numeric_dtype(s):
            out[col] = s.astype("float64")
            measure[col] = "scale"
            labels = item_val.get(col) if col in item_var else voc.values.get(col)
            if labels:
                val_labels[col] = {float(k): v for k, v in labels.items()}
                measure[col] = "ordinal"
        else:
            out[col] = s.astype(object).where(s.notna(), "").astype(str)
            measure[col] = "nominal"
    return out, var_labels, val_labels, measure


def _sql_path(path: Path) -> str:
    return str(path).replace("'", "''")


def _write(st, fmt: str, part: Part, path: Path, voc: Vocabulary | None) -> int:
    """Write `part` to `path` as `fmt`; returns its rows. CSV and Parquet of a SQL part stream from the store; CSV
    of a frame goes through the same DuckDB writer, Parquet of a frame through pandas (its pandas metadata keeps
    nullable integer attributes nullable integers); .sav is one pyreadstat call on the whole frame."""
    if fmt == "sav":
        import pyreadstat

        df = part.frame if part.frame is not None else st.df(part.sql)
        instrument = part.name[len(WIDE):] if part.name.startswith(WIDE) else None
        frame, var_labels, val_labels, measure = to_spss_frame(part.name, df, voc, instrument)
        pyreadstat.write_sav(frame, str(path), file_label=f"{voc.title}: {part.name}"[:64], column_labels=var_labels,
                             variable_value_labels=val_labels or None, variable_measure=measure or None)
        return len(df)
    if part.frame is not None and fmt == "parquet":
        part.frame.to_parquet(path, index=False)
        return len(part.frame)
    options = "FORMAT csv, HEADER true" if fmt == "csv" else "FORMAT parquet"
    if part.sql is not None:
        return int(st.con.execute(f"COPY ({part.sql}) TO '{_sql_path(path)}' ({options})").fetchone()[0])
    view = f"_export_{id(part.frame)}"
    st.con.register(view, part.frame)
    try:
        st.con.execute(f'COPY "{view}" TO \'{_sql_path(path)}\' ({options})')
    finally:
        st.con.unregister(view)
    return len(part.frame)


@contextmanager
def _snapshot(st, bounded: bool):
    """Every file of one export from one snapshot of the store (a transaction: a drive stored meanwhile is in all
    files or in none); `bounded`: DuckDB's memory held to :data:`EXPORT_MEMORY` (:mod:`study.common.duck_memory`; a .sav
    export fetches whole tables, which a bound would refuse)."""
    from study.common.duck_memory import bounded as held

    with held(st.con, EXPORT_MEMORY if bounded else None), st.transaction():
        yield


def export(st, fmt: str, outdir: str | Path, deidentify: bool = False) -> ExportResult:
    """Write every table (and the wide survey files) to `outdir` as `fmt` (csv | parquet | sav)."""
    check_choice("export format", fmt, FORMATS)
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise UserError(f"{outdir} exists and is not a directory")
    files: dict[str, int] = {}
    with _snapshot(st, bounded=fmt != "sav"):
        parts, skipped = collect(st, deidentify)
        voc = vocabulary(st) if fmt == "sav" else None
        outdir.mkdir(parents=True, exist_ok=True)
        for part in parts:
            path = outdir / f"{part.name}.{fmt}"
            tmp = path.with_name(path.name + ".partial")
            files[path.name] = _write(st, fmt, part, tmp, voc)
            if fmt == "sav" and deidentify:  # no export date and time in a de-identified file's header
                from study.export.sav_header import clear_timestamp

                clear_timestamp(tmp)
            tmp.replace(path)  # a crash never leaves a half-written file under the final name
    manifest = {"format": fmt, "deidentified": deidentify, "schema_version": st.schema_version,
                "files": files, "left_out": list(skipped)}
    (outdir / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return ExportResult(outdir, files, skipped)

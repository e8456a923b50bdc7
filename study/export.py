"""Export of the store for SPSS, R and Python: every table as CSV, Parquet or SPSS ``.sav``.

Besides the tables, a wide survey file per instrument (``survey_wide_<instrument>``: one row per participant,
one column per item, the final answers) is written, because that is the file an analyst opens in SPSS.
A ``manifest.json`` lists the files, their row counts, the schema version and what was left out.

``.sav`` files carry variable labels (a description per column; the item wording for survey items) and value
labels. Text enumerations (gender, style, scope, condition, ...) are written as numeric codes 1..k with value
labels, as SPSS users expect; booleans as 0/1 with labels no/yes.

``deidentify=True`` keeps only what is needed for analysis under the pseudonymous participant IDs: exact age
becomes ``age_band`` and licence years ``license_band``; free-text notes, people's names (entered_by,
actor, ...) and source file names are dropped; the audit log (which repeats exact values), survey link tokens
and drafts and any table this module does not know are left out (listed in the manifest).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from study.errors import UserError, check_choice

FORMATS = ("csv", "parquet", "sav")

ENUMS: dict[str, tuple[str, ...]] = {
    "gender": ("female", "male", "diverse", "undisclosed"),
    "style": ("cautious", "normal", "sporty"),
    "scope": ("all", "objective", "subjective"),
    "reason": ("motion_sickness", "technical_issue", "incomplete_survey", "withdrawn", "other"),
    "condition": ("baseline", "pedas"),
    "outcome": ("in_progress", "completed", "aborted"),
    "segment": ("urban", "highway"),
    "tl_state": ("green", "yellow", "red"),
    "controller": ("rt", "cf", "none"),
    "action": ("insert", "update", "delete"),
    "age_band": ("16-24", "25-34", "35-44", "45-54", "55-64", "65+"),
    "license_band": ("0-2", "3-5", "6-10", "11-20", "21+"),
}
# `source` means different things in drives and survey_submissions: per table.
TABLE_ENUMS: dict[str, dict[str, tuple[str, ...]]] = {
    "drives": {"source": ("import", "simulation")},
    "survey_submissions": {"source": ("web", "import", "entry")},
}
NUMERIC_LABELS: dict[str, dict[int, str]] = {
    "eco_familiarity": {1: "never heard of eco-driving", 2: "heard of it, never used it",
                        3: "moderately familiar, used a few times", 4: "quite familiar, used occasionally",
                        5: "uses or used a similar system regularly"},
    "hud_arrow": {-1: "slow down", 0: "keep speed", 1: "speed up"},
}
LABELS: dict[str, str] = {
    "participant_id": "Pseudonymous participant ID",
    "age": "Age (years)",
    "age_band": "Age band (years)",
    "gender": "Gender",
    "license_years": "Years holding a driving licence",
    "license_band": "Years holding a driving licence (band)",
    "style": "Self-reported driving style",
    "eco_familiarity": "Familiarity with eco-driving (1-5)",
    "protocol": "Study protocol",
    "created_at": "Recorded at (UTC)",
    "phase": "Protocol phase",
    "seq": "Position of the phase in the protocol",
    "started_at": "Phase start (UTC)",
    "ended_at": "Phase end (UTC)",
    "outcome": "Phase outcome",
    "note": "Note",
    "scope": "Exclusion scope",
    "reason": "Exclusion reason",
    "drive_id": "Drive ID",
    "condition": "Drive condition (baseline = no assistance, pedas = with pEDAS)",
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
                       "created_by", "email", "phone", "name")
AGE_BANDS = ((16, 24), (25, 34), (35, 44), (45, 54), (55, 64), (65, 200))
LICENSE_BANDS = ((0, 2), (3, 5), (6, 10), (11, 20), (21, 200))


@dataclass(frozen=True)
class ExportResult:
    outdir: Path
    files: dict[str, int]          # file name -> rows
    skipped: tuple[str, ...]       # tables left out


def _band(values: pd.Series, bands, labels: tuple[str, ...]) -> pd.Series:
    out = pd.Series([None] * len(values), index=values.index, dtype=object)
    for (lo, hi), lab in zip(bands, labels):
        out[(values >= lo) & (values <= hi)] = lab
    return out


def deidentify_table(table: str, df: pd.DataFrame) -> pd.DataFrame:
    """The deidentified form of one table (see module docstring)."""
    df = df.copy()
    if table == "participants":
        if "age" in df:
            df.insert(df.columns.get_loc("age"), "age_band", _band(df["age"], AGE_BANDS, ENUMS["age_band"]))
            df = df.drop(columns="age")
        if "license_years" in df:
            df.insert(df.columns.get_loc("license_years"), "license_band",
                      _band(df["license_years"], LICENSE_BANDS, ENUMS["license_band"]))
            df = df.drop(columns="license_years")
        df = df.drop(columns=[c for c in ("created_at",) if c in df])
    return df.drop(columns=[c for c in IDENTIFYING_COLUMNS if c in df.columns])


def survey_wide(st, instrument: str) -> pd.DataFrame:
    """Final answers, one row per participant and one column per item (``study.survey.final_responses``)."""
    from study.survey import final_responses

    return final_responses(st, instrument)


def collect(st, deidentify: bool = False) -> tuple[dict[str, pd.DataFrame], tuple[str, ...]]:
    """Frames to export: every table (or the deidentified set) and the wide survey file(s)."""
    frames: dict[str, pd.DataFrame] = {}
    skipped = []
    for table in st.tables():
        if deidentify and table not in DEIDENTIFIED_TABLES:
            skipped.append(table)
            continue
        order = " ORDER BY drive_id, idx" if table == "drive_samples" else ""
        df = st.df(f'SELECT * FROM "{table}"{order}')
        frames[table] = deidentify_table(table, df) if deidentify else df
    instruments = [r[0] for r in st.con.execute("SELECT DISTINCT instrument FROM responses ORDER BY 1").fetchall()]
    if not instruments:
        instruments = [r[0] for r in st.con.execute("SELECT instrument FROM instruments ORDER BY 1").fetchall()]
    for ins in instruments:
        try:
            frames[f"survey_wide_{ins}"] = survey_wide(st, ins)
        except (ValueError, KeyError):  # a codebook no longer shipped: the long table is still exported
            skipped.append(f"survey_wide_{ins}")
    return frames, tuple(skipped)


# ---------------------------------------------------------------------------------------------- SPSS
def _item_labels(st) -> tuple[dict[str, str], dict[str, dict[int, str]]]:
    """Variable labels (item wording) and value labels (scale anchors) of the survey items."""
    items = st.df("SELECT item_id, text, scale_min, scale_max, anchor_low, anchor_high FROM items")
    var, val = {}, {}
    for r in items.itertuples(index=False):
        var[r.item_id] = str(r.text)[:250]
        if pd.notna(r.scale_min) and pd.notna(r.scale_max):
            labs = {}
            if isinstance(r.anchor_low, str) and r.anchor_low:
                labs[int(r.scale_min)] = r.anchor_low
            if isinstance(r.anchor_high, str) and r.anchor_high:
                labs[int(r.scale_max)] = r.anchor_high
            if labs:
                val[r.item_id] = labs
    return var, val


def to_spss_frame(table: str, df: pd.DataFrame, item_var: dict[str, str] | None = None,
                  item_val: dict[str, dict[int, str]] | None = None):
    """(frame with SPSS-friendly types, variable labels, value labels, measures) for pyreadstat.write_sav."""
    out = pd.DataFrame(index=df.index)
    var_labels: dict[str, str] = {}
    val_labels: dict[str, dict] = {}
    measure: dict[str, str] = {}
    enums = {**ENUMS, **TABLE_ENUMS.get(table, {})}
    for col in df.columns:
        s = df[col]
        label = (item_var or {}).get(col) if table.startswith("survey_wide") else None
        var_labels[col] = label or LABELS.get(col, col)
        if col in enums and col != "participant_id" and not pd.api.types.is_numeric_dtype(s):
            codes = {v: i for i, v in enumerate(enums[col], start=1)}
            unknown = set(s.dropna().unique()) - set(codes)
            if unknown:  # a value the label set does not know: keep the text rather than lose it
                out[col] = s.astype(object).where(s.notna(), "").astype(str)
                continue
            out[col] = s.map(codes).astype("float64")
            val_labels[col] = {float(i): v for v, i in codes.items()}
            measure[col] = "ordinal" if col in ("age_band", "license_band") else "nominal"
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
            if col in NUMERIC_LABELS:
                val_labels[col] = {float(k): v for k, v in NUMERIC_LABELS[col].items()}
                measure[col] = "ordinal"
            elif item_val and col in item_val and table.startswith("survey_wide"):
                val_labels[col] = {float(k): v for k, v in item_val[col].items()}
                measure[col] = "ordinal"
        else:
            out[col] = s.astype(object).where(s.notna(), "").astype(str)
            measure[col] = "nominal"
    return out, var_labels, val_labels, measure


def _sql_path(path: Path) -> str:
    return str(path).replace("'", "''")


def _write(fmt: str, table: str, df: pd.DataFrame, path: Path, item_var, item_val) -> None:
    if fmt == "csv":
        # DuckDB's CSV writer is ~10x faster than pandas' on million-row drive logs
        import duckdb

        con = duckdb.connect()
        try:
            con.execute("SET TimeZone = 'UTC'")
            con.register("frame", df)
            con.execute(f"COPY frame TO '{_sql_path(path)}' (FORMAT csv, HEADER true)")
        finally:
            con.close()
    elif fmt == "parquet":
        df.to_parquet(path, index=False)
    else:
        import pyreadstat

        frame, var_labels, val_labels, measure = to_spss_frame(table, df, item_var, item_val)
        pyreadstat.write_sav(frame, str(path), file_label=f"pEDAS study: {table}"[:64], column_labels=var_labels,
                             variable_value_labels=val_labels or None, variable_measure=measure or None)


def export(st, fmt: str, outdir: str | Path, deidentify: bool = False) -> ExportResult:
    """Write every table (and the wide survey files) to `outdir` as `fmt` (csv | parquet | sav)."""
    check_choice("export format", fmt, FORMATS)
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise UserError(f"{outdir} exists and is not a directory")
    frames, skipped = collect(st, deidentify)
    item_var, item_val = _item_labels(st) if fmt == "sav" else ({}, {})
    outdir.mkdir(parents=True, exist_ok=True)
    files: dict[str, int] = {}
    for name, df in frames.items():
        path = outdir / f"{name}.{fmt}"
        tmp = path.with_name(path.name + ".partial")
        _write(fmt, name, df, tmp, item_var, item_val)
        tmp.replace(path)  # a crash never leaves a half-written file under the final name
        files[path.name] = int(len(df))
    manifest = {"format": fmt, "deidentified": deidentify, "schema_version": st.schema_version,
                "files": files, "left_out": list(skipped)}
    (outdir / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return ExportResult(outdir, files, skipped)

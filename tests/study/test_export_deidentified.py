"""The deidentified export lists no absolute time and no free text that can carry names: every exported column
of every exported table, read back from CSV, Parquet and .sav (pyreadstat), is checked by dtype and by value."""
from __future__ import annotations

import json
import re
from datetime import date, datetime

import numpy as np
import pandas as pd
import pyreadstat
import pytest

from study.survey import answers as sv
from study.logs.importing import import_drive_frame
from study.export.writer import export
from study.people.participants import add_participant
from study.people.protocol import advance
from study.store.store import Store
from tests.study.test_export import db, small_drive  # noqa: F401  (the fixture: three participants, notes, a drive)
from tests.study.test_survey_web import seeded_answers

DATE = re.compile(r"\d{4}-\d{2}-\d{2}|\d{1,2}:\d{2}:\d{2}|\d{2}\.\d{2}\.\d{4}")
SECRETS = ("John", "john_doe", "ra_mueller", "felt sick", "fine", "my route near Anna's house", "Bob's rig",
           "answer 4: ok", "checked with Carla")
TEN_YEARS_S = 10 * 365.25 * 86400


@pytest.fixture
def full(db):  # noqa: F811
    """The export fixture plus what carries every other timestamp and free text: a web submission with a free-text
    answer, a double entry with a resolution, a counterbalanced order assignment, a forced import with a route."""
    with Store.open(db, actor="ra_mueller") as st:
        add_participant(st, "P004", protocol="counterbalanced_v1")
        advance(st, "P004", first_phase(st, "P004"))
        answers = seeded_answers(4)
        sv.save_draft(st, "P004", answers)
        sv.submit_web(st, "P004")
        items = sv.response_items(sv.instrument_of(st))
        one = {i: "3" for i in items if i not in ("Q1", "Q2", "Q3")}
        sv.save_entry(st, "P003", 1, one)
        sv.save_entry(st, "P003", 2, {**one, "PU1": "4"})
        sv.resolve(st, "P003", "PU1", "4", note="checked with Carla")
        log = small_drive().assign(p_batt=-1e12)
        import_drive_frame(st, "P004", "baseline", log, source="import", route="my route near Anna's house",
                           force="Bob's rig")
    return db


def first_phase(st, pid: str) -> str:
    from study.people.protocol import protocol_of

    return protocol_of(st, pid).phases[0]


def _read(path, fmt: str) -> pd.DataFrame:
    if fmt == "csv":
        return pd.read_csv(path, dtype=str, keep_default_na=False)
    if fmt == "parquet":
        return pd.read_parquet(path)
    return pyreadstat.read_sav(str(path), apply_value_formats=True)[0]


def _absolute_times(df: pd.DataFrame) -> list[str]:
    """Columns holding an absolute time: a datetime dtype, a date/time object, a date-like text, a number beyond
    ten years of seconds (epoch seconds or days)."""
    bad = []
    for col in df.columns:
        s = df[col]
        if pd.api.types.is_datetime64_any_dtype(s) or col.endswith("_at"):
            bad.append(f"{col} ({s.dtype})")
        elif pd.api.types.is_numeric_dtype(s) and not pd.api.types.is_bool_dtype(s):
            if col.endswith("_s") and (s.abs() > TEN_YEARS_S).any():
                bad.append(f"{col} = {s.abs().max()}")
        else:
            values = s.dropna().astype(object)
            if values.map(lambda v: isinstance(v, (datetime, date, pd.Timestamp))).any():
                bad.append(f"{col} (date objects)")
            elif values.astype(str).str.contains(DATE).any():
                bad.append(f"{col} = {values[values.astype(str).str.contains(DATE)].iloc[0]!r}")
    return bad


@pytest.mark.parametrize("fmt", ["csv", "parquet", "sav"])
def test_no_absolute_time_and_no_names_in_any_column(full, tmp_path, fmt):
    out = tmp_path / fmt
    with Store.open(full) as st:
        r = export(st, fmt, out, deidentify=True)
        reg = st.df("SELECT participant_id, created_at FROM participants").set_index("participant_id")["created_at"]
        ph = st.df("SELECT started_at, ended_at FROM phase_events WHERE participant_id = 'P001' AND seq = 2")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["deidentified"] is True and sorted(manifest["files"]) == sorted(r.files)
    listing, found = [], []
    for name in sorted(r.files):
        df = _read(out / name, fmt)
        assert len(df) == r.files[name]
        listing.append(f"{name}: {', '.join(f'{c}[{df[c].dtype}]' for c in df.columns)}")
        found += [f"{name}.{b}" for b in _absolute_times(df)]
        text = df.astype(str).to_csv(index=False)
        found += [f"{name} contains {s!r}" for s in SECRETS if s in text]
    print("\n" + "\n".join(listing))
    assert found == []
    # the relative times are right: seconds after the participant's first event (here the registration)
    events = _read(out / f"phase_events.{fmt}", fmt)
    row = events[(events["participant_id"] == "P001") & (events["seq"].astype(float) == 2)].iloc[0]
    assert float(row["started_at_s"]) == pytest.approx((ph.loc[0, "started_at"] - reg["P001"]).total_seconds(),
                                                       abs=1e-3)
    assert float(row["started_at_s"]) >= 0
    people = _read(out / f"participants.{fmt}", fmt)
    assert (people["created_at_s"].astype(float) == 0).all()      # registration is everyone's first event here
    for table in ("phase_events", "exclusions", "drives", "responses", "survey_submissions", "survey_resolutions",
                  "order_assignments"):
        cols = list(_read(out / f"{table}.{fmt}", fmt).columns)
        assert [c for c in cols if c.endswith("_s") and c[:-2].endswith("_at")], (table, cols)
    drives = _read(out / f"drives.{fmt}", fmt)
    forced = json.loads(drives.loc[drives["participant_id"] == "P004", "meta"].iloc[0])["forced"]
    assert "reason" not in forced and forced["overridden"][0].startswith("column p_batt row 1")
    wide = _read(out / f"survey_wide_pedas_acceptance_v1.{fmt}", fmt)
    assert "Q1" not in wide.columns and "PU1" in wide.columns


def test_the_check_itself_finds_absolute_times():
    """The detector is not blind: a timestamp dtype, an ISO text, a date object and epoch seconds are found."""
    df = pd.DataFrame({"a_at": pd.to_datetime(["2026-05-04 09:30"]), "b": ["2026-05-04T09:30:00"],
                       "c": [date(2026, 5, 4)], "d_s": [1.78e9], "e_s": [3600.0], "f": ["P001"],
                       "g": np.array([1.5])})
    assert [b.split(" ")[0] for b in _absolute_times(df)] == ["a_at", "b", "c", "d_s"]

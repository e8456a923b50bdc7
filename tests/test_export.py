"""Exports: every table as CSV/Parquet/SPSS, labels in the .sav, deidentification."""
import json

import numpy as np
import pandas as pd
import pyreadstat
import pytest

from study.drives import import_drive_frame
from study.exclusions import exclude
from study.export import export
from study.participants import add_participant
from study.protocol import abort, advance
from study.store import Store


def small_drive(n=50):
    t = np.arange(n) * 0.5
    v = np.linspace(5, 20, n)
    return pd.DataFrame({"t": t, "s": np.concatenate([[0], np.cumsum(v[:-1] * 0.5)]), "v": v,
                         "segment": ["urban"] * (n // 2) + ["highway"] * (n - n // 2), "speed_limit": 13.89,
                         "tl_state": "green", "controller": "cf", "hud_arrow": 1, "warning": False})


@pytest.fixture
def db(tmp_db):
    with Store.open(tmp_db, actor="ra_mueller") as st:
        add_participant(st, "P001", age=23, gender="female", license_years=5, style="cautious", eco_familiarity=1)
        add_participant(st, "P002", age=67, gender="male", license_years=45, style="sporty", eco_familiarity=5)
        add_participant(st, "P003", age=35, gender="diverse")
        advance(st, "P001", "familiarisation")
        advance(st, "P001", "baseline_drive")
        advance(st, "P002", "familiarisation")
        advance(st, "P002", "baseline_drive")
        abort(st, "P002", "motion sickness, called John")
        exclude(st, "P002", "all", "motion_sickness", note="felt sick")
        import_drive_frame(st, "P001", "baseline", small_drive(), file_name="john_doe_run1.csv")
        for item, value in (("PU1", 4), ("PU2", 5), ("PEoU3", 2)):
            st.insert("responses", {"participant_id": "P001", "instrument": "pedas_acceptance_v1", "item_id": item,
                                    "entry_round": 1, "value": value, "entered_by": "ra_mueller"})
        st.insert("responses", {"participant_id": "P001", "instrument": "pedas_acceptance_v1", "item_id": "Q1",
                                "entry_round": 1, "text": "fine", "entered_by": "ra_mueller"})
    return tmp_db


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_every_table_exported(db, tmp_path, fmt):
    out = tmp_path / fmt
    with Store.open(db) as st:
        export(st, fmt, out)
        tables = st.tables()
        counts = st.counts()
    for t in tables:
        assert (out / f"{t}.{fmt}").exists()
        back = pd.read_csv(out / f"{t}.csv") if fmt == "csv" else pd.read_parquet(out / f"{t}.parquet")
        assert len(back) == counts[t]
    assert (out / f"survey_wide_pedas_acceptance_v1.{fmt}").exists()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["files"][f"participants.{fmt}"] == 3 and manifest["deidentified"] is False


def test_sav_labels_and_values(db, tmp_path):
    out = tmp_path / "sav"
    with Store.open(db) as st:
        export(st, "sav", out)
        parts = st.df("SELECT * FROM participants ORDER BY participant_id")
        samples = st.df("SELECT * FROM drive_samples ORDER BY idx")
    df, meta = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=False)
    assert meta.column_names_to_labels["eco_familiarity"] == "Familiarity with eco-driving (1-5)"
    assert meta.column_names_to_labels["style"] == "Self-reported driving style"
    assert meta.variable_value_labels["gender"] == {1.0: "female", 2.0: "male", 3.0: "diverse", 4.0: "undisclosed"}
    assert meta.variable_value_labels["eco_familiarity"][1.0] == "never heard of eco-driving"
    assert df["participant_id"].tolist() == parts["participant_id"].tolist()
    assert df["age"].tolist() == parts["age"].astype(float).tolist()
    labelled, _ = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=True)
    assert labelled["gender"].tolist() == parts["gender"].tolist()
    assert labelled["style"].tolist()[:2] == ["cautious", "sporty"]

    ex, meta = pyreadstat.read_sav(out / "exclusions.sav", apply_value_formats=True)
    assert (ex.loc[0, "scope"], ex.loc[0, "reason"]) == ("all", "motion_sickness")

    sm, meta = pyreadstat.read_sav(out / "drive_samples.sav", apply_value_formats=False)
    np.testing.assert_allclose(sm["v"], samples["v"])
    assert meta.variable_value_labels["segment"] == {1.0: "urban", 2.0: "highway"}
    assert meta.variable_value_labels["warning"] == {0.0: "no", 1.0: "yes"}
    assert meta.column_names_to_labels["v"] == "Speed (m/s)"

    wide, meta = pyreadstat.read_sav(out / "survey_wide_pedas_acceptance_v1.sav", apply_value_formats=False)
    assert wide["participant_id"].tolist() == ["P001"]
    assert (wide.loc[0, "PU1"], wide.loc[0, "PU2"], wide.loc[0, "PEoU3"]) == (4.0, 5.0, 2.0)
    assert wide.loc[0, "Q1"] == "fine"
    assert meta.column_names_to_labels["PU2"] == "Using the pEDAS would improve my energy savings"
    assert meta.variable_value_labels["PU1"][5.0] == "Strongly agree"


def test_deidentified(db, tmp_path):
    out = tmp_path / "deid"
    with Store.open(db) as st:
        r = export(st, "sav", out, deidentify=True)
    assert "audit_log" in r.skipped and not (out / "audit_log.sav").exists()
    df, meta = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=True)
    assert "age" not in df.columns and "license_years" not in df.columns
    assert df["age_band"].tolist() == ["16-24", "65+", "35-44"]
    assert df["license_band"].tolist()[:2] == ["3-5", "21+"]
    everything = ""
    for f in out.glob("*.sav"):
        d, _ = pyreadstat.read_sav(f)
        assert not {"note", "entered_by", "actor", "file_name"} & set(d.columns)
        everything += d.astype(str).to_csv()
    for secret in ("John", "john_doe", "ra_mueller", "felt sick"):
        assert secret not in everything


def test_cli_export(cli, db, tmp_path):
    r = cli("export", "csv", tmp_path / "x", "--deidentify")
    assert r.code == 0 and "left out:" in r.out and "audit_log" in r.out
    assert cli("export", "xlsx", tmp_path / "y").code == 2

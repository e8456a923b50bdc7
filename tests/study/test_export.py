"""Exports: every table as CSV/Parquet/SPSS, labels in the .sav, deidentification."""
import json

import numpy as np
import pandas as pd
import pyreadstat
import pytest

from study.logs.importing import import_drive_frame
from study.people.exclusions import exclude
from study.export.writer import export
from study.people.participants import add_participant
from study.people.protocol import abort, advance
from study.store.store import Store
from tests.conftest import LK_STUDY


def small_drive(n=50):
    t = np.arange(n) * 0.5
    v = np.linspace(5, 20, n)
    return pd.DataFrame({"t": t, "s": np.concatenate([[0], np.cumsum(v[:-1] * 0.5)]), "v": v,
                         "segment": ["urban"] * (n // 2) + ["highway"] * (n - n // 2), "speed_limit": 13.89,
                         "tl_state": "green", "controller": "cf", "hud_arrow": 1, "warning": False})


@pytest.fixture
def db(paper_db):
    tmp_db = paper_db
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
                                    "entry_round": 1, "value": value, "entered_by": "ra_mueller", "occasion": "survey"})
        st.insert("responses", {"participant_id": "P001", "instrument": "pedas_acceptance_v1", "item_id": "Q1",
                                "entry_round": 1, "text": "fine", "entered_by": "ra_mueller", "occasion": "survey"})
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
    from study.people.participants import participant_attributes

    out = tmp_path / "sav"
    with Store.open(db) as st:
        export(st, "sav", out)
        parts = participant_attributes(st)
        samples = st.df("SELECT * FROM drive_samples ORDER BY idx")
    df, meta = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=False)
    # labels as studies/pedas_paper/study.toml declares them
    assert meta.column_names_to_labels["eco_familiarity"] == "Familiarity with eco-driving (1-5)"
    assert meta.column_names_to_labels["style"] == "Self-reported driving style"
    assert list(df.columns[:6]) == ["participant_id", "age", "gender", "license_years", "style", "eco_familiarity"]
    assert meta.variable_value_labels["gender"] == {1.0: "female", 2.0: "male", 3.0: "diverse", 4.0: "undisclosed"}
    assert meta.variable_value_labels["style"] == {1.0: "cautious", 2.0: "normal", 3.0: "sporty"}
    # eco_familiarity (integer 1..5) is filled by the choice item ECO_FAM: its choices label the numbers
    assert meta.variable_value_labels["eco_familiarity"][1.0] == "I have never heard of eco-driving before"
    assert df["participant_id"].tolist() == parts["participant_id"].tolist()
    assert df["age"].tolist() == parts["age"].astype(float).tolist()
    assert df["gender"].tolist() == [1.0, 2.0, 3.0]
    labelled, _ = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=True)
    assert labelled["gender"].tolist() == parts["gender"].tolist()
    assert labelled["style"].tolist()[:2] == ["cautious", "sporty"]

    ex, meta = pyreadstat.read_sav(out / "exclusions.sav", apply_value_formats=True)
    assert (ex.loc[0, "scope"], ex.loc[0, "reason"]) == ("all", "motion_sickness")

    sm, meta = pyreadstat.read_sav(out / "drive_samples.sav", apply_value_formats=False)
    np.testing.assert_allclose(sm["v"], samples["v"])
    assert meta.variable_value_labels["segment"] == {1.0: "urban", 2.0: "highway"}   # the study's route order
    assert meta.variable_value_labels["warning"] == {0.0: "no", 1.0: "yes"}
    assert meta.column_names_to_labels["v"] == "Speed (m/s)"
    dr, meta = pyreadstat.read_sav(out / "drives.sav", apply_value_formats=False)
    assert meta.variable_value_labels["condition"] == {1.0: "baseline", 2.0: "pedas"}
    assert meta.column_names_to_labels["condition"].startswith("Drive condition (baseline = Baseline drive")

    wide, meta = pyreadstat.read_sav(out / "survey_wide_pedas_acceptance_v1.sav", apply_value_formats=False)
    assert wide["participant_id"].tolist() == ["P001"]
    assert (wide.loc[0, "PU1"], wide.loc[0, "PU2"], wide.loc[0, "PEoU3"]) == (4.0, 5.0, 2.0)
    assert wide.loc[0, "Q1"] == "fine"
    assert wide.loc[0, "AGE"] == 23 and wide.loc[0, "GENDER"] == 1       # attribute items: the participant's values
    assert meta.column_names_to_labels["PU2"] == "Using the pEDAS would improve my energy savings"
    assert meta.variable_value_labels["PU1"] == {1.0: "Strongly disagree", 5.0: "Strongly agree"}
    assert meta.variable_value_labels["GENDER"][4.0] == "Prefer not to say"
    assert meta.file_label == "pedas_paper: survey_wide_pedas_acceptance_v1"


def test_deidentified(db, tmp_path):
    out = tmp_path / "deid"
    with Store.open(db) as st:
        r = export(st, "sav", out, deidentify=True)
    assert "audit_log" in r.skipped and not (out / "audit_log.sav").exists()
    assert "participant_attributes" in r.skipped
    df, meta = pyreadstat.read_sav(out / "participants.sav", apply_value_formats=True)
    # the bands studies/pedas_paper/study.toml declares under [export.bands]
    assert "age" not in df.columns and "license_years" not in df.columns
    assert df["age_band"].tolist() == ["16-24", "65+", "35-44"]
    assert df["license_band"].tolist()[:2] == ["3-5", "21+"]
    assert meta.column_names_to_labels["age_band"] == "Age (years) (band)"
    wide, _ = pyreadstat.read_sav(out / "survey_wide_pedas_acceptance_v1.sav")
    assert not {"AGE", "LICENSE_YEARS", "GENDER"} & set(wide.columns) and wide.loc[0, "PU1"] == 4
    everything = ""
    for f in out.glob("*.sav"):
        d, _ = pyreadstat.read_sav(f)
        assert not {"note", "entered_by", "actor", "file_name"} & set(d.columns)
        everything += d.astype(str).to_csv()
    for secret in ("John", "john_doe", "ra_mueller", "felt sick"):
        assert secret not in everything


def test_no_bands_declared_no_banding(lk_db, tmp_path):
    """A study without [export.bands] (lane_keeping) exports its attributes as they are, with their labels."""
    with Store.open(lk_db, actor="lab") as st:
        add_participant(st, "LK-01", attributes={"age": 31, "gender": "male", "km_per_year": 12000.5})
        add_participant(st, "LK-02", attributes={"age": 64})
        export(st, "sav", tmp_path / "d", deidentify=True)
    df, meta = pyreadstat.read_sav(tmp_path / "d" / "participants.sav", apply_value_formats=False)
    assert df["age"].tolist() == [31.0, 64.0] and df["km_per_year"].tolist()[0] == 12000.5
    assert meta.column_names_to_labels["km_per_year"] == "Kilometres driven per year"
    assert meta.variable_value_labels["gender"] == {1.0: "female", 2.0: "male", 3.0: "diverse", 4.0: "undisclosed"}
    assert not [c for c in df.columns if c.endswith("_band")]


def test_bad_bands_are_refused(tmp_path):
    import shutil

    from study.folder.definition import check, load
    from study.common.errors import UserError
    from study.export.writer import declared_bands

    folder = tmp_path / "lk"
    shutil.copytree(LK_STUDY, folder)
    toml = folder / "study.toml"
    toml.write_text(toml.read_text() + '\n[export.bands]\ngender = ["1-2"]\n')
    with pytest.raises(UserError, match="only a numeric attribute can be banded"):
        declared_bands(load(folder))
    toml.write_text(toml.read_text().replace('gender = ["1-2"]', 'age = ["30-39", "18-29"]'))
    assert any("ascending" in p.message for p in check(folder))


def _two_versions(tmp_path):
    """A copy of studies/lane_keeping whose [instrument] version is 2 and whose PE2 has another wording."""
    import shutil

    folder = tmp_path / "lk_v2"
    shutil.copytree(LK_STUDY, folder)
    toml = folder / "study.toml"
    toml.write_text(toml.read_text().replace('name = "lk_acceptance"\nversion = 1', 'name = "lk_acceptance"\nversion = 2'))
    book = folder / "codebook.csv"
    assert "Using the display makes my driving safer." in book.read_text()
    book.write_text(book.read_text().replace("Using the display makes my driving safer.",
                                             "With the display I drive more safely.")
                    .replace("PE1,PE,Usefulness,The lane-keeping display helps me keep my lane.,likert7,1,7,"
                             "Strongly disagree,Strongly agree",
                             "PE1,PE,Usefulness,The lane-keeping display helps me keep my lane.,likert7,1,7,"
                             "Not at all,Completely"))
    return folder


def test_two_instrument_versions_keep_their_own_labels(cli, lk_db, tmp_path):
    """Answers to v1 and v2 of an instrument reuse item ids: each wide file carries its version's wording and
    anchors, looked up per (instrument, item_id)."""
    items = ["PE1", "PE2", "PE3", "EE1", "EE2", "EE3", "SI1", "SI2", "SI3", "BI1", "BI2", "BI3"]

    def answers(path, pid, seed):
        path.write_text("participant_id," + ",".join(items) + f"\n{pid}," +
                        ",".join(str(1 + (k + seed) % 7) for k in range(12)) + "\n")
        return path

    assert cli("participant", "add", "LK-01", "--attr", "age=30").code == 0
    assert cli("survey", "import", answers(tmp_path / "a1.csv", "LK-01", 0)).code == 0
    r = cli("init", "--study", _two_versions(tmp_path), "--new-version")
    assert r.code == 0, r.err
    assert cli("participant", "add", "LK-02", "--attr", "age=40").code == 0
    assert cli("survey", "import", answers(tmp_path / "a2.csv", "LK-02", 3)).code == 0
    r = cli("export", "sav", tmp_path / "out")
    assert r.code == 0, r.err
    v1, m1 = pyreadstat.read_sav(tmp_path / "out" / "survey_wide_lk_acceptance_v1.sav", apply_value_formats=False)
    v2, m2 = pyreadstat.read_sav(tmp_path / "out" / "survey_wide_lk_acceptance_v2.sav", apply_value_formats=False)
    assert v1["participant_id"].tolist() == ["LK-01"] and v2["participant_id"].tolist() == ["LK-02"]
    assert v1.loc[0, items].tolist() == [float(1 + k % 7) for k in range(12)]
    assert v2.loc[0, items].tolist() == [float(1 + (k + 3) % 7) for k in range(12)]
    assert m1.column_names_to_labels["PE2"] == "Using the display makes my driving safer."
    assert m2.column_names_to_labels["PE2"] == "With the display I drive more safely."
    assert m1.variable_value_labels["PE1"] == {1.0: "Strongly disagree", 7.0: "Strongly agree"}
    assert m2.variable_value_labels["PE1"] == {1.0: "Not at all", 7.0: "Completely"}
    assert m1.column_names_to_labels["PE3"] == m2.column_names_to_labels["PE3"]
    assert m1.variable_value_labels["EE3"] == m2.variable_value_labels["EE3"]


def test_cli_export(cli, db, tmp_path):
    r = cli("export", "csv", tmp_path / "x", "--deidentify")
    assert r.code == 0 and "left out:" in r.out and "audit_log" in r.out
    assert cli("export", "xlsx", tmp_path / "y").code == 2

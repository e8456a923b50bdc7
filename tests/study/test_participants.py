"""Participants of the store's study: id pattern, declared attributes (typed), checks, protocol, listing, CLI."""
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st_

from study.common.errors import UserError
from study.people.participants import add_participant, list_participants, participant_attributes
from study.store.store import Store

STUDIES = Path(__file__).resolve().parents[2] / "studies"
REPO_ARGS = dict(capture_output=True, text=True, timeout=300)


def test_add_and_list(paper_db):
    with Store.open(paper_db) as st:
        add_participant(st, "P002", age=41, gender="female", license_years=20, style="cautious", eco_familiarity=2)
        add_participant(st, "P001")
        df = list_participants(st)
        stored = st.df("SELECT * FROM participant_attributes WHERE participant_id = 'P002' ORDER BY attribute")
        versions = st.df("SELECT study_version FROM participants")["study_version"].tolist()
    assert df.columns.tolist() == ["participant_id", "age", "gender", "license_years", "style", "eco_familiarity",
                                   "protocol", "order", "phase", "phase_outcome", "excluded", "created_at"]
    assert df["participant_id"].tolist() == ["P001", "P002"]
    p2 = df.set_index("participant_id").loc["P002"]
    assert (p2["age"], p2["gender"], p2["license_years"], p2["style"], p2["eco_familiarity"]) == (
        41, "female", 20, "cautious", 2)
    assert p2["protocol"] == "paper_v1" and p2["excluded"] == ""
    # one text row per given attribute, none for P001 who gave none
    assert stored[["attribute", "value"]].values.tolist() == [
        ["age", "41"], ["eco_familiarity", "2"], ["gender", "female"], ["license_years", "20"], ["style", "cautious"]]
    assert versions == [1, 1]
    assert df.set_index("participant_id").loc["P001", ["age", "style"]].isna().all()


def test_attributes_are_typed_by_the_declaration(lk_db):
    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": "34", "km_per_year": "12000.5", "gender": "diverse"})
        add_participant(st, "LK-02", {"age": 61})
        wide = participant_attributes(st)
        only = participant_attributes(st, ids=["LK-02"])
        listed = list_participants(st)
    assert wide.columns.tolist() == ["participant_id", "age", "gender", "km_per_year"]
    assert str(wide["age"].dtype) == "Int64" and wide["km_per_year"].dtype == float
    assert wide["age"].tolist() == [34, 61] and wide["km_per_year"].iloc[0] == 12000.5
    assert wide["gender"].iloc[0] == "diverse" and pd.isna(wide["gender"].iloc[1])
    assert only["participant_id"].tolist() == ["LK-02"] and only["age"].tolist() == [61]
    assert listed["protocol"].tolist() == ["lk_counterbalanced_v1"] * 2


@pytest.mark.parametrize("kwargs, msg", [
    ({"participant_id": "p001"}, "bad participant id 'p001': study pedas_paper uses ids matching"),
    ({"participant_id": "P01"}, "bad participant id"),
    ({"participant_id": "Anna"}, "bad participant id"),
    ({"participant_id": "P001", "age": 12}, "age must be between 16 and 110, not 12"),
    ({"participant_id": "P001", "age": "thirty"}, "age must be a whole number"),
    ({"participant_id": "P001", "gender": "x"}, "gender must be one of female|male|diverse|undisclosed"),
    ({"participant_id": "P001", "style": "fast"}, "style must be one of"),
    ({"participant_id": "P001", "eco_familiarity": 0}, "eco_familiarity must be between 1 and 5"),
    ({"participant_id": "P001", "age": 20, "license_years": 6},
     r"license years impossible at this age \(licence from 16\) \(age 20, license_years 6\)"),
    ({"participant_id": "P001", "attributes": {"shoe_size": 44}},
     r"unknown participant attribute 'shoe_size' \(study pedas_paper: age, gender, license_years, style, "
     r"eco_familiarity\)"),
    ({"participant_id": "P001", "protocol": "nope"}, "unknown protocol 'nope'"),
])
def test_invalid_values_refused_and_store_unchanged(paper_db, kwargs, msg):
    with Store.open(paper_db) as st:
        before = st.counts()
        with pytest.raises(UserError, match=msg):
            add_participant(st, **kwargs)
        assert st.counts() == before


def test_required_attribute_and_null_passes_a_check(lk_db, paper_db_second):
    with Store.open(lk_db) as st:
        before = st.counts()
        with pytest.raises(UserError, match=r"^age is required \(study lane_keeping\)$"):
            add_participant(st, "LK-01", {"gender": "male"})
        with pytest.raises(UserError, match="age is required"):
            add_participant(st, "LK-01", {"age": "  "})
        assert st.counts() == before
    with Store.open(paper_db_second) as st:
        # the licence check needs age; without it the expression is NULL, which passes (as a SQL CHECK)
        add_participant(st, "P001", license_years=50)
        assert participant_attributes(st)["license_years"].tolist() == [50]


@pytest.fixture
def paper_db_second(tmp_path):
    from pedas_study.cli import main

    db = tmp_path / "second.duckdb"
    assert main([f"--db={db}", "init", "--study", str(STUDIES / "pedas_paper")]) == 0
    return db


def test_duplicate_refused(paper_db):
    with Store.open(paper_db) as st:
        add_participant(st, "P001", age=30)
        before = st.counts()
        with pytest.raises(UserError, match="already exists"):
            add_participant(st, "P001", age=50)
        assert st.counts() == before
        assert participant_attributes(st)["age"].tolist() == [30]


def test_a_check_that_fails_to_evaluate_is_a_user_error(tmp_path):
    """A check that type-checks on an empty table can still fail on a value (a cast): one line, nothing stored."""
    from pedas_study.cli import main

    folder = tmp_path / "lk"
    shutil.copytree(STUDIES / "lane_keeping", folder)
    toml = folder / "study.toml"
    toml.write_text(toml.read_text() + '\n[[checks]]\nsql = "CAST(gender AS INTEGER) > 0"\nmessage = "never"\n')
    db = tmp_path / "s.duckdb"
    assert main([f"--db={db}", "init", "--study", str(folder)]) == 0
    with Store.open(db) as st:
        before = st.counts()
        with pytest.raises(UserError, match="check 'CAST.*failed"):
            add_participant(st, "LK-01", {"age": 30, "gender": "male"})
        assert st.counts() == before
        add_participant(st, "LK-01", {"age": 30})  # gender NULL -> the check is NULL -> passes


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st_.from_regex(r"(LK)?-?[0-9A-Za-z\u0660-\u0669\n ]{0,3}", fullmatch=True))
def test_ids_follow_the_study_pattern(lk_study, s):
    """The lane-keeping study accepts exactly LK- and two ASCII digits (no other digits, no trailing newline)."""
    expected = len(s) == 5 and s[:3] == "LK-" and all(c in "0123456789" for c in s[3:])
    try:
        lk_study.validate_id(s)
        accepted = True
    except UserError:
        accepted = False
    assert accepted == expected


@pytest.fixture(scope="module")
def lk_study():
    from study.folder.definition import load

    return load(STUDIES / "lane_keeping")


def test_cli_add_list_formats(cli, paper_db):
    assert cli("participant", "add", "P001", "--age", "30", "--gender", "male", "--style", "sporty",
               "--license-years", "12", "--eco-familiarity", "4").code == 0
    r = cli("participant", "add", "P002", "--attr", "age=44", "--attr", "style=normal", "--protocol",
            "counterbalanced_v1")
    assert r.code == 0 and "counterbalanced_v1" in r.out, r.err
    r = cli("participant", "list", "--format", "json")
    rows = json.loads(r.out)
    assert [x["participant_id"] for x in rows] == ["P001", "P002"]
    assert (rows[0]["style"], rows[0]["age"], rows[1]["age"], rows[1]["protocol"]) == (
        "sporty", 30, 44, "counterbalanced_v1")
    r = cli("participant", "list", "--format", "csv")
    assert r.out.splitlines()[0] == ("participant_id,age,gender,license_years,style,eco_familiarity,protocol,order,"
                                     "phase,phase_outcome,excluded,created_at")
    assert len(r.out.splitlines()) == 3
    r = cli("participant", "list")
    assert "P001" in r.out and "sporty" in r.out


@pytest.mark.parametrize("args, msg", [
    (("--attr", "age"), "--attr 'age': use NAME=VALUE"),
    (("--attr", "age=30", "--age", "31"), "attribute age given twice"),
    (("--attr", "age=30", "--attr", "age=31"), "attribute age given twice"),
    (("--attr", "shoe=44",), "unknown participant attribute 'shoe'"),
    (("--protocol", "no_such_protocol"), "unknown protocol 'no_such_protocol'"),
    (("--eco-familiarity", "9"), "eco_familiarity must be between 1 and 5"),
])
def test_cli_add_refusals_are_one_line(cli, paper_db, args, msg):
    with Store.open(paper_db) as st:
        before = st.counts()
    r = cli("participant", "add", "P001", *args)
    assert r.code == 2 and msg in r.err and len(r.err.strip().splitlines()) == 1, r.err
    with Store.open(paper_db) as st:
        assert st.counts() == before


def test_cli_aliases_need_the_attribute_in_the_study(cli, lk_db):
    r = cli("participant", "add", "LK-01", "--age", "30", "--style", "sporty")
    assert r.code == 2 and "--style: study lane_keeping has no attribute style" in r.err
    r = cli("participant", "add", "LK-01", "--age", "30", "--attr", "km_per_year=8000")
    assert r.code == 0, r.err
    rows = json.loads(cli("participant", "list", "--format", "json").out)
    assert (rows[0]["age"], rows[0]["km_per_year"]) == (30, 8000.0)


def test_cli_needs_init(cli):
    r = cli("participant", "add", "P001")
    assert r.code == 2 and "pedas-study init --study DIR" in r.err and len(r.err.strip().splitlines()) == 1


def test_list_into_a_closed_pipe_is_quiet(paper_db):
    """`participant list | head -1`: no 'Broken pipe' message, exit 0 (checked with pipefail)."""
    n = 2000  # output well beyond a pipe's buffer, so the writer meets the closed pipe
    with Store.open(paper_db) as st:
        st.insert_df("participants", pd.DataFrame({"participant_id": [f"P{i:04d}" for i in range(1, n + 1)],
                                                   "protocol": "paper_v1", "study_version": 1}))
    cmd = f"set -o pipefail; '{sys.executable}' -m pedas_study.cli --db='{paper_db}' participant list | head -1"
    p = subprocess.run(["bash", "-c", cmd], **REPO_ARGS)
    assert p.stdout.split() == ["participant_id", "age", "gender", "license_years", "style", "eco_familiarity",
                                "protocol", "order", "phase", "phase_outcome", "excluded", "created_at"]
    assert p.stderr == "" and p.returncode == 0, p.stderr
    assert not re.search(r"(?i)broken pipe|errno 32", p.stderr)

"""Participants: ID pattern, demographics validation, listing."""
import json

import duckdb
import pytest
from hypothesis import given, settings, strategies as st_

from study.errors import UserError
from study.participants import ID_PATTERN, add_participant, list_participants
from study.store import Store


def test_add_and_list(tmp_db):
    with Store.open(tmp_db) as st:
        add_participant(st, "P002", age=41, gender="female", license_years=20, style="cautious", eco_familiarity=2)
        add_participant(st, "P001")
        df = list_participants(st)
    assert df["participant_id"].tolist() == ["P001", "P002"]
    p2 = df.set_index("participant_id").loc["P002"]
    assert (p2["age"], p2["gender"], p2["license_years"], p2["style"], p2["eco_familiarity"]) == (
        41, "female", 20, "cautious", 2)
    assert p2["protocol"] == "paper_v1" and p2["excluded"] == ""


@pytest.mark.parametrize("kwargs, msg", [
    ({"participant_id": "p001"}, "bad participant id"),
    ({"participant_id": "P01"}, "bad participant id"),
    ({"participant_id": "Anna"}, "bad participant id"),
    ({"participant_id": "P001", "age": 12}, "age must be between"),
    ({"participant_id": "P001", "gender": "x"}, "gender must be one of"),
    ({"participant_id": "P001", "style": "fast"}, "style must be one of"),
    ({"participant_id": "P001", "eco_familiarity": 0}, "eco familiarity must be between 1 and 5"),
    ({"participant_id": "P001", "age": 20, "license_years": 6}, "impossible at age 20"),
    ({"participant_id": "P001", "protocol": "nope"}, "unknown protocol"),
])
def test_invalid_values_refused(tmp_db, kwargs, msg):
    with Store.open(tmp_db) as st:
        with pytest.raises(UserError, match=msg):
            add_participant(st, **kwargs)
        assert st.counts()["participants"] == 0 and st.counts()["audit_log"] == 0


def test_duplicate_refused(tmp_db):
    with Store.open(tmp_db) as st:
        add_participant(st, "P001", age=30)
        with pytest.raises(UserError, match="already exists"):
            add_participant(st, "P001", age=50)
        assert st.one("SELECT age FROM participants") == 30


_CON = duckdb.connect()


@settings(max_examples=60, deadline=None)
@given(st_.from_regex(r"P?[0-9A-Za-z\u0660-\u0669\n]{0,6}", fullmatch=True))
def test_python_and_schema_agree_on_ids(s):
    """The Python pattern and the schema's CHECK accept exactly the same IDs."""
    ok_schema = _CON.execute("SELECT regexp_full_match(?, '^P[0-9]{3,}$')", [s]).fetchone()[0]
    assert bool(ID_PATTERN.fullmatch(s)) == ok_schema


def test_cli_add_list_formats(cli):
    assert cli("init").code == 0
    assert cli("participant", "add", "P001", "--age", "30", "--gender", "male", "--style", "sporty",
               "--license-years", "12", "--eco-familiarity", "4").code == 0
    assert cli("participant", "add", "P002").code == 0
    r = cli("participant", "list", "--format", "json")
    rows = json.loads(r.out)
    assert [x["participant_id"] for x in rows] == ["P001", "P002"] and rows[0]["style"] == "sporty"
    r = cli("participant", "list", "--format", "csv")
    assert r.out.splitlines()[0].startswith("participant_id,age,gender")
    assert len(r.out.splitlines()) == 3
    r = cli("participant", "list")
    assert "P001" in r.out and "sporty" in r.out


def test_cli_needs_init(cli):
    r = cli("participant", "add", "P001")
    assert r.code == 2 and "pedas-study init" in r.err and len(r.err.strip().splitlines()) == 1

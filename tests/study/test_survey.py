"""Survey instrument, answers logic (links, drafts, submission, double entry, resolution, final answers) and
`survey import` / the survey CLI, against real DuckDB stores."""
from __future__ import annotations

import csv
import json

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from study.survey import answers as sv
from study.folder.definition import load
from study.common.errors import UserError
from study.folder.instrument import Answer
from study.people.participants import add_participant, participant_attributes
from study.store.store import Store
from study.store.studies import register
from study.survey.survey_import import import_survey
from tests.conftest import PAPER_STUDY

INS = load(PAPER_STUDY).instrument()
SCALED = INS.scaled_items
ATTRIBUTE_ITEMS = ["AGE", "GENDER", "LICENSE_YEARS", "STYLE", "ECO_FAM"]


def make_store(path, pids=("P001", "P002", "P003")) -> Store:
    """A store serving the paper's study with participants `pids` (no attributes recorded)."""
    st = Store.open(path, actor="tester")
    register(st, PAPER_STUDY)
    for p in pids:
        add_participant(st, p)
    return st


@pytest.fixture
def st(tmp_db):
    s = make_store(tmp_db)
    yield s
    s.close()


def full_answers(seed: int = 0) -> dict:
    """A complete, valid answer set whose values depend on `seed` and the item position (hand-checkable)."""
    ans = {item: 1 + (k + seed) % 5 for k, item in enumerate(SCALED)}
    ans.update(AGE=30 + seed % 40, GENDER=1 + seed % 4, LICENSE_YEARS=5 + seed % 10, STYLE=1 + seed % 3,
               ECO_FAM=1 + seed % 5, Q1=f"feedback {seed}", Q3="")
    return ans


def write_csv(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


def csv_rows(answers_by_pid: dict[str, dict]):
    header = ["participant_id"] + SCALED + INS.text_items
    rows = [[pid] + [a.get(i, "") for i in header[1:]] for pid, a in answers_by_pid.items()]
    return header, rows


# ------------------------------------------------------------------------------------------------ codebook
def test_codebook_has_every_appendix_item():
    assert INS.name == "pedas_acceptance_v1" and INS.version == "1"
    assert INS.constructs == {
        "PU": ["PU1", "PU2", "PU3", "PU4"], "PEoU": ["PEoU1", "PEoU2", "PEoU3", "PEoU4"],
        "ATT": [f"ATT{i}" for i in range(1, 10)], "PBC": ["PBC1", "PBC2", "PBC3"], "SN": ["SN1", "SN2", "SN3"],
        "BI": ["BI1", "BI2"]}
    assert INS.reverse_items == ["PEoU3"]
    assert INS.text_items == ["Q1", "Q2", "Q3"]
    pairs = [(INS.items.loc[f"ATT{i}", "anchor_low"], INS.items.loc[f"ATT{i}", "anchor_high"]) for i in range(1, 10)]
    assert pairs == [("Bad", "Good"), ("Useless", "Useful"), ("Undesirable", "Desirable"), ("Ineffective", "Effective"),
                     ("Drowsy", "Alerting"), ("Unpleasant", "Pleasant"), ("Annoying", "Not at all annoying"),
                     ("Irritating", "Likeable"), ("Worthless", "Assisting")]
    likert = INS.items[INS.items["response_type"] == "likert5"]
    assert set(likert["anchor_low"]) == {"Strongly disagree"} and set(likert["anchor_high"]) == {"Strongly agree"}
    assert INS.items.loc["SN3", "reconstructed"] == 1
    assert INS.items.loc[[i for i in SCALED if i != "SN3"], "reconstructed"].eq(0).all()
    assert INS.items.loc["SN2", "text"].endswith("I should use pEDAS") and "should pEDAS" in INS.items.loc["SN2", "source"]


def test_codebook_attribute_items():
    assert sv.attribute_items(INS) == {"AGE": "age", "GENDER": "gender", "LICENSE_YEARS": "license_years",
                                       "STYLE": "style", "ECO_FAM": "eco_familiarity"}
    assert sv.response_items(INS) == SCALED + INS.text_items
    assert list(INS.choices("STYLE").values()) == ["Cautious", "Normal", "Sporty"]
    eco = INS.choices("ECO_FAM")
    assert list(eco) == [1, 2, 3, 4, 5]
    assert "never heard of eco-driving" in eco[1] and "regularly use" in eco[5]
    study = load(PAPER_STUDY)
    # a choice item's code k is the attribute's k-th choice; numbers are taken as they are
    assert sv.attribute_value(INS, "GENDER", Answer(value=4), study.attribute("gender")) == "undisclosed"
    assert sv.attribute_value(INS, "STYLE", Answer(value=1), study.attribute("style")) == "cautious"
    assert sv.attribute_value(INS, "ECO_FAM", Answer(value=3), study.attribute("eco_familiarity")) == 3
    assert sv.attribute_value(INS, "AGE", Answer(), study.attribute("age")) is None
    assert sv.item_answer(INS, "GENDER", study.attribute("gender"), "undisclosed") == 4
    with pytest.raises(UserError, match="AGE: age must be between 16 and 110, not 120"):
        sv.attribute_value(INS, "AGE", Answer(value=120), study.attribute("age"))


def test_parse_answers():
    assert INS.parse("PU1", "4") == Answer(value=4)
    assert INS.parse("PU1", "4.0") == INS.parse("PU1", " 4.00 ") == Answer(value=4)   # spreadsheet whole numbers
    assert INS.parse("PU1", "") == Answer() and INS.parse("PU1", None) == Answer()
    assert INS.parse("GENDER", "male") == Answer(value=2)
    assert INS.parse("Q1", "  ok  ") == Answer(text="ok")
    for bad, msg in (("6", "outside 1-5"), ("0", "outside 1-5"), ("3.5", "not an integer"), ("x", "not an integer")):
        with pytest.raises(ValueError, match=msg):
            INS.parse("PU1", bad)
    with pytest.raises(ValueError, match="unknown item"):
        INS.parse("PU9", "1")


@settings(max_examples=60, deadline=None)
@given(hs.integers(-20, 20))
def test_parse_accepts_exactly_the_scale(v):
    ok = 1 <= v <= 5
    try:
        a = INS.parse("ATT3", str(v))
        assert ok and a.value == v
    except ValueError:
        assert not ok


@settings(max_examples=40, deadline=None)
@given(hs.lists(hs.one_of(hs.none(), hs.integers(1, 5)), min_size=1, max_size=8))
def test_reverse_is_an_involution_and_keeps_missing(values):
    df = pd.DataFrame({"PEoU3": pd.array(values, dtype="Float64"), "PU1": pd.array(values, dtype="Float64")})
    once = INS.reverse(df)
    assert once["PU1"].equals(df["PU1"])                    # only reverse-scored items change
    assert (once["PEoU3"].isna() == df["PEoU3"].isna()).all()
    assert INS.reverse(once)["PEoU3"].equals(df["PEoU3"])
    assert ((once["PEoU3"] + df["PEoU3"]).dropna() == 6).all()  # x -> 1 + 5 - x


# ------------------------------------------------------------------------------------------------ web flow (API level)
def test_link_draft_submit(st):
    token = sv.issue_link(st, "P001")
    assert len(token) == 43 and st.one("SELECT count(*) FROM survey_tokens WHERE token_hash = ?",
                                       [sv.hash_token(token)]) == 1
    assert st.one("SELECT count(*) FROM survey_tokens WHERE token_hash = ?", [token]) == 0  # only the hash
    link = sv.resolve_token(st, token)
    assert link.participant_id == "P001" and not link.submitted
    ans = full_answers(3)
    ans["Q2"] = ""                      # left empty -> stored as missing
    sv.save_draft(st, "P001", {k: ans[k] for k in list(ans)[:10]})
    assert len(sv.draft(st, "P001")) == 10   # resumable
    with pytest.raises(UserError, match="unanswered"):
        sv.submit_web(st, "P001")
    sv.save_draft(st, "P001", ans)
    n = sv.submit_web(st, "P001")
    assert n == len(sv.response_items(INS)) == 28
    got = st.df("SELECT item_id, value, text, entry_round, entered_by, instrument FROM responses "
                "WHERE participant_id = 'P001'").set_index("item_id")
    assert set(got["entry_round"]) == {1} and set(got["entered_by"]) == {"participant"}
    assert set(got["instrument"]) == {"pedas_acceptance_v1"}
    for item in SCALED:
        assert got.loc[item, "value"] == ans[item]
    assert st.one("SELECT count(*) FROM responses WHERE item_id = 'Q2' AND value IS NULL AND text IS NULL") == 1
    assert st.one("SELECT count(*) FROM responses WHERE value = 0 OR text = ''") == 0   # missing, never 0 / ''
    assert got.loc["Q1", "text"] == "feedback 3"
    p = participant_attributes(st, ["P001"]).iloc[0]
    assert (p["age"], p["gender"], p["license_years"], p["style"], p["eco_familiarity"]) == (33, "undisclosed", 8, "cautious", 4)
    assert st.one("SELECT count(*) FROM responses WHERE item_id IN ('AGE', 'GENDER')") == 0   # attributes only
    assert st.one("SELECT count(*) FROM survey_drafts") == 0
    assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'responses' AND actor = 'tester'") == 28
    assert sv.resolve_token(st, token).submitted
    with pytest.raises(UserError, match="submitted"):
        sv.save_draft(st, "P001", {"PU1": 1})
    with pytest.raises(UserError, match="already"):
        sv.submit_web(st, "P001")
    with pytest.raises(UserError, match="already has survey answers"):
        sv.issue_link(st, "P001")
    final = sv.final_responses(st)
    assert final["participant_id"].tolist() == ["P001"]
    assert final.loc[0, SCALED].tolist() == [float(ans[i]) for i in SCALED]


def test_tokens_are_per_participant_and_revocable(st):
    t1, t2 = sv.issue_link(st, "P001"), sv.issue_link(st, "P002")
    assert sv.resolve_token(st, t2).participant_id == "P002"
    t1b = sv.issue_link(st, "P001")
    with pytest.raises(sv.LinkError) as e:
        sv.resolve_token(st, t1)
    assert e.value.status == 403
    assert sv.resolve_token(st, t1b).participant_id == "P001"
    for bad in (t1b[:-1] + ("A" if t1b[-1] != "A" else "B"), "short", "../../etc", t1b + "x"):
        with pytest.raises(sv.LinkError) as e:
            sv.resolve_token(st, bad)
        assert e.value.status == 404
    with pytest.raises(UserError, match="unknown participant P009"):
        sv.issue_link(st, "P009")


def test_license_years_cannot_exceed_age_minus_16(st):
    """The study's [[checks]] apply to the attributes a survey fills; a refusal stores nothing."""
    ans = full_answers(0)
    ans.update(AGE=20, LICENSE_YEARS=6)
    sv.save_draft(st, "P001", ans)
    before = st.counts()
    with pytest.raises(UserError, match=r"license years impossible at this age \(licence from 16\)"):
        sv.submit_web(st, "P001")
    assert st.counts() == before
    assert sv.submission(st, "P001", 1) is None and len(sv.draft(st, "P001")) == len(ans)


def test_survey_answer_replaces_a_recorded_attribute(st):
    """An attribute recorded at registration and answered differently on the form: the participant's answer is
    stored (an audited update), as the form is their own statement."""
    add_participant(st, "P010", attributes={"age": 40, "gender": "female"})
    sv.save_draft(st, "P010", dict(full_answers(0), AGE=41, GENDER=1))
    sv.submit_web(st, "P010")
    p = participant_attributes(st, ["P010"]).iloc[0]
    assert (p["age"], p["gender"], p["style"]) == (41, "female", "cautious")
    audit = st.df("SELECT action, old, new FROM audit_log WHERE table_name = 'participant_attributes' "
                  "AND row_key LIKE '%P010%' AND row_key LIKE '%\"age\"%' ORDER BY \"at\"")
    assert audit["action"].tolist() == ["insert", "update"] and json.loads(audit["new"][1])["value"] == "41"


def test_bad_draft_answer_stores_nothing(st):
    with pytest.raises(UserError, match="outside 1-5"):
        sv.save_draft(st, "P001", {"PU1": 2, "PU2": 7})
    with pytest.raises(UserError, match="unknown item"):
        sv.save_draft(st, "P001", {"PU1": 2, "XYZ": 1})
    assert sv.draft(st, "P001") == {}


# ------------------------------------------------------------------------------------------------ double entry
def test_double_entry_discrepancy_and_resolution(st):
    a = {i: 3 for i in SCALED}
    a["Q1"] = "good"
    sv.save_entry(st, "P002", 1, a)
    assert sv.final_responses(st).empty                       # awaiting the second entry
    assert sv.survey_status(st).set_index("participant_id").loc["P002", "basis"] == "awaiting_second_entry"
    b = dict(a, PU3=4, BI2="")                                # two typing differences
    with sv.acting_as(st, "second typist"):
        sv.save_entry(st, "P002", 2, b)
    d = sv.discrepancies(st)
    assert d[["participant_id", "item_id"]].values.tolist() == [["P002", "PU3"], ["P002", "BI2"]]
    assert d.loc[0, "value_1"] == 3 and d.loc[0, "value_2"] == 4 and pd.isna(d.loc[1, "value_2"])
    assert d.loc[1, "entered_by_2"] == "second typist" and not d["resolved"].any()
    assert sv.final_responses(st).empty                       # unresolved -> not final
    with pytest.raises(UserError, match="no discrepancy"):
        sv.resolve(st, "P002", "PU1", 2)
    with pytest.raises(UserError, match="outside"):
        sv.resolve(st, "P002", "PU3", 8)
    sv.resolve(st, "P002", "PU3", 4, note="form shows 4")
    sv.resolve(st, "P002", "BI2", "")                         # not answered on the form
    f = sv.final_responses(st).set_index("participant_id")
    assert f.loc["P002", "PU3"] == 4 and pd.isna(f.loc["P002", "BI2"]) and f.loc["P002", "PU1"] == 3
    assert f.loc["P002", "Q1"] == "good"
    audit = st.df("SELECT actor, new FROM audit_log WHERE table_name = 'survey_resolutions'")
    assert len(audit) == 2 and json.loads(audit["new"][0])["value"] == 4
    sv.resolve(st, "P002", "PU3", 5)                          # a second look: replaced, audited as update
    assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'survey_resolutions' AND action = 'update'") == 1
    assert sv.final_responses(st).set_index("participant_id").loc["P002", "PU3"] == 5


def test_entry_rules(st):
    with pytest.raises(UserError, match="enter round 1 before round 2"):
        sv.save_entry(st, "P001", 2, {"PU1": 1})
    sv.save_entry(st, "P001", 1, {"PU1": 1})
    with pytest.raises(UserError, match="already has entry round 1"):
        sv.save_entry(st, "P001", 1, {"PU1": 2})
    sv.save_entry(st, "P001", 1, {"PU1": 2}, replace=True)    # correction of the same round
    assert sv.entry_answers(st, "P001", 1)["PU1"] == Answer(value=2)
    assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'responses' AND action = 'update'") == 1
    paper = {k: v for k, v in full_answers(1).items() if k not in ATTRIBUTE_ITEMS}
    sv.save_entry(st, "P003", 1, paper, double_entry=False, source="import")
    with pytest.raises(UserError, match="single import entry"):
        sv.save_entry(st, "P003", 2, paper)
    with pytest.raises(UserError, match="AGE fills the participant attribute age"):
        sv.save_entry(st, "P002", 1, {"AGE": 30})             # a double entry does not fill attributes


@pytest.fixture(scope="module")
def prop_store(tmp_path_factory):
    s = Store.open(tmp_path_factory.mktemp("prop") / "study.duckdb", actor="first")
    register(s, PAPER_STUDY)
    yield s
    s.close()


_pid_counter = iter(range(100, 10**6))
ENTRY_ITEMS = ["PU1", "PEoU3", "ATT5", "Q2"]
answer_st = hs.one_of(hs.none(), hs.integers(1, 5))


@settings(max_examples=12, deadline=None)
@given(e1=hs.lists(answer_st, min_size=3, max_size=3), e2=hs.lists(answer_st, min_size=3, max_size=3),
       fix=hs.lists(hs.booleans(), min_size=3, max_size=3), resolved_to=hs.lists(answer_st, min_size=3, max_size=3))
def test_final_rule_property(prop_store, e1, e2, fix, resolved_to):
    """final = resolution where recorded, else the agreed value; a participant with an open discrepancy is left out."""
    st = prop_store
    pid = f"P{next(_pid_counter)}"
    add_participant(st, pid)
    items = ENTRY_ITEMS[:3]
    sv.save_entry(st, pid, 1, {i: ("" if v is None else v) for i, v in zip(items, e1)})
    with sv.acting_as(st, "second"):
        sv.save_entry(st, pid, 2, {i: ("" if v is None else v) for i, v in zip(items, e2)})
    differ = [a != b for a, b in zip(e1, e2)]
    d = sv.discrepancies(st)
    assert d.loc[d["participant_id"] == pid, "item_id"].tolist() == [i for i, x in zip(items, differ) if x]
    for i, x, f, r in zip(items, differ, fix, resolved_to):
        if x and f:
            sv.resolve(st, pid, i, "" if r is None else r)
    final = sv.final_responses(st).set_index("participant_id")
    if any(x and not f for x, f in zip(differ, fix)):
        assert pid not in final.index
        return
    for i, a, x, r in zip(items, e1, differ, resolved_to):
        want = r if x else a
        got = final.loc[pid, i]
        assert (pd.isna(got) and want is None) or got == want
    assert final.loc[pid, [c for c in SCALED if c not in items]].isna().all()   # not entered -> missing, not 0


# ------------------------------------------------------------------------------------------------ import
def test_import_single_entry_is_final(st, tmp_path):
    data = {"P001": full_answers(0), "P002": full_answers(1)}
    data["P002"]["PU4"] = ""                                   # empty cell = missing
    path = write_csv(tmp_path / "s.csv", *csv_rows(data))
    r = import_survey(st, path)
    assert (r.participants, r.entry_round, r.double_entry) == (2, 1, False)
    f = sv.final_responses(st).set_index("participant_id")
    assert f.loc["P001", SCALED].tolist() == [float(data["P001"][i]) for i in SCALED]
    assert pd.isna(f.loc["P002", "PU4"])
    assert st.one("SELECT count(*) FROM responses WHERE value = 0") == 0
    assert st.one("SELECT count(*) FROM responses WHERE participant_id = 'P002' AND item_id = 'PU4' "
                  "AND value IS NULL") == 1


def test_import_fills_attributes_single_entry_only(st, tmp_path):
    data = {"P001": full_answers(0), "P002": full_answers(1)}
    header, rows = csv_rows(data)
    header += ATTRIBUTE_ITEMS
    for r, pid in zip(rows, data):
        r += [data[pid][i] for i in ATTRIBUTE_ITEMS]
    path = write_csv(tmp_path / "a.csv", header, rows)
    before = st.counts()
    with pytest.raises(UserError, match="AGE, GENDER, LICENSE_YEARS, STYLE, ECO_FAM fill participant attributes"):
        import_survey(st, path, entry=1)
    assert st.counts() == before
    r = import_survey(st, path)
    assert r.answers == 2 * (len(SCALED) + 1)                    # Q1 answered; attribute items are not responses
    attrs = participant_attributes(st, ["P001", "P002"]).set_index("participant_id")
    assert attrs.loc["P001"].tolist() == [30, "female", 5, "cautious", 1]
    assert attrs.loc["P002"].tolist() == [31, "male", 6, "normal", 2]
    final = sv.final_responses(st).set_index("participant_id")
    assert final.loc["P002", ATTRIBUTE_ITEMS].tolist() == [31, 2, 6, 2, 2]


def test_import_double_entry(st, tmp_path):
    one = {"P001": full_answers(0), "P002": full_answers(1)}
    two = {"P001": dict(full_answers(0)), "P002": full_answers(1)}
    two["P001"]["ATT7"] = 1 if one["P001"]["ATT7"] != 1 else 2
    import_survey(st, write_csv(tmp_path / "e1.csv", *csv_rows(one)), entry=1)
    import_survey(st, write_csv(tmp_path / "e2.csv", *csv_rows(two)), entry=2)
    d = sv.discrepancies(st)
    assert d[["participant_id", "item_id"]].values.tolist() == [["P001", "ATT7"]]
    assert sv.final_responses(st)["participant_id"].tolist() == ["P002"]
    sv.resolve(st, "P001", "ATT7", one["P001"]["ATT7"])
    assert sv.final_responses(st)["participant_id"].tolist() == ["P001", "P002"]


BAD_CASES = {
    "out_of_range": (lambda h, r: (h, [r[0][:3] + ["6"] + r[0][4:]] + r[1:]), "line 2, PU3: value 6 outside 1-5"),
    "not_integer": (lambda h, r: (h, [r[0][:1] + ["2.5"] + r[0][2:]] + r[1:]), "PU1: '2.5' is not an integer"),
    "unknown_item": (lambda h, r: (h + ["PU5"], [x + ["3"] for x in r]), "unknown item column(s) PU5"),
    "duplicate_participant": (lambda h, r: (h, r + [r[0]]), "duplicate participant P001 (also on line 2)"),
    "unknown_participant": (lambda h, r: (h, r + [["P077"] + r[0][1:]]), "unknown participant P077"),
    "missing_required_column": (lambda h, r: ([c for c in h if c != "BI2"], [x[:-4] + x[-3:] for x in r]),
                                "required item column(s) missing: BI2"),
    "attribute_out_of_range": (lambda h, r: (h + ["AGE"], [x + ["30"] for x in r[:1]] + [x + ["7"] for x in r[1:]]),
                               "line 3, AGE: value 7 outside 18-99"),
    "attribute_check": (lambda h, r: (h + ["AGE", "LICENSE_YEARS"], [x + ["20", "6"] for x in r]),
                        "license years impossible at this age"),
    "bad_id": (lambda h, r: (h, [["X1"] + r[0][1:]] + r[1:]), "bad participant id 'X1'"),
    "first_column": (lambda h, r: (["pid"] + h[1:], r), "first column must be participant_id"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_import_bad_input_stores_nothing(st, tmp_path, case):
    make, msg = BAD_CASES[case]
    header, rows = csv_rows({"P001": full_answers(0), "P002": full_answers(1)})
    path = write_csv(tmp_path / "bad.csv", *make(header, [list(map(str, r)) for r in rows]))
    before = st.counts()
    with pytest.raises(UserError) as e:
        import_survey(st, path)
    assert msg in str(e.value) and "\n" not in str(e.value)
    assert st.counts() == before


@pytest.mark.parametrize("content,msg", [
    ("participant_id," + ",".join(SCALED) + "\nP001," + ",".join(["1"] * 26) + "\n",
     "line 2: malformed CSV: 27 fields, header has 26"),
    ("participant_id," + ",".join(SCALED) + ',Q1\nP001,' + ",".join(["1"] * 25) + ',"unterminated\n',
     "malformed CSV"),
    ("", "empty file"),
    ("\x00\x01binary", "NUL bytes"),
])
def test_import_malformed_csv(st, tmp_path, content, msg):
    path = tmp_path / "m.csv"
    path.write_text(content)
    before = st.counts()
    with pytest.raises(UserError, match=msg.replace("(", r"\(")):
        import_survey(st, path)
    assert st.counts() == before


def test_import_refuses_existing_answers_atomically(st, tmp_path):
    import_survey(st, write_csv(tmp_path / "a.csv", *csv_rows({"P001": full_answers(0)})))
    before = st.counts()
    path = write_csv(tmp_path / "b.csv", *csv_rows({"P002": full_answers(1), "P001": full_answers(2)}))
    with pytest.raises(UserError, match="line 3: P001 already has answers"):
        import_survey(st, path)
    assert st.counts() == before                             # P002 (line 2, valid) not imported either
    with pytest.raises(UserError, match="no entry round 1 yet"):
        import_survey(st, write_csv(tmp_path / "c.csv", *csv_rows({"P002": full_answers(1)})), entry=2)


# ------------------------------------------------------------------------------------------------ CLI
def test_cli_import_link_discrepancies_resolve(cli, tmp_db, tmp_path):
    make_store(tmp_db).close()
    e1 = write_csv(tmp_path / "e1.csv", *csv_rows({"P001": full_answers(0)}))
    bad = dict(full_answers(0), SN1=5 if full_answers(0)["SN1"] != 5 else 4)
    e2 = write_csv(tmp_path / "e2.csv", *csv_rows({"P001": bad}))
    r = cli("survey", "import", e1, "--entry", "1")
    assert r.code == 0 and "imported 1 participants" in r.out and "entry round 1" in r.out
    assert cli("survey", "import", e2, "--entry", "2").code == 0
    r = cli("survey", "discrepancies", "--format", "csv")
    assert r.code == 0 and "P001,SN1," in r.out
    r = cli("survey", "resolve", "P001", "SN1", "9")
    assert r.code == 2 and r.err.startswith("pedas-study: error: SN1: value 9 outside 1-5") and r.err.count("\n") == 1
    r = cli("survey", "resolve", "P001", "SN1", str(full_answers(0)["SN1"]), "--note", "checked form")
    assert r.code == 0, r.err
    out = tmp_path / "final.csv"
    assert cli("survey", "final", "--out", out).code == 0
    final = pd.read_csv(out)
    assert list(final.columns) == ["participant_id"] + ATTRIBUTE_ITEMS + SCALED + ["Q1", "Q2", "Q3"]
    assert final.loc[0, "SN1"] == full_answers(0)["SN1"]
    r = cli("survey", "link", "P002", "--base-url", "http://127.0.0.1:9000/")
    assert r.code == 0 and r.out.startswith("http://127.0.0.1:9000/s/") and len(r.out.strip().rsplit("/", 1)[1]) == 43
    r = cli("survey", "status", "--format", "json")
    rows = {x["participant_id"]: x for x in json.loads(r.out)}
    assert rows["P001"]["final"] and rows["P001"]["basis"] == "double_entry_final" and rows["P002"]["link"] == "issued"


def test_cli_import_error_is_one_line_and_changes_nothing(cli, tmp_db, tmp_path):
    make_store(tmp_db).close()
    header, rows = csv_rows({"P001": full_answers(0)})
    rows[0][5] = "17"
    path = write_csv(tmp_path / "x.csv", header, rows)
    with Store.open(tmp_db, read_only=True) as s:
        before = s.counts()
    r = cli("survey", "import", path)
    assert r.code == 2 and r.err.count("\n") == 1 and "outside 1-5" in r.err and "nothing imported" in r.err
    with Store.open(tmp_db, read_only=True) as s:
        assert s.counts() == before
    r = cli("survey", "import", tmp_path / "nope.csv")
    assert r.code == 2 and "not found" in r.err


def test_cli_import_then_final_round_trips(cli, tmp_db, tmp_path):
    make_store(tmp_db).close()
    data = {"P001": full_answers(0), "P002": full_answers(4), "P003": full_answers(2)}
    data["P003"]["SN2"] = ""
    header, rows = csv_rows(data)
    header, rows = header[:26], [[str(v) for v in r[:26]] for r in rows]     # scaled items only
    header[1:1] = ["AGE", "GENDER"]                                            # and two attribute items
    for r, (age, gender) in zip(rows, (("30", "1"), ("", "2"), ("71", ""))):
        r[1:1] = [age, gender]
    src = tmp_path / "in.csv"
    src.write_text("\n".join(",".join(r) for r in [header] + rows) + "\n")
    assert cli("survey", "import", src).code == 0
    out = tmp_path / "out.csv"
    assert cli("survey", "final", "--out", out).code == 0
    lines = out.read_text().splitlines()
    keep = [k for k, c in enumerate(lines[0].split(",")) if c in header]         # LICENSE_YEARS... stay empty
    assert [",".join(line.split(",")[k] for k in keep) for line in lines] == src.read_text().splitlines()
    assert all(line.split(",")[3:6] == ["", "", ""] for line in lines[1:])

"""The survey side of a study that is not the paper's: studies/lane_keeping (12 items on 7-point scales, EE3
reverse-coded, AGE and GENDER filling participant attributes) through the CLI: CSV import, `survey final`,
double entry on 7 points, and refusals that leave the store unchanged."""
from __future__ import annotations

import csv

import pandas as pd
import pytest

from study.folder.definition import load
from study.store.store import Store
from tests.conftest import LK_STUDY

STUDY = load(LK_STUDY)
INS = STUDY.instrument()
ITEMS = ["PE1", "PE2", "PE3", "EE1", "EE2", "EE3", "SI1", "SI2", "SI3", "BI1", "BI2", "BI3"]


def ticked(seed: int) -> dict[str, int]:
    """Answers as ticked, covering 1..7 (hand-checkable: item k gets 1 + (k + seed) mod 7)."""
    return {item: 1 + (k + seed) % 7 for k, item in enumerate(ITEMS)}


def write_csv(path, header, rows):
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


@pytest.fixture
def lk(cli, lk_db):
    """The lane-keeping store with LK-01..LK-03 registered (age is required by the study)."""
    for pid, age in (("LK-01", 25), ("LK-02", 38), ("LK-03", 61)):
        r = cli("participant", "add", pid, "--attr", f"age={age}")
        assert r.code == 0, r.err
    return lk_db


def counts(db) -> dict[str, int]:
    with Store.open(db, read_only=True) as st:
        return st.counts()


def test_the_instrument_is_the_studys():
    assert INS.name == "lk_acceptance_v1"
    assert INS.scaled_items == ITEMS
    assert {INS.scale(i) for i in ITEMS} == {(1, 7)} and set(INS.items.loc[ITEMS, "response_type"]) == {"likert7"}
    assert INS.reverse_items == ["EE3"]
    df = pd.DataFrame({"EE3": [1.0, 2.0, 7.0], "EE1": [1.0, 2.0, 7.0]})
    assert INS.reverse(df)["EE3"].tolist() == [7.0, 6.0, 1.0] and INS.reverse(df)["EE1"].tolist() == [1.0, 2.0, 7.0]


def test_import_then_final_writes_every_item_and_the_attributes(cli, lk, tmp_path):
    answers = {"LK-01": ticked(0), "LK-02": ticked(3), "LK-03": ticked(6)}
    genders = {"LK-01": "2", "LK-02": "", "LK-03": "4"}     # GENDER fills the attribute gender (4 = undisclosed)
    header = ["participant_id", "GENDER"] + ITEMS + ["REMARKS"]
    rows = [[pid, genders[pid]] + [str(a[i]) for i in ITEMS] + ["clear" if pid == "LK-02" else ""]
            for pid, a in answers.items()]
    r = cli("survey", "import", write_csv(tmp_path / "answers.csv", header, rows))
    assert r.code == 0, r.err
    assert r.out.strip() == ("imported 3 participants (37 answers, 2 missing) as single electronic entry (final)")
    out = tmp_path / "final.csv"
    r = cli("survey", "final", "--out", out)            # --instrument defaults to the study's
    assert r.code == 0 and r.out.strip() == f"wrote 3 participants to {out}"
    final = pd.read_csv(out, dtype=str, keep_default_na=False)
    assert list(final.columns) == ["participant_id", "AGE", "GENDER"] + ITEMS + ["REMARKS"]
    assert final["participant_id"].tolist() == ["LK-01", "LK-02", "LK-03"]
    for _, row in final.iterrows():
        pid = row["participant_id"]
        assert [int(row[i]) for i in ITEMS] == [answers[pid][i] for i in ITEMS]   # EE3 as ticked, not reversed
        assert row["GENDER"] == genders[pid]
    assert final["AGE"].tolist() == ["25", "38", "61"]                            # from the registration
    assert final["REMARKS"].tolist() == ["", "clear", ""]
    r = cli("participant", "list", "--format", "csv")
    listed = pd.read_csv(pd.io.common.StringIO(r.out)).set_index("participant_id")
    assert listed.loc["LK-01", "gender"] == "male" and listed.loc["LK-03", "gender"] == "undisclosed"
    assert pd.isna(listed.loc["LK-02", "gender"])
    same = tmp_path / "same.csv"
    assert cli("survey", "final", "--out", same, "--instrument", "lk_acceptance_v1").code == 0
    assert same.read_text() == out.read_text()


@pytest.mark.parametrize("column,value,message", [
    ("PE2", "8", "answers.csv: line 3, PE2: value 8 outside 1-7 (and 1 more problem); nothing imported"),
    ("EE3", "0", "answers.csv: line 3, EE3: value 0 outside 1-7 (and 1 more problem); nothing imported"),
    ("GENDER", "5", "answers.csv: line 3, GENDER: value 5 outside 1-4 (and 1 more problem); nothing imported"),
])
def test_out_of_range_is_refused_in_one_line_and_changes_nothing(cli, lk, tmp_path, column, value, message):
    header = ["participant_id", "GENDER"] + ITEMS
    rows = [["LK-01", "1"] + [str(v) for v in ticked(0).values()],
            ["LK-02", "2"] + [str(v) for v in ticked(1).values()],
            ["LK-03", "3"] + [str(v) for v in ticked(2).values()]]
    for r in rows[1:]:
        r[header.index(column)] = value                  # lines 3 and 4: two problems
    path = write_csv(tmp_path / "answers.csv", header, rows)
    before = counts(lk)
    r = cli("survey", "import", path)
    assert r.code == 2 and r.err == f"pedas-study: error: {path}{message.removeprefix(path.name)}\n"
    assert counts(lk) == before


def test_attribute_values_are_checked_by_the_study(cli, lk, tmp_path):
    """An attribute item's answer must fit the attribute (age 18..90 in study.toml), even within the item's own
    range; refused in one line, nothing stored."""
    path = write_csv(tmp_path / "a.csv", ["participant_id", "AGE"] + ITEMS,
                     [["LK-01", "95"] + [str(v) for v in ticked(0).values()]])
    before = counts(lk)
    r = cli("survey", "import", path)
    assert r.code == 2 and "AGE: value 95 outside 18-90" in r.err and r.err.count("\n") == 1
    assert counts(lk) == before


def test_double_entry_on_seven_points(cli, lk, tmp_path):
    one = ticked(2)
    two = dict(one, SI2=7 if one["SI2"] != 7 else 6)
    header = ["participant_id"] + ITEMS
    e1 = write_csv(tmp_path / "e1.csv", header, [["LK-02"] + [str(one[i]) for i in ITEMS]])
    e2 = write_csv(tmp_path / "e2.csv", header, [["LK-02"] + [str(two[i]) for i in ITEMS]])
    assert cli("survey", "import", e1, "--entry", "1").code == 0
    assert cli("survey", "import", e2, "--entry", "2").code == 0
    r = cli("survey", "discrepancies", "--format", "csv")
    assert r.code == 0 and r.out.splitlines()[1].startswith(f"LK-02,SI2,{one['SI2']},")
    r = cli("survey", "resolve", "LK-02", "SI2", "8")
    assert r.code == 2 and r.err == "pedas-study: error: SI2: value 8 outside 1-7\n"
    assert cli("survey", "resolve", "LK-02", "SI2", "7").code == 0
    out = tmp_path / "f.csv"
    assert cli("survey", "final", "--out", out).code == 0
    final = pd.read_csv(out).set_index("participant_id")
    assert final.loc["LK-02", "SI2"] == 7 and final.loc["LK-02", "AGE"] == 38
    bad = write_csv(tmp_path / "e3.csv", ["participant_id", "AGE"] + ITEMS,
                    [["LK-03", "61"] + [str(one[i]) for i in ITEMS]])
    r = cli("survey", "import", bad, "--entry", "1")
    assert r.code == 2 and "AGE fill participant attributes" in r.err


def test_unknown_instrument_is_one_line(cli, lk, tmp_path):
    r = cli("survey", "final", "--out", tmp_path / "x.csv", "--instrument", "pedas_acceptance_v1")
    assert r.code == 2 and r.err == ("pedas-study: error: unknown instrument 'pedas_acceptance_v1' "
                                     "(study lane_keeping: lk_acceptance_v1)\n")
    assert not (tmp_path / "x.csv").exists()

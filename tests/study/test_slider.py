"""Slider (visual analogue scale) items: the codebook's checks, and one validation at every entry path (web form,
CSV import, double entry, the analysis' own frame): an answer off the step grid, below min or above max is refused
with one line and nothing is stored."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from pedas_study.cli import main
from pedas_study.cli.study import template_files
from study.survey import answers as sv
from study.folder.instrument import Instrument
from study.people.participants import add_participant
from study.common.problems import Problems
from study.store.store import Store

HEADER = ("item_id,construct,section,text,response_type,scale_min,scale_max,anchor_low,anchor_high,choices,"
          "reverse_scored,required,step\n")
SLIDERS = ("TLX_MD,TLX,Workload,How mentally demanding was the drive?,slider,0,100,Very low,Very high,,0,1,5\n"
           "VAS,TLX,Workload,How tired are you now?,slider,0,100,Not at all,Extremely,,0,0,\n")


def slider_study(folder: Path) -> Path:
    """The `study new` template with two slider items added to its codebook (TLX_MD 0..100 in steps of 5, VAS
    0..100 in steps of 1): the study's default instrument, answered in its `survey` phase."""
    folder.mkdir(parents=True)
    for name, text in template_files("sliders", str(folder)).items():
        if name == "codebook.csv":
            head, *rows = text.splitlines(keepends=True)
            text = head.rstrip("\n") + ",step\n" + "".join(r.rstrip("\n") + ",\n" for r in rows) + \
                SLIDERS.replace(",5\n", ",,5\n").replace(",\n", ",,\n", 1)
        (folder / name).write_text(text, encoding="utf-8")
    return folder


@pytest.fixture
def slider_db(tmp_path):
    db = tmp_path / "s.duckdb"
    assert main([f"--db={db}", "init", "--study", str(slider_study(tmp_path / "sliders"))]) == 0
    st = Store.open(db, actor="lab")
    for pid in ("P001", "P002"):
        add_participant(st, pid, {"age": 30, "gender": "female", "license_years": 5})
    st.close()
    return db


def instrument(rows: str) -> tuple[Instrument | None, list[str]]:
    problems = Problems()
    ins = Instrument.from_csv("t_v1", HEADER + rows, problems=problems)
    return ins, [str(p) for p in problems]


def test_a_slider_is_a_scaled_item_on_a_grid_of_steps():
    ins, problems = instrument(SLIDERS)
    assert problems == [] and ins.scaled_items == ["TLX_MD", "VAS"]
    assert (ins.step("TLX_MD"), ins.step("VAS"), ins.scale("TLX_MD")) == (5, 1, (0, 100))
    assert ins.parse("TLX_MD", "35").value == 35 and ins.parse("TLX_MD", "35.0").value == 35
    assert ins.parse("VAS", 37).value == 37 and ins.parse("TLX_MD", "").missing
    for raw, reason in (("37", "TLX_MD: value 37 is not a step of 5 from 0 (nearest allowed: 35 or 40)"),
                        ("105", "TLX_MD: value 105 outside 0-100"), ("-5", "TLX_MD: value -5 outside 0-100"),
                        ("37.5", "TLX_MD: '37.5' is not an integer")):
        with pytest.raises(ValueError) as exc:
            ins.parse("TLX_MD", raw)
        assert str(exc.value) == reason
    assert ins.reverse(pd.DataFrame({"TLX_MD": [35.0]}))["TLX_MD"].tolist() == [35.0]   # not reverse-scored


@pytest.mark.parametrize("row, message", [
    ("S,T,W,t,slider,0,100,,,,0,1,7\n", "codebook.csv:2: S.step: step 7 does not divide scale_max - scale_min = 100 "
                                         "(the ends 0 and 100 must be answers)"),
    ("S,T,W,t,slider,0,100,,,,0,1,0\n", "codebook.csv:2: S.step: '0' is not a whole number above 0"),
    ("S,T,W,t,slider,0,100,,,,0,1,2.5\n", "codebook.csv:2: S.step: '2.5' is not a whole number above 0"),
    ("S,T,W,t,likert5,1,5,,,,0,1,1\n", "codebook.csv:2: S.step: only a slider has a step (this item is likert5)"),
    ("S,T,W,t,slider,0,5000,,,,0,1,\n", "codebook.csv:2: S.step: 5000 steps; a slider has at most 1000"),
    ("S,T,W,t,slider,0,2,,,0=a|1=b|2=c,0,1,\n",
     "codebook.csv:2: S.choices: a slider has no choices (anchor_low and anchor_high label its ends)"),
    ("S,T,W,t,slider,,,,,,0,1,5\n", "codebook.csv:2: S.scale_min: a slider item needs whole-number scale_min and "
                                    "scale_max"),
    ("S,T,W,t,vas,0,100,,,,0,1,5\n", "codebook.csv:2: S.response_type: 'vas' is not likert[K] | semantic[K] | "
                                     "slider | number | choice | text"),
])
def test_bad_slider_declarations_are_named_with_their_line(row, message):
    assert instrument(row)[1] == [message]


def test_csv_import_refuses_an_answer_off_the_grid_and_stores_nothing(slider_db, tmp_path, capsys):
    st = Store.open(slider_db)
    before = st.counts()
    st.close()
    items = "PU1,PU2,PU3,EOU1,EOU2,EOU3,BI1,BI2,BI3"
    good = "3,3,3,3,3,3,3,3,3"
    bad = tmp_path / "bad.csv"
    bad.write_text(f"participant_id,{items},TLX_MD,VAS\nP001,{good},35,12\nP002,{good},37,12\n")
    capsys.readouterr()
    assert main([f"--db={slider_db}", "survey", "import", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"pedas-study: error: {bad}: line 3, TLX_MD: value 37 is not a step of 5 from 0 "
                   "(nearest allowed: 35 or 40); nothing imported")
    st = Store.open(slider_db)
    assert st.counts() == before
    st.close()
    bad.write_text(bad.read_text().replace("P002,3,3,3,3,3,3,3,3,3,37", "P002,3,3,3,3,3,3,3,3,3,100"))
    assert main([f"--db={slider_db}", "survey", "import", str(bad)]) == 0
    st = Store.open(slider_db)
    final = sv.final_responses(st).set_index("participant_id")
    st.close()
    assert final.loc[["P001", "P002"], "TLX_MD"].tolist() == [35.0, 100.0]
    assert final.loc[["P001", "P002"], "VAS"].tolist() == [12.0, 12.0]


def test_double_entry_refuses_an_answer_off_the_grid(slider_db, tmp_path, capsys):
    items = "PU1,PU2,PU3,EOU1,EOU2,EOU3,BI1,BI2,BI3"
    f = tmp_path / "entry.csv"
    f.write_text(f"participant_id,{items},TLX_MD\nP001,3,3,3,3,3,3,3,3,3,45\n")
    assert main([f"--db={slider_db}", "survey", "import", str(f), "--entry", "1"]) == 0
    f.write_text(f"participant_id,{items},TLX_MD\nP001,3,3,3,3,3,3,3,3,3,44\n")
    capsys.readouterr()
    assert main([f"--db={slider_db}", "survey", "import", str(f), "--entry", "2"]) == 2
    assert "TLX_MD: value 44 is not a step of 5 from 0 (nearest allowed: 40 or 45)" in capsys.readouterr().err
    st = Store.open(slider_db)
    assert st.df("SELECT count(*) AS n FROM responses WHERE entry_round = 2")["n"].item() == 0
    st.close()


def test_web_form_refuses_an_answer_off_the_grid_and_shows_the_slider(slider_db):
    from study.webapp import create_app

    st = Store.open(slider_db, actor="lab")
    try:
        token = sv.issue_link(st, "P001")
        client = create_app(st, "pw for tests").test_client()
        page = client.get(f"/s/{token}").get_data(as_text=True)
        assert 'type="range" id="range-TLX_MD"' in page and 'min="0" max="100" step="5"' in page
        assert 'name="TLX_MD"' in page and 'name="VAS"' in page
        before = st.counts()
        r = client.post(f"/s/{token}/answer", data={"item": "TLX_MD", "value": "37"})
        assert r.status_code == 400
        assert r.json["error"] == "TLX_MD: value 37 is not a step of 5 from 0 (nearest allowed: 35 or 40)"
        r = client.post(f"/s/{token}", data={"TLX_MD": "101", "action": "save"})
        assert r.status_code == 400 and "TLX_MD: value 101 outside 0-100" in r.get_data(as_text=True)
        assert st.counts() == before
        assert client.post(f"/s/{token}/answer", data={"item": "TLX_MD", "value": "40"}).status_code == 200
        assert 'value="40"' in client.get(f"/s/{token}").get_data(as_text=True)
    finally:
        st.close()


def test_the_analysis_frame_refuses_an_answer_off_the_grid(tmp_path):
    from analysis.survey.scoring import score_responses

    ins, _ = instrument(SLIDERS)
    with pytest.raises(ValueError, match=r"^item TLX_MD: answer 37 of P2 is not a step of 5 from 0$"):
        score_responses(pd.DataFrame({"participant_id": ["P1", "P2"], "TLX_MD": [35, 37], "VAS": [1, 2]}), ins)
    ok = score_responses(pd.DataFrame({"participant_id": ["P1", "P2"], "TLX_MD": [35, 40], "VAS": [1, 2]}), ins)
    assert ok.scored["TLX_MD"].tolist() == [35.0, 40.0]

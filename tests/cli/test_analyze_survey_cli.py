"""`analyze_survey` and `pedas-study analyze survey`: outputs per docs/contracts.md, determinism, bad input, the store
path."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from analysis.survey.acceptance import COLUMNS, analyze_survey as _analyze_survey
from analysis.paper.published import paper_study
from analysis.paper.synthetic import simulate_paper_responses as simulate_responses

STUDY = paper_study()
STUDY_DIR = "studies/pedas_paper"


def analyze_survey(data, **kw):
    """The analysis with the paper's study (its codebook, model file and settings)."""
    return _analyze_survey(data, STUDY, **kw)

CONTRACT_FILES = ["descriptives", "loadings", "fit", "reliability", "correlations", "htmt", "regressions", "hypotheses"]


@pytest.fixture(scope="module")
def data():
    return simulate_responses(40, seed=11)


@pytest.fixture(scope="module")
def res(data):
    return analyze_survey(data, n_boot=300, seed=5)


def test_frames_follow_the_contract_columns(res):
    for name in CONTRACT_FILES:
        frame = getattr(res, name)
        assert list(frame.columns[:len(COLUMNS[name])]) == COLUMNS[name], name
    assert set(res.fit["stage"]) == {"initial", "final"}
    assert len(res.descriptives) == 25 and (res.descriptives["n"] == 40).all()
    assert list(res.composites.columns) == ["PU", "PEoU", "ATT", "PBC", "SN", "BI"]
    assert len(res.correlations) == 15 and len(res.htmt) == 15 and len(res.hypotheses) == 7


def test_default_deletion_is_the_papers_final_model(res):
    lo = res.loadings
    fin = set(lo.loc[lo.stage == "final", "item"])
    ini = lo[lo.stage == "initial"]
    assert fin.isdisjoint({"PEoU3", "ATT1", "ATT2", "ATT3", "ATT4", "ATT5"}) and len(fin) == 19
    assert set(ini.loc[~ini.retained, "item"]) == {"PEoU3", "ATT1", "ATT2", "ATT3", "ATT4", "ATT5"}
    assert {"flag_low", "flag_negative", "flag_cross", "rule"} <= set(ini.columns)


def test_composites_and_regressions_are_consistent(res, data):
    from analysis.survey.scoring import score_responses

    s = score_responses(data, STUDY.instrument()).scored
    assert np.allclose(res.composites["ATT"], s[["ATT6", "ATT7", "ATT8", "ATT9"]].mean(axis=1))
    m1 = res.regressions[(res.regressions.model == "1") & (res.regressions.predictor == "PEoU")].iloc[0]
    r = res.correlations.set_index(["a", "b"]).loc[("PU", "PEoU"), "r"]
    assert m1.beta == pytest.approx(r) and m1.r2 == pytest.approx(r ** 2)  # one predictor: beta = r, R^2 = r^2
    h1 = res.hypotheses.set_index("hypothesis").loc["H1"]
    assert h1.beta == pytest.approx(m1.beta) and bool(h1.supported) == bool(m1.beta > 0 and m1.p < 0.05)


def test_reliability_uses_final_items(res):
    from analysis.survey.reliability import cronbach_alpha
    from analysis.survey.scoring import score_responses

    rel = res.reliability.set_index("construct")
    s = score_responses(simulate_responses(40, seed=11), STUDY.instrument()).scored
    assert rel.loc["PEoU", "alpha"] == pytest.approx(cronbach_alpha(s[["PEoU1", "PEoU2", "PEoU4"]])[0])
    assert rel.loc["PEoU", "n_items"] == 3 and rel.loc["ATT", "n_items"] == 4


def test_same_seed_same_output(data, res):
    again = analyze_survey(data, n_boot=300, seed=5)
    for name in CONTRACT_FILES:
        pd.testing.assert_frame_equal(getattr(res, name), getattr(again, name))


def test_a_model_instead_of_the_studys(data):
    """A model in lavaan syntax replaces the study's: no item dropped, one model, a two-sided hypothesis."""
    inst = STUDY.instrument()
    text = "\n".join(f"{c} =~ {' + '.join(items)}" for c, items in inst.constructs.items())
    out = analyze_survey(data, n_boot=0, model=text + "\nBI ~ Hx*PU + PEoU\n")
    assert out.loadings.loc[out.loadings.stage == "final", "item"].size == 25
    assert out.loadings["retained"].all() and out.settings["dropped_items"] == []
    assert list(out.hypotheses["hypothesis"]) == ["Hx"] and out.regressions["boot_ci_low"].isna().all()
    assert out.settings["hypothesis_signs"] == {"Hx": "!="}
    h = out.hypotheses.iloc[0]
    assert bool(h.supported) == bool(h.p < 0.05)  # two-sided: either sign


FULL = "PU =~ PU1 + PU2\nPEoU =~ PEoU1 + PEoU2\nBI =~ BI1 + BI2\n"


@pytest.mark.parametrize("model,match", [
    (FULL + "BI ~ TRUST\n", "'TRUST' is neither a construct"),
    (FULL.replace("PU2", "ATT99") + "BI ~ PU\n", "not scaled items of instrument pedas_acceptance_v1: ATT99"),
    ("PU =~ PU1\nBI =~ BI1 + BI2\nBI ~ PU\n", "construct needs at least 2 items"),
    (FULL + "BI ~ H1*gender\n", "H1: gender is a choice attribute"),
    (FULL + "BI ~ age\n", "pass the participants' attributes"),
])
def test_bad_models(data, model, match):
    with pytest.raises(ValueError, match=match):
        analyze_survey(data, n_boot=0, model=model)


def test_constant_column_is_refused(data):
    with pytest.raises(ValueError, match="item SN2 is constant"):
        analyze_survey(data.assign(SN2=4), n_boot=0)


def test_too_few_rows_is_refused(data):
    with pytest.raises(ValueError):
        analyze_survey(data.head(3), n_boot=0)


def test_cli_writes_the_design_files(cli, data, tmp_path):
    csv = tmp_path / "survey.csv"
    data.to_csv(csv, index=False)
    out = tmp_path / "out"
    r = cli("analyze", "survey", "--responses", csv, "--study", STUDY_DIR, "--out", out, "--bootstrap", "200",
            "--seed", "3")
    assert r.code == 0, r.err
    assert "H7" in r.out and "40 participants" in r.out
    for name in CONTRACT_FILES:
        frame = pd.read_csv(out / f"{name}.csv")
        assert list(frame.columns[:len(COLUMNS[name])]) == COLUMNS[name]
    for t in ("table3", "table4", "table5"):
        assert (out / f"{t}.md").read_text().startswith("**")
        tex = (out / f"{t}.tex").read_text()
        assert r"\toprule" in tex and r"\bottomrule" in tex
    assert json.loads((out / "settings.json").read_text())["n_boot"] == 200


def test_cli_bad_input_is_one_line(cli, data, tmp_path):
    csv = tmp_path / "bad.csv"
    data.assign(PU2=9).to_csv(csv, index=False)
    r = cli("analyze", "survey", "--responses", csv, "--out", tmp_path / "o")
    assert r.code == 2 and r.err.count("\n") == 1 and "store not found" in r.err  # which study?
    r = cli("analyze", "survey", "--responses", csv, "--study", STUDY_DIR, "--out", tmp_path / "o")
    assert r.code == 2 and r.err.count("\n") == 1 and "outside 1..5" in r.err
    r = cli("analyze", "survey", "--responses", tmp_path / "missing.csv", "--out", tmp_path / "o")
    assert r.code == 2 and "not found" in r.err


def test_cli_from_the_store_applies_subjective_exclusions(cli, paper_db, data, tmp_path):
    from study.people.exclusions import exclude
    from study.store.store import Store

    inst = STUDY.instrument()
    with Store.open(paper_db, actor="tester") as st:
        with st.transaction():
            for pid in data["participant_id"]:
                st.insert("participants", {"participant_id": pid, "protocol": STUDY.protocol().name})
            long = data.melt(id_vars="participant_id", value_vars=inst.scaled_items, var_name="item_id",
                             value_name="value")
            long["instrument"] = inst.name
            long["entry_round"] = 1
            long["value"] = long["value"].astype(int)
            long["occasion"] = "survey"   # the paper's study has one questionnaire phase
            st.insert_df("responses", long[["participant_id", "instrument", "item_id", "entry_round", "value",
                                            "occasion"]])
        exclude(st, "P040", "subjective", "motion_sickness")
        exclude(st, "P039", "objective", "technical_issue")  # does not affect the survey
    out = tmp_path / "store_out"
    r = cli("analyze", "survey", "--out", out, "--bootstrap", "0", db=paper_db)
    assert r.code == 0, r.err
    assert "39 participants" in r.out and "H7 PBC -> BI (expected beta > 0)" in r.out
    desc = pd.read_csv(out / "descriptives.csv")
    assert (desc["n"] == 39).all()
    expected = analyze_survey(data[data.participant_id != "P040"], n_boot=0)
    assert np.allclose(desc["mean"], expected.descriptives["mean"])
    # a CSV analysed with the store's study gives the same regressions
    csv = tmp_path / "survey.csv"
    data[data.participant_id != "P040"].to_csv(csv, index=False)
    r = cli("analyze", "survey", "--responses", csv, "--out", tmp_path / "csv_out", "--bootstrap", "0", db=paper_db)
    assert r.code == 0, r.err
    assert (tmp_path / "csv_out" / "regressions.csv").read_bytes() == (out / "regressions.csv").read_bytes()


def test_tables_are_rendered_from_the_frames(res):
    from analysis import apa
    from analysis.survey.tables import render_all

    out = render_all(res)
    t3, t4, t5 = out["table3.md"], out["table4.md"], out["table5.md"]
    pu = res.reliability.set_index("construct").loc["PU"]
    # APA: values bounded by 1 without a leading zero, the report's one star convention
    assert f"**{apa.num(pu.sqrt_ave, 3, bounded=True)}**" in t4
    assert " | ".join(apa.num(x, 3, bounded=True) for x in (pu.alpha, pu.cr, pu.ave)) in t3
    c = res.correlations.set_index(["a", "b"]).loc[("PU", "ATT")]
    assert f"| ATT | {apa.num(c.r, 3, bounded=True)}{apa.stars(c.p)} |" in t4
    ini = res.loadings[(res.loadings.stage == "initial")].set_index("item")
    assert "| ATT1 |" in t3 and f"{apa.num(ini.loc['ATT1', 'loading'], 3, bounded=True)}‡" in t3
    assert "| PEoU3† |" in t3
    if res.settings.get("paper_idioms"):
        assert t5.count("Step ") == 8 and t5.count("Independent Variable - ") == 1 + 3 + 3 + 6
    else:
        assert t5.count("Step ") == 8 and "(DV: " in t5 and "Independent Variable" not in t5
    assert r"$\beta$" in out["table5.tex"] and r"\textbf{" in out["table4.tex"]


def test_reference_survey_files_are_byte_identical_between_runs(tmp_path):
    """The reference survey has a Heywood case (BI): optimiser noise must not reach the written files."""
    from pedas.paths import REFERENCE_DIR

    responses = pd.read_csv(REFERENCE_DIR / "survey.csv")
    outs = []
    for k in range(2):
        out = tmp_path / f"run{k}"
        analyze_survey(responses, n_boot=50, seed=3).write(out)
        outs.append({p.name: p.read_bytes() for p in sorted(out.iterdir())})
    assert outs[0] == outs[1]


def test_missing_answers_listwise_and_available_case(data):
    """Three participants leave one answer each blank: listwise leaves them out everywhere (n = 37, warned);
    available-case keeps their other answers (item n 39 or 40) and says which analyses use complete rows."""
    holes = data.copy()
    for pid, item in (("P001", "PU2"), ("P002", "SN1"), ("P003", "PU2")):
        holes.loc[holes["participant_id"] == pid, item] = np.nan
    lw = analyze_survey(holes, n_boot=0, seed=5)
    assert lw.n == 37 and set(lw.descriptives["n"]) == {37}
    assert set(lw.regressions["n"]) == {37}
    assert any(w.startswith("listwise deletion: 3 of 40") for w in lw.warnings)
    ac = analyze_survey(holes, n_boot=0, seed=5, listwise=False)
    n_item = ac.descriptives.set_index("item")["n"]
    assert n_item["PU2"] == 38 and n_item["SN1"] == 39 and n_item["PU1"] == 40
    assert any(w.startswith("available-case analysis: CFA, alpha and omega use the 37 complete rows")
               for w in ac.warnings)
    # a participant who skipped one PU item still has a PU composite (mean of the answered items)
    comp = ac.composites
    assert comp.loc["P001", "PU"] == pytest.approx(holes.set_index("participant_id").loc["P001", ["PU1", "PU3", "PU4"]]
                                                   .astype(float).mean())

"""Hypotheses from the study's model file: the paper's model reads each hypothesis where its Section 5.2.2 does;
verdicts by declared sign ('>' beta > 0 and p < alpha, '<' symmetric, '!=' two-sided)."""
from __future__ import annotations

import pandas as pd
import pytest

from analysis.survey.acceptance import survey_plan
from analysis.survey.hypotheses import judge_hypotheses, load_hypotheses
from analysis.paper.published import paper_study
from study.folder.definition import Hypothesis, parse_model
from study.common.problems import Problems, StudyError


def test_paper_model_tests_each_hypothesis_where_the_paper_does():
    study = paper_study()
    hyps = load_hypotheses(study.model)
    got = {h.hypothesis: (h.predictor, h.dv, h.model, h.step, h.sign) for h in hyps}
    assert study.alpha == 0.05
    assert got == {"H1": ("PEoU", "PU", "1", 1, ">"), "H2": ("PU", "ATT", "2", 2, ">"),
                   "H3": ("ATT", "BI", "3", 2, ">"), "H4": ("PEoU", "ATT", "2", 2, ">"),
                   "H5": ("PU", "BI", "3", 2, ">"), "H6": ("SN", "BI", "4", 2, ">"),
                   "H7": ("PBC", "BI", "4", 3, ">")}
    plan = survey_plan(study, study.instrument(), study.model)
    models = {m.name: m for m in plan.models}
    # the blocks of paper Table 5 (new predictors per step)
    assert {k: m.steps for k, m in models.items()} == {
        "1": (("PEoU",),), "2": (("PEoU",), ("PU",)), "3": (("ATT",), ("PU",)), "4": (("ATT",), ("SN",), ("PBC",))}
    for h in hyps:  # every hypothesis points at a predictor present in that model step
        m = models[h.model]
        assert m.dv == h.dv and h.predictor in m.predictors(h.step)
    assert plan.dropped == ["PEoU3", "ATT1", "ATT2", "ATT3", "ATT4", "ATT5"]


def _reg(beta, p):
    return pd.DataFrame([{"model": "1", "step": 1, "dv": "PU", "predictor": "PEoU", "beta": beta, "p": p,
                          "b": beta, "se_b": 0.1, "t": 2.0, "n": 40}])


@pytest.mark.parametrize("sign,beta,p,expected", [
    (">", 0.4, 0.01, True), (">", 0.4, 0.05, False), (">", -0.4, 0.001, False), (">", 0.0, 0.001, False),
    ("<", -0.4, 0.01, True), ("<", 0.4, 0.001, False), ("<", -0.4, 0.05, False),
    ("!=", -0.4, 0.01, True), ("!=", 0.4, 0.01, True), ("!=", 0.4, 0.2, False)])
def test_verdict_rule(sign, beta, p, expected):
    h = Hypothesis("H1", predictor="PEoU", dv="PU", model="1", step=1, sign=sign)
    out = judge_hypotheses(_reg(beta, p), [h])
    assert list(out.columns[:5]) == ["hypothesis", "path", "beta", "p", "supported"]
    assert bool(out.loc[0, "supported"]) is expected and out.loc[0, "path"] == "PEoU -> PU"


def test_alpha_is_strict():
    h = Hypothesis("H1", predictor="PEoU", dv="PU", model="1", step=1, sign=">")
    assert bool(judge_hypotheses(_reg(0.4, 0.01), [h], alpha=0.01).loc[0, "supported"]) is False
    assert bool(judge_hypotheses(_reg(0.4, 0.009), [h], alpha=0.01).loc[0, "supported"]) is True


def test_a_label_without_sign_is_two_sided_and_signs_follow_the_model_file():
    m = parse_model("Y =~ y1 + y2\nX =~ x1 + x2\nZ =~ z1 + z2\nY ~ Ha*X + Hb*Z\nHb < 0\n", "m.lav", Problems())
    assert [(h.hypothesis, h.sign) for h in load_hypotheses(m)] == [("Hb", "<"), ("Ha", "!=")]


def test_missing_coefficient_is_an_error():
    h = Hypothesis("H9", predictor="SN", dv="PU", model="1", step=1)
    with pytest.raises(ValueError, match="no coefficient of SN"):
        judge_hypotheses(_reg(0.3, 0.01), [h])
    with pytest.raises(ValueError, match="predicts PU, not BI"):
        judge_hypotheses(_reg(0.3, 0.01), [Hypothesis("H9", predictor="PEoU", dv="BI", model="1", step=1)])
    with pytest.raises(StudyError, match="sign given for a label"):
        parse_model("Y =~ y1 + y2\nX =~ x1 + x2\nY ~ X\nH1 > 0\n", "m.lav", Problems(), strict=True)

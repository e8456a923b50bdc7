"""Hypotheses H1-H7: the shipped spec mirrors the paper's Section 5.2.2; verdict rule beta > 0 and p < .05."""
from __future__ import annotations

import pandas as pd
import pytest

from analysis.hypotheses import judge_hypotheses, load_hypotheses
from analysis.acceptance import load_models


def test_shipped_spec_tests_each_hypothesis_where_the_paper_does():
    hyps, alpha = load_hypotheses()
    got = {h.hypothesis: (h.predictor, h.dv, h.model, h.step) for h in hyps}
    assert alpha == 0.05
    assert got == {"H1": ("PEoU", "PU", "1", 1), "H2": ("PU", "ATT", "2", 2), "H3": ("ATT", "BI", "3", 2),
                   "H4": ("PEoU", "ATT", "2", 2), "H5": ("PU", "BI", "3", 2), "H6": ("SN", "BI", "4", 2),
                   "H7": ("PBC", "BI", "4", 3)}
    models = {m.name: m for m in load_models()}
    for h in hyps:  # every hypothesis points at a predictor present in that model step
        m = models[h.model]
        assert m.dv == h.dv and h.predictor in m.predictors(h.step)


def _reg(beta, p):
    return pd.DataFrame([{"model": "1", "step": 1, "dv": "PU", "predictor": "PEoU", "beta": beta, "p": p,
                          "b": beta, "se_b": 0.1, "t": 2.0, "n": 40}])


@pytest.mark.parametrize("beta,p,expected", [(0.4, 0.01, True), (0.4, 0.05, False), (-0.4, 0.001, False),
                                             (0.0, 0.001, False)])
def test_verdict_rule(beta, p, expected):
    hyps, _ = load_hypotheses([{"hypothesis": "H1", "predictor": "PEoU", "dv": "PU", "model": "1", "step": 1}])
    out = judge_hypotheses(_reg(beta, p), hyps)
    assert list(out.columns[:5]) == ["hypothesis", "path", "beta", "p", "supported"]
    assert bool(out.loc[0, "supported"]) is expected and out.loc[0, "path"] == "PEoU -> PU"


def test_missing_coefficient_is_an_error():
    hyps, _ = load_hypotheses([{"hypothesis": "H9", "predictor": "SN", "dv": "PU", "model": "1", "step": 1}])
    with pytest.raises(ValueError, match="no coefficient of SN"):
        judge_hypotheses(_reg(0.3, 0.01), hyps)
    with pytest.raises(ValueError, match="bad hypothesis spec"):
        load_hypotheses([{"hypothesis": "H9"}])

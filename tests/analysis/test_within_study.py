"""analysis.within: every variable of a within-subjects study compared at once, on the seeded takeover data
(tests/data/takeover): the stacked tables are compare_within's, the orders are counted, alpha/omega per condition
come from the scored items, and the generated sentences quote the numbers of the tables."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from tests.conftest import REPO

DATA = REPO / "tests" / "data" / "takeover"
CONDITIONS = ("none", "visual", "audiovisual")


@pytest.fixture(scope="module")
def study():
    from analysis.within import analyze_within

    scores = pd.read_csv(DATA / "scores.csv")
    long = scores.melt(id_vars=["participant", "order", "period", "condition"], value_vars=["sus", "tlx", "trust"],
                       var_name="variable", value_name="value")
    items = pd.read_csv(DATA / "items.csv")
    trust = items.melt(id_vars=["participant", "condition"], value_vars=[f"trust{i}" for i in range(1, 7)],
                       var_name="item", value_name="value").assign(variable="trust")
    rev = trust["item"].isin(["trust2", "trust5"])
    trust.loc[rev, "value"] = 8 - trust.loc[rev, "value"]
    return analyze_within(long, CONDITIONS, items=trust), long, trust


def test_tables_are_compare_within_of_each_variable(study):
    from analysis.survey.within import compare_within

    res, long, _ = study
    assert list(res.variables["variable"]) == ["sus", "tlx", "trust"]
    for v in ("sus", "tlx", "trust"):
        one = compare_within(long[long["variable"] == v], period="period", conditions=CONDITIONS, variable=v)
        pd.testing.assert_frame_equal(res.anova[res.anova["variable"] == v].reset_index(drop=True), one.anova)
        pd.testing.assert_frame_equal(res.posthoc[res.posthoc["variable"] == v].reset_index(drop=True), one.posthoc)
    # the Latin square's orders: 7 / 6 / 6 (TOR-A19 in the first)
    assert dict(zip(res.orders["order"], res.orders["n"])) == {
        "none-visual-audiovisual": 7, "visual-audiovisual-none": 6, "audiovisual-none-visual": 6}


def test_reliability_per_condition(study):
    from analysis.survey.omega import omega_stack
    from analysis.survey.reliability import cronbach_alpha

    res, _, trust = study
    rel = res.reliability.set_index("condition")
    for c in CONDITIONS:
        wide = trust[trust["condition"] == c].pivot(index="participant", columns="item", values="value").dropna()
        assert rel.loc[c, "n"] == len(wide) and rel.loc[c, "k"] == 6
        assert rel.loc[c, "alpha"] == pytest.approx(cronbach_alpha(wide)[0], abs=1e-12)
        assert rel.loc[c, "omega"] == pytest.approx(omega_stack(np.cov(wide.to_numpy(float), rowvar=False)[None])[0],
                                                    abs=1e-12)
    # item descriptives: the mean of trust1 under 'none' is the plain mean of those answers
    d = res.item_descriptives.set_index(["item", "condition"])
    assert d.loc[("trust1", "none"), "mean"] == pytest.approx(
        trust[(trust["item"] == "trust1") & (trust["condition"] == "none")]["value"].mean())


def test_sentences_quote_the_tables(study):
    from analysis.within import methods_markdown

    res, _, _ = study
    a = res.anova.set_index("variable").loc["sus"]
    text = methods_markdown(res)
    assert f"sus: F(2, 34) = {a['f']:.2f}, p < .001" in text
    # TOR-A19 broke off: the repeated-measures n (df2 = 2 (n - 1) = 34) is 18, not 19
    assert "Of the 19 participants, 18 were measured under all 3 conditions (none, visual, audiovisual" in text
    assert "p = 0" not in text and "η² = 0." not in text and "eta^2" not in text   # APA: no leading zero where bounded
    assert "TOR-A19" in text   # the incomplete participant is named in the warnings


def test_bad_input_is_one_line():
    from analysis.within import analyze_within
    from study.common.errors import UserError

    with pytest.raises(UserError, match="lack column"):
        analyze_within(pd.DataFrame({"participant": ["a"], "condition": ["x"]}), ["x", "y"])
    with pytest.raises(UserError, match="no values of the conditions"):
        analyze_within(pd.DataFrame({"participant": ["a"], "condition": ["z"], "variable": ["v"], "value": [1.0]}),
                       ["x", "y"])

"""Hierarchical regressions: a hand-worked example, equality with statsmodels OLS, the vectorised bootstrap."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.survey.regression import (ModelSpec, bootstrap_coefs, f_change, hierarchical_regression, run_models,
                                 validate_models)

# Hand-worked: x1, x2 centred and orthogonal, y = 3 + 2 x1 + 1 x2 + e with e orthogonal to 1, x1, x2.
#   SST = 34; step 1: SSR = 2^2 * 6 = 24 -> R^2 = 12/17; step 2 adds 1^2 * 4 = 4 -> R^2 = 14/17, SSE = 6.
#   F change step 1 = (12/17) / ((5/17)/4) = 9.6; step 2 = (2/17) / ((3/17)/3) = 2.
HAND = pd.DataFrame({"x1": [-1, -1, -1, 1, 1, 1], "x2": [-1, 1, 0, -1, 1, 0], "y": [1, 3, -1, 4, 6, 5]},
                    dtype=float)
HAND_MODEL = ModelSpec(name="h", dv="y", steps=(("x1",), ("x2",)))


@pytest.fixture(scope="module")
def hand():
    return hierarchical_regression(HAND, HAND_MODEL, n_boot=0)


def test_hand_worked_model_summary(hand):
    s1 = hand[(hand.step == 1) & (hand.predictor == "x1")].iloc[0]
    s2 = hand[(hand.step == 2) & (hand.predictor == "x2")].iloc[0]
    assert s1.r2 == pytest.approx(12 / 17) and s1.adj_r2 == pytest.approx(43 / 68)
    assert s1.delta_r2 == pytest.approx(12 / 17) and s1.f_change == pytest.approx(9.6)
    assert (s1.df1, s1.df2) == (1, 4)
    assert s2.r2 == pytest.approx(14 / 17) and s2.delta_r2 == pytest.approx(2 / 17)
    assert s2.f_change == pytest.approx(2.0) and (s2.df1, s2.df2) == (1, 3)
    # the hand formula (Delta R^2/df1) / ((1 - R^2)/df2)
    assert s2.f_change == pytest.approx((s2.delta_r2 / s2.df1) / ((1 - s2.r2) / s2.df2))


def test_hand_worked_coefficients(hand):
    s2 = hand[hand.step == 2].set_index("predictor")
    assert s2.loc["(Constant)", "b"] == pytest.approx(3.0)
    assert s2.loc["x1", "b"] == pytest.approx(2.0) and s2.loc["x2", "b"] == pytest.approx(1.0)
    # sigma^2 = SSE/df2 = 2; Var(b2) = sigma^2 / sum(x2^2) = 2/4
    assert s2.loc["x2", "se_b"] == pytest.approx(np.sqrt(0.5))
    assert s2.loc["x1", "beta"] == pytest.approx(2.0 * np.sqrt(6 / 34))


def test_f_change_function():
    f, p = f_change(14 / 17, 12 / 17, 1, 3)
    assert f == pytest.approx(2.0) and 0 < p < 1


def _data(n=40, seed=5):
    rng = np.random.default_rng(seed)
    a, b, c = rng.standard_normal((3, n))
    return pd.DataFrame({"A": a, "B": 0.5 * a + b, "C": c, "Y": 0.4 * a + 0.3 * b - 0.2 * c + rng.standard_normal(n)})


def test_matches_statsmodels_ols_to_1e9():
    sm = pytest.importorskip("statsmodels.api")

    d = _data()
    m = ModelSpec(name="m", dv="Y", steps=(("A",), ("B", "C")))
    out = hierarchical_regression(d, m, n_boot=0)
    prev = 0.0
    for step, preds in ((1, ["A"]), (2, ["A", "B", "C"])):
        fit = sm.OLS(d["Y"], sm.add_constant(d[preds])).fit()
        rows = out[out.step == step].set_index("predictor")
        ci = fit.conf_int(0.05)
        for term, name in zip(["(Constant)"] + preds, ["const"] + preds):
            assert rows.loc[term, "b"] == pytest.approx(fit.params[name], abs=1e-9)
            assert rows.loc[term, "se_b"] == pytest.approx(fit.bse[name], abs=1e-9)
            assert rows.loc[term, "t"] == pytest.approx(fit.tvalues[name], abs=1e-9)
            assert rows.loc[term, "p"] == pytest.approx(fit.pvalues[name], abs=1e-9)
            assert rows.loc[term, "ci_low"] == pytest.approx(ci.loc[name, 0], abs=1e-9)
            assert rows.loc[term, "ci_high"] == pytest.approx(ci.loc[name, 1], abs=1e-9)
        r = rows.iloc[0]
        assert r.r2 == pytest.approx(fit.rsquared, abs=1e-9)
        assert r.adj_r2 == pytest.approx(fit.rsquared_adj, abs=1e-9)
        # standardized beta = coefficient of the z-scored regression
        z = (d - d.mean()) / d.std(ddof=1)
        zfit = sm.OLS(z["Y"], sm.add_constant(z[preds])).fit()
        for p_ in preds:
            assert rows.loc[p_, "beta"] == pytest.approx(zfit.params[p_], abs=1e-9)
        if step == 2:  # F change = statsmodels' nested-model F test
            small = sm.OLS(d["Y"], sm.add_constant(d[["A"]])).fit()
            f, p, df_diff = fit.compare_f_test(small)
            assert r.f_change == pytest.approx(f, abs=1e-9) and r.p_change == pytest.approx(p, abs=1e-9)
            assert r.df1 == df_diff == 2
        else:
            assert r.f_change == pytest.approx(fit.fvalue, abs=1e-9)
            assert r.p_change == pytest.approx(fit.f_pvalue, abs=1e-9)
        assert r.delta_r2 == pytest.approx(fit.rsquared - prev, abs=1e-12)
        prev = fit.rsquared


def test_vectorised_bootstrap_equals_loop_of_lstsq():
    d = _data(30, 9)
    X, y = d[["A", "B"]].to_numpy(), d["Y"].to_numpy()
    boot = bootstrap_coefs(y, X, 50, np.random.default_rng(1))
    idx = np.random.default_rng(1).integers(0, 30, size=(50, 30))
    for k in range(50):
        Xc = np.column_stack([np.ones(30), X[idx[k]]])
        b, *_ = np.linalg.lstsq(Xc, y[idx[k]], rcond=None)
        assert np.allclose(boot[k], b, atol=1e-9)


def test_bootstrap_is_seeded_and_brackets_b():
    d = _data()
    m = ModelSpec(name="m", dv="Y", steps=(("A", "B"),))
    a1 = hierarchical_regression(d, m, n_boot=500, seed=3)
    a2 = hierarchical_regression(d, m, n_boot=500, seed=3)
    a3 = hierarchical_regression(d, m, n_boot=500, seed=4)
    pd.testing.assert_frame_equal(a1, a2)
    assert not np.allclose(a1.boot_ci_low, a3.boot_ci_low)
    assert (a1.boot_ci_low < a1.b).all() and (a1.b < a1.boot_ci_high).all()


def test_bca_interval_is_close_to_percentile_for_a_symmetric_case():
    d = _data(200, 2)
    m = ModelSpec(name="m", dv="Y", steps=(("A",),))
    pc = hierarchical_regression(d, m, n_boot=2000, seed=1)
    bca = hierarchical_regression(d, m, n_boot=2000, seed=1, boot_method="bca")
    assert np.allclose(pc.boot_ci_low, bca.boot_ci_low, atol=0.05)
    assert (bca.boot_ci_low < bca.b).all() and (bca.b < bca.boot_ci_high).all()


def test_bad_input_errors():
    d = _data()
    with pytest.raises(ValueError, match="unknown construct 'Q'"):
        validate_models([ModelSpec(name="x", dv="Y", steps=(("Q",),))], d.columns)
    with pytest.raises(ValueError, match="dependent variable"):
        validate_models([ModelSpec(name="x", dv="Y", steps=(("Y",),))], d.columns)
    with pytest.raises(ValueError, match="smaller than predictors"):
        hierarchical_regression(d.head(3), ModelSpec(name="x", dv="Y", steps=(("A", "B"),)), n_boot=0)
    const = d.assign(C=1.0)
    with pytest.raises(ValueError, match="C is constant"):
        run_models(const, [ModelSpec(name="x", dv="Y", steps=(("C",),))], n_boot=0)
    with pytest.raises(ValueError, match="needs name, dv and steps"):
        ModelSpec.from_dict({"dv": "Y"})



@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(8, 60))
def test_property_r2_never_drops_and_f_change_matches_formula(seed, n):
    rng = np.random.default_rng(seed)
    d = pd.DataFrame(rng.standard_normal((n, 4)), columns=["A", "B", "C", "Y"])
    out = hierarchical_regression(d, ModelSpec(name="p", dv="Y", steps=(("A",), ("B",), ("C",))), n_boot=0)
    steps = out.groupby("step").first()
    assert (steps["delta_r2"] >= -1e-12).all() and (np.diff(steps["r2"]) >= -1e-12).all()
    assert np.allclose(steps["f_change"], (steps["delta_r2"] / steps["df1"]) / ((1 - steps["r2"]) / steps["df2"]))
    one = out[(out.step == 1) & (out.predictor == "A")].iloc[0]
    assert one.beta == pytest.approx(d["A"].corr(d["Y"]), abs=1e-9)  # one predictor: beta = r


def test_covariates_enter_numeric_as_is_and_choices_as_dummies():
    """A choice attribute in a step: one 0/1 column per occurring level except the first declared one that occurs;
    the step's block holds all of them (F change with df1 = 2 + 1), and the numbers are OLS on those columns."""
    import statsmodels.api as sm

    from analysis.survey.acceptance import analyze_survey
    from analysis.survey.testing import simulate_study_participants, simulate_study_responses
    from pedas.paths import REPO_ROOT
    from study.folder.definition import load

    study = load(REPO_ROOT / "studies" / "lane_keeping")
    answers = simulate_study_responses(study, 40, seed=5)
    people = simulate_study_participants(study, 40, seed=5)
    people["gender"] = (["female", "male", "diverse"] * 14)[:40]   # 'undisclosed' does not occur: no column
    model = ("PE =~ PE1 + PE2 + PE3\nBI =~ BI1 + BI2 + BI3\n"
             "BI ~ age\nBI ~ age + gender + km_per_year\nBI ~ age + gender + km_per_year + H1*PE\n")
    res = analyze_survey(answers, study, attributes=people, model=model, n_boot=0)
    reg = res.regressions
    assert res.settings["covariates"] == {"age": ["age"], "gender": ["gender_male", "gender_diverse"],
                                          "km_per_year": ["km_per_year"]}
    s2 = reg[reg.step == 2]
    assert list(s2["predictor"]) == ["(Constant)", "age", "gender_male", "gender_diverse", "km_per_year"]
    assert (s2["df1"] == 3).all() and (reg[reg.step == 3]["df1"] == 1).all()
    X = pd.DataFrame({"age": people["age"].astype(float), "gender_male": (people["gender"] == "male") * 1.0,
                      "gender_diverse": (people["gender"] == "diverse") * 1.0, "km_per_year": people["km_per_year"],
                      "PE": res.composites["PE"].to_numpy()})
    fit = sm.OLS(res.composites["BI"].to_numpy(), sm.add_constant(X)).fit()
    s3 = reg[reg.step == 3].set_index("predictor")
    for term in X.columns:
        assert s3.loc[term, "b"] == pytest.approx(fit.params[term], rel=1e-9)
        assert s3.loc[term, "p"] == pytest.approx(fit.pvalues[term], rel=1e-7)
    assert list(res.hypotheses["hypothesis"]) == ["H1"] and res.hypotheses.loc[0, "step"] == 3

"""CFA: lavaan's published Holzinger-Swineford output, SRMR by hand, Heywood reporting, item flags."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.survey.cfa import fit_cfa, fit_indices, flag_items, heywood_cases, srmr

HS_MODEL = {"visual": ["x1", "x2", "x3"], "textual": ["x4", "x5", "x6"], "speed": ["x7", "x8", "x9"]}
# lavaan 0.6 cfa(HS.model, data = HolzingerSwineford1939): fitMeasures and standardizedSolution (std.all)
LAVAAN_FIT = {"chi2": 85.306, "df": 24, "cfi": 0.931, "tli": 0.896, "rmsea": 0.092, "srmr": 0.065}
LAVAAN_STD = {"x1": 0.772, "x2": 0.424, "x3": 0.581, "x4": 0.852, "x5": 0.855, "x6": 0.838,
              "x7": 0.570, "x8": 0.723, "x9": 0.665}


@pytest.fixture(scope="module")
def hs():
    from semopy.examples import holzinger39

    data = holzinger39.get_data()
    return data, fit_cfa(data, HS_MODEL)


@pytest.mark.parametrize("name", list(LAVAAN_FIT))
def test_holzinger_fit_matches_lavaan(hs, name):
    _, res = hs
    assert res.fit[name] == pytest.approx(LAVAAN_FIT[name], abs=1e-3)


def test_holzinger_df_and_convergence(hs):
    _, res = hs
    assert res.fit["df"] == 24 and res.fit["n_params"] == 21 and res.fit["n"] == 301
    assert res.converged and res.warnings == []


def test_non_convergence_is_reported(hs, monkeypatch):
    """An optimiser stopped after one iteration: the result says it did not converge, with a warning."""
    import analysis.survey.cfa as cfa

    data, _ = hs
    monkeypatch.setattr(cfa, "SOLVERS", (("SLSQP", {"maxiter": 1}),))
    res = cfa.fit_cfa(data, HS_MODEL, label="initial")
    assert not res.converged
    assert any("CFA initial: did not converge (SLSQP" in w for w in res.warnings), res.warnings


@pytest.mark.parametrize("item", list(LAVAAN_STD))
def test_holzinger_std_loadings_match_lavaan(hs, item):
    _, res = hs
    got = res.loadings.set_index("item").loc[item, "loading"]
    assert got == pytest.approx(LAVAAN_STD[item], abs=1e-3)


def test_holzinger_latent_correlations_match_lavaan(hs):
    # lavaan std.all of the factor covariances: visual~~textual .459, visual~~speed .471, textual~~speed .283
    _, res = hs
    assert res.latent_corr.loc["visual", "textual"] == pytest.approx(0.459, abs=1e-3)
    assert res.latent_corr.loc["visual", "speed"] == pytest.approx(0.471, abs=1e-3)
    assert res.latent_corr.loc["textual", "speed"] == pytest.approx(0.283, abs=1e-3)


def test_srmr_hand_example():
    S = np.array([[1.0, 0.5], [0.5, 4.0]])
    sigma = np.array([[1.0, 0.3], [0.3, 4.0]])
    # only r_12 = (0.5 - 0.3) / sqrt(1 * 4) = 0.1 is non-zero among the 3 elements i <= j
    assert srmr(S, sigma) == pytest.approx(np.sqrt(0.1 ** 2 / 3))


def test_fit_indices_of_a_saturated_fit_are_perfect():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((50, 3))
    S = np.cov(x, rowvar=False, ddof=0)
    out = fit_indices(S, S, 50, 6)  # 6 free parameters = 3*4/2 moments -> df 0
    assert out["chi2"] == pytest.approx(0.0, abs=1e-10) and out["df"] == 0 and out["srmr"] == pytest.approx(0.0)


def test_heywood_cases_are_reported():
    lo = pd.DataFrame([{"construct": "F", "item": "a", "loading": 1.02, "error_var": 0.1},
                       {"construct": "F", "item": "b", "loading": 0.6, "error_var": -0.05}])
    psi = pd.DataFrame([[1.0]], index=["F"], columns=["F"])
    S = pd.DataFrame(np.eye(2), index=["a", "b"], columns=["a", "b"])
    msgs = heywood_cases(lo, psi, S)
    assert any("a" in m and "|lambda| >= 1" in m for m in msgs)
    assert any("error variance of b" in m for m in msgs)


def test_fit_cfa_rejects_unknown_item_and_single_item_construct(hs):
    data, _ = hs
    with pytest.raises(ValueError, match="not in the data"):
        fit_cfa(data, {"visual": ["x1", "nope"]})
    with pytest.raises(ValueError, match="at least 2 items"):
        fit_cfa(data, {"visual": ["x1"], "textual": ["x4", "x5"]})


def test_flag_items_fires_each_rule():
    rng = np.random.default_rng(3)
    n = 200
    f1, f2 = rng.standard_normal(n), rng.standard_normal(n)
    noise = lambda: 0.5 * rng.standard_normal(n)  # noqa: E731
    data = pd.DataFrame({"a1": f1 + noise(), "a2": f1 + noise(), "a3": f1 + noise(),
                         "b1": f2 + noise(), "b2": f2 + noise(),
                         "b3": f1 + 0.2 * f2 + noise(),     # belongs to A rather than B -> cross
                         "a4": -f1 + noise()})              # negatively keyed, unreversed -> negative
    cons = {"A": ["a1", "a2", "a3", "a4"], "B": ["b1", "b2", "b3"]}
    lo = pd.DataFrame([{"construct": c, "item": i, "loading": l} for c, i, l in
                       [("A", "a1", .9), ("A", "a2", .9), ("A", "a3", .65), ("A", "a4", -.8),
                        ("B", "b1", .9), ("B", "b2", .9), ("B", "b3", .3)]])
    fl = flag_items(lo, data, cons).set_index("item")
    assert fl.loc["a3", "flag_low"] and not fl.loc["a3", "flag_negative"]
    assert fl.loc["a4", "flag_negative"] and "negative_lambda" in fl.loc["a4", "rule"]
    assert fl.loc["b3", "flag_cross"] and fl.loc["b3", "cross_construct"] == "A"
    assert not fl.loc["a1", "flag_cross"] and fl.loc["a1", "rule"] == ""

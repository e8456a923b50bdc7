"""Validity: correlation p-values and stars, Fornell-Larcker verdicts, HTMT by hand."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.survey.validity import composite_correlations, fornell_larcker, htmt, pearson_p, stars


def test_pearson_p_equals_scipy():
    rng = np.random.default_rng(1)
    x, y = rng.standard_normal((2, 41))
    y = y + 0.4 * x
    r, p = stats.pearsonr(x, y)
    assert pearson_p(r, 41) == pytest.approx(p, rel=1e-9)


def test_stars_thresholds():
    assert stars(0.0099) == "**" and stars(0.01) == "*" and stars(0.0499) == "*" and stars(0.05) == ""
    assert stars(float("nan")) == ""


def test_composite_correlations_table():
    rng = np.random.default_rng(2)
    a = rng.standard_normal(40)
    comp = pd.DataFrame({"A": a, "B": a + rng.standard_normal(40), "C": rng.standard_normal(40)})
    out = composite_correlations(comp)
    assert list(out[["a", "b"]].itertuples(index=False, name=None)) == [("A", "B"), ("A", "C"), ("B", "C")]
    r, p = stats.pearsonr(comp["A"], comp["B"])
    row = out.iloc[0]
    assert row.r == pytest.approx(r) and row.p == pytest.approx(p) and row.stars == "**"


def test_fornell_larcker_pass_and_fail():
    corr = pd.DataFrame({"a": ["PU", "PU"], "b": ["ATT", "BI"], "r": [0.772, 0.622], "p": [0.0, 0.0]})
    rel = pd.DataFrame({"construct": ["PU", "ATT", "BI"], "sqrt_ave": [0.803, 0.796, 0.91]})
    latent = pd.DataFrame(np.eye(3), index=["PU", "ATT", "BI"], columns=["PU", "ATT", "BI"])
    latent.loc["PU", "ATT"] = latent.loc["ATT", "PU"] = 0.95
    fl = fornell_larcker(corr, rel, latent).set_index("b")
    assert fl.loc["ATT", "pass"]                 # paper Table 4: .772 < .796
    assert not fl.loc["ATT", "pass_latent"]      # a latent correlation of .95 would fail
    assert fl.loc["BI", "pass"]
    corr.loc[1, "r"] = -0.85
    assert not fornell_larcker(corr, rel).set_index("b").loc["BI", "pass"]


@pytest.mark.parametrize("hetero, above_085, above_090", [(0.426, True, False), (0.465, True, True)])
def test_htmt_flags(hetero, above_085, above_090):
    """HTMT = hetero / sqrt(0.6 x 0.4): 0.870 is above the strict 0.85 only, 0.949 above both thresholds."""
    R = np.array([[1.0, 0.6, hetero, hetero],
                  [0.6, 1.0, hetero, hetero],
                  [hetero, hetero, 1.0, 0.4],
                  [hetero, hetero, 0.4, 1.0]])
    rng = np.random.default_rng(1)
    z = rng.standard_normal((5000, 4))
    z = (z - z.mean(0)) @ np.linalg.inv(np.linalg.cholesky(np.cov(z, rowvar=False))).T
    x = pd.DataFrame(z @ np.linalg.cholesky(R).T, columns=["a1", "a2", "b1", "b2"])
    out = htmt(x, {"A": ["a1", "a2"], "B": ["b1", "b2"]})
    assert out.loc[0, "htmt"] == pytest.approx(hetero / np.sqrt(0.24), abs=1e-9)
    assert (bool(out.loc[0, "above_085"]), bool(out.loc[0, "above_090"])) == (above_085, above_090)


def test_htmt_hand_example():
    # Correlation structure built so every item correlation is known:
    R = np.array([[1.0, 0.6, 0.3, 0.3],
                  [0.6, 1.0, 0.3, 0.3],
                  [0.3, 0.3, 1.0, 0.4],
                  [0.3, 0.3, 0.4, 1.0]])
    rng = np.random.default_rng(0)
    z = rng.standard_normal((5000, 4))
    z = (z - z.mean(0)) @ np.linalg.inv(np.linalg.cholesky(np.cov(z, rowvar=False))).T
    x = pd.DataFrame(z @ np.linalg.cholesky(R).T, columns=["a1", "a2", "b1", "b2"])
    out = htmt(x, {"A": ["a1", "a2"], "B": ["b1", "b2"]})
    # HTMT = mean heterotrait 0.3 / sqrt(0.6 * 0.4)
    assert out.loc[0, "htmt"] == pytest.approx(0.3 / np.sqrt(0.24), abs=1e-9)
    assert not out.loc[0, "above_085"]

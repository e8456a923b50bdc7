"""SPSS-style extractions (analysis.survey.extraction) and the feasibility test of Table 3's loadings
(analysis.paper.procedure): hand-worked numbers, properties, the audit finding, `analyze survey --loadings`."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from analysis.survey import extraction as X
from analysis.paper import audit as A
from analysis.paper import procedure as F


def corr(lam):
    R = np.outer(lam, lam)
    np.fill_diagonal(R, 1.0)
    return R


# ---- hand-worked numbers

def test_two_items_pca_is_sqrt_half_one_plus_r():
    # the BI case worked by hand in docs/paper_reproduction.md: r = .656 -> λ = √(1.656/2) = .90995
    ex = X.pca_loadings(np.array([[1, .656], [.656, 1]]))
    assert ex.loadings == pytest.approx([0.90995, 0.90995], abs=1e-5)
    assert ex.eigenvalue == pytest.approx(1.656)


def test_bi_alpha_determines_the_pca_loading():
    # Cα .792 with SDs 1.03 and .93: cov = α(v1 + v2)/(4 - 2α) = .6313, r = .6591, λ = √((1 + r)/2) = .9108
    s1, s2, a = 1.03, .93, .792
    cov = a * (s1 ** 2 + s2 ** 2) / (4 - 2 * a)
    r = cov / (s1 * s2)
    assert r == pytest.approx(0.6591, abs=1e-4)
    assert X.pca_loadings(np.array([[1, r], [r, 1]])).loadings[0] == pytest.approx(0.9108, abs=1e-4)
    # and the CFA reading (r = λ1 λ2 = .911²) gives α .904, not .792
    r_cfa = .911 ** 2
    alpha_cfa = A.alpha_from_cov(np.array([[s1 * s1, r_cfa * s1 * s2], [r_cfa * s1 * s2, s2 * s2]]))
    assert alpha_cfa == pytest.approx(0.9045, abs=1e-3)


def test_one_factor_data_give_the_factor_loadings_under_paf_and_ml():
    lam = np.array([.8, .7, .6, .5])
    R = corr(lam)
    assert X.paf_loadings(R, max_iter=5000, tol=1e-12).loadings == pytest.approx(lam, abs=1e-6)
    ml = X.ml_loadings(R)
    assert ml.converged and ml.loadings == pytest.approx(lam, abs=1e-4)
    # PCA loadings of the same matrix are higher (they absorb unique variance)
    assert np.all(X.pca_loadings(R).loadings > lam)


def test_paf_stops_at_spss_defaults():
    ex = X.paf_loadings(corr(np.array([.9, .8, .7])))
    assert ex.iterations <= X.PAF_MAX_ITER


def test_bad_matrix_is_refused():
    with pytest.raises(ValueError, match="correlation matrix"):
        X.pca_loadings(np.array([[2.0, .5], [.5, 1.0]]))
    with pytest.raises(ValueError, match="unknown extraction"):
        X.extract(np.eye(2), "varimax")


# ---- properties

@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.3, 0.9), min_size=3, max_size=5), st.integers(0, 4))
def test_pca_ave_is_eigenvalue_over_k_and_reversal_flips_one_sign(lam, flip):
    lam = np.array(lam)
    R = corr(lam)
    ex = X.pca_loadings(R)
    assert np.mean(ex.loadings ** 2) == pytest.approx(ex.eigenvalue / len(lam))
    j = flip % len(lam)
    D = np.eye(len(lam))
    D[j, j] = -1
    ex2 = X.pca_loadings(D @ R @ D)
    expect = ex.loadings.copy()
    expect[j] *= -1
    assert ex2.loadings == pytest.approx(expect if expect.sum() >= 0 else -expect, abs=1e-9)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(0.4, 0.9), min_size=3, max_size=4), st.sampled_from(F.METHODS))
def test_the_linear_system_holds_at_the_extraction(lam, method):
    # extract λ from a random one-factor-plus-noise matrix, then R must solve M r = b for that λ
    rng = np.random.default_rng(len(lam))
    R = corr(np.array(lam))
    E = rng.normal(0, 0.03, R.shape)
    R = R + (E + E.T) / 2
    np.fill_diagonal(R, 1.0)
    ex = X.paf_loadings(R, max_iter=20000, tol=1e-13) if method == "paf" else X.extract(R, method)
    M, b, pairs = F.system(ex.loadings, method)
    r = np.array([R[i, j] for i, j in pairs])
    assert M @ r == pytest.approx(b, abs=1e-5)
    assert F.top_gap(R, ex.loadings, method) > 0


# ---- the feasibility test on the paper's Table 3

@pytest.fixture(scope="module")
def feasible():
    return F.feasibility()


@pytest.fixture(scope="module")
def table(feasible):
    return F.feasibility_table(feasible).set_index(["construct", "method", "item_set"])


# one worker computes the feasibility once for both tests
@pytest.mark.xdist_group("extraction_feasibility")
def test_pca_fits_the_determined_constructs_and_factor_models_do_not(table):
    for c in ("PBC", "SN", "BI"):
        assert table.loc[(c, "pca", "retained"), "status"] == "fits"
        assert table.loc[(c, "pca", "retained"), "how"] == "closed form"
        for m in ("paf", "ml"):
            assert table.loc[(c, m, "retained"), "status"] == "rejected"
    bi = table.loc[("BI", "pca", "retained")]
    assert bi["alpha_low"] <= 0.7925 and bi["alpha_high"] >= 0.7915
    assert table.loc[("BI", "ml", "retained"), "alpha_low"] == pytest.approx(0.903, abs=0.002)
    assert table.loc[("PU", "pca", "retained"), "status"] == "fits"
    assert table.loc[("ATT", "pca", "all"), "status"] == "fits"
    assert table.loc[("ATT", "pca", "retained"), "status"] == "rejected"
    assert not (table.xs("PEoU")["status"] == "fits").any()


@pytest.mark.xdist_group("extraction_feasibility")
def test_witness_is_checked(feasible):
    res = {(r.construct, r.method, r.item_set): r for r in feasible}
    w = res[("ATT", "pca", "all")]
    assert F.is_solution(w.witness, np.array([.464, -.034, .249, .687, .579, .817, .82, .802, .743]), "pca")


@pytest.mark.slow
def test_audit_has_the_extraction_finding():
    audit = A.run_audit()
    f = A.findings(audit)
    row = f[f["group"] == "extraction"]
    assert len(row) == 1 and int(row["finding"].iloc[0]) == 10
    bad = audit[(audit["group"] == "extraction") & (audit["status"] == "inconsistent")]
    assert set(bad["where"].str.extract(r"Table 3 (\w+)")[0]) == {"PU", "PEoU", "ATT", "PBC", "SN", "BI"}
    # the earlier findings keep their numbers
    assert A.finding_for(audit, "loadings_vs_alpha") == 5 and A.finding_for(audit, "ci_not_t") == 8


# ---- analyze survey --loadings

def test_cli_loadings_pca(cli, tmp_path):
    from analysis.paper.synthetic import simulate_paper_responses

    csv = tmp_path / "survey.csv"
    data = simulate_paper_responses(40, seed=11)
    data.to_csv(csv, index=False)
    out = {}
    for m in ("cfa", "pca"):
        r = cli("analyze", "survey", "--responses", csv, "--study", "studies/pedas_paper", "--out", tmp_path / m,
                "--bootstrap", "0", "--loadings", m)
        assert r.code == 0, r.err
        out[m] = pd.read_csv(tmp_path / m / "loadings.csv")
    fin = out["pca"][out["pca"]["stage"] == "final"]
    scored = data.copy()
    scored["PEoU3"] = 6 - scored["PEoU3"]
    R = scored[["BI1", "BI2"]].corr().to_numpy()
    assert fin.set_index("item").loc["BI1", "loading"] == pytest.approx(np.sqrt((1 + R[0, 1]) / 2), abs=1e-9)
    rel = pd.read_csv(tmp_path / "pca" / "reliability.csv").set_index("construct")
    lam = fin[fin["construct"] == "SN"]["loading"].to_numpy()
    assert rel.loc["SN", "cr"] == pytest.approx(A.cr_ave(lam)[0]) and rel.loc["SN", "ave"] == pytest.approx(
        A.cr_ave(lam)[1])
    assert "principal component" in (tmp_path / "pca" / "table3.md").read_text()
    assert not np.allclose(out["cfa"]["loading"], out["pca"]["loading"])
    r = cli("analyze", "survey", "--responses", csv, "--study", "studies/pedas_paper", "--out", tmp_path / "x",
            "--loadings", "varimax")
    assert r.code == 2 and not (tmp_path / "x").exists()


def test_a_paf_that_does_not_converge_is_warned_per_stage():
    from analysis.survey.extraction import construct_loadings

    rng = np.random.default_rng(3)
    x = rng.normal(size=(40, 1))
    # two items almost identical and one unrelated: the communalities run past 1 (a Heywood case)
    data = pd.DataFrame(np.hstack([x, x + 0.01 * rng.normal(size=(40, 1)), rng.normal(size=(40, 1))]),
                        columns=["a1", "a2", "a3"])
    _, warn = construct_loadings(data, {"A": ["a1", "a2", "a3"]}, "paf", "initial")
    assert warn == ["PAF loadings initial of A: extraction did not converge (or a communality exceeded 1); the "
                    "loadings are unreliable"]
    frame, warn = construct_loadings(data, {"A": ["a1", "a2", "a3"]}, "pca")
    assert warn == [] and list(frame.columns) == ["construct", "item", "loading"]

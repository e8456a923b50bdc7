"""The extended acceptance statistics: building blocks checked against independent computations (scipy, semopy,
closed forms), the bootstrap's failure accounting, invariance refusals, and the `analyze extended` CLI on both
shipped studies. The comparison with R (lavaan/semTools) is tests/analysis/test_extended_reference.py."""
from __future__ import annotations

import doctest
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.survey import bootstrap as B
from analysis.survey import ordinal as O
from analysis.survey.htmt import htmt2, reliability_bootstrap
from analysis.survey.invariance import invariance
from analysis.survey.omega import omega_stack
from analysis.survey.scoring import score_responses
from analysis.survey.validity import htmt
from study.folder.definition import load

REPO = Path(__file__).resolve().parents[2]
PAPER = REPO / "studies" / "pedas_paper"
LK = REPO / "studies" / "lane_keeping"
REF = REPO / "tests" / "data" / "r_reference"


@pytest.fixture(scope="module")
def paper_scored():
    survey = pd.read_csv(REPO / "data" / "reference" / "survey.csv", dtype={"participant_id": str})
    study = load(PAPER)
    return score_responses(survey, study.instrument()).scored, {c: list(v) for c, v in study.model.measurement.items()}


@pytest.mark.parametrize("module", ["bootstrap", "ordinal", "omega", "htmt", "sem", "method_bias", "extended"])
def test_docstring_examples(module):
    import importlib

    res = doctest.testmod(importlib.import_module(f"analysis.survey.{module}"), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0 and res.attempted > 0


def test_bivariate_normal_matches_scipy():
    rng = np.random.default_rng(3)
    h, k = rng.normal(0, 1.5, 40), rng.normal(0, 1.5, 40)
    r = np.concatenate([rng.uniform(-0.999, 0.999, 36), [0.93, -0.93, 0.9999, -0.9999]])
    ours = O.bvn_cdf(h, k, r)
    theirs = [stats.multivariate_normal(mean=[0, 0], cov=[[1, c], [c, 1]]).cdf([a, b]) for a, b, c in zip(h, k, r)]
    np.testing.assert_allclose(ours, theirs, atol=1e-7)  # scipy's own integration error is ~1e-8
    assert O.bvn_cdf(np.inf, 0.3, 0.5) == pytest.approx(stats.norm.cdf(0.3), abs=1e-15)
    assert O.bvn_cdf(-np.inf, 0.3, 0.5) == 0.0


def test_polychoric_agrees_with_an_independent_scipy_computation(paper_scored):
    # semopy 2.3's own polychoric_corr calls scipy.stats.mvn.mvnun, which current scipy no longer has; the check is
    # the same two-step likelihood with scipy's bivariate normal CDF and optimiser
    from scipy import optimize

    scored, meas = paper_scored
    a, b = meas["PU"][:2]
    poly = O.polychoric(scored, [a, b], acov=False)
    ca, ta = O.codes(scored[a])
    cb, tb = O.codes(scored[b])
    n = np.zeros((len(ta) + 1, len(tb) + 1))
    np.add.at(n, (ca, cb), 1.0)
    ea = np.clip(np.concatenate([[-np.inf], ta, [np.inf]]), -10, 10)
    eb = np.clip(np.concatenate([[-np.inf], tb, [np.inf]]), -10, 10)

    def nll(r):
        mvn = stats.multivariate_normal(mean=[0, 0], cov=[[1, r], [r, 1]])
        F = np.array([[mvn.cdf([x, y]) for y in eb] for x in ea])
        P = F[1:, 1:] - F[:-1, 1:] - F[1:, :-1] + F[:-1, :-1]
        return -np.sum(n[n > 0] * np.log(P[n > 0]))

    r = optimize.minimize_scalar(nll, bounds=(-0.99, 0.99), method="bounded", options={"xatol": 1e-7})
    assert r.success and poly.R.loc[a, b] == pytest.approx(r.x, abs=1e-5)


def test_ordinal_cfa_reproduces_an_exact_one_factor_structure():
    # a population polychoric matrix of loadings .8/.7/.6/.5 is fitted exactly by ULS and DWLS
    lam = np.array([0.8, 0.7, 0.6, 0.5])
    R = np.outer(lam, lam)
    np.fill_diagonal(R, 1.0)
    items = ["a", "b", "c", "d"]
    poly = O.Polychoric(items=items, R=pd.DataFrame(R, index=items, columns=items),
                        thresholds={i: np.array([-1.0, 0.0, 1.0]) for i in items},
                        avar=pd.DataFrame(np.full((4, 4), 0.5), index=items, columns=items), n=100)
    for est in ("ULS", "DWLS"):
        fit = O.fit_ordinal_cfa(pd.DataFrame(), {"F": items}, estimator=est, poly=poly)
        assert fit.converged and fit.fit["f_min"] < 1e-20
        np.testing.assert_allclose(fit.loadings["loading"], lam, atol=1e-9)
    # ordinal omega with a perfect model: common = total off the diagonal, so the ratio is < 1 only by the
    # diagonal (lambda^2 instead of 1)
    om = O.ordinal_omega(fit).loc[0, "omega_ordinal"]
    assert 0.5 < om < 1.0


def test_ordinal_cfa_refuses_a_single_category_item():
    d = pd.DataFrame({"a": [3, 3, 3, 3], "b": [1, 2, 3, 4], "c": [2, 2, 3, 4]})
    with pytest.raises(ValueError, match="item a has a single observed answer category"):
        O.fit_ordinal_cfa(d, {"F": ["a", "b", "c"]})


def test_htmt2_beside_htmt(paper_scored):
    scored, meas = paper_scored
    h = htmt2(scored, meas)
    np.testing.assert_allclose(h["htmt"], htmt(scored, meas)["htmt"], rtol=1e-12)
    # geometric <= arithmetic mean: with equal monotrait means HTMT2 <= HTMT is not guaranteed, but both are
    # positive and of the same order on these data
    assert (h["htmt2"] > 0).all() and (abs(h["htmt2"] - h["htmt"]) < 0.2).all()


def test_one_factor_omega_three_items_closed_form_and_iteration_agree():
    rng = np.random.default_rng(5)
    lam = np.array([0.9, 0.7, 0.6, 0.8])
    x = rng.normal(size=(500, 1)) * lam + rng.normal(size=(500, 4)) * np.sqrt(1 - lam ** 2)
    S = np.cov(x[:, :3], rowvar=False, bias=True)
    three = omega_stack(S[None])[0]
    from analysis.survey.omega import one_factor_loadings

    l3, ok = one_factor_loadings(S[None])
    assert ok[0] and three == pytest.approx(l3[0].sum() ** 2 / S.sum(), abs=1e-8)


def _fragile_mean(s):
    if (s[:, 0] == 0).sum() >= 2:  # a resample that draws row 0 twice "fails"
        raise ValueError("fit failed")
    return [s[:, 0].mean()]


def test_bootstrap_counts_failed_resamples_and_does_not_drop_them_silently():
    x = np.arange(12, dtype=float)[:, None]
    stat = _fragile_mean
    res = B.bootstrap(x, stat, ["mean"], n_boot=300, seed=11, method="bca")
    idx = B.resample_indices(12, 300, 11)
    expected = int(((idx == 0).sum(axis=1) >= 2).sum())
    tab = res.table()
    assert expected > 0 and int(tab.loc[0, "n_failed"]) == expected and int(tab.loc[0, "n_boot"]) == 300
    ok = idx[(idx == 0).sum(axis=1) < 2]
    np.testing.assert_array_equal(res.draws[np.isfinite(res.draws[:, 0]), 0], x[ok, 0].mean(axis=1))
    # the same draws in two worker processes
    res2 = B.bootstrap(x, stat, ["mean"], n_boot=300, seed=11, method="bca", workers=2)
    pd.testing.assert_frame_equal(tab, res2.table())


def test_bca_of_the_mean_is_close_to_the_t_interval():
    rng = np.random.default_rng(2)
    x = rng.normal(10, 2, size=(200, 1))
    res = B.bootstrap(x, lambda s: s.mean(axis=1), ["mean"], n_boot=4000, seed=1, vectorised=True).table()
    half = stats.t.ppf(0.975, 199) * x.std(ddof=1) / np.sqrt(200)
    assert res.loc[0, "ci_low"] == pytest.approx(x.mean() - half, abs=0.05)
    assert res.loc[0, "ci_high"] == pytest.approx(x.mean() + half, abs=0.05)


def test_reliability_bootstrap_is_seeded(paper_scored):
    scored, meas = paper_scored
    a = reliability_bootstrap(scored, meas, n_boot=100, seed=4)
    b = reliability_bootstrap(scored, meas, n_boot=100, seed=4)
    pd.testing.assert_frame_equal(a, b)
    alpha = a[a["statistic"] == "alpha"].set_index("a")["estimate"]
    from analysis.survey.reliability import cronbach_alpha

    for c, its in meas.items():
        assert alpha[c] == pytest.approx(cronbach_alpha(scored[its])[0], abs=1e-12)
    assert (a["n_boot"] == 100).all()


def test_invariance_refuses_small_groups_in_one_line(paper_scored):
    scored, meas = paper_scored
    people = pd.read_csv(REPO / "data" / "reference" / "participants.csv", dtype={"participant_id": str})
    groups = people.set_index("participant_id")["style"]
    with pytest.raises(ValueError) as e:
        invariance(scored, meas, groups, group_var="style")
    msg = str(e.value)
    assert "\n" not in msg and "too small" in msg and "at least 20 participants" in msg
    with pytest.raises(ValueError, match="1 group"):
        invariance(scored, meas, pd.Series("all", index=scored.index), group_var="site")


def test_invariance_decisions_follow_delta_cfi_and_delta_rmsea():
    data = pd.read_csv(REF / "invariance_survey.csv", dtype={"participant_id": str})
    study = load(PAPER)
    scored = score_responses(data.drop(columns="style"), study.instrument()).scored
    res = invariance(scored, {c: list(v) for c, v in study.model.measurement.items()},
                     data.set_index("participant_id")["style"], group_var="style")
    st = res.steps.set_index("step")
    assert list(st.index) == ["configural", "metric", "scalar"]
    assert (st["df"].diff().iloc[1:] > 0).all() and (st["chi2"].diff().iloc[1:] > 0).all()
    assert st.loc["configural", "holds"] == bool(st.loc["configural", "cfi"] >= 0.90
                                                  and st.loc["configural", "rmsea"] <= 0.08)
    for step in ("metric", "scalar"):
        holds_here = st.loc[step, "delta_cfi"] >= -0.01 and st.loc[step, "delta_rmsea"] <= 0.015
        prev = st.index[list(st.index).index(step) - 1]
        assert st.loc[step, "holds"] == bool(holds_here and st.loc[prev, "holds"])
    assert list(st["holds"]) == [True, True, False] and st.loc["scalar", "reason"] == "Delta CFI -0.012 < -0.01"
    assert res.groups["n"].sum() == 240


def test_cli_extended_on_the_lane_keeping_study(cli, tmp_path):
    survey = pd.read_csv(REPO / "tests" / "data" / "lane_keeping" / "survey.csv", dtype={"participant_id": str})
    resp = tmp_path / "survey.csv"
    survey.drop(columns="AGE").to_csv(resp, index=False)
    out = tmp_path / "ext"
    r = cli("analyze", "extended", "--responses", resp, "--study", LK, "--attributes",
            REPO / "tests" / "data" / "lane_keeping" / "participants.csv", "--out", out, "--bootstrap", "200",
            "--workers", "1", db=None)
    assert r.code == 0, r.err
    assert "extended survey statistics of 24 participants" in r.out and "time:" in r.out
    for name in ("ordinal_loadings", "omega", "reliability_boot", "htmt2", "sem_paths", "sem_fit", "indirect",
                 "vif", "full_vif", "harman"):
        assert (out / f"{name}.csv").is_file(), name
    assert not (out / "invariance.csv").exists()  # no --group
    sp = pd.read_csv(out / "sem_paths.csv", keep_default_na=False)
    assert set(sp["hypothesis"]) == {"H1", "H2", "H3", ""} and "age" in set(sp["predictor"])
    assert (out / "sem.lav").read_text().splitlines()[-1] == "BI ~ age + PE + EE + SI"


def test_cli_extended_refuses_a_small_group_and_writes_nothing(cli, tmp_path):
    out = tmp_path / "ext"
    r = cli("analyze", "extended", "--responses", REPO / "data" / "reference" / "survey.csv", "--study", PAPER,
            "--attributes", REPO / "data" / "reference" / "participants.csv", "--group", "style", "--out", out,
            "--bootstrap", "10", "--workers", "1", db=None)
    assert r.code == 2 and not out.exists()
    assert r.err.strip().count("\n") == 0 and "too small" in r.err


@pytest.mark.slow
def test_cli_extended_from_the_paper_store(cli, paper_db, tmp_path):
    people = pd.read_csv(REPO / "data" / "reference" / "participants.csv", dtype={"participant_id": str})
    survey_ids = set(pd.read_csv(REPO / "data" / "reference" / "survey.csv", dtype={"participant_id": str})
                     ["participant_id"])
    for row in people[people["participant_id"].isin(survey_ids)].itertuples():
        r = cli("participant", "add", row.participant_id, "--attr", f"style={row.style}", db=paper_db)
        assert r.code == 0, r.err
    r = cli("survey", "import", REPO / "data" / "reference" / "survey.csv", db=paper_db)
    assert r.code == 0, r.err
    out = tmp_path / "ext"
    r = cli("analyze", "extended", "--out", out, "--bootstrap", "100", "--workers", "1", db=paper_db)
    assert r.code == 0, r.err
    assert "indirect PEoU -> PU -> ATT" in r.out
    ind = pd.read_csv(out / "indirect.csv")
    assert (ind["n_boot"] == 100).all() and len(ind) == 8
    both = tmp_path / "both"
    r = cli("analyze", "survey", "--extended", "--out", both, "--bootstrap", "100", db=paper_db)
    assert r.code == 0, r.err
    assert "extended survey statistics of" in r.out and "indirect PEoU -> PU -> ATT" in r.out
    # the fit taken from the survey analysis gives the files of a run of its own (only the timings differ)
    files = sorted(p.name for p in out.iterdir() if p.name != "timings.json")
    assert files == sorted(p.name for p in (both / "extended").iterdir() if p.name != "timings.json")
    for name in files:
        assert (both / "extended" / name).read_bytes() == (out / name).read_bytes(), name


def test_cli_survey_extended_refuses_available_case_and_writes_nothing(cli, tmp_path):
    out = tmp_path / "both"
    r = cli("analyze", "survey", "--extended", "--available-case", "--responses",
            REPO / "data" / "reference" / "survey.csv", "--study", PAPER, "--out", out, "--bootstrap", "0", db=None)
    assert r.code == 2 and not out.exists()
    assert r.err == ("pedas-study: error: --extended builds on the listwise analysis; it does not go with "
                     "--available-case\n")

"""Improper solutions are said, never silent: the admissibility warnings of every fit, the ordinal CFA's refusal of
empty categories, HTMT2 at a zero correlation and the invariance verdict, on the two small data sets of
tests/data/admissibility/ (N = 35, 4 % missing; generate.py) and checked against lavaan 0.6-14
(lavaan_reference.R wrote lavaan_reference.csv; one test reruns it when Rscript and lavaan are installed)."""
from __future__ import annotations

import doctest
import importlib
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.survey import ordinal as O
from analysis.survey.extended import analyze_extended
from analysis.survey.htmt import _htmt_stack, htmt2, reliability_bootstrap
from analysis.survey.invariance import invariance
from analysis.survey.scoring import score_responses
from analysis.survey.sem import fit_sem, structural_paths
from study.folder.definition import load

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "admissibility"
PAPER = REPO / "studies" / "pedas_paper"


@pytest.fixture(scope="module")
def study():
    return load(PAPER)


@pytest.fixture(scope="module")
def lavaan():
    return pd.read_csv(DATA / "lavaan_reference.csv", keep_default_na=False)


def _set(name, study):
    raw = pd.read_csv(DATA / f"set_b_{name}.csv", dtype={"participant_id": str})
    return raw, score_responses(raw, study.instrument()).scored, {c: list(v) for c, v in study.model.measurement.items()}


def _ref(lavaan, ds, quantity, key=None):
    r = lavaan[(lavaan["dataset"] == ds) & (lavaan["quantity"] == quantity)]
    return r if key is None else r[r["key"] == key]


@pytest.mark.parametrize("module", ["admissibility", "invariance", "ordinal", "htmt", "cfa"])
def test_docstring_examples(module):
    res = doctest.testmod(importlib.import_module(f"analysis.survey.{module}"),
                          optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0 and res.attempted > 0


def test_generator_writes_the_committed_files(tmp_path):
    import runpy

    mod = runpy.run_path(str(DATA / "generate.py"))
    for kind in mod["SEED"]:
        got = mod["_answers"](kind)
        committed = pd.read_csv(DATA / f"set_b_{kind}.csv", dtype={"participant_id": str})
        assert got.shape == (35, 26) and int(got.iloc[:, 1:].isna().sum().sum()) == 35   # 4 % of 875 cells
        assert list(got["participant_id"]) == list(committed["participant_id"])
        pd.testing.assert_frame_equal(got.iloc[:, 1:].astype("float64"), committed.iloc[:, 1:].astype("float64"))


def test_set_b_sem_is_a_heywood_case_and_says_so(study, lavaan):
    _, scored, meas = _set("heywood", study)
    assert len(scored) == 32
    sem = fit_sem(scored, meas, structural_paths(study.model), study.model.hypotheses)
    assert sem.converged and not sem.admissible
    assert "SEM: Heywood case: error variance of PBC1 = 0 (<= 0)" in sem.warnings
    assert "SEM: R^2 of BI = 1.0000 (residual variance at its bound)" in sem.warnings
    # lavaan, unbounded, makes these variances negative and warns; every variance semopy stops at its bound 0 is
    # one lavaan makes negative (PEoU1 -0.509, PBC1 -0.412; lavaan's SN2 -0.060 is positive in our bounded solution)
    ev = _ref(lavaan, "heywood", "sem_error_var").set_index("key")["value"].astype(float)
    ours = {w.split("error variance of ")[1].split(" ")[0] for w in sem.warnings if "error variance of" in w}
    assert ours == {"PEoU1", "PBC1"} and all(ev[i] < 0 for i in ours)
    assert ev["PBC1"] == pytest.approx(-0.41209074057739609, abs=1e-9)
    msgs = " ".join(_ref(lavaan, "heywood", "sem_message")["text"])
    assert "some estimated ov variances are negative" in msgs and "some estimated lv variances are negative" in msgs


def test_set_b_ordinal_cfa_latent_correlation_above_one_is_improper(study, lavaan):
    _, scored, meas = _set("heywood", study)
    poly = O.polychoric(scored, [i for v in meas.values() for i in v])
    for est, lav in (("ULS", "ULSMV"), ("DWLS", "WLSMV")):
        fit = O.fit_ordinal_cfa(scored, meas, estimator=est, poly=poly)
        r = fit.latent_corr.loc["PU", "ATT"]
        assert r > 1 and r == pytest.approx(float(_ref(lavaan, "heywood", f"ordinal_cor_lv_{lav}", "PU-ATT")["value"]
                                                   .iloc[0]), abs=1e-5)
        assert fit.converged and not fit.admissible
        assert f"ordinal CFA ({est}): latent covariance matrix is not positive definite (largest latent correlation " \
               f"PU-ATT = {r:.3f})" in fit.warnings
        assert "is not positive definite" in " ".join(_ref(lavaan, "heywood", f"ordinal_message_{lav}")["text"])
        # SRMR as lavaan's categorical srmr: the residual correlations over p(p+1)/2 elements
        assert fit.fit["srmr"] == pytest.approx(float(_ref(lavaan, "heywood", f"ordinal_srmr_{lav}")["value"].iloc[0]),
                                                abs=1e-6)


def test_ordinal_cfa_refuses_an_empty_category_as_lavaan(study, lavaan):
    raw, scored, meas = _set("empty_category", study)
    full = score_responses(raw, study.instrument(), listwise=False).scored
    cats = {it: sorted(full[it].dropna().unique()) for it in full.columns}
    with pytest.raises(ValueError) as e:
        O.fit_ordinal_cfa(scored, meas, estimator="ULS", categories=cats)
    assert str(e.value) == ("ordinal CFA: some categories of item PU1 are empty among the 32 complete rows (answers "
                            "1 2 3 4 5: frequencies [0 8 12 8 4]); pass collapse_empty (CLI: --collapse-empty of "
                            "`analyze extended` or `analyze survey --extended`) to merge them")
    for lav in ("ULSMV", "WLSMV"):
        assert ("some categories of variable `PU1' are empty" in
                _ref(lavaan, "empty_category", f"ordinal_message_{lav}")["text"].iloc[0])
    with pytest.raises(ValueError, match="categories of item PU1 are empty"):
        analyze_extended(raw, study, n_boot=0, workers=1)
    fit = O.fit_ordinal_cfa(scored, meas, estimator="ULS", categories=cats, collapse_empty=True)
    assert fit.warnings[0] == ("ordinal CFA: item PU1: empty category 1 among the 32 complete rows collapsed "
                               "(4 of 5 categories analysed)")
    assert len(fit.poly.thresholds["PU1"]) == 3
    # collapsed, it is the fit on the categories the complete rows use (no categories given)
    plain = O.fit_ordinal_cfa(scored, meas, estimator="ULS")
    assert plain.warnings == fit.warnings[1:]
    pd.testing.assert_frame_equal(plain.loadings, fit.loadings)


def test_cli_collapses_only_when_asked(cli, tmp_path):
    resp = DATA / "set_b_empty_category.csv"
    r = cli("analyze", "extended", "--responses", resp, "--study", PAPER, "--out", tmp_path / "a", "--bootstrap", "0",
            "--workers", "1", db=None)
    assert r.code == 2 and r.err.strip().count("\n") == 0 and "categories of item PU1 are empty" in r.err
    assert not (tmp_path / "a").exists()
    r = cli("analyze", "extended", "--responses", resp, "--study", PAPER, "--out", tmp_path / "b", "--bootstrap", "0",
            "--workers", "1", "--collapse-empty", db=None)
    assert r.code == 0, r.err
    warn = (tmp_path / "b" / "warnings.txt").read_text().splitlines()
    assert warn[0].startswith("ordinal CFA: item PU1: empty category 1 among the 32 complete rows collapsed")
    fit = pd.read_csv(tmp_path / "b" / "ordinal_fit.csv")
    assert list(fit["admissible"]) == [False, False]   # PU-ATT latent matrix not positive definite (lavaan agrees)


def test_htmt2_is_undefined_at_a_zero_monotrait_correlation():
    # x1, x2 correlate exactly 0 (cross-products cancel); numpy gives ~1e-17 for it
    items = pd.DataFrame({"x1": [1, 2, 3, 4, 1, 2, 3, 4], "x2": [1, 2, 2, 1, 1, 2, 2, 1],
                          "y1": [1, 2, 4, 3, 2, 1, 4, 3], "y2": [2, 1, 4, 4, 2, 1, 3, 4]})
    cons = {"X": ["x1", "x2"], "Y": ["y1", "y2"]}
    assert abs(np.corrcoef(items["x1"], items["x2"])[0, 1]) < 1e-15
    tab = htmt2(items, cons)
    assert np.isnan(tab["htmt2"].iloc[0]) and not tab["above_085"].iloc[0]
    R = np.array([[[1, 1e-17, .5, .5], [1e-17, 1, .5, .5], [.5, .5, 1, .8], [.5, .5, .8, 1]]])
    assert np.isnan(_htmt_stack(R, cons, ["x1", "x2", "y1", "y2"], True)[0, 0])   # was .5 / sqrt(1e-17 x .8) = 1.8e8
    R[0, 2, 0] = R[0, 0, 2] = 1e-17
    R[0, 0, 1] = R[0, 1, 0] = .6
    het = np.exp(np.mean(np.log([0.0 + 1e-300, .5, .5, .5])))  # a zero heterotrait r: its limit 0
    assert _htmt_stack(R, cons, ["x1", "x2", "y1", "y2"], True)[0, 0] == pytest.approx(0.0, abs=het)
    boot = reliability_bootstrap(items, cons, n_boot=200, seed=1)
    h2 = boot[boot["statistic"] == "htmt2"].iloc[0]
    assert h2["n_failed"] > 0 and (not np.isfinite(h2["ci_high"]) or h2["ci_high"] < 10)


def test_invariance_says_when_configural_fit_is_poor(study):
    data = pd.read_csv(REPO / "tests" / "data" / "r_reference" / "invariance_survey.csv", dtype={"participant_id": str})
    scored = score_responses(data.drop(columns="style"), study.instrument()).scored
    # a wrong measurement model: PU's and SN's items on one factor
    wrong = {"A": ["PU1", "PU2", "PU3", "PU4", "SN1", "SN2", "SN3"], "B": ["PBC1", "PBC2", "PBC3", "BI1", "BI2"]}
    res = invariance(scored, wrong, data.set_index("participant_id")["style"], group_var="style")
    st = res.steps.set_index("step")
    assert st.loc["configural", "cfi"] < 0.90 and list(st["holds"]) == [False, False, False]
    assert st.loc["configural", "reason"].startswith(f"CFI {st.loc['configural', 'cfi']:.3f} < 0.90")
    assert st.loc["metric", "reason"] == "the configural step does not hold"
    assert any(w.startswith("invariance configural: the configural model fits poorly (CFI ") for w in res.warnings)


@pytest.mark.skipif(shutil.which("Rscript") is None, reason="Rscript not installed")
def test_lavaan_reference_reruns(tmp_path):
    ok = subprocess.run(["Rscript", "-e", "library(lavaan)"], capture_output=True).returncode == 0
    if not ok:
        pytest.skip("lavaan not installed")
    copy = tmp_path / "tests" / "data" / "admissibility"
    copy.mkdir(parents=True)
    for f in ("lavaan_reference.R", "set_b_heywood.csv", "set_b_empty_category.csv"):
        shutil.copy(DATA / f, copy / f)
    (tmp_path / "tests" / "data" / "r_reference").mkdir()
    shutil.copy(REPO / "tests" / "data" / "r_reference" / "paper_sem.lav", tmp_path / "tests" / "data" / "r_reference")
    subprocess.run(["Rscript", str(copy / "lavaan_reference.R")], check=True, capture_output=True)
    new = pd.read_csv(copy / "lavaan_reference.csv", keep_default_na=False)
    old = pd.read_csv(DATA / "lavaan_reference.csv", keep_default_na=False)
    assert list(new["quantity"]) == list(old["quantity"])
    nv, ov = pd.to_numeric(new["value"], errors="coerce"), pd.to_numeric(old["value"], errors="coerce")
    np.testing.assert_allclose(nv.to_numpy(), ov.to_numpy(), rtol=1e-8, atol=1e-10)


# ---------------------------------------------------------------------------------------------- singular samples
def _duplicated(study, tweak: bool):
    """The R reference survey (N = 40) with PU2 a copy of PU1; `tweak`: 20 copies of it with one PU2 answer one step
    higher, so that r(PU1, PU2) = .9991 (near-singular, not singular)."""
    raw = pd.read_csv(REPO / "tests" / "data" / "r_reference" / "survey.csv", dtype={"participant_id": str})
    if tweak:
        raw = pd.concat([raw] * 20, ignore_index=True)
        raw["participant_id"] = [f"P{i + 1:03d}" for i in range(len(raw))]
    raw["PU2"] = raw["PU1"]
    if tweak:
        raw.loc[raw.index[raw["PU1"] < 5][0], "PU2"] += 1
    return score_responses(raw, study.instrument()).scored, {c: list(v) for c, v in study.model.measurement.items()}


@pytest.mark.parametrize("tweak, r", [(False, "1.0000"), (True, "0.9991")])
def test_a_duplicated_item_is_named_in_every_fit_and_semopy_prints_nothing(study, capfd, tweak, r):
    """lavaan 0.6-14 on the same data (WLSMV): "correlation between variables PU2 and PU1 is (nearly) 1.0"; ML on
    the exact copy: no solution found. Here every fit names the pair; semopy's nearPD notice is a warning, not
    stderr."""
    from analysis.survey.cfa import fit_cfa

    scored, meas = _duplicated(study, tweak)
    named = f"(nearly) singular: items PU1 and PU2 correlate {r} (|r| >= 0.999)"
    ml = fit_cfa(scored, meas, label="final")
    assert f"CFA final: sample covariance matrix {named}" in ml.warnings[0]
    assert any("semopy: Sample covariance matrix is not PD" in w for w in ml.warnings) != tweak
    for est in ("ULS", "DWLS"):
        fit = O.fit_ordinal_cfa(scored, meas, estimator=est)
        assert f"ordinal CFA ({est}): polychoric correlation matrix (nearly) singular: items PU1 and PU2" \
               in fit.warnings[0] and not fit.admissible
    sem = fit_sem(scored, meas, structural_paths(study.model))
    assert sem.warnings[0].startswith(f"SEM: sample covariance matrix {named}") and not sem.admissible
    assert capfd.readouterr().err == ""


def test_a_linear_combination_is_named_singular():
    from analysis.survey.admissibility import singular_sample

    rng = np.random.default_rng(3)
    x = pd.DataFrame(rng.normal(size=(50, 3)), columns=["a", "b", "c"])
    x["d"] = x["a"] + x["b"] - x["c"]
    (w,) = singular_sample("CFA: ", x.cov(ddof=0))
    assert w.startswith("CFA: sample covariance matrix singular (smallest eigenvalue of the item correlations")
    assert singular_sample("CFA: ", x[["a", "b", "c"]].cov()) == []

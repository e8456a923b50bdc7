"""The extended acceptance statistics (analysis/survey/extended.py) against R: lavaan 0.6-14 and semTools 0.5-6.

tests/data/r_reference/ holds the R script ``extended_reference.R``, its output ``extended_reference.csv``
(committed; R is not needed to run these tests), the model syntax it reads (``paper_sem.lav``, ``paper_paths.lav``,
``lk_sem.lav``, ``lk_paths.lav``: written from the model files by :func:`write_inputs`, checked below to be what the
analysis fits) and the invariance data ``invariance_survey.csv`` (240 seeded synthetic respondents of the paper's
study with a style column). ``python tests/analysis/test_extended_reference.py`` writes these inputs again. When Rscript is
installed, one test reruns the script into a temporary copy and compares it with the committed fixture.

Tolerances (docs/acceptance_statistics.md records the observed differences): polychoric correlations 1e-6;
ULS (= lavaan ULSMV) and DWLS (= lavaan WLSMV) loadings and ordinal omega 1e-5; omega (ML on the lane-keeping data,
one-factor) 1e-5, ML omega on the paper's improper solution 5e-3; HTMT/HTMT2 1e-10; latent SEM (lane-keeping data)
standardized paths and R^2 1e-4, fit 1e-5 (chi2 relative); composite path betas and indirect effects 1e-10; full VIF
and Harman 1e-10; invariance chi2 (relative) 1e-6, CFI/TLI/RMSEA 1e-6.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.survey.extended import analyze_extended
from analysis.survey.invariance import invariance
from analysis.survey.scoring import score_responses
from analysis.survey.testing import simulate_study_participants, simulate_study_responses
from study.folder.definition import load
from tests.conftest import needs_r, python_under_kernel

REPO = Path(__file__).resolve().parents[2]
REF = REPO / "tests" / "data" / "r_reference"
PAPER = REPO / "studies" / "pedas_paper"
LK = REPO / "studies" / "lane_keeping"
INV_N, INV_SEED = 240, 7


def _paper_inputs():
    # a frozen copy of the reference survey the R fixtures were computed on (data/reference/survey.csv is
    # regenerated whenever the reconstruction changes; R is not available to recompute the fixtures)
    survey = pd.read_csv(REF / "survey.csv", dtype={"participant_id": str})
    return survey, None


def _lk_inputs():
    survey = pd.read_csv(REPO / "tests" / "data" / "lane_keeping" / "survey.csv", dtype={"participant_id": str})
    people = pd.read_csv(REPO / "tests" / "data" / "lane_keeping" / "participants.csv", dtype={"participant_id": str})
    return survey.drop(columns="AGE"), people


def invariance_data() -> pd.DataFrame:
    """The generator of the committed invariance data: seeded answers of the paper's study and the participants'
    style. Drawn with numpy's multivariate_normal, as the generator did when the R references were computed: the
    same bits only under the OpenBLAS kernel the file was written with (Haswell; see
    test_committed_invariance_data_are_the_generators). The tests read the committed file."""
    study = load(PAPER)
    answers = simulate_study_responses(study, INV_N, INV_SEED, latent="numpy-svd")
    people = simulate_study_participants(study, INV_N, INV_SEED)
    return answers.assign(style=people["style"].to_numpy())


@pytest.fixture(scope="module")
def reference() -> pd.DataFrame:
    return pd.read_csv(REF / "extended_reference.csv", keep_default_na=False,
                       dtype={"dataset": str, "quantity": str, "key": str})


def ref(reference, dataset, quantity) -> dict[str, float]:
    sel = reference[(reference["dataset"] == dataset) & (reference["quantity"] == quantity)]
    assert len(sel), (dataset, quantity)
    return dict(zip(sel["key"], pd.to_numeric(sel["value"])))


@pytest.fixture(scope="module")
def paper_ext():
    survey, people = _paper_inputs()
    return analyze_extended(survey, PAPER, attributes=people, n_boot=200, seed=1, workers=1)


@pytest.fixture(scope="module")
def lk_ext():
    survey, people = _lk_inputs()
    return analyze_extended(survey, LK, attributes=people, n_boot=200, seed=1, workers=1)


def write_inputs() -> None:
    """Write the model syntax files and the invariance data the R script reads."""
    REF.mkdir(parents=True, exist_ok=True)
    for tag, (survey, people), study in (("paper", _paper_inputs(), PAPER), ("lk", _lk_inputs(), LK)):
        ext = analyze_extended(survey, study, attributes=people, n_boot=0, workers=1)
        (REF / f"{tag}_sem.lav").write_text(ext.specs["sem"] + "\n")
        (REF / f"{tag}_paths.lav").write_text(ext.specs["path_model"] + "\n")
    invariance_data().to_csv(REF / "invariance_survey.csv", index=False, lineterminator="\n")


def _close(ours: dict, theirs: dict, tol: float, what: str) -> float:
    assert set(theirs) <= set(ours), f"{what}: missing {sorted(set(theirs) - set(ours))}"
    worst = 0.0
    for k, v in theirs.items():
        d = abs(ours[k] - v)
        worst = max(worst, d)
        assert d <= tol, f"{what} {k}: ours {ours[k]!r}, R {v!r} (|d| = {d:.3g} > {tol:g})"
    return worst


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_committed_model_syntax_is_what_the_analysis_fits(tag, paper_ext, lk_ext):
    ext = paper_ext if tag == "paper" else lk_ext
    assert (REF / f"{tag}_sem.lav").read_text() == ext.specs["sem"] + "\n"
    assert (REF / f"{tag}_paths.lav").read_text() == ext.specs["path_model"] + "\n"


def test_committed_invariance_data_are_the_generators():
    out = python_under_kernel("Haswell", "import sys; from tests.analysis.test_extended_reference import invariance_data; "
                                         "sys.stdout.write(invariance_data().to_csv(index=False, lineterminator='\\n'))")
    assert (REF / "invariance_survey.csv").read_text() == out


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_ordinal_cfa_and_omega_agree_with_lavaan(tag, reference, paper_ext, lk_ext):
    from analysis.survey import ordinal as _ord

    ext = paper_ext if tag == "paper" else lk_ext
    study = load(PAPER if tag == "paper" else LK)
    survey, _ = _paper_inputs() if tag == "paper" else _lk_inputs()
    scored = score_responses(survey, study.instrument()).scored
    items = list(ext.ordinal_loadings["item"])
    poly = _ord.polychoric(scored, items, acov=False)
    ours = {f"{a}-{b}": poly.R.loc[a, b] for i, a in enumerate(items) for b in items[i + 1:]}
    w = {"polychoric": _close(ours, ref(reference, tag, "polychoric"), 1e-6, "polychoric")}
    lo = ext.ordinal_loadings.set_index("item")
    w["uls"] = _close(lo["loading_uls"].to_dict(), ref(reference, tag, "loading_ULSMV"), 1e-5, "ULS loading")
    w["dwls"] = _close(lo["loading_dwls"].to_dict(), ref(reference, tag, "loading_WLSMV"), 1e-5, "DWLS loading")
    om = ext.omega.set_index("construct")
    w["omega_ord_uls"] = _close(om["omega_ordinal_uls"].to_dict(), ref(reference, tag, "omega_ordinal_ULSMV"), 1e-5,
                                "ordinal omega (ULS)")
    w["omega_ord_dwls"] = _close(om["omega_ordinal_dwls"].to_dict(), ref(reference, tag, "omega_ordinal_WLSMV"),
                                 1e-5, "ordinal omega (DWLS)")
    # the paper's reference data give an improper ML solution (BI1's error variance: semopy stops at its bound 0,
    # lavaan goes negative; both warn), which moves the ML omega of BI by 0.004 there (others < 2e-4)
    w["omega_ml"] = _close(om["omega_ml"].to_dict(), ref(reference, tag, "omega_ml"), 5e-3 if tag == "paper" else 1e-5,
                           "omega (ML)")
    boot = ext.reliability_boot
    one = boot[boot["statistic"] == "omega"].set_index("a")["estimate"].to_dict()
    w["omega_1f"] = _close(one, ref(reference, tag, "omega_one_factor"), 1e-5, "one-factor omega")
    print(tag, {k: f"{v:.2g}" for k, v in w.items()})


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_htmt_and_htmt2_agree_with_semtools(tag, reference, paper_ext, lk_ext):
    ext = paper_ext if tag == "paper" else lk_ext
    h = ext.htmt2.assign(key=lambda d: d["a"] + "-" + d["b"]).set_index("key")
    _close(h["htmt"].to_dict(), ref(reference, tag, "htmt"), 1e-10, "HTMT")
    _close(h["htmt2"].to_dict(), ref(reference, tag, "htmt2"), 1e-10, "HTMT2")
    boot = ext.reliability_boot
    est = boot[boot["statistic"] == "htmt2"].assign(key=lambda d: d["a"] + "-" + d["b"]).set_index("key")["estimate"]
    _close(est.to_dict(), ref(reference, tag, "htmt2"), 1e-10, "HTMT2 (bootstrap table)")


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_sem_paths_indirect_effects_and_method_bias_agree_with_r(tag, reference, paper_ext, lk_ext):
    ext = paper_ext if tag == "paper" else lk_ext
    sp = ext.sem_paths.assign(key=lambda d: d["dv"] + "~" + d["predictor"]).set_index("key")
    w = {}
    if tag == "paper":
        # the paper's reference data make the latent SEM improper (PU-ATT latent r ~ .95, BI's residual variance at
        # its bound in semopy, negative in lavaan): two different boundary solutions; both warn, ours says so
        assert any("R^2 of BI" in x for x in ext.warnings) and any("|beta| >= 1" in x for x in ext.warnings)
    else:
        w["sem_std"] = _close(sp["std"].to_dict(), ref(reference, tag, "sem_std"), 1e-4, "SEM std path")
        w["sem_r2"] = _close(ext.sem_r2.set_index("variable")["r2"].to_dict(), ref(reference, tag, "sem_r2"), 1e-4,
                             "SEM R^2")
        fit = ext.sem_fit.iloc[0]
        r_fit = ref(reference, tag, "sem_fit")
        assert int(fit["df"]) == int(r_fit["df"])
        assert abs(fit["chi2"] - r_fit["chisq"]) <= 1e-5 * r_fit["chisq"]
        w["sem_fit"] = _close({q: fit[q] for q in ("cfi", "tli", "rmsea", "srmr")},
                              {q: r_fit[q] for q in ("cfi", "tli", "rmsea", "srmr")}, 1e-5, "SEM fit")
    w["path_std"] = _close(sp["std_composite"].to_dict(), ref(reference, tag, "path_std"), 1e-10, "path beta")
    ind = ext.indirect[~ext.indirect["chain"].str.contains("total")]
    if tag == "lk":  # one equation: no mediator, no indirect effect
        assert ext.indirect.empty
    else:
        assert list(ind["chain"]) == ["PEoU -> PU -> ATT", "PEoU -> PU -> ATT -> BI", "PEoU -> PU -> BI",
                                      "PEoU -> ATT -> BI", "PU -> ATT -> BI"]
        b = {c.replace(" -> ", "_"): v for c, v in zip(ind["chain"], ind["b"])}
        w["indirect_b"] = _close(b, ref(reference, tag, "indirect_b"), 1e-10, "indirect effect (b)")
        # standardized indirect effect = product of the R betas along the chain
        rb = ref(reference, tag, "path_std")
        std = {c: float(np.prod([rb[f"{ch[i + 1]}~{ch[i]}"] for i in range(len(ch) - 1)]))
               for c, ch in ((c, c.split(" -> ")) for c in ind["chain"])}
        w["indirect_std"] = _close(dict(zip(ind["chain"], ind["std"])), std, 1e-10, "indirect effect (std)")
        assert (ind["ci_low"] <= ind["std"]).all() and (ind["std"] <= ind["ci_high"]).all()
    w["full_vif"] = _close(ext.full_vif.set_index("construct")["vif"].to_dict(), ref(reference, tag, "full_vif"),
                           1e-10, "full VIF")
    w["harman"] = _close({"first_share": ext.harman.loc[0, "first_share"]}, ref(reference, tag, "harman"), 1e-10,
                         "Harman")
    print(tag, {k: f"{v:.2g}" for k, v in w.items()})


def test_invariance_steps_agree_with_lavaan(reference):
    data = pd.read_csv(REF / "invariance_survey.csv", dtype={"participant_id": str, "style": str})
    study = load(PAPER)
    scored = score_responses(data.drop(columns="style"), study.instrument()).scored
    groups = data.set_index("participant_id")["style"]
    res = invariance(scored, {c: list(v) for c, v in study.model.measurement.items()}, groups, group_var="style")
    assert res.steps["converged"].all(), res.warnings
    for step in ("configural", "metric", "scalar"):
        r = ref(reference, "inv", step)
        ours = res.steps.set_index("step").loc[step]
        assert int(ours["df"]) == int(r["df"]), step
        assert abs(ours["chi2"] - r["chisq"]) <= 1e-6 * r["chisq"], (step, ours["chi2"], r["chisq"])
        for q in ("cfi", "tli", "rmsea"):
            assert abs(ours[q] - r[q]) <= 1e-6, (step, q, ours[q], r[q])
    print(res.steps[["step", "chi2", "df", "cfi", "delta_chi2", "p_delta", "delta_cfi", "holds"]].to_string())


@needs_r("lavaan", "semTools")
def test_r_script_reproduces_the_committed_fixture(tmp_path):
    work = tmp_path / "r_reference"
    shutil.copytree(REF, work)
    # the script resolves the repository from its own location: run a copy placed at the same depth
    repo_copy = tmp_path / "repo"
    (repo_copy / "tests" / "data").mkdir(parents=True)
    shutil.copytree(work, repo_copy / "tests" / "data" / "r_reference")
    for sub in ("studies", "data/reference", "tests/data/lane_keeping"):
        shutil.copytree(REPO / sub, repo_copy / sub)
    (repo_copy / "tests" / "data" / "r_reference" / "extended_reference.csv").unlink()
    p = subprocess.run(["Rscript", str(repo_copy / "tests" / "data" / "r_reference" / "extended_reference.R")],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    new = pd.read_csv(repo_copy / "tests" / "data" / "r_reference" / "extended_reference.csv", keep_default_na=False)
    old = pd.read_csv(REF / "extended_reference.csv", keep_default_na=False)
    assert list(new["key"]) == list(old["key"])
    np.testing.assert_allclose(pd.to_numeric(new["value"]), pd.to_numeric(old["value"]), rtol=1e-8, atol=1e-10,
                               equal_nan=True)


if __name__ == "__main__":  # write the inputs of the R script again
    write_inputs()
    print(f"wrote the model syntax and invariance_survey.csv to {REF}")

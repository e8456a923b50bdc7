"""The report's reviewer statistics against R (base R, car, lmtest, lavaan): paired t-tests with their CIs and d_z,
Wilcoxon signed-rank tests (with ties and zeros), the condition x group mixed ANOVA, the regression diagnostics
(Shapiro-Wilk, Breusch-Pagan, Cook's D, VIF, the CI of beta and of f^2) and the RMSEA's 90 % interval.

tests/data/r_reference/ holds the R script ``statistics_reference.R``, its output ``statistics_reference.csv``
(committed; R is not needed to run these tests) and two inputs: ``paper_drive_pairs.csv`` (the per-participant KPIs
of the paper study's simulated reference cohort, both drives, as the report writes drives/per_participant.csv) and
``takeover_times.csv`` (takeover time per participant and condition from the seeded logs of tests/takeover_logs.py;
``python tests/analysis/test_statistics_reference.py`` writes it again). When Rscript is installed, one test reruns
the script into a temporary copy and compares it with the committed fixture.

Tolerances: paired t, CI, d_z, mixed ANOVA F and p 1e-10 (relative for F); Wilcoxon V exact, p 1e-12; Shapiro-Wilk
1e-6 (scipy and R implement Royston's algorithm separately); Breusch-Pagan, Cook's D, VIF, beta CI 1e-9; f^2 CI 1e-6
(scipy's and R's noncentral F differ in the 8th digit); RMSEA CI against exact roots from lavaan's chi^2 1e-6 (the
chi^2 of our ML fit and lavaan's differ in the 6th digit on the paper's improper solution), against fitMeasures'
printout 1e-4 (lavaan's root search stops at a tolerance of ~1e-4 on lambda).
"""
from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.survey.acceptance import analyze_survey
from analysis.survey.cfa import rmsea_ci
from analysis.survey.diagnostics import regression_diagnostics
from analysis.survey.paired import mixed_anova, paired_comparison
from analysis.survey.statistics_tables import models_of
from study.folder.definition import load
from tests.conftest import needs_r

REPO = Path(__file__).resolve().parents[2]
REF = REPO / "tests" / "data" / "r_reference"
CONDITIONS = ("none", "visual", "audiovisual")


def takeover_times() -> pd.DataFrame:
    """participant, condition, takeover_time (s): from the takeover request's first sample to the first sample with
    the hands on the wheel, in the seeded 20 Hz logs (tests/takeover_logs.py) of the takeover data's participants."""
    from tests.takeover_logs import make_log

    scores = pd.read_csv(REPO / "tests" / "data" / "takeover" / "scores.csv")
    rows = []
    for p, c in scores[["participant", "condition"]].itertuples(index=False):
        log = make_log(p, c)
        t = log["time_ms"].to_numpy() / 1000.0
        rows.append({"participant": p, "condition": c,
                     "takeover_time": float(t[np.argmax(log["hands_on"].to_numpy() == 1)]
                                            - t[np.argmax(log["tor"].to_numpy() == 1)])})
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def reference() -> pd.DataFrame:
    return pd.read_csv(REF / "statistics_reference.csv", dtype={"key": str})


def ref(reference, dataset, quantity) -> dict[str, float]:
    sel = reference[(reference["dataset"] == dataset) & (reference["quantity"] == quantity)]
    return {k: float(v) for k, v in zip(sel["key"], sel["value"])}


def _gap(ours: dict, theirs: dict, what: str) -> float:
    assert set(theirs) <= set(ours), f"{what}: no value of ours for {sorted(set(theirs) - set(ours))[:5]}"
    assert theirs, f"{what}: no reference values"
    return max(abs(ours[k] - theirs[k]) for k in theirs)


def _close(ours: dict, theirs: dict, tol: float, what: str, rel: bool = False) -> float:
    worst = 0.0
    for k, v in theirs.items():
        assert k in ours, f"{what} {k}: missing"
        err = abs(ours[k] - v) / (max(abs(v), 1.0) if rel else 1.0)
        assert err <= tol, f"{what} {k}: ours {ours[k]!r} vs R {v!r}"
        worst = max(worst, err)
    return worst


# ---------------------------------------------------------------------------------------------- inputs
def test_committed_takeover_times_are_the_generators():
    committed = pd.read_csv(REF / "takeover_times.csv")
    pd.testing.assert_frame_equal(committed, takeover_times(), check_exact=False, rtol=0, atol=1e-12)


def test_reference_survey_is_the_one_r_saw(reference):
    md5 = reference[(reference["dataset"] == "paper") & (reference["quantity"] == "input_md5")]["value"].iloc[0]
    ours = hashlib.md5((REPO / "data" / "reference" / "survey.csv").read_bytes()).hexdigest()
    assert ours == md5, "data/reference/survey.csv changed: rerun Rscript tests/data/r_reference/statistics_reference.R"


# ---------------------------------------------------------------------------------------------- paired
def _paired_ours(dataset: str) -> tuple[dict[str, dict], dict[str, dict]]:
    """key -> paired_comparison, key -> mixed ANOVA rows, for the drives or the takeover data."""
    out, anova = {}, {}
    if dataset == "drives":
        d = pd.read_csv(REF / "paper_drive_pairs.csv", dtype={"participant_id": str})
        for a in [c for c in d.columns if "_baseline" in c]:
            key = a.replace("_baseline", "", 1)
            x, y = d[a].to_numpy(float), d[a.replace("_baseline", "_pedas", 1)].to_numpy(float)
            out[key] = paired_comparison(x, y)
            if out[key]["sd_diff"] > 0:
                long = pd.DataFrame({"participant": np.tile(d["participant_id"], 2),
                                     "group": np.tile(d["style"], 2), "condition": np.repeat(["a", "b"], len(d)),
                                     "value": np.concatenate([x, y])})
                anova[key] = mixed_anova(long).set_index("source")
        return out, anova
    scores = pd.read_csv(REPO / "tests" / "data" / "takeover" / "scores.csv")
    long = scores.merge(takeover_times(), on=["participant", "condition"])
    wide = {v: long.pivot(index="participant", columns="condition", values=v).dropna()
            for v in ("sus", "tlx", "trust", "takeover_time")}
    for v, w in wide.items():
        for i, a in enumerate(CONDITIONS):
            for b in CONDITIONS[i + 1:]:
                out[f"{v}.{a}-{b}"] = paired_comparison(w[a].to_numpy(), w[b].to_numpy())
    return out, anova


@pytest.mark.parametrize("dataset", ["drives", "takeover"])
def test_paired_t_ci_dz_and_wilcoxon_agree_with_r(dataset, reference):
    ours, _ = _paired_ours(dataset)
    for field, tol in (("mean_diff", 1e-10), ("ci_low", 1e-10), ("ci_high", 1e-10), ("t", 1e-10), ("df", 0),
                       ("p_t", 1e-12), ("dz", 1e-12), ("v", 0), ("p_wilcoxon", 1e-12)):
        theirs = ref(reference, dataset, field)
        _close({k: float(r[field]) for k, r in ours.items()}, theirs, tol, f"{dataset} {field}", rel=field == "t")
    exact = ref(reference, dataset, "wilcoxon_exact")
    assert {k: float(ours[k]["wilcoxon_method"] == "exact") for k in exact} == exact


def test_ties_and_zeros_are_exercised(reference):
    """The references hold Wilcoxon tests by the normal approximation (ties or zeros) and exact ones, and at least
    one case where R on the raw values splits a tie that float noise made (fractional scores), which the grid
    does not."""
    exact = {**ref(reference, "drives", "wilcoxon_exact"), **ref(reference, "takeover", "wilcoxon_exact")}
    assert 0 < sum(exact.values()) < len(exact)
    raw, grid = ref(reference, "takeover", "p_wilcoxon_raw"), ref(reference, "takeover", "p_wilcoxon")
    assert any(abs(raw[k] - grid[k]) > 1e-6 for k in grid)


def test_mixed_anova_agrees_with_aov(reference):
    _, ours = _paired_ours("drives")
    for effect, source in (("group", "group"), ("condition", "condition"), ("interaction", "condition × group")):
        _close({k: float(t.loc[source, "f"]) for k, t in ours.items()}, ref(reference, "drives", f"anova_f_{effect}"),
               1e-9, f"F {effect}", rel=True)
        _close({k: float(t.loc[source, "p"]) for k, t in ours.items()}, ref(reference, "drives", f"anova_p_{effect}"),
               1e-10, f"p {effect}")


# ---------------------------------------------------------------------------------------------- survey
@pytest.fixture(scope="module")
def surveys():
    """dataset -> (steps, coefficients, cooks distances by 'model.step.participant', fit frame) of our analysis."""
    out = {}
    paper = load(REPO / "studies" / "pedas_paper")
    answers = pd.read_csv(REPO / "data" / "reference" / "survey.csv", dtype={"participant_id": str})
    lk = load(REPO / "studies" / "lane_keeping")
    lk_answers = pd.read_csv(REPO / "tests" / "data" / "lane_keeping" / "survey.csv", dtype={"participant_id": str})
    people = pd.read_csv(REPO / "tests" / "data" / "lane_keeping" / "participants.csv", dtype={"participant_id": str})
    for tag, study, data, attrs in (("paper", paper, answers, None), ("lk", lk, lk_answers.drop(columns="AGE"), people)):
        res = analyze_survey(data, study, attributes=attrs, n_boot=0)
        comp = res.composites
        if attrs is not None:
            comp = comp.join(attrs.set_index("participant_id")[["age"]].astype(float))
        models = models_of(res.settings)
        steps, coefs = regression_diagnostics(comp, models)
        out[tag] = (steps, coefs, _cooks(comp, models), res.fit)
    return out


def _cooks(data: pd.DataFrame, models) -> dict[str, float]:
    from analysis.survey.diagnostics import cooks_distance
    from analysis.survey.regression import ols

    out = {}
    for i, m in enumerate(models, start=1):
        for s in range(1, len(m.steps) + 1):
            d = data[[m.dv] + m.predictors(len(m.steps))].dropna()
            X = d[m.predictors(s)].to_numpy(float)
            for pid, v in zip(d.index, cooks_distance(ols(d[m.dv].to_numpy(float), X), X)):
                out[f"{i}.{s}.{pid}"] = float(v)
    return out


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_regression_diagnostics_agree_with_r(tag, reference, surveys):
    steps, coefs, cooks, _ = surveys[tag]
    models = {m: i for i, m in enumerate(dict.fromkeys(steps["model"]), start=1)}
    key = [f"{models[m]}.{s}" for m, s in zip(steps["model"], steps["step"])]
    ckey = [f"{models[m]}.{s}.{p}" for m, s, p in zip(coefs["model"], coefs["step"], coefs["predictor"])]
    for field, tol in (("shapiro_w", 1e-6), ("shapiro_p", 1e-5), ("bp", 1e-9), ("bp_df", 0), ("bp_p", 1e-9),
                       ("f2", 1e-10), ("f2_ci_low", 1e-6), ("f2_ci_high", 1e-6)):
        _close(dict(zip(key, steps[field].astype(float))), ref(reference, tag, field), tol, f"{tag} {field}")
    _close(cooks, ref(reference, tag, "cooks"), 1e-9, f"{tag} Cook's D")
    multi = {k: v for k, v in zip(ckey, coefs["vif"].astype(float))}
    _close(multi, ref(reference, tag, "vif"), 1e-9, f"{tag} VIF")
    for field in ("beta_ci_low", "beta_ci_high"):
        _close(dict(zip(ckey, coefs[field].astype(float))), ref(reference, tag, field), 1e-9, f"{tag} {field}")
    # an influential case as the report flags it is one R's Cook's D puts above 4/n
    r_cooks = ref(reference, tag, "cooks")
    for row in steps.itertuples():
        k = f"{models[row.model]}.{row.step}."
        theirs = sorted(p[len(k):] for p, v in r_cooks.items() if p.startswith(k) and v > 4.0 / row.n)
        assert sorted(filter(None, row.influential.split(", "))) == theirs


@pytest.mark.parametrize("tag", ["paper", "lk"])
def test_rmsea_interval_agrees_with_lavaan(tag, reference, surveys):
    fit = surveys[tag][3].set_index("stage")
    stages = ref(reference, tag, "cfa_chisq")
    for stage in stages:
        chi2, df, n = (ref(reference, tag, f"cfa_{q}")[stage] for q in ("chisq", "df", "ntotal"))
        # the interval from lavaan's chi^2: equal to the exact roots, and to lavaan's printout within its tolerance
        lo, hi = rmsea_ci(chi2, int(df), int(n))
        assert abs(lo - ref(reference, tag, "cfa_rmsea_ci_exact_low")[stage]) < 1e-9
        assert abs(hi - ref(reference, tag, "cfa_rmsea_ci_exact_high")[stage]) < 1e-9
        assert abs(lo - ref(reference, tag, "cfa_rmsea.ci.lower")[stage]) < 1e-4
        assert abs(hi - ref(reference, tag, "cfa_rmsea.ci.upper")[stage]) < 1e-4
        # and from our own fit's chi^2
        ours = fit.loc[stage]
        assert int(ours["df"]) == int(df) and int(ours["n"]) == int(n)
        lo2, hi2 = rmsea_ci(float(ours["chi2"]), int(ours["df"]), int(ours["n"]))
        assert abs(lo2 - lo) < 1e-6 and abs(hi2 - hi) < 1e-6, (stage, lo2, lo, hi2, hi)


def test_rmsea_interval_equals_lavaans_function_on_a_grid(reference):
    """lavaan:::lav_fit_rmsea_ci over chi^2 x df x N: our limits are the exact roots (to 1e-9) and within
    lavaan's root-search tolerance of its own (1e-4 on the RMSEA scale)."""
    exact_lo, exact_hi = ref(reference, "grid", "exact_low"), ref(reference, "grid", "exact_high")
    lav_lo, lav_hi = ref(reference, "grid", "lavaan_low"), ref(reference, "grid", "lavaan_high")
    assert len(exact_lo) == 72
    ours = {k: rmsea_ci(float(k.split("/")[0]), int(k.split("/")[1]), int(k.split("/")[2])) for k in exact_lo}
    _close({k: v[0] for k, v in ours.items()}, exact_lo, 1e-9, "exact low")
    _close({k: v[1] for k, v in ours.items()}, exact_hi, 1e-9, "exact high")
    _close({k: v[0] for k, v in ours.items()}, lav_lo, 1e-4, "lavaan low")
    _close({k: v[1] for k, v in ours.items()}, lav_hi, 1e-4, "lavaan high")


def max_differences(reference, surveys) -> pd.DataFrame:
    """max |ours - R| per data set and group of statistics (printed by ``python tests/analysis/...py --gaps``)."""
    rows = []
    grid = {k: rmsea_ci(float(k.split("/")[0]), int(k.split("/")[1]), int(k.split("/")[2]))
            for k in ref(reference, "grid", "exact_low")}
    for src in ("exact", "lavaan"):
        rows.append({"data": "grid", "statistics": f"RMSEA 90 % CI vs {src}", "max_abs_diff": max(
            _gap({k: v[i] for k, v in grid.items()}, ref(reference, "grid", f"{src}_{end}"), src)
            for i, end in ((0, "low"), (1, "high")))})
    for dataset in ("drives", "takeover"):
        ours, anova = _paired_ours(dataset)
        for group, fields in (("paired t, CI, d_z", ("mean_diff", "ci_low", "ci_high", "t", "p_t", "dz")),
                              ("Wilcoxon V, p", ("v", "p_wilcoxon"))):
            rows.append({"data": dataset, "statistics": group, "max_abs_diff": max(
                _gap({k: float(r[f]) for k, r in ours.items()}, ref(reference, dataset, f), f) for f in fields)})
        if anova:
            rows.append({"data": dataset, "statistics": "mixed ANOVA F, p", "max_abs_diff": max(
                _gap({k: float(t.loc[s, c]) for k, t in anova.items()}, ref(reference, dataset, f"anova_{c}_{e}"), e)
                for e, s in (("group", "group"), ("condition", "condition"), ("interaction", "condition × group"))
                for c in ("f", "p"))})
    for tag in ("paper", "lk"):
        steps, coefs, cooks, fit = surveys[tag]
        models = {m: i for i, m in enumerate(dict.fromkeys(steps["model"]), start=1)}
        key = [f"{models[m]}.{s}" for m, s in zip(steps["model"], steps["step"])]
        ckey = [f"{models[m]}.{s}.{p}" for m, s, p in zip(coefs["model"], coefs["step"], coefs["predictor"])]
        for group, fields in (("Shapiro-Wilk W, p", ("shapiro_w", "shapiro_p")), ("Breusch-Pagan", ("bp", "bp_p")),
                              ("f², its 95 % CI", ("f2", "f2_ci_low", "f2_ci_high"))):
            rows.append({"data": tag, "statistics": group, "max_abs_diff": max(
                _gap(dict(zip(key, steps[f].astype(float))), ref(reference, tag, f), f) for f in fields)})
        rows.append({"data": tag, "statistics": "Cook's D", "max_abs_diff": _gap(cooks, ref(reference, tag, "cooks"),
                                                                                 "cooks")})
        rows.append({"data": tag, "statistics": "VIF, β 95 % CI", "max_abs_diff": max(
            _gap(dict(zip(ckey, coefs[f].astype(float))), ref(reference, tag, f), f)
            for f in ("vif", "beta_ci_low", "beta_ci_high"))})
        f = fit.set_index("stage")
        gaps = []
        for stage in ref(reference, tag, "cfa_chisq"):
            lo, hi = rmsea_ci(float(f.loc[stage, "chi2"]), int(f.loc[stage, "df"]), int(f.loc[stage, "n"]))
            gaps += [abs(lo - ref(reference, tag, "cfa_rmsea.ci.lower")[stage]),
                     abs(hi - ref(reference, tag, "cfa_rmsea.ci.upper")[stage])]
        rows.append({"data": tag, "statistics": "RMSEA 90 % CI (our fit vs lavaan fitMeasures)",
                     "max_abs_diff": max(gaps)})
    return pd.DataFrame(rows)


@needs_r("lavaan", "car", "lmtest")
def test_rerun_r_script_reproduces_committed_fixture(tmp_path):
    copy = tmp_path / "tests" / "data" / "r_reference"
    copy.mkdir(parents=True)
    for name in ("statistics_reference.R", "paper_drive_pairs.csv", "takeover_times.csv"):
        shutil.copy2(REF / name, copy / name)
    for rel in ("data/reference/survey.csv", "studies/pedas_paper/model.lav", "studies/lane_keeping/model.lav",
                "tests/data/lane_keeping/survey.csv", "tests/data/lane_keeping/participants.csv",
                "tests/data/takeover/scores.csv"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, tmp_path / rel)
    subprocess.run(["Rscript", str(copy / "statistics_reference.R")], check=True, capture_output=True, timeout=600)
    ours = pd.read_csv(copy / "statistics_reference.csv", dtype={"key": str})
    committed = pd.read_csv(REF / "statistics_reference.csv", dtype={"key": str})
    assert list(ours["quantity"]) == list(committed["quantity"]) and list(ours["key"]) == list(committed["key"])
    num = pd.to_numeric(ours["value"], errors="coerce")
    ref_num = pd.to_numeric(committed["value"], errors="coerce")
    both = num.notna() & ref_num.notna()
    assert np.allclose(num[both], ref_num[both], rtol=1e-9, atol=1e-12)


if __name__ == "__main__":
    import sys

    if "--gaps" in sys.argv:
        ref_frame = pd.read_csv(REF / "statistics_reference.csv", dtype={"key": str})
        print(max_differences(ref_frame, surveys.__wrapped__()).to_string(index=False))
    else:
        takeover_times().to_csv(REF / "takeover_times.csv", index=False, float_format="%.12g")
        print("wrote", REF / "takeover_times.csv")

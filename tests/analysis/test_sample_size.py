"""A priori power (analysis.survey.sample_size, `pedas-study plan power`): the analytic cases against R (pwr.f2.test and
the noncentral chi-square of MacCallum et al. 1996, committed in tests/data/r_reference_power/, recomputed when
Rscript is present; the planning case, beta = .3 at N = 44, stored here and rerun in R when pwr is installed), the
effect size by hand, the batched regression against OLS, the Monte-Carlo estimate against the exact noncentral F,
worker independence, the CLI end to end, and bad input."""
from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis.survey import sample_size as ss
from tests.conftest import needs_r

REPO = Path(__file__).resolve().parents[2]
REF = REPO / "tests" / "data" / "r_reference_power"
PAPER = REPO / "studies" / "pedas_paper"

# The planning case: one predictor with a standardized beta of .3 (f2 = .09/.91), alpha .05. R 4 with pwr 1.3:
#   pwr.f2.test(u = 1, v = 42, f2 = .09/.91, sig.level = .05)$power  -> 0.531227296447126  (N = 44 = v + k + 1)
#   pwr.f2.test(u = 1, f2 = .09/.91, sig.level = .05, power = .8)$v  -> 79.3267997016854, so N = 80 + 1 + 1 = 82
R_POWER_44 = 0.531227296447126
R_V_80 = 79.3267997016854
R_N_80 = 82


def _reference() -> pd.DataFrame:
    return pd.read_csv(REF / "power_reference.csv")


@needs_r("pwr")
def test_r_reproduces_the_committed_fixture(tmp_path):
    copy = tmp_path / "power_reference.R"
    shutil.copy(REF / "power_reference.R", copy)
    subprocess.run(["Rscript", str(copy)], check=True, capture_output=True)
    new = pd.read_csv(tmp_path / "power_reference.csv")
    pd.testing.assert_frame_equal(new, _reference(), rtol=1e-12)


def test_f2_power_equals_r_pwr():
    ref = _reference().query("quantity == 'f2'")
    assert len(ref) == 24
    for r in ref.itertuples():
        assert ss.f2_power(r.a, int(r.b), u=1, k=int(r.c)) == pytest.approx(r.value, abs=1e-9), r


def test_rmsea_power_and_n_equal_r():
    ref = _reference()
    for r in ref.query("quantity == 'rmsea'").itertuples():
        assert ss.rmsea_power(int(r.a), int(r.b), 0.05, r.c) == pytest.approx(r.value, abs=1e-9), r
    for r in ref.query("quantity == 'rmsea_n'").itertuples():
        assert ss.rmsea_n(int(r.a), 0.8, 0.05, r.c) == int(r.value), r


def _one_beta(beta: float) -> tuple[ss.Population, list[ss.Target]]:
    pop = ss.Population(("X", "Y"), (0.0, 0.0), ((1.0, beta), (beta, 1.0)))
    return pop, [ss.Target("H1", "Y", ("X",), "X", "!=")]


def test_the_planning_case_equals_the_stored_r_numbers():
    f2 = 0.09 / 0.91
    assert ss.f2_power(f2, 44) == pytest.approx(R_POWER_44, abs=1e-9)
    assert ss.analytic_n(f2, 1, 0.8) == R_N_80 == math.ceil(R_V_80) + 2
    # the smallest N: one fewer misses the target
    assert ss.f2_power(f2, R_N_80 - 1) < 0.8 <= ss.f2_power(f2, R_N_80)
    pop, tgt = _one_beta(0.3)
    power, need = ss.analytic_power(pop, tgt, n_current=44, sizes=[20, 300])
    row = need.iloc[0]
    assert row["n_required"] == R_N_80 and row["power_current"] == pytest.approx(R_POWER_44, abs=1e-9)
    assert row["f2"] == pytest.approx(f2, abs=1e-15) and row["beta"] == pytest.approx(0.3, abs=1e-15)
    assert list(power["n"]) == [20, 44, 82, 300] and power["power"].is_monotonic_increasing


@needs_r("pwr")
def test_the_planning_case_equals_r_pwr_now():
    script = ("suppressPackageStartupMessages(library(pwr)); f2 <- 0.09 / 0.91; "
              "a <- pwr.f2.test(u = 1, v = 42, f2 = f2, sig.level = 0.05)$power; "
              "v <- pwr.f2.test(u = 1, f2 = f2, sig.level = 0.05, power = 0.8)$v; "
              "cat(sprintf('%.15g %.15g', a, v))")
    out = subprocess.run(["Rscript", "-e", script], check=True, capture_output=True, text=True).stdout.split()
    power, v = float(out[0]), float(out[1])
    assert power == pytest.approx(R_POWER_44, abs=1e-12) and v == pytest.approx(R_V_80, abs=1e-6)
    assert ss.f2_power(0.09 / 0.91, 44) == pytest.approx(power, abs=1e-6)
    assert ss.analytic_n(0.09 / 0.91) == math.ceil(v) + 2


def test_analytic_n_is_the_smallest_n_reaching_the_target():
    for f2, k in ((0.02, 1), (0.15, 3), (0.35, 2), (0.0989, 1)):
        n = ss.analytic_n(f2, k, 0.9)
        assert ss.f2_power(f2, n, 1, k) >= 0.9 > ss.f2_power(f2, n - 1, 1, k)
    assert ss.analytic_n(0.0, 1) is None
    assert ss.analytic_n(0.001, 1, n_max=500) is None   # needs ~7850
    assert ss.analytic_n(200.0, 2) == 4                 # k + 2, the smallest regression


def test_effect_size_of_two_correlated_predictors_by_hand():
    # standardized: R2 = (r1^2 + r2^2 - 2 r1 r2 r12) / (1 - r12^2); without x2: r1^2
    r1, r2, r12 = 0.4, 0.3, 0.5
    r2_full = (r1 ** 2 + r2 ** 2 - 2 * r1 * r2 * r12) / (1 - r12 ** 2)   # = 0.1733...
    beta2 = (r2 - r1 * r12) / (1 - r12 ** 2)                               # = 0.1333...
    cov = ((4.0, 2 * 3 * r12, 2 * 5 * r1), (2 * 3 * r12, 9.0, 3 * 5 * r2), (2 * 5 * r1, 3 * 5 * r2, 25.0))
    pop = ss.Population(("X1", "X2", "Y"), (1.0, 2.0, 3.0), cov)     # sds 2, 3, 5: beta is scale-free
    e = ss.effect(pop, ss.Target("H", "Y", ("X2", "X1"), "X2", ">"))
    assert e.k == 2 and e.r2_full == pytest.approx(r2_full, abs=1e-14) and e.r2_reduced == pytest.approx(r1 ** 2)
    assert e.f2 == pytest.approx((r2_full - r1 ** 2) / (1 - r2_full), abs=1e-14)
    assert e.beta == pytest.approx(beta2, abs=1e-14)
    table = ss.effect_sizes(pop, [ss.Target("H", "Y", ("X1", "X2"), "X1", "<")])
    assert table.loc[0, "r2_full"] == pytest.approx(r2_full) and table.loc[0, "beta"] == pytest.approx(
        (r1 - r2 * r12) / (1 - r12 ** 2))


def test_effect_of_a_degenerate_population_is_refused():
    pop = ss.Population(("A", "B", "Y"), (0.0,) * 3, ((1.0, 1.0, 0.5), (1.0, 1.0, 0.5), (0.5, 0.5, 1.0)))
    with pytest.raises(ValueError, match="collinear in the population"):
        ss.effect(pop, ss.Target("H", "Y", ("A", "B"), "A", ">"))
    exact = ss.Population(("X", "Y"), (0.0, 0.0), ((1.0, 2.0), (2.0, 4.0)))
    with pytest.raises(ValueError, match="R² = 1"):
        ss.effect(exact, ss.Target("H", "Y", ("X",), "X", ">"))


def test_batched_t_equals_ols():
    from analysis.survey.regression import ols

    rng = np.random.default_rng(4)
    X = rng.standard_normal((6, 25, 3))
    y = 0.3 * X[:, :, 0] - 0.2 * X[:, :, 2] + rng.standard_normal((6, 25))
    t, df = ss.batch_t(y, [X[:, :, i] for i in range(3)])
    assert df == 21
    for r in range(6):
        fit = ols(y[r], X[r])
        assert t[r] == pytest.approx(float(fit["t"][3]), abs=1e-10)
    # a sample whose predictors are collinear gets NaN, the others their t
    X[2, :, 1] = 2 * X[2, :, 0]
    t2, _ = ss.batch_t(y, [X[:, :, i] for i in range(3)])
    assert np.isnan(t2[2]) and np.isfinite(np.delete(t2, 2)).all()


def test_batched_verdicts_follow_the_study_rule():
    from analysis.survey.hypotheses import supported

    t = np.array([-4.0, -2.1, -2.0, -0.5, 0.0, 0.5, 2.0, 2.1, 4.0, np.nan])
    df = 40
    p = 2 * stats.t.sf(np.abs(t), df)
    for sign in (">", "<", "!="):
        want = [bool(not np.isnan(ti)) and supported(float(ti), float(pi), sign, 0.05) for ti, pi in zip(t, p)]
        assert ss._supported(t, df, sign, 0.05).tolist() == want, sign


def test_samples_do_not_depend_on_the_block_size(monkeypatch):
    pop, tgt = _one_beta(0.25)
    whole = ss._counts(pop, tgt, 40, 300, 9, 0.05)
    monkeypatch.setattr(ss, "BLOCK", 40 * 2 * 7)   # 7 samples per block
    assert ss._counts(pop, tgt, 40, 300, 9, 0.05) == whole


def test_simulated_n_is_near_the_analytic_n_and_the_same_for_any_workers():
    pop, tgt = _one_beta(0.3)
    tgts = tgt + [ss.Target("H2", "Y", ("X",), "X", "<")]
    one = ss.simulated_power(pop, tgts, reps=1000, seed=3, n_current=44, workers=1)
    two = ss.simulated_power(pop, tgts, reps=1000, seed=3, n_current=44, workers=2)
    pd.testing.assert_frame_equal(one[0], two[0])
    pd.testing.assert_frame_equal(one[1], two[1])
    power, need = one
    h1 = need.iloc[0]
    assert abs(h1["n_required"] - R_N_80) <= 6 and h1["power_at_n"] >= 0.8
    # its power at N = 44 is within the binomial noise of the exact value
    at44 = power[(power["hypothesis"] == "H1") & (power["n"] == 44)].iloc[0]
    assert at44["ci_low"] <= R_POWER_44 <= at44["ci_high"] and h1["power_current"] == at44["power"]
    # the search simulated N = 81 below the target (it is the smallest N of the search reaching it)
    below = power[(power["hypothesis"] == "H1") & (power["n"] == h1["n_required"] - 1)]
    assert len(below) == 1 and below["power"].iloc[0] < 0.8
    # the wrong-sign hypothesis is not searched
    h2 = need.iloc[1]
    assert pd.isna(h2["n_required"]) and h2["note"] == ss.WRONG_SIGN
    assert list(power.loc[power["hypothesis"] == "H2", "n"]) == [44]


def test_analytic_wrong_sign_has_no_power():
    pop, _ = _one_beta(0.4)
    power, need = ss.analytic_power(pop, [ss.Target("H1", "Y", ("X",), "X", "<")], n_current=40, sizes=[50])
    assert pd.isna(need.loc[0, "n_required"]) and pd.isna(need.loc[0, "power_current"])
    assert need.loc[0, "note"] == ss.WRONG_SIGN and power["power"].isna().all()
    # a two-sided hypothesis has the F test's power whatever the sign
    _, two = ss.analytic_power(pop, [ss.Target("H1", "Y", ("X",), "X", "!=")], n_current=40)
    assert two.loc[0, "power_current"] == pytest.approx(ss.f2_power(0.16 / 0.84, 40))


def test_monte_carlo_power_matches_the_noncentral_f():
    beta, n, reps = 0.3, 50, 1500
    pop, tgt = _one_beta(beta)
    res = ss.mc_power(pop, tgt, [n], reps=reps, seed=7)
    exact = ss.f2_power(beta ** 2 / (1 - beta ** 2), n)
    row = res.iloc[0]
    assert row["ci_low"] <= exact <= row["ci_high"], (row.to_dict(), exact)
    assert abs(row["power"] - exact) < 0.04


def test_power_is_the_same_for_any_number_of_workers():
    pop, tgt = _one_beta(0.25)
    one = ss.mc_power(pop, tgt, [30, 60], reps=60, seed=3, workers=1)
    two = ss.mc_power(pop, tgt, [30, 60], reps=60, seed=3, workers=2)
    pd.testing.assert_frame_equal(one, two)
    assert one["power"].iloc[1] >= one["power"].iloc[0]


def test_a_wrong_sign_hypothesis_has_no_power():
    pop, _ = _one_beta(0.4)
    res = ss.mc_power(pop, [ss.Target("H1", "Y", ("X",), "X", "<")], [80], reps=100, seed=1)
    assert res["power"].iloc[0] == 0.0


def test_required_n_is_the_first_size_that_stays_above_target():
    df = pd.DataFrame({"hypothesis": "H1", "path": "X -> Y", "sign": ">", "n": [20, 40, 60, 80],
                       "power": [0.5, 0.81, 0.79, 0.9]})
    assert ss.required_n(df, 0.8, 0.05)["n_required"].iloc[0] == 80


def test_measurement_df_of_the_paper_and_a_hand_count():
    # 2 factors x 3 items: 21 moments - (6 residuals + 4 loadings + 3 factor (co)variances) = 8
    assert ss.measurement_df({"A": ["a1", "a2", "a3"], "B": ["b1", "b2", "b3"]}) == 8


def test_cholesky_and_sampling_reproduce_the_covariance():
    from analysis.survey.mvn import cholesky, draw

    cov = ((2.0, 0.6, 0.2), (0.6, 1.0, 0.3), (0.2, 0.3, 1.5))
    L = np.array(cholesky(cov))
    np.testing.assert_allclose(L @ L.T, cov, atol=1e-14)
    x = draw(L.tolist(), (1.0, 2.0, 3.0), 40000, np.random.default_rng(0))
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.05)
    with pytest.raises(ValueError, match="not positive definite"):
        cholesky(((1.0, 2.0), (2.0, 1.0)))


def _paper_population(tmp_path, r_peou_pu: float = 0.3):
    """The paper's six constructs, uncorrelated except PEoU-PU (H1's path, a one-predictor step)."""
    names = ["PU", "PEoU", "ATT", "BI", "SN", "PBC"]
    corr = pd.DataFrame(np.eye(6), index=names, columns=names)
    corr.loc["PU", "PEoU"] = corr.loc["PEoU", "PU"] = r_peou_pu
    corr.to_csv(tmp_path / "pop.csv")
    return tmp_path / "pop.csv"


def test_plan_power_cli_answers_the_planning_case_analytically(tmp_path, capsys):
    """H1 (PU ~ PEoU) with a standardized beta of .3, power at N = 44 and the N for 80 %: R's pwr numbers."""
    from pedas_study.cli import main

    out = tmp_path / "plan"
    code = main(["plan", "power", "--population", str(_paper_population(tmp_path)), "--study", str(PAPER),
                 "--n-current", "44", "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "H1 PEoU -> PU (> 0): f2 = 0.0989 (beta = 0.300); power 0.531 at N = 44; N = 82" in text
    need = pd.read_csv(out / "sample_size.csv", keep_default_na=False, na_values=[""])
    assert list(need.columns) == ss.N_COLUMNS
    h1 = need.set_index("hypothesis").loc["H1"]
    assert h1["n_required"] == R_N_80 and h1["power_current"] == pytest.approx(R_POWER_44, abs=1e-9)
    assert h1["method"] == "analytic" and h1["f2"] == pytest.approx(0.09 / 0.91, abs=1e-12) and h1["k"] == 1
    # no correlation, no effect: the other hypotheses have no N
    h2 = need.set_index("hypothesis").loc["H2"]
    assert pd.isna(h2["n_required"]) and h2["note"] == "no effect in the population"
    power = pd.read_csv(out / "power.csv")
    assert list(power.columns) == ss.POWER_COLUMNS
    h1p = power[power["hypothesis"] == "H1"]
    assert set(range(20, 301, 20)) | {44, 82} == set(h1p["n"])   # the default curve, the current and required N
    assert h1p["reps"].isna().all() and (power["method"] == "analytic").all()
    assert (out / "power_curve.png").exists() and (out / "rmsea_n.csv").exists() and (out / "population.csv").exists()


def test_plan_power_cli_simulation_is_reproducible(tmp_path, capsys):
    from pedas_study.cli import main

    pop = _paper_population(tmp_path, 0.5)
    runs = []
    for i, workers in enumerate(("1", "2")):
        out = tmp_path / f"plan{i}"
        code = main(["plan", "power", "--method", "simulation", "--population", str(pop), "--study", str(PAPER),
                     "--n-current", "30", "--n", "40,120", "--reps", "200", "--workers", workers, "--out", str(out),
                     "--no-progress"])
        assert code == 0
        runs.append({f: (out / f).read_bytes() for f in ("power.csv", "sample_size.csv")})
    assert runs[0] == runs[1]
    capsys.readouterr()
    need = pd.read_csv(tmp_path / "plan0" / "sample_size.csv").set_index("hypothesis")
    assert (need["method"] == "simulation").all()
    # beta = .5 (f2 = 1/3): the analytic N is 26; the search lands near it
    assert ss.analytic_n(1 / 3) == 26 and abs(need.loc["H1", "n_required"] - 26) <= 6
    power = pd.read_csv(tmp_path / "plan0" / "power.csv")
    h1 = power[power["hypothesis"] == "H1"]
    assert {30, 40, 120, need.loc["H1", "n_required"]} <= set(h1["n"]) and (h1["reps"] == 200).all()
    # a hypothesis without an effect is not searched: only the asked sizes are simulated
    assert set(power.loc[power["hypothesis"] == "H2", "n"]) == {30, 40, 120}


@pytest.mark.parametrize("args, message", [
    (["--n", "abc"], "--n 'abc'"),
    (["--power", "1.5"], "--power must be between 0 and 1"),
    (["--n", "2,3"], "sample sizes must be >= 4"),
    (["--n-current", "2"], "--n-current must be >= 4"),
    (["--n-max", "3"], "--n-max must be >= 4"),
    (["--method", "simulation", "--reps", "0"], "--reps must be >= 1"),
    (["--method", "simulation", "--workers", "0"], "--workers must be >= 1"),
    (["--method", "exact"], "invalid choice: 'exact'"),
    (["--n-current", "4"], "the current N 4 is too small for a regression with 3 predictor(s)"),
])
def test_plan_power_bad_input_is_one_line_exit_2(tmp_path, capsys, args, message):
    from pedas_study.cli import main

    names = ["PU", "PEoU", "ATT", "BI", "SN", "PBC"]
    pd.DataFrame(np.eye(6), index=names, columns=names).to_csv(tmp_path / "pop.csv")
    code = main(["plan", "power", "--population", str(tmp_path / "pop.csv"), "--study", str(PAPER),
                 "--out", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and "\n" not in err, err
    assert not (tmp_path / "o").exists()


def test_a_population_that_is_not_a_matrix_is_refused(tmp_path):
    (tmp_path / "bad.csv").write_text("x,A,B\nA,1,0.5\nC,0.5,1\n")
    with pytest.raises(ValueError, match="first column must name the same variables"):
        ss.population_from_csv(tmp_path / "bad.csv")
    (tmp_path / "asym.csv").write_text("x,A,B\nA,1,0.5\nB,0.4,1\n")
    with pytest.raises(ValueError, match="not symmetric"):
        ss.population_from_csv(tmp_path / "asym.csv")

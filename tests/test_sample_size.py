"""A priori power (analysis.survey.sample_size, `pedas-study plan power`): the analytic cases against R (pwr.f2.test and
the noncentral chi-square of MacCallum et al. 1996, committed in tests/data/r_reference_power/, recomputed when
Rscript is present), the Monte-Carlo estimate against the exact noncentral F, worker independence, and bad input."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.survey import sample_size as ss
from tests.conftest import needs_r

REPO = Path(__file__).resolve().parents[1]
REF = REPO / "tests" / "data" / "r_reference_power"
PAPER = REPO / "studies" / "pedas_paper"


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


def test_plan_power_cli_on_a_given_population(tmp_path, capsys):
    from pedas_study.cli import main

    names = ["PU", "PEoU", "ATT", "BI", "SN", "PBC"]
    corr = pd.DataFrame(np.eye(6) + 0.3 * (1 - np.eye(6)), index=names, columns=names)
    corr.to_csv(tmp_path / "pop.csv")
    out = tmp_path / "plan"
    code = main(["plan", "power", "--population", str(tmp_path / "pop.csv"), "--study", str(PAPER), "--n", "40,120",
                 "--reps", "40", "--out", str(out), "--no-progress"])
    assert code == 0
    text = capsys.readouterr().out
    assert "H7" in text and "RMSEA test of close fit" in text
    power = pd.read_csv(out / "power.csv")
    assert set(power["hypothesis"]) == {f"H{i}" for i in range(1, 8)} and set(power["n"]) == {40, 120}
    assert (out / "power_curve.png").exists() and (out / "rmsea_n.csv").exists()


@pytest.mark.parametrize("args, message", [
    (["--n", "abc"], "--n 'abc'"),
    (["--power", "1.5"], "--power must be between 0 and 1"),
    (["--n", "2,3"], "sample sizes must be >= 4"),
])
def test_plan_power_bad_input_is_one_line_exit_2(tmp_path, capsys, args, message):
    from pedas_study.cli import main

    names = ["PU", "PEoU", "ATT", "BI", "SN", "PBC"]
    pd.DataFrame(np.eye(6), index=names, columns=names).to_csv(tmp_path / "pop.csv")
    code = main(["plan", "power", "--population", str(tmp_path / "pop.csv"), "--study", str(PAPER),
                 "--out", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err.strip()
    assert code == 2 and message in err and "\n" not in err
    assert not (tmp_path / "o").exists()


def test_a_population_that_is_not_a_matrix_is_refused(tmp_path):
    (tmp_path / "bad.csv").write_text("x,A,B\nA,1,0.5\nC,0.5,1\n")
    with pytest.raises(ValueError, match="first column must name the same variables"):
        ss.population_from_csv(tmp_path / "bad.csv")
    (tmp_path / "asym.csv").write_text("x,A,B\nA,1,0.5\nB,0.4,1\n")
    with pytest.raises(ValueError, match="not symmetric"):
        ss.population_from_csv(tmp_path / "asym.csv")

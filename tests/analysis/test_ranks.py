"""Rank statistics with ties where the data tie (analysis/ranks.py) against R: wilcox.test (paired and two-sample),
friedman.test and cor.test(method = "spearman") on values k/6 with float noise (tests/data/ranks: the numerators,
and R's results on them, tests/data/ranks/rank_reference.R), deliberately tied and zero differences included, and
on untied data for the exact distributions (n <= 9 enumerated and the AS 89 series for Spearman)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from analysis import ranks
from tests.conftest import REPO

DATA = REPO / "tests" / "data" / "ranks"
#: pairs of columns and the statistic each reference name stands for
PAIRS = [("a", "b"), ("a", "c"), ("b", "c")]


def noisy(k: np.ndarray, seed: int) -> np.ndarray:
    """k / 6 as floating point computes it along different paths: each value off by up to two units in the last
    place (7/6 as 1.1666...665 here, 1.1666...660 there)."""
    rng = np.random.default_rng(seed)
    out = k.astype(float) / 6
    steps = rng.integers(-2, 3, len(out))
    for i, s in enumerate(steps):
        for _ in range(abs(int(s))):
            out[i] = np.nextafter(out[i], np.inf if s > 0 else -np.inf)
    return out


def ours(case: pd.DataFrame, resolution: float | None) -> dict[str, ranks.RankTest]:
    v = {c: noisy(case[c].to_numpy(), seed=k) for k, c in enumerate("abc")}
    out = {f"wilcoxon_{a}_{b}": ranks.wilcoxon_signed_rank(v[a], v[b], resolution) for a, b in PAIRS}
    out["friedman"] = ranks.friedman(np.column_stack([v["a"], v["b"], v["c"]]), resolution)
    out["spearman_a_b"] = ranks.spearman(v["a"], v["b"], resolution)
    out["spearman8_a_c"] = ranks.spearman(v["a"][:8], v["c"][:8], resolution)
    out["mannwhitney_a_c"] = ranks.mann_whitney(v["a"], v["c"], resolution)
    out["mannwhitney7_a_b"] = ranks.mann_whitney(v["a"][:7], v["b"][:6], resolution)
    return out


def differences(resolution: float | None) -> pd.DataFrame:
    ref = json.loads((DATA / "rank_reference.json").read_text())
    values = pd.read_csv(DATA / "values.csv")
    rows = []
    for case, d in values.groupby("case"):
        for name, t in ours(d, resolution).items():
            r = ref[f"{case}_{name}"]
            est = abs(t.estimate - r["estimate"]) if isinstance(r["estimate"], float) else 0.0
            rows.append({"case": case, "test": name, "statistic": t.statistic, "r_statistic": r["statistic"],
                         "p": t.p, "r_p": r["p"], "method": t.method, "r_method": r["method"],
                         "max_abs_diff": max(abs(t.statistic - r["statistic"]), abs(t.p - r["p"]), est)})
    return pd.DataFrame(rows)


@pytest.mark.parametrize("resolution", [1 / 6, None])
def test_rank_tests_on_tied_fractional_data_equal_r(resolution):
    """At the declared resolution (1/6) and at the default relative one, every statistic, p and estimate is R's."""
    diffs = differences(resolution)
    print(diffs.to_string(index=False))
    assert (diffs["method"] == diffs["r_method"]).all(), diffs[["test", "method", "r_method"]]
    assert diffs["max_abs_diff"].max() < 1e-12, diffs


def test_the_raw_floats_split_the_ties_r_keeps():
    """Ranked as raw floats (a resolution finer than the noise), the tied case's Wilcoxon tests take the exact
    no-ties distribution and differ from R: the failure this module exists to prevent."""
    diffs = differences(1e-18)
    tied = diffs[(diffs["case"] == "tied") & diffs["test"].str.startswith("wilcoxon")]
    assert (tied["max_abs_diff"] > 1e-6).any()


def test_exact_distributions_sum_to_one_and_match_the_normal_limit():
    assert ranks._signrank_counts(10).sum() == 2 ** 10
    assert ranks._wilcox_counts(4, 6).sum() == 210                       # C(10, 4)
    assert ranks._rho_counts(5).sum() == 120
    # the signed-rank distribution is symmetric about n (n + 1) / 4
    c = ranks._signrank_counts(12)
    assert np.array_equal(c, c[::-1])


def test_a_declared_resolution_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        ranks.resolution_of([1.0, 2.0], 0.0)


def test_a_score_s_resolution_follows_from_its_declaration():
    """The takeover study's scores: SUS 2.5 (sum x 2.5), raw TLX 5/6 (mean of six subscales in steps of 5), trust
    1/6 (mean of six 1-7 items)."""
    from study.folder.definition import load
    from study.folder.scores import score_resolution, study_scores

    study = load(REPO / "studies" / "takeover", units=False)
    got = {s.name: score_resolution(s, study.instruments[s.instrument]) for s in study_scores(study)}
    assert got == pytest.approx({"sus": 2.5, "tlx_raw": 5 / 6, "trust": 1 / 6}, abs=1e-15)

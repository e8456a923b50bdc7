"""Audit finding #8 against SPSS's bootstrap (analysis.paper.bootstrap_check): formulas, determinism, the verdict."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from analysis.survey.bootstrap import interval
from analysis.paper import audit as A
from analysis.paper import bootstrap_check as B


def test_slope_is_ols():
    x = np.array([1.0, 2, 3, 4, 5])
    y = np.array([2.0, 1, 4, 3, 6])
    # Σ(x - 3)(y - 3.2) = 2.4 + 2.2 + 0 - 0.2 + 5.6 = 10, Σ(x - 3)² = 10
    assert B.slopes(x, y, np.arange(5)[None, :])[0] == pytest.approx(1.0)
    assert B.slopes(x, y, np.arange(5)[None, :])[0] == pytest.approx(np.polyfit(x, y, 1)[0])


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000))
def test_intervals_agree_with_the_generic_bootstrap_and_the_seed_decides(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=30)
    y = 0.5 * x + rng.normal(size=30)
    iv = B.seed_intervals(x, y, n_boot=400, n_seeds=2, first_seed=seed)
    assert iv.equals(B.seed_intervals(x, y, n_boot=400, n_seeds=2, first_seed=seed))
    d = B.slopes(x, y, np.random.default_rng(seed).integers(0, 30, size=(400, 30)))
    jk = B.slopes(x, y, np.array([np.delete(np.arange(30), i) for i in range(30)]))
    b = B.slopes(x, y, np.arange(30)[None, :])[0]
    first = iv[iv["seed"] == seed].set_index("method")
    assert tuple(first.loc["percentile", ["low", "high"]]) == pytest.approx(interval(b, d, None, 0.95, "percentile"))
    assert tuple(first.loc["bca", ["low", "high"]]) == pytest.approx(interval(b, d, jk, 0.95, "bca"))


def test_printed_peou_cis_are_not_spss_bootstrap_intervals_on_the_reference_data():
    res = B.check_printed_cis(n_seeds=200).set_index(["model", "method"])
    for model in (1, 2):
        for method in ("percentile", "bca"):
            r = res.loc[(model, method)]
            assert not r["consistent"]
            assert r["printed_low"] > r["low_max"] + 0.05       # far outside what any seed gives
    # the t-based CI of model 3 step 1 lies inside the bootstrap range: the test can say yes
    assert res.loc[(3, "percentile"), "consistent"]


def test_audit_rows_join_finding_8():
    audit = A.run_audit()
    rows = audit[audit["check"].str.startswith("CI = SPSS bootstrap")]
    assert len(rows) == 6
    assert set(rows.loc[rows["status"] == "inconsistent", "finding"]) == {A.finding_for(audit, "ci_not_t")} == {8}

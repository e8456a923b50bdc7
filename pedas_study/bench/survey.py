"""Time of `analysis.survey.acceptance.analyze_survey` on synthetic answers, and of its stacked bootstrap against a
statsmodels loop (`pedas-study bench survey`)."""
from __future__ import annotations

import time

import numpy as np

from pedas_study.extras import require


def bench_survey(n: int = 40, n_boot: int = 2000, repeats: int = 3, seed: int = 1) -> dict:
    """Median wall time of `analyze_survey` on `n` synthetic rows of the paper's study with `n_boot` resamples, and
    the share of it the bootstrap takes (ratio to the same run with n_boot = 0)."""
    from analysis.survey.acceptance import analyze_survey
    from analysis.paper.published import paper_study
    from analysis.paper.synthetic import simulate_paper_responses

    study = paper_study()
    data = simulate_paper_responses(n, seed)
    analyze_survey(data, study, n_boot=0)  # warm-up: imports, semopy compile paths
    full, none = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        analyze_survey(data, study, n_boot=n_boot, seed=seed)
        full.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        analyze_survey(data, study, n_boot=0)
        none.append(time.perf_counter() - t0)
    med_full, med_none = float(np.median(full)), float(np.median(none))
    return {"n": n, "n_boot": n_boot, "repeats": repeats, "median_s": med_full, "median_s_no_bootstrap": med_none,
            "ratio_vs_no_bootstrap": med_full / med_none if med_none > 0 else float("nan")}


def bench_bootstrap(n: int = 40, k: int = 3, n_boot: int = 2000, repeats: int = 5, seed: int = 1) -> dict:
    """Median time of the stacked bootstrap (`analysis.survey.regression.bootstrap_coefs`) vs the peer it replaces,
    one statsmodels OLS fit per resample, on the same resample indices; also checks they agree."""
    require("statsmodels", "bench", "the statsmodels peer of bench survey")
    import statsmodels.api as sm

    from analysis.survey.regression import bootstrap_coefs

    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, k))
    y = X @ np.linspace(0.5, 0.1, k) + rng.standard_normal(n)
    vec, loop = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fast = bootstrap_coefs(y, X, n_boot, np.random.default_rng(seed))
        vec.append(time.perf_counter() - t0)
    idx = np.random.default_rng(seed).integers(0, n, size=(n_boot, n))
    Xc = sm.add_constant(X)
    for _ in range(max(1, repeats // 2)):
        t0 = time.perf_counter()
        slow = np.array([sm.OLS(y[i], Xc[i]).fit().params for i in idx])
        loop.append(time.perf_counter() - t0)
    v, s = float(np.median(vec)), float(np.median(loop))
    return {"n": n, "k": k, "n_boot": n_boot, "median_s_stacked": v, "median_s_statsmodels_loop": s,
            "speedup": s / v if v > 0 else float("nan"), "max_abs_diff": float(np.nanmax(np.abs(fast - slow)))}

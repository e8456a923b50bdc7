"""Synthetic survey answers for tests and the `bench survey` timing of `analyze_survey`.

`simulate_responses` draws a seeded six-factor population (PU, PEoU, ATT, PBC, SN, BI) with loadings ~0.8,
discretised to the 1-5 scale; PEoU3 is generated negatively keyed (raw, as a participant ticks it) and ATT1-ATT5
lean on PU, so the data carry the structure the paper's item deletions respond to. It is a test fixture, not a
reconstruction of the paper's data.
"""
from __future__ import annotations

import time

import numpy as np
import pandas as pd

FACTORS = ("PU", "PEoU", "ATT", "PBC", "SN", "BI")
# Latent correlations loosely shaped like the paper's Table 4.
PHI = np.array([
    [1.00, 0.45, 0.75, 0.38, 0.49, 0.62],
    [0.45, 1.00, 0.33, 0.55, 0.00, 0.31],
    [0.75, 0.33, 1.00, 0.11, 0.46, 0.40],
    [0.38, 0.55, 0.11, 1.00, 0.00, 0.50],
    [0.49, 0.00, 0.46, 0.00, 1.00, 0.35],
    [0.62, 0.31, 0.40, 0.50, 0.35, 1.00],
])


def simulate_responses(n: int = 40, seed: int = 1, instrument=None, loading: float = 0.8) -> pd.DataFrame:
    """Wide survey frame (participant_id P001.. + every scaled item, raw 1-5) of `n` synthetic participants."""
    from analysis.scoring import resolve_instrument

    inst = resolve_instrument(instrument)
    rng = np.random.default_rng(seed)
    eta = rng.multivariate_normal(np.zeros(len(FACTORS)), PHI, size=n)
    col = {f: k for k, f in enumerate(FACTORS)}
    out = {"participant_id": [f"P{i + 1:03d}" for i in range(n)]}
    for c, items in inst.constructs.items():
        for item in items:
            lam = loading
            signal = eta[:, col[c]]
            if c == "ATT" and int(item[3:]) <= 5:  # ATT1-ATT5 share variance with PU
                signal = 0.5 * eta[:, col[c]] + 0.6 * eta[:, col["PU"]]
            x = lam * signal + np.sqrt(1 - lam ** 2) * rng.standard_normal(n)
            if item in inst.reverse_items:
                x = -x
            lo, hi = inst.scale(item)
            # thresholds placed so answers centre around 4 of 5, like the paper's item means
            ans = np.digitize(x, [-1.8, -1.0, -0.2, 0.9]) + lo
            out[item] = np.clip(ans, lo, hi).astype(int)
    return pd.DataFrame(out)


def bench_survey(n: int = 40, n_boot: int = 2000, repeats: int = 3, seed: int = 1) -> dict:
    """Median wall time of `analyze_survey` on `n` synthetic rows with `n_boot` resamples, and the share of it
    the bootstrap takes (ratio to the same run with n_boot = 0)."""
    from analysis.acceptance import analyze_survey

    data = simulate_responses(n, seed)
    analyze_survey(data, n_boot=0)  # warm-up: imports, semopy compile paths
    full, none = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        analyze_survey(data, n_boot=n_boot, seed=seed)
        full.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        analyze_survey(data, n_boot=0)
        none.append(time.perf_counter() - t0)
    med_full, med_none = float(np.median(full)), float(np.median(none))
    return {"n": n, "n_boot": n_boot, "repeats": repeats, "median_s": med_full, "median_s_no_bootstrap": med_none,
            "ratio_vs_no_bootstrap": med_full / med_none if med_none > 0 else float("nan")}


def bench_bootstrap(n: int = 40, k: int = 3, n_boot: int = 2000, repeats: int = 5, seed: int = 1) -> dict:
    """Median time of the stacked bootstrap (`analysis.regression.bootstrap_coefs`) vs the peer it replaces,
    one statsmodels OLS fit per resample, on the same resample indices; also checks they agree."""
    import statsmodels.api as sm

    from analysis.regression import bootstrap_coefs

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

"""Could SPSS's bootstrap have printed the two Table 5 CIs that are not B ± t·SE (audit finding "ci_not_t")?

SPSS's REGRESSION with "Bootstrap" draws case resamples (default 1000) with a Mersenne Twister whose seed is random
unless the user fixed one, and prints percentile or BCa intervals of B. Which seed was used is unknowable, so the
test asks whether *any* seed plausibly gives the printed interval: on data that meets everything else the paper
prints (the reconstructed reference survey: item distributions, Cα, Tables 4-5 within tolerance), the intervals
of ``n_seeds`` independent seeds (each ``n_boot`` resamples, ``numpy.random.default_rng(seed)``: a different
generator than SPSS's, but the seed is random anyway, so only the distribution over seeds matters) give the range
an endpoint takes. A printed endpoint outside [min, max] over all seeds, by more than its rounding, is not what
this procedure produces on such data.

What this can show: consistency *on this data*. Bootstrap intervals depend on the joint distribution (skew,
heteroscedasticity), not only on the moments the paper prints; another dataset with the same printed statistics
could bootstrap differently. The t-interval reading of the audit depends on the printed numbers alone.

BCa (Efron 1987): z0 = Φ⁻¹(share of draws below B), acceleration a = Σd³ / (6 (Σd²)^1.5) with d the jackknife
deviations, endpoints at the draws' quantiles Φ(z0 + (z0 + z_q)/(1 - a(z0 + z_q))), q = .025, .975.
Percentile: the draws' .025 and .975 quantiles.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from analysis.paper import grim
from analysis.paper import published as P

N_BOOT = 1000           # SPSS's default number of bootstrap samples
N_SEEDS = 500


def slopes(x: np.ndarray, y: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """OLS slope B of y on x for each row of resample indices idx (m x n): cov(x, y)/var(x)."""
    xs, ys = x[idx], y[idx]
    xc = xs - xs.mean(axis=1, keepdims=True)
    return (xc * (ys - ys.mean(axis=1, keepdims=True))).sum(axis=1) / (xc ** 2).sum(axis=1)


def seed_intervals(x: np.ndarray, y: np.ndarray, n_boot: int = N_BOOT, n_seeds: int = N_SEEDS,
                   first_seed: int = 1) -> pd.DataFrame:
    """Percentile and BCa 95 % intervals of B for seeds first_seed.. (one row per seed and method):
    seed, method, low, high."""
    n = len(x)
    b = slopes(x, y, np.arange(n)[None, :])[0]
    jk = slopes(x, y, np.array([np.delete(np.arange(n), i) for i in range(n)]))
    dev = jk.mean() - jk
    a = float((dev ** 3).sum() / (6 * ((dev ** 2).sum()) ** 1.5))
    q = np.array([0.025, 0.975])
    zq = stats.norm.ppf(q)
    rows = []
    for seed in range(first_seed, first_seed + n_seeds):
        d = slopes(x, y, np.random.default_rng(seed).integers(0, n, size=(n_boot, n)))
        lo, hi = np.quantile(d, q)
        rows.append((seed, "percentile", lo, hi))
        prop = min(max((np.sum(d < b) + 0.5 * np.sum(d == b)) / n_boot, 0.5 / n_boot), 1 - 0.5 / n_boot)
        z0 = stats.norm.ppf(prop)
        lo, hi = np.quantile(d, stats.norm.cdf(z0 + (z0 + zq) / (1 - a * (z0 + zq))))
        rows.append((seed, "bca", lo, hi))
    return pd.DataFrame(rows, columns=["seed", "method", "low", "high"])


def reference_composites(survey: pd.DataFrame | None = None) -> pd.DataFrame:
    """Composites (mean of retained scored items) of the reference survey (default data/reference/survey.csv)."""
    from analysis.survey.scoring import composites, score_responses
    from pedas.paths import REFERENCE_DIR

    study = P.paper_study()
    data = survey if survey is not None else pd.read_csv(REFERENCE_DIR / "survey.csv", dtype={"participant_id": str})
    scored = score_responses(data, study.instrument()).scored
    t3 = P.table3()
    retained = {c: t3[(t3["construct"] == c) & ~t3["omitted"]]["item"].tolist() for c in P.TABLE4_ORDER}
    return composites(scored, retained)


def check_printed_cis(comp: pd.DataFrame | None = None, published: pd.DataFrame | None = None,
                      n_boot: int = N_BOOT, n_seeds: int = N_SEEDS) -> pd.DataFrame:
    """For each one-predictor step of Table 5 whose CI is not B ± t·SE (the PEoU-only steps) and, for contrast,
    the one that is (model 3 step 1): the printed CI against the range of SPSS-style bootstrap intervals over seeds.

    Returns model, step, dv, predictor, method, printed_low, printed_high, b_data, t_low, t_high (t-interval of the
    data), low_min, low_max, high_min, high_max (over seeds), share_both (seeds whose interval prints as the printed
    one at 3 decimals), consistent (both printed endpoints inside the seeds' range, widened by half a unit)."""
    comp = comp if comp is not None else reference_composites()
    co = P.table5_coefficients(published)
    one = co[(co["step"] == 1) & co["model"].isin([1, 2, 3])]
    n = len(comp)
    rows = []
    for r in one.itertuples():
        x, y = comp[r.predictor].to_numpy(float), comp[r.dv].to_numpy(float)
        b = float(slopes(x, y, np.arange(n)[None, :])[0])
        resid = y - y.mean() - b * (x - x.mean())
        se = float(np.sqrt((resid ** 2).sum() / (n - 2) / ((x - x.mean()) ** 2).sum()))
        t = stats.t.ppf(0.975, n - 2)
        iv = seed_intervals(x, y, n_boot, n_seeds)
        h = grim.half_unit(3)
        for method, g in iv.groupby("method", sort=False):
            both = grim.prints_as(g["low"].to_numpy(), r.ci_low, 3) & grim.prints_as(g["high"].to_numpy(), r.ci_high, 3)
            ok = bool(g["low"].min() - h <= r.ci_low <= g["low"].max() + h
                      and g["high"].min() - h <= r.ci_high <= g["high"].max() + h)
            rows.append({"model": r.model, "step": r.step, "dv": r.dv, "predictor": r.predictor, "method": method,
                         "printed_low": r.ci_low, "printed_high": r.ci_high, "b_data": b,
                         "t_low": b - t * se, "t_high": b + t * se,
                         "low_min": g["low"].min(), "low_max": g["low"].max(),
                         "high_min": g["high"].min(), "high_max": g["high"].max(),
                         "share_both": float(both.mean()), "consistent": ok})
    return pd.DataFrame(rows)

"""Seeded, failure-tolerant case-resampling bootstrap with BCa intervals (Efron 1987; Efron & Tibshirani 1993, ch. 14).

For a statistic vector theta(X) of an n-row sample X:

* resample b = 1..B draws n row indices with replacement from ``numpy.random.default_rng(seed)`` (the whole index
  matrix is drawn at once, so the resamples depend only on (seed, n, B));
* a resample whose statistic cannot be computed (the function raises, or returns a non-finite value, e.g. a CFA that
  does not converge or a construct without variance in the resample) is a *failure*: it is counted per statistic and
  reported (``n_failed``), never silently dropped; the interval uses the B - n_failed successful resamples;
* BCa: z0 = Phi^-1(#{theta*_b < theta_hat} / B_ok) (ties counted half), acceleration from the jackknife
  a = sum (m - theta_(i))^3 / (6 [sum (m - theta_(i))^2]^{3/2}), m = mean theta_(i); the interval is the
  percentiles Phi(z0 + (z0 + z_q)/(1 - a (z0 + z_q))) for q = g/2 and 1 - g/2 of the successful resamples
  (linear interpolation, numpy's default). Percentile intervals use q directly.

Statistics that are cheap are computed for all resamples in one vectorised call (``vectorised=True``: the function
receives the stacked (B, n, p) resamples and returns (B, k)); others are called once per resample, in worker
processes when ``workers > 1`` (results are identical with any number of workers: each resample's indices are
fixed before any work starts).
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd
from scipy import stats


@dataclass
class BootResult:
    """estimate: theta_hat (k,); draws: (B, k) with NaN for failed resamples; the intervals in `table`."""

    names: list[str]
    estimate: np.ndarray
    draws: np.ndarray
    jackknife: np.ndarray | None
    level: float
    method: str

    def table(self) -> pd.DataFrame:
        """statistic, estimate, ci_low, ci_high, n_boot, n_failed, method."""
        rows = []
        for j, name in enumerate(self.names):
            lo, hi = interval(self.estimate[j], self.draws[:, j],
                              None if self.jackknife is None else self.jackknife[:, j], self.level, self.method)
            ok = np.isfinite(self.draws[:, j])
            rows.append({"statistic": name, "estimate": float(self.estimate[j]), "ci_low": lo, "ci_high": hi,
                         "n_boot": int(len(ok)), "n_failed": int((~ok).sum()), "method": self.method})
        return pd.DataFrame(rows, columns=["statistic", "estimate", "ci_low", "ci_high", "n_boot", "n_failed",
                                           "method"])


def resample_indices(n: int, n_boot: int, seed: int) -> np.ndarray:
    """(n_boot, n) row indices drawn with replacement (one draw for all resamples).

    Examples
    --------
    >>> from analysis.survey.bootstrap import resample_indices
    >>> resample_indices(5, 2, seed=1).tolist()
    [[2, 2, 3, 4, 0], [0, 4, 4, 1, 1]]
    """
    return np.random.default_rng(seed).integers(0, n, size=(n_boot, n))


def interval(estimate: float, draws: np.ndarray, jackknife: np.ndarray | None, level: float = 0.95,
             method: str = "bca") -> tuple[float, float]:
    """The bootstrap interval of one statistic from its successful draws (NaN = failed, left out and counted by the
    caller); BCa needs the n jackknife values (a failed jackknife value makes the acceleration 0, i.e. BC).

    Examples
    --------
    With a symmetric set of draws around the estimate and no skew in the jackknife, BCa equals the percentile
    interval:

    >>> import numpy as np
    >>> from analysis.survey.bootstrap import interval
    >>> d = np.linspace(-1, 1, 201)
    >>> interval(0.0, d, np.array([-1.0, 0.0, 1.0]), 0.9, "bca") == interval(0.0, d, None, 0.9, "percentile")
    True
    """
    d = np.asarray(draws, float)
    d = d[np.isfinite(d)]
    if len(d) < 2 or not np.isfinite(estimate):
        return float("nan"), float("nan")
    g = 1.0 - level
    q = np.array([g / 2, 1 - g / 2])
    if method == "percentile":
        lo, hi = np.quantile(d, q)
        return float(lo), float(hi)
    if method != "bca":
        raise ValueError(f"unknown bootstrap interval {method!r} (bca or percentile)")
    prop = (np.sum(d < estimate) + 0.5 * np.sum(d == estimate)) / len(d)
    prop = min(max(prop, 0.5 / len(d)), 1 - 0.5 / len(d))
    z0 = stats.norm.ppf(prop)
    a = 0.0
    if jackknife is not None:
        jk = np.asarray(jackknife, float)
        if np.all(np.isfinite(jk)):
            dev = jk.mean() - jk
            den = 6.0 * np.sum(dev ** 2) ** 1.5
            a = float(np.sum(dev ** 3) / den) if den > 0 else 0.0
    zq = stats.norm.ppf(q)
    adj = stats.norm.cdf(z0 + (z0 + zq) / (1.0 - a * (z0 + zq)))
    lo, hi = np.quantile(d, adj)
    return float(lo), float(hi)


def _safe(fn, x):
    try:
        v = np.asarray(fn(x), float)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError):
        return None
    return v


def _chunk(args):
    fn, X, idx = args
    out = []
    for row in idx:
        v = _safe(fn, X[row])
        out.append(v)
    return out


def bootstrap(X: np.ndarray, fn: Callable[[np.ndarray], Sequence[float]], names: Sequence[str], *, n_boot: int,
              seed: int, level: float = 0.95, method: str = "bca", vectorised: bool = False, workers: int = 1
              ) -> BootResult:
    """Bootstrap the statistics ``fn(X)`` (k values, named `names`) of the rows of X (n x p array).

    ``vectorised``: fn accepts a stack (B, n, p) and returns (B, k) (NaN marks a failed value). Otherwise fn takes
    one (n, p) sample; raising ValueError/ArithmeticError/LinAlgError/RuntimeError marks the resample failed.
    ``workers > 1`` spreads per-resample calls over that many processes (fn must be picklable).
    """
    X = np.asarray(X, float)
    n = X.shape[0]
    if vectorised:
        est = np.asarray(fn(X[None]), float)[0]
    else:
        est = np.asarray(fn(X), float)
    k = len(names)
    if est.shape != (k,):
        raise ValueError(f"bootstrap statistic returned shape {est.shape}, expected ({k},)")
    idx = resample_indices(n, int(n_boot), seed)
    jk_idx = np.array([np.delete(np.arange(n), i) for i in range(n)]) if method == "bca" else None
    if vectorised:
        draws = np.asarray(fn(X[idx]), float) if n_boot else np.empty((0, k))
        jk = np.asarray(fn(X[jk_idx]), float) if jk_idx is not None else None
    else:
        draws = _per_resample(fn, X, idx, k, workers)
        jk = _per_resample(fn, X, jk_idx, k, workers) if jk_idx is not None else None
    draws = np.where(np.isfinite(draws), draws, np.nan)
    return BootResult(names=list(names), estimate=est, draws=draws, jackknife=jk, level=level, method=method)


def _per_resample(fn, X, idx, k, workers) -> np.ndarray:
    if len(idx) == 0:
        return np.empty((0, k))
    if workers > 1 and len(idx) >= 4 * workers:
        parts = np.array_split(idx, workers * 4)
        with ProcessPoolExecutor(max_workers=workers) as ex:
            results = [v for part in ex.map(_chunk, [(fn, X, p) for p in parts]) for v in part]
    else:
        results = _chunk((fn, X, idx))
    out = np.full((len(idx), k), np.nan)
    for b, v in enumerate(results):
        if v is not None and v.shape == (k,):
            out[b] = v
    return out

"""Rank statistics with ties where the data tie: every rank-based test of the tool ranks through this module.

Values are compared at the resolution they carry before they are ranked. A score that is a mean of six items on a
1-7 scale moves in steps of 1/6; computed in floating point, 7/6 comes out as 1.1666...665 from one set of answers
and 1.1666...660 from another, and a ranking of the raw floats splits a tie the data have (and a Wilcoxon test then
takes the exact no-ties distribution where R's normal approximation with tie correction applies). So each value is
first put on its grid: ``k = round(value / resolution)``, an integer, and ranks, ties, zeros and differences are
taken on those integers.

- A score's resolution follows from its declaration (:func:`study.folder.scores.score_resolution`: the items' step
  times the multiplier, over the number of items for a mean): TLX raw 5/6, trust 1/6, SUS 2.5.
- Any other value (a KPI) is compared at :data:`RELATIVE_RESOLUTION` of the largest magnitude of the values
  compared (:func:`resolution_of`), far below any measurement's precision and far above float noise.

The tests follow R (``stats``) exactly, two-sided:

- :func:`wilcoxon_signed_rank` = ``wilcox.test(x, y, paired = TRUE)``: zero differences dropped; V = the sum of the
  ranks of the positive differences; the exact distribution of V when n < 50 and there are neither ties nor zeros,
  else the normal approximation with continuity correction and the tie correction of the variance.
- :func:`mann_whitney` = ``wilcox.test(x, y)``: W = the rank sum of x minus n_x (n_x + 1) / 2; exact when both
  samples have fewer than 50 values and there are no ties, else normal with continuity and tie correction.
- :func:`friedman` = ``friedman.test(y)``: ranks within each block (row), chi^2 with the tie correction on k - 1
  df; Kendall's W = chi^2 / (n (k - 1)).
- :func:`spearman` = ``cor.test(x, y, method = "spearman")``: rho = the Pearson correlation of the ranks, S =
  (n^3 - n)(1 - rho) / 6; without ties (n <= 1290) the exact distribution of S (all permutations for n <= 9, the
  Edgeworth series of AS 89 above), with ties Student's t approximation on n - 2 df.

tests/analysis/test_ranks.py compares each with R on deliberately tied fractional data (tests/data/ranks/).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import stats

#: values closer than this fraction of the largest magnitude compared are ties (a KPI's default resolution)
RELATIVE_RESOLUTION = 1e-9
#: R's `exact = NULL` limits: the exact distribution below these sample sizes (and without ties)
EXACT_BELOW = 50
SPEARMAN_EXACT_MAX = 1290
#: up to this n the exact distribution of Spearman's S enumerates every permutation (R's prho.c, n_small)
SPEARMAN_ENUMERATE_MAX = 9
#: the Edgeworth coefficients of AS 89 (Best & Roberts 1975), as R's prho.c uses them
_AS89 = (0.2274, 0.2531, 0.1745, 0.0758, 0.1033, 0.3932, 0.0879, 0.0151, 0.0072, 0.0831, 0.0131, 4.6e-4)


@dataclass(frozen=True)
class RankTest:
    """One test: its statistic (R's V, W, chi-squared or S), the p-value (two-sided), the number of values or
    blocks that entered it, whether ties (or zero differences) were found, the method as R names it, and the
    estimate (rho, Kendall's W; NaN where the test has none)."""

    statistic: float
    p: float
    n: int
    ties: bool
    method: str
    estimate: float = float("nan")


# ---------------------------------------------------------------------------------------------- resolution
def resolution_of(values, resolution: float | None = None) -> float:
    """The resolution at which `values` are compared: `resolution` when given (> 0), else
    :data:`RELATIVE_RESOLUTION` times the largest finite magnitude (1 when all are zero)."""
    if resolution is not None:
        if not resolution > 0:
            raise ValueError(f"a resolution must be positive, not {resolution}")
        return float(resolution)
    v = np.abs(np.asarray(values, dtype=float))
    top = float(np.nanmax(v)) if v.size and np.isfinite(v).any() else 0.0
    return RELATIVE_RESOLUTION * top if top > 0 else 1.0


def on_grid(values, resolution: float, origin: float | None = None) -> np.ndarray:
    """`values` as whole multiples of `resolution` from `origin` (floats holding integers): equal at that
    resolution = equal. `origin` None = the smallest value (a grid need not pass through 0: a score's offset);
    differences, whose grid does, take 0."""
    v = np.asarray(values, dtype=float)
    if origin is None:
        origin = float(np.nanmin(v)) if v.size and not np.isnan(v).all() else 0.0
    return np.round((v - origin) / resolution)


def ranks(values) -> np.ndarray:
    """Average ranks (1..n, ties sharing their mean rank, as R's ``rank``) of values already on a grid."""
    return stats.rankdata(values, method="average")


def _tie_sum(r: np.ndarray) -> float:
    """sum(t^3 - t) over the groups of tied ranks (R's ``table(r)``)."""
    _, t = np.unique(r, return_counts=True)
    return float(np.sum(t.astype(float) ** 3 - t))


def _normal_p(z: float) -> float:
    return float(2 * min(stats.norm.cdf(z), stats.norm.sf(z)))


# ---------------------------------------------------------------------------------------------- Wilcoxon
@lru_cache(maxsize=None)
def _signrank_counts(n: int) -> np.ndarray:
    """counts[v] = how many of the 2^n sign patterns give V = v (ranks 1..n, no ties)."""
    counts = np.zeros(n * (n + 1) // 2 + 1)
    counts[0] = 1
    for k in range(1, n + 1):
        counts[k:] = counts[k:] + counts[:-k].copy()
    return counts


def _psignrank(v: float, n: int, upper: bool) -> float:
    """P(V <= v), or P(V > v) when `upper` (R's psignrank)."""
    c = _signrank_counts(n)
    k = int(math.floor(v + 1e-7))
    below = float(c[:max(k + 1, 0)].sum())
    total = float(c.sum())
    return (total - below) / total if upper else below / total


def wilcoxon_signed_rank(x, y, resolution: float | None = None, correct: bool = True) -> RankTest:
    """R's ``wilcox.test(x, y, paired = TRUE, correct = correct)``, two-sided, on the differences x - y at
    `resolution` (:func:`resolution_of` of x and y when None). NaN pairs are left out."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    keep = ~(np.isnan(x) | np.isnan(y))
    x, y = x[keep], y[keep]
    d = on_grid(x - y, resolution_of(np.concatenate([x, y]), resolution), origin=0.0)
    zeros = bool((d == 0).any())
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return RankTest(float("nan"), float("nan"), 0, zeros, "no non-zero difference")
    r = ranks(np.abs(d))
    v = float(r[d > 0].sum())
    ties = len(np.unique(r)) != n
    if n < EXACT_BELOW and not ties and not zeros:
        p = _psignrank(v - 1, n, upper=True) if v > n * (n + 1) / 4 else _psignrank(v, n, upper=False)
        return RankTest(v, min(2 * p, 1.0), n, False, "Wilcoxon signed rank exact test")
    z = v - n * (n + 1) / 4
    sigma = math.sqrt(n * (n + 1) * (2 * n + 1) / 24 - _tie_sum(r) / 48)
    z = (z - (np.sign(z) * 0.5 if correct else 0.0)) / sigma
    method = "Wilcoxon signed rank test" + (" with continuity correction" if correct else "")
    return RankTest(v, _normal_p(z), n, ties or zeros, method)


# ---------------------------------------------------------------------------------------------- Mann-Whitney
@lru_cache(maxsize=None)
def _wilcox_counts(m: int, n: int) -> np.ndarray:
    """counts[w] = how many of the C(m + n, m) arrangements give the Mann-Whitney W = w (no ties)."""
    # f(m, n) = f(m - 1, n) shifted by n + f(m, n - 1): built over a table of n
    table = [np.ones(1) for _ in range(n + 1)]          # m = 0: W = 0 once, for every n
    for i in range(1, m + 1):
        new = [np.ones(1)]                               # n = 0: W = 0 once
        for j in range(1, n + 1):
            a, b = table[j], new[j - 1]                  # f(i-1, j) shifted by j, f(i, j-1)
            out = np.zeros(i * j + 1)
            out[j:j + len(a)] += a
            out[:len(b)] += b
            new.append(out)
        table = new
    return table[n]


def _pwilcox(w: float, m: int, n: int, upper: bool) -> float:
    c = _wilcox_counts(m, n)
    k = int(math.floor(w + 1e-7))
    below = float(c[:max(k + 1, 0)].sum())
    total = float(c.sum())
    return (total - below) / total if upper else below / total


def mann_whitney(x, y, resolution: float | None = None, correct: bool = True) -> RankTest:
    """R's ``wilcox.test(x, y, correct = correct)`` (two independent samples), two-sided, at `resolution`
    (:func:`resolution_of` of both samples when None). NaN values are left out."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    x, y = x[~np.isnan(x)], y[~np.isnan(y)]
    nx, ny = len(x), len(y)
    res = resolution_of(np.concatenate([x, y]), resolution)
    r = ranks(on_grid(np.concatenate([x, y]), res))
    w = float(r[:nx].sum() - nx * (nx + 1) / 2)
    ties = len(np.unique(r)) != len(r)
    if nx < EXACT_BELOW and ny < EXACT_BELOW and not ties:
        p = _pwilcox(w - 1, nx, ny, upper=True) if w > nx * ny / 2 else _pwilcox(w, nx, ny, upper=False)
        return RankTest(w, min(2 * p, 1.0), nx + ny, False, "Wilcoxon rank sum exact test")
    z = w - nx * ny / 2
    sigma = math.sqrt((nx * ny / 12) * ((nx + ny + 1) - _tie_sum(r) / ((nx + ny) * (nx + ny - 1))))
    z = (z - (np.sign(z) * 0.5 if correct else 0.0)) / sigma
    method = "Wilcoxon rank sum test" + (" with continuity correction" if correct else "")
    return RankTest(w, _normal_p(z), nx + ny, ties, method)


# ---------------------------------------------------------------------------------------------- Friedman
def friedman(blocks, resolution: float | None = None) -> RankTest:
    """R's ``friedman.test(y)`` of the matrix `blocks` (one row per participant, one column per condition; rows
    with a NaN are left out), ranks within each row at `resolution` (:func:`resolution_of` of all values when
    None); the estimate is Kendall's W = chi^2 / (n (k - 1))."""
    y = np.asarray(blocks, dtype=float)
    y = y[~np.isnan(y).any(axis=1)]
    n, k = y.shape
    grid = on_grid(y, resolution_of(y, resolution)) if y.size else y
    r = np.vstack([ranks(row) for row in grid])
    tie = sum(_tie_sum(row) for row in r)
    chi2 = (12 * float(np.sum((r.sum(axis=0) - n * (k + 1) / 2) ** 2))) / (n * k * (k + 1) - tie / (k - 1))
    return RankTest(chi2, float(stats.chi2.sf(chi2, k - 1)), n, tie > 0, "Friedman rank sum test",
                    chi2 / (n * (k - 1)))


# ---------------------------------------------------------------------------------------------- Spearman
@lru_cache(maxsize=None)
def _rho_counts(n: int) -> np.ndarray:
    """counts[s] = how many permutations of 1..n give S = sum (i - p_i)^2 (n <= SPEARMAN_ENUMERATE_MAX)."""
    from itertools import permutations

    counts = np.zeros(n * (n * n - 1) // 3 + 1)
    idx = range(1, n + 1)
    for perm in permutations(idx):
        counts[sum((i - p) ** 2 for i, p in zip(idx, perm))] += 1
    return counts


def _prho(s: float, n: int, lower: bool) -> float:
    """P(S >= s), or P(S < s) when `lower`: R's prho (AS 89), exact for n <= 9, else its Edgeworth series."""
    if s <= 0:
        return 0.0 if lower else 1.0
    top = n * (n * n - 1) / 3
    if s > top:
        return 1.0 if lower else 0.0
    if n <= SPEARMAN_ENUMERATE_MAX:
        c = _rho_counts(n)
        at_least = float(c[int(math.ceil(s - 1e-9)):].sum())   # S takes whole (even) values
        total = float(c.sum())
        return (total - at_least) / total if lower else at_least / total
    c1, c2, c3, c4, c5, c6, c7, c8, c9, c10, c11, c12 = _AS89
    b = 1 / n
    x = (6 * (s - 1) * b / (n * n - 1) - 1) * math.sqrt(n - 1)
    y = x * x
    u = x * b * (c1 + b * (c2 + c3 * b) + y * (-c4 + b * (c5 + c6 * b)
                                              - y * b * (c7 + c8 * b - y * (c9 - c10 * b + y * b * (c11 - c12 * y)))))
    corr = u / math.exp(y / 2)
    p = -corr + stats.norm.cdf(x) if lower else corr + stats.norm.sf(x)
    return min(max(float(p), 0.0), 1.0)


def spearman(x, y, resolution: float | None = None) -> RankTest:
    """R's ``cor.test(x, y, method = "spearman")``, two-sided; each variable ranked at its own resolution
    (`resolution` applies to both; None = :func:`resolution_of` of each). NaN pairs are left out."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    keep = ~(np.isnan(x) | np.isnan(y))
    x, y = x[keep], y[keep]
    n = len(x)
    rx = ranks(on_grid(x, resolution_of(x, resolution)))
    ry = ranks(on_grid(y, resolution_of(y, resolution)))
    rho = float(np.corrcoef(rx, ry)[0, 1])
    ties = min(len(np.unique(rx)), len(np.unique(ry))) < n
    q = (n ** 3 - n) * (1 - rho) / 6
    if not ties and n <= SPEARMAN_EXACT_MAX:
        lower = q <= (n ** 3 - n) / 6
        p = _prho(round(q) + 2 * lower, n, lower=lower)
    else:
        t = rho / math.sqrt((1 - rho * rho) / (n - 2))
        p = float(stats.t.sf(abs(t), n - 2))
    return RankTest(q, min(2 * p, 1.0), n, ties, "Spearman's rank correlation rho", rho)

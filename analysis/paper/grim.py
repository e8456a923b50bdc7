"""GRIM and GRIMMER for bounded integer items (Brown & Heathers 2017; Anaya 2016; Allard 2018).

A mean of ``n`` integer answers is a multiple of ``1/n``; GRIM asks whether any such multiple rounds to the printed
mean. GRIMMER asks the same of the standard deviation (sample SD, ``n - 1`` in the denominator): is there a
distribution of ``n`` answers on ``lo..hi`` whose mean *and* SD round to the printed pair? On a 5-point scale the
answer is exact by enumerating all count vectors (``C(n + 4, 4)`` of them, about 136 000 for n = 40).
"""
from __future__ import annotations

from functools import lru_cache
from itertools import combinations

import numpy as np

# Half a unit in the last printed digit, widened by a little float noise (values are compared, never ==).
_EPS = 1e-9


def half_unit(decimals: int) -> float:
    """Half a unit of the last printed digit: the rounding interval is value ± this."""
    return 0.5 * 10.0 ** (-decimals) + _EPS


def interval(printed_value: float, decimals: int, mode: str = "round") -> tuple[float, float]:
    """The closed interval of true values that print as ``printed_value`` with ``decimals`` digits.

    ``mode='round'``: value ± half a unit; ``mode='truncate'``: digits cut off (toward zero), so the true value lies
    in [v, v + 1 unit) for v >= 0."""
    if mode == "round":
        h = half_unit(decimals)
        return printed_value - h, printed_value + h
    if mode == "truncate":
        unit = 10.0 ** (-decimals)
        if printed_value >= 0:
            return printed_value - _EPS, printed_value + unit - _EPS
        return printed_value - unit + _EPS, printed_value + _EPS
    raise ValueError(f"unknown rounding mode {mode!r} (round | truncate)")


def prints_as(true_value, printed_value: float, decimals: int, mode: str = "round"):
    """Whether ``true_value`` (scalar or array) prints as ``printed_value`` under the rounding ``mode``."""
    lo, hi = interval(printed_value, decimals, mode)
    return (np.asarray(true_value) >= lo) & (np.asarray(true_value) <= hi)


def grim_sums(mean: float, n: int, decimals: int) -> list[int]:
    """Integer sums S such that S / n rounds to the printed ``mean`` (empty list = GRIM-inconsistent)."""
    h = half_unit(decimals)
    lo, hi = int(np.ceil((mean - h) * n)), int(np.floor((mean + h) * n))
    return list(range(lo, hi + 1))


def grim_consistent(mean: float, n: int, decimals: int) -> bool:
    """True if some integer sum over n answers gives the printed mean."""
    return bool(grim_sums(mean, n, decimals))


@lru_cache(maxsize=16)
def count_vectors(n: int, lo: int = 1, hi: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All count vectors of n answers on lo..hi: (counts[K, hi-lo+1], sums[K], sums_of_squares[K])."""
    k = hi - lo + 1
    # stars and bars: choose k-1 bar positions among n+k-1 slots
    bars = np.array(list(combinations(range(n + k - 1), k - 1)), dtype=np.int64)
    edges = np.hstack([np.full((len(bars), 1), -1), bars, np.full((len(bars), 1), n + k - 1)])
    counts = np.diff(edges, axis=1) - 1
    values = np.arange(lo, hi + 1)
    return counts, counts @ values, counts @ (values ** 2)


def sd_from_sums(s: np.ndarray, q: np.ndarray, n: int) -> np.ndarray:
    """Sample SD (n - 1) from sum and sum of squares."""
    return np.sqrt(np.maximum(q - s.astype(float) ** 2 / n, 0.0) / (n - 1))


def grimmer_candidates(mean: float, sd: float, n: int, mean_decimals: int, sd_decimals: int,
                       lo: int = 1, hi: int = 5, sd_mode: str = "round") -> np.ndarray:
    """Count vectors (rows, values lo..hi) whose mean rounds to the printed mean and whose sample SD prints as
    the printed SD under ``sd_mode`` (round | truncate)."""
    counts, s, q = count_vectors(n, lo, hi)
    ok = np.abs(s / n - mean) <= half_unit(mean_decimals)
    ok &= prints_as(sd_from_sums(s, q, n), sd, sd_decimals, sd_mode)
    return counts[ok]


def grimmer_consistent(mean: float, sd: float, n: int, mean_decimals: int, sd_decimals: int,
                       lo: int = 1, hi: int = 5, sd_mode: str = "round") -> bool:
    """True if some distribution of n answers on lo..hi reproduces the printed mean and SD."""
    return len(grimmer_candidates(mean, sd, n, mean_decimals, sd_decimals, lo, hi, sd_mode)) > 0


def nearest_sd(mean_sum: int, sd: float, n: int, lo: int = 1, hi: int = 5) -> float:
    """The achievable sample SD closest to ``sd`` among distributions with sum ``mean_sum``."""
    counts, s, q = count_vectors(n, lo, hi)
    sds = sd_from_sums(s[s == mean_sum], q[s == mean_sum], n)
    return float(sds[np.argmin(np.abs(sds - sd))])

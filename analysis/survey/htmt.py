"""HTMT2 and bootstrap confidence intervals of alpha, omega, HTMT and HTMT2.

* HTMT (Henseler, Ringle & Sarstedt 2015), as :func:`analysis.survey.validity.htmt`: the arithmetic mean of the
  heterotrait |r| over the geometric mean of the two constructs' mean monotrait |r|.
* HTMT2 (Roemer, Schuberth & Henseler 2021; semTools ``htmt(htmt2 = TRUE)``): every arithmetic mean replaced by
  the geometric mean, HTMT2_ab = GM(|r_het|) / sqrt(GM(|r_mono,a|) GM(|r_mono,b|)); consistent under congeneric
  (unequal) loadings, where HTMT is not.
* Bootstrap (:func:`reliability_bootstrap`): BCa (:mod:`analysis.survey.bootstrap`), seeded, vectorised over resamples:
  Cronbach's alpha per construct, one-factor ML omega per construct (:mod:`analysis.survey.omega`), HTMT and HTMT2 per
  construct pair. A resample in which an item has no variance (likely at N ~ 35 with 5-point items) makes the
  statistics that use that item NaN: a counted failure (``n_failed``), the interval from the other resamples.
* Zero correlations: a correlation of integer answers is exactly 0 when their cross-products cancel, but floating
  point gives ~1e-17, whose logarithm made HTMT2 explode (bootstrap upper bounds of 456). |r| < ``ZERO_R`` is
  therefore 0 (a non-zero |r| of N integer answers on a K-point scale is at least 4/(N^2 (K-1)^2): its numerator
  N sum xy - sum x sum y is a non-zero integer; 2e-4 at N = 35, K = 5, far above it). A zero heterotrait correlation gives HTMT2 = 0 (its limit); a zero monotrait
  correlation makes the construct's geometric mean 0 and HTMT2 undefined: NaN (a counted failure in a resample).
"""
from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd

from analysis.survey.bootstrap import bootstrap
from analysis.survey.omega import omega_stack
from analysis.survey.validity import HTMT_LIBERAL, HTMT_STRICT

ZERO_R = 1e-12  # |r| below this is a zero correlation up to rounding (module docstring)


def _corr_stack(X: np.ndarray) -> np.ndarray:
    """Pearson correlation matrices of stacked samples X (B, n, p); NaN rows/columns for a constant item."""
    Xc = X - X.mean(axis=1, keepdims=True)
    C = np.einsum("bni,bnj->bij", Xc, Xc)
    d = np.sqrt(np.diagonal(C, axis1=1, axis2=2))
    with np.errstate(divide="ignore", invalid="ignore"):
        R = C / d[:, :, None] / d[:, None, :]
    bad = d <= 1e-12
    R = np.where(bad[:, :, None] | bad[:, None, :], np.nan, R)
    return R


def _htmt_stack(R: np.ndarray, constructs: dict[str, list[str]], items: list[str], geometric: bool) -> np.ndarray:
    """(B, n_pairs) HTMT (arithmetic) or HTMT2 (geometric) from stacked correlation matrices; NaN where a
    construct's mean monotrait correlation is 0 (undefined)."""
    A = np.abs(R)
    A = np.where(A < ZERO_R, 0.0, A)  # rounding noise of an exact zero (module docstring); NaN stays NaN
    pos = {i: k for k, i in enumerate(items)}

    def mean(block):
        if geometric:
            with np.errstate(divide="ignore"):
                return np.exp(np.mean(np.log(block), axis=1))
        return np.mean(block, axis=1)

    mono = {}
    for c, its in constructs.items():
        idx = [pos[i] for i in its]
        iu = np.triu_indices(len(idx), 1)
        mono[c] = mean(A[:, idx][:, :, idx][:, iu[0], iu[1]])
    out = []
    for a, b in combinations(constructs, 2):
        ia, ib = [pos[i] for i in constructs[a]], [pos[i] for i in constructs[b]]
        het = mean(A[:, ia][:, :, ib].reshape(A.shape[0], -1))
        den = np.sqrt(mono[a] * mono[b])
        with np.errstate(divide="ignore", invalid="ignore"):
            out.append(np.where(den > 0, het / den, np.nan))
    return np.stack(out, axis=1)


def htmt2(scored: pd.DataFrame, constructs: dict[str, list[str]]) -> pd.DataFrame:
    """a, b, htmt, htmt2, above_085, above_090 (the flags on HTMT2) of every construct pair (complete rows);
    htmt2 NaN (flags False) where a construct has a zero monotrait correlation (module docstring).

    Examples
    --------
    Items that agree within each construct (monotrait r = 1) and correlate .5 across: HTMT = HTMT2 = .5.

    >>> import pandas as pd
    >>> from analysis.survey.htmt import htmt2
    >>> items = pd.DataFrame({"x1": [1, 2, 3], "x2": [1, 2, 3], "y1": [1, 3, 2], "y2": [1, 3, 2]})
    >>> htmt2(items, {"X": ["x1", "x2"], "Y": ["y1", "y2"]}).round(3)
       a  b  htmt  htmt2  above_085  above_090
    0  X  Y   0.5    0.5      False      False
    """
    items = [i for its in constructs.values() for i in its]
    X = scored[items].dropna().to_numpy(float)[None]
    R = _corr_stack(X)
    h1 = _htmt_stack(R, constructs, items, False)[0]
    h2 = _htmt_stack(R, constructs, items, True)[0]
    pairs = list(combinations(constructs, 2))
    return pd.DataFrame({"a": [a for a, _ in pairs], "b": [b for _, b in pairs], "htmt": h1, "htmt2": h2,
                         "above_085": h2 > HTMT_STRICT, "above_090": h2 > HTMT_LIBERAL})


def _alpha_stack(X: np.ndarray) -> np.ndarray:
    k = X.shape[2]
    v_items = X.var(axis=1, ddof=1).sum(axis=1)
    v_sum = X.sum(axis=2).var(axis=1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = k / (k - 1) * (1.0 - v_items / v_sum)
    return np.where(v_sum > 0, a, np.nan)


def reliability_bootstrap(scored: pd.DataFrame, constructs: dict[str, list[str]], *, n_boot: int = 2000,
                          seed: int = 20240101, level: float = 0.95, method: str = "bca") -> pd.DataFrame:
    """Bootstrap CIs (module docstring) of alpha and omega per construct and HTMT/HTMT2 per pair.

    Returns statistic ("alpha" | "omega" | "htmt" | "htmt2"), a, b ("" for one construct), estimate, ci_low,
    ci_high, n_boot, n_failed, method; omega's estimate is the one-factor ML omega (:mod:`analysis.survey.omega`).
    """
    items = [i for its in constructs.values() for i in its]
    X = scored[items].dropna().to_numpy(float)
    pos = {i: k for k, i in enumerate(items)}
    pairs = list(combinations(constructs, 2))
    names, keys = [], []
    for c in constructs:
        names += [f"alpha {c}", f"omega {c}"]
        keys += [("alpha", c, ""), ("omega", c, "")]
    for a, b in pairs:
        names += [f"htmt {a}-{b}", f"htmt2 {a}-{b}"]
        keys += [("htmt", a, b), ("htmt2", a, b)]

    def stats_of(B: np.ndarray) -> np.ndarray:
        cols = []
        for c, its in constructs.items():
            sub = B[:, :, [pos[i] for i in its]]
            cols.append(_alpha_stack(sub))
            Xc = sub - sub.mean(axis=1, keepdims=True)
            S = np.einsum("bni,bnj->bij", Xc, Xc) / sub.shape[1]
            dS = np.diagonal(S, axis1=1, axis2=2)
            om = np.full(B.shape[0], np.nan)
            ok = dS.min(axis=1) > 0
            if ok.any():
                om[ok] = omega_stack(S[ok])
            cols.append(om)
        R = _corr_stack(B)
        h1 = _htmt_stack(R, constructs, items, False)
        h2 = _htmt_stack(R, constructs, items, True)
        for j in range(len(pairs)):
            cols += [h1[:, j], h2[:, j]]
        return np.stack(cols, axis=1)

    res = bootstrap(X, stats_of, names, n_boot=n_boot, seed=seed, level=level, method=method, vectorised=True)
    tab = res.table().drop(columns="statistic")
    tab.insert(0, "statistic", [k[0] for k in keys])
    tab.insert(1, "a", [k[1] for k in keys])
    tab.insert(2, "b", [k[2] for k in keys])
    return tab

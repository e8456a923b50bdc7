"""Ordinal treatment of Likert items: thresholds, polychoric correlations, a CFA on them (ULS or DWLS) and
ordinal omega.

* Bivariate normal probabilities (:func:`bvn_upper`): Drezner & Wesolowsky (1990) as refined by Genz (2004), with
  Gauss-Legendre quadrature (20 nodes), accurate to ~1e-15; deterministic (no Monte Carlo).
* Thresholds of an item with categories c_1 < ... < c_m: tau_j = Phi^-1(share of answers <= c_j), j = 1..m-1.
  The categories are the answers the item has anywhere in the data set (lavaan's ``ordered=`` levels, taken
  before listwise deletion; an answer of the scale nobody gave is not a category). A category without answers
  among the analysed (complete) rows has no threshold (tau_j = tau_j+1 or -inf: a boundary solution), so it is
  refused as lavaan refuses it ("some categories of variable ... are empty"), or merged with its neighbours only
  when asked (``collapse_empty=True``), with a warning naming it (:func:`check_categories`).
* Polychoric correlation (two-step, Olsson 1979, lavaan's ``lavCor(ordered=)``): thresholds fixed at their
  univariate estimates, rho maximises sum_ab n_ab log P_ab(rho), P_ab the bivariate normal probability of the cell
  rectangle; Brent's bounded search on (-1, 1) to 1e-10 (scipy's steps; the searches of all pairs run in
  lockstep, :mod:`analysis.survey.lockstep`, one vectorised probability call per round, each result bit for bit
  that of the pair alone, :func:`polychoric_pair`). The asymptotic variance of each rho (the DWLS weights)
  follows Muthen (1984) as lavaan computes it (:func:`_avar`): the empirical variance of its influence function,
  with the thresholds' sampling error carried through, from outer products of the case-wise scores.
* Ordinal CFA, delta parameterisation: rho_ij = lambda_i lambda_j phi_{c(i)c(j)} for i < j (standardized loadings
  lambda, factor correlations phi), error variance 1 - lambda_i^2; estimated by least squares on the p(p-1)/2
  polychoric correlations, ``ULS`` (unit weights; the point estimates of lavaan ``estimator="ULSMV"``) or ``DWLS``
  (weights 1/avar(rho_ij), lavaan's diagonal WLS.V; the point estimates of lavaan ``estimator="WLSMV"``).
  The scaled-shifted test statistic of WLSMV is not computed; the fit reported is the weighted discrepancy and
  the SRMR of the polychoric residuals, lavaan's categorical ``srmr``: sqrt(sum_{i<j} (r_ij - rho_ij)^2 /
  (p(p+1)/2)), the p zero residuals of the unit diagonal counted as lavaan counts them.
* Admissibility (:func:`analysis.survey.admissibility.improper`): an error variance 1 - lambda_i^2 <= 0 or a
  factor correlation matrix that is not positive definite (e.g. a |correlation| > 1, which this unbounded
  least-squares fit can reach) is a warning, and ``admissible`` is False.
* Ordinal omega (Green & Yang 2009; semTools ``compRelSEM(ord.scale=TRUE)``):
  omega = sum_jj' [sum_cc' Phi2(tau_jc, tau_j'c'; r*_jj') - Phi(tau_jc)Phi(tau_j'c')] /
          sum_jj' [sum_cc' Phi2(tau_jc, tau_j'c'; rho_jj') - Phi(tau_jc)Phi(tau_j'c')],
  r* = Lambda Phi Lambda' (the common part; diagonal lambda_j^2) and rho the sample polychoric matrix (unit
  diagonal): the reliability of the sum of the *observed* ordinal answers.

semopy (2.3) has a polychoric correlation (``semopy.polycorr.polychoric_corr``, same two-step estimator, bounded
search to ~1e-5) but its ``DWLS``/``WLS`` objectives weight by the fourth moments of the raw data treated as
continuous, not by the sampling variance of polychoric correlations, so the CFA here is estimated directly.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import optimize
from scipy.special import ndtr, ndtri

from analysis.survey.admissibility import improper, singular_sample

_GL_X, _GL_W = np.polynomial.legendre.leggauss(20)
TWO_PI = 2.0 * np.pi
BIG = 1e3


def _sf(x):
    return ndtr(-np.asarray(x, float))


def bvn_upper(h, k, r) -> np.ndarray:
    """P(X > h, Y > k) for standard bivariate normal X, Y with correlation r (arrays broadcast; +-inf allowed).

    Examples
    --------
    >>> from analysis.survey.ordinal import bvn_upper
    >>> round(float(bvn_upper(0.0, 0.0, 0.5)), 12)          # 1/4 + asin(r)/(2 pi) = 1/3
    0.333333333333
    >>> round(float(bvn_upper(0.0, 0.0, -0.95)), 12)        # 1/4 + asin(-.95)/(2 pi)
    0.050541312052
    """
    h, k, r = np.broadcast_arrays(np.asarray(h, float), np.asarray(k, float), np.asarray(r, float))
    shape = h.shape
    # +-inf as +-BIG: every term then under/overflows to the exact limit (Phi(-BIG) = 0, exp(-BIG^2) = 0)
    h = np.clip(h.ravel(), -BIG, BIG)
    k = np.clip(k.ravel(), -BIG, BIG)
    r = np.clip(r.ravel(), -1.0, 1.0)
    out = np.empty(h.shape)
    sf = _sf
    lo = np.abs(r) < 0.925
    one = r >= 1.0
    mone = r <= -1.0
    hi = ~lo & ~one & ~mone
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        if lo.any():
            hh, kk, rr = h[lo], k[lo], r[lo]
            hk = hh * kk
            hs = (hh * hh + kk * kk) / 2.0
            asr = np.arcsin(rr)
            sn = np.sin(asr[:, None] * (_GL_X[None, :] + 1.0) / 2.0)
            s = np.sum(_GL_W * np.exp((sn * hk[:, None] - hs[:, None]) / (1.0 - sn * sn)), axis=1)
            out[lo] = s * asr / (2.0 * TWO_PI) + sf(hh) * sf(kk)
        out[one] = sf(np.maximum(h[one], k[one]))
        out[mone] = np.maximum(0.0, sf(h[mone]) - ndtr(k[mone]))
        if hi.any():
            hh, rr = h[hi], r[hi]
            neg = rr < 0
            kk = np.where(neg, -k[hi], k[hi])
            hk = hh * kk
            a2 = (1.0 - rr) * (1.0 + rr)
            a = np.sqrt(a2)
            bs = (hh - kk) ** 2
            c = (4.0 - hk) / 8.0
            d = (12.0 - hk) / 16.0
            bvn = a * np.exp(-(bs / a2 + hk) / 2.0) * (1.0 - c * (bs - a2) * (1.0 - d * bs / 5.0) / 3.0
                                                      + c * d * a2 * a2 / 5.0)
            b = np.sqrt(bs)
            corr = np.exp(-hk / 2.0) * np.sqrt(TWO_PI) * ndtr(-b / a) * b * (1.0 - c * bs * (1.0 - d * bs / 5.0) / 3.0)
            bvn = bvn - np.where(hk > -160.0, np.nan_to_num(corr), 0.0)
            half = a / 2.0
            xs = (half[:, None] * (_GL_X[None, :] + 1.0)) ** 2
            rs = np.sqrt(1.0 - xs)
            terms = np.exp(-bs[:, None] / (2.0 * xs) - hk[:, None] / (1.0 + rs)) / rs \
                - np.exp(-(bs[:, None] / xs + hk[:, None]) / 2.0) * (1.0 + c[:, None] * xs * (1.0 + d[:, None] * xs))
            bvn = bvn + np.sum(half[:, None] * _GL_W * terms, axis=1)
            bvn = -bvn / TWO_PI
            pos_v = bvn + sf(np.maximum(hh, kk))
            lower = np.where(hh < 0, ndtr(kk) - ndtr(hh), sf(hh) - sf(kk))
            neg_v = -bvn + np.where(kk > hh, lower, 0.0)
            out[hi] = np.where(neg, neg_v, pos_v)
    return np.clip(out, 0.0, 1.0).reshape(shape)


def bvn_cdf(h, k, r) -> np.ndarray:
    """P(X <= h, Y <= k) = P(X > -h, Y > -k) for the standard bivariate normal with correlation r.

    Examples
    --------
    >>> from analysis.survey.ordinal import bvn_cdf
    >>> round(float(bvn_cdf(1.0, 1.0, 1.0)), 12), round(float(bvn_cdf(0.0, 0.0, 0.0)), 12)
    (0.841344746069, 0.25)
    """
    return bvn_upper(-np.asarray(h, float), -np.asarray(k, float), r)


def codes(x: pd.Series) -> tuple[np.ndarray, np.ndarray]:
    """(category index 0..m-1 of each answer, thresholds tau_1..tau_{m-1}) of one item (observed categories only).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.ordinal import codes
    >>> c, tau = codes(pd.Series([1, 1, 3, 3, 3, 5]))       # shares <= 1: 2/6, <= 3: 5/6
    >>> c.tolist(), tau.round(4).tolist()
    ([0, 0, 1, 1, 1, 2], [-0.4307, 0.9674])
    """
    v = np.asarray(x, float)
    levels = np.unique(v)
    c = np.searchsorted(levels, v)
    counts = np.bincount(c, minlength=len(levels))
    cum = np.cumsum(counts)[:-1] / len(v)
    return c, ndtri(cum)


def _cells(tx, ty, rho):
    """(m_x, m_y) matrix of cell probabilities for thresholds tx, ty and correlation rho."""
    ex = np.concatenate([[-np.inf], tx, [np.inf]])
    ey = np.concatenate([[-np.inf], ty, [np.inf]])
    F = bvn_cdf(ex[:, None], ey[None, :], rho)
    return F[1:, 1:] - F[:-1, 1:] - F[1:, :-1] + F[:-1, :-1]


def _univariate(t):
    e = np.concatenate([[-np.inf], t, [np.inf]])
    return np.diff(ndtr(e))


def polychoric_pair(cx: np.ndarray, cy: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> float:
    """Two-step ML polychoric correlation of two coded items (thresholds fixed); ValueError if the search fails."""
    n = np.zeros((len(tx) + 1, len(ty) + 1))
    np.add.at(n, (cx, cy), 1.0)

    def nll(r):
        p = _cells(tx, ty, r)
        with np.errstate(divide="ignore"):
            return -float(np.sum(n[n > 0] * np.log(np.clip(p[n > 0], 1e-300, None))))

    res = optimize.minimize_scalar(nll, bounds=(-0.999999, 0.999999), method="bounded",
                                   options={"xatol": 1e-10, "maxiter": 500})
    if not res.success or not np.isfinite(res.x):
        raise ValueError(f"polychoric correlation: search did not converge ({res.message})")
    return float(res.x)


def _cells_many(grids: list) -> list[np.ndarray]:
    """:func:`_cells` of each (tx, ty, rho) in `grids`, from one :func:`bvn_upper` call on all their grid points
    (elementwise, so each matrix equals its own :func:`_cells` bit for bit)."""
    hs, ks, rs, shapes = [], [], [], []
    for tx, ty, rho in grids:
        h, k = _grid(tx, ty)
        hs.append(h)
        ks.append(k)
        rs.append(np.full(h.size, rho, dtype=float))
        shapes.append((len(tx) + 2, len(ty) + 2))
    F_all = bvn_upper(np.concatenate(hs), np.concatenate(ks), np.concatenate(rs))
    out, at = [], 0
    for shape in shapes:
        F = F_all[at:at + shape[0] * shape[1]].reshape(shape)
        at += shape[0] * shape[1]
        out.append(F[1:, 1:] - F[:-1, 1:] - F[1:, :-1] + F[:-1, :-1])
    return out


def _grid(tx, ty) -> tuple[np.ndarray, np.ndarray]:
    """The flattened (h, k) of the bvn_upper call of :func:`_cells` (bvn_cdf(ex, ey) = bvn_upper(-ex, -ey))."""
    ex = np.concatenate([[-np.inf], tx, [np.inf]])
    ey = np.concatenate([[-np.inf], ty, [np.inf]])
    return np.repeat(-ex, len(ey)), np.tile(-ey, len(ex))


def _polychoric_pairs(pairs: list) -> list[float]:
    """:func:`polychoric_pair` of every (cx, cy, tx, ty) in `pairs` (the same searches and results, bit for bit),
    the searches run in lockstep (:func:`analysis.survey.lockstep.minimize_bounded_many`) so that each round
    evaluates the trial correlations of all pairs in one vectorised call. ValueError (the first pair in order)
    if a search fails."""
    from analysis.survey.lockstep import minimize_bounded_many

    counts, grids = [], []
    for cx, cy, tx, ty in pairs:
        n = np.zeros((len(tx) + 1, len(ty) + 1))
        np.add.at(n, (cx, cy), 1.0)
        counts.append(n)
        grids.append(_grid(tx, ty))

    def evaluate(idx, xs):
        h = np.concatenate([grids[i][0] for i in idx])
        k = np.concatenate([grids[i][1] for i in idx])
        sizes = [grids[i][0].size for i in idx]
        F_all = bvn_upper(h, k, np.repeat(xs, sizes))
        out, at = [], 0
        for i, size in zip(idx, sizes):
            n = counts[i]
            F = F_all[at:at + size].reshape(n.shape[0] + 1, n.shape[1] + 1)
            at += size
            p = F[1:, 1:] - F[:-1, 1:] - F[1:, :-1] + F[:-1, :-1]
            with np.errstate(divide="ignore"):  # the negative log-likelihood of polychoric_pair's nll
                out.append(-float(np.sum(n[n > 0] * np.log(np.clip(p[n > 0], 1e-300, None)))))
        return out

    results = minimize_bounded_many(evaluate, len(pairs), (-0.999999, 0.999999), xatol=1e-10, maxiter=500)
    for res in results:
        if not res.success or not np.isfinite(res.x):
            raise ValueError(f"polychoric correlation: search did not converge ({res.message})")
    return [res.x for res in results]


def check_categories(data: pd.DataFrame, items: list[str], categories: dict | None = None, *,
                     collapse_empty: bool = False) -> list[str]:
    """Refuse (ValueError, one line) an item whose categories are not all answered among the complete rows of
    `data`, as lavaan does; with `collapse_empty` return one warning per such item instead (its empty categories
    are merged: the item is analysed with the categories it has).

    `categories`: item -> its categories (the answers it has anywhere in the data set, e.g. before listwise
    deletion); None: the answers of the complete rows themselves (then no category can be empty).

    Examples
    --------
    Answer 3 was given to PU1 only by a participant left out for a missing answer elsewhere:

    >>> import pandas as pd
    >>> from analysis.survey.ordinal import check_categories
    >>> rows = pd.DataFrame({"PU1": [1, 2, 2, 4, 5, 3], "PU2": [1, 2, 3, 4, 5, None]})
    >>> cats = {"PU1": [1, 2, 3, 4, 5], "PU2": [1, 2, 3, 4, 5]}
    >>> check_categories(rows, ["PU1", "PU2"], cats)
    Traceback (most recent call last):
    ...
    ValueError: ordinal CFA: some categories of item PU1 are empty among the 5 complete rows (answers 1 2 3 4 5: frequencies [1 2 0 1 1]); pass collapse_empty (CLI: --collapse-empty of `analyze extended` or `analyze survey --extended`) to merge them
    >>> check_categories(rows, ["PU1", "PU2"], cats, collapse_empty=True)
    ['ordinal CFA: item PU1: empty category 3 among the 5 complete rows collapsed (4 of 5 categories analysed)']
    """
    if categories is None:
        return []
    x = data[items].dropna()
    out = []
    for it in items:
        cats = np.sort(np.asarray(list(categories[it]), float))
        freq = np.array([int((x[it] == c).sum()) for c in cats])
        if np.all(freq > 0):
            continue
        shown = " ".join(f"{c:g}" for c in cats)
        if not collapse_empty:
            raise ValueError(f"ordinal CFA: some categories of item {it} are empty among the {len(x)} complete rows "
                             f"(answers {shown}: frequencies [{' '.join(map(str, freq))}]); pass collapse_empty "
                             f"(CLI: --collapse-empty of `analyze extended` or `analyze survey --extended`) to merge "
                             f"them")
        empty = " ".join(f"{c:g}" for c in cats[freq == 0])
        word = "category" if (freq == 0).sum() == 1 else "categories"
        out.append(f"ordinal CFA: item {it}: empty {word} {empty} among the {len(x)} complete rows collapsed "
                   f"({int((freq > 0).sum())} of {len(cats)} categories analysed)")
    return out


@dataclass
class Polychoric:
    """items; R: polychoric correlation matrix (DataFrame, unit diagonal); thresholds: item -> tau array;
    avar: asymptotic variance of each rho_ij (DataFrame, NaN diagonal) as N x var; n; warnings: the collapsed
    empty categories (:func:`check_categories`)."""

    items: list[str]
    R: pd.DataFrame
    thresholds: dict[str, np.ndarray]
    avar: pd.DataFrame
    n: int
    warnings: list[str] = field(default_factory=list)


def polychoric(data: pd.DataFrame, items: list[str], *, acov: bool = True, categories: dict | None = None,
               collapse_empty: bool = False) -> Polychoric:
    """Polychoric correlations of `items` (complete rows of integer answers), with the influence-function
    asymptotic variances of the module docstring when `acov`. `categories`, `collapse_empty`: as
    :func:`check_categories` (an empty category is refused unless collapsed).

    Raises ValueError when an item has a single observed category or an empty category not collapsed.
    """
    warn = check_categories(data, items, categories, collapse_empty=collapse_empty)
    x = data[items].dropna()
    n = len(x)
    cod, thr = {}, {}
    for it in items:
        c, t = codes(x[it])
        if len(t) == 0:
            raise ValueError(f"ordinal CFA: item {it} has a single observed answer category")
        cod[it], thr[it] = c, t
    p = len(items)
    R = np.eye(p)
    V = np.full((p, p), np.nan)
    pairs = list(combinations(range(p), 2))
    # every pair's search in lockstep (the same steps as polychoric_pair, one vectorised bvn call per round)
    rhos = _polychoric_pairs([(cod[items[i]], cod[items[j]], thr[items[i]], thr[items[j]]) for i, j in pairs])
    for (i, j), r in zip(pairs, rhos):
        R[i, j] = R[j, i] = r
    if acov:
        # the cell probabilities of every pair's influence function in one vectorised call, then each avar alone
        requests = [_avar_requests(thr[items[i]], thr[items[j]], r) for (i, j), r in zip(pairs, rhos)]
        cells = _cells_many([g for req in requests for g in req])
        k = 0
        for (i, j), r, req in zip(pairs, rhos, requests):
            a, b = items[i], items[j]
            V[i, j] = V[j, i] = _avar(cod[a], cod[b], thr[a], thr[b], r, cells=cells[k:k + len(req)])
            k += len(req)
    return Polychoric(items=list(items), R=pd.DataFrame(R, index=items, columns=items), thresholds=thr,
                      avar=pd.DataFrame(V, index=items, columns=items), n=n, warnings=warn)


def _uni_scores(c: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n, m-1) scores d log P(c_i) / d tau_m of the univariate threshold model."""
    e = np.concatenate([[-np.inf], t, [np.inf]])
    P = np.diff(ndtr(e))
    m = np.arange(len(t))
    dens = np.exp(-t * t / 2.0) / np.sqrt(TWO_PI)
    return dens[None, :] * ((c[:, None] == m[None, :]).astype(float)
                            - (c[:, None] == m[None, :] + 1).astype(float)) / P[c][:, None]


def _avar(cx, cy, tx, ty, rho, eps: float = 1e-6, cells: list | None = None) -> float:
    """N x asymptotic variance of the two-step rho (Muthen 1984, as lavaan's ``lav_muthen1984``): the mean squared
    influence value IF_i = [s_i - sum_{x,y} E(s s_tau,biv') B_tau^-1 s_tau,uni,i] / E(s^2), with s_i the score of
    rho, s_tau,biv the scores of the bivariate likelihood in the thresholds, s_tau,uni the univariate threshold
    scores and B_tau = E(s_tau,uni s_tau,uni'); every expectation the sample mean of cross-products (outer-product
    information), the scores of the bivariate likelihood by central differences.

    `cells`: the :func:`_cells` of :func:`_avar_requests` (tx, ty, rho, eps), in its order, when computed
    beforehand (e.g. for many pairs in one call); None computes them here."""
    if cells is None:
        cells = [_cells(*g) for g in _avar_requests(tx, ty, rho, eps)]
    logl = [np.log(p[cx, cy]) for p in cells]
    s = (logl[0] - logl[1]) / (2 * eps)
    infl = s.copy()
    at = 2
    for t, c in ((tx, cx), (ty, cy)):
        su = _uni_scores(c, t)
        if_t = su @ np.linalg.inv(su.T @ su / len(c))
        sb = np.empty((len(c), len(t)))
        for m in range(len(t)):
            sb[:, m] = (logl[at] - logl[at + 1]) / (2 * eps)
            at += 2
        infl = infl - if_t @ (s[:, None] * sb).mean(axis=0)
    return float(np.mean((infl / np.mean(s ** 2)) ** 2))


def _avar_requests(tx, ty, rho, eps: float = 1e-6) -> list[tuple]:
    """The (tx, ty, rho) whose cell probabilities :func:`_avar` needs, in its order: rho +- eps, then each
    threshold of x and then of y moved up and down by eps."""
    out = [(tx, ty, rho + eps), (tx, ty, rho - eps)]
    for which, t in (("x", tx), ("y", ty)):
        for m in range(len(t)):
            up, dn = t.copy(), t.copy()
            up[m] += eps
            dn[m] -= eps
            out += [(up, ty, rho), (dn, ty, rho)] if which == "x" else [(tx, up, rho), (tx, dn, rho)]
    return out


@dataclass
class OrdinalCFA:
    """loadings: construct, item, loading (standardized, delta parameterisation), error_var (1 - loading^2);
    latent_corr; fit: estimator, n, f_min (weighted residual sum of squares), srmr (lavaan's: the residual
    correlations over p(p+1)/2 elements), n_params, df; poly: the Polychoric input; converged (the optimiser's
    postcondition); admissible (no improper estimate); warnings."""

    constructs: dict[str, list[str]]
    estimator: str
    loadings: pd.DataFrame
    latent_corr: pd.DataFrame
    fit: dict
    poly: Polychoric
    converged: bool
    warnings: list[str] = field(default_factory=list)
    admissible: bool = True


def fit_ordinal_cfa(data: pd.DataFrame, constructs: dict[str, list[str]], *, estimator: str = "DWLS",
                    poly: Polychoric | None = None, categories: dict | None = None,
                    collapse_empty: bool = False) -> OrdinalCFA:
    """Correlated-factors CFA on polychoric correlations (module docstring), estimator "DWLS" or "ULS".
    `categories`, `collapse_empty`: as :func:`check_categories` (used when `poly` is not given; the warnings of
    collapsed categories are the fit's only then, not repeated for a shared `poly`).

    Raises ValueError on an unknown estimator, a construct with fewer than 2 items, an empty category not
    collapsed, or a failed optimisation.
    """
    if estimator not in ("DWLS", "ULS"):
        raise ValueError(f"ordinal CFA: unknown estimator {estimator!r} (DWLS or ULS)")
    for c, its in constructs.items():
        if len(its) < 2:
            raise ValueError(f"ordinal CFA: construct {c} needs at least 2 items, has {len(its)}")
    items = [i for its in constructs.values() for i in its]
    own = poly is None
    if own:
        poly = polychoric(data, items, acov=estimator == "DWLS", categories=categories,
                          collapse_empty=collapse_empty)
    R = poly.R.loc[items, items].to_numpy()
    p, names = len(items), list(constructs)
    k = len(names)
    fac = np.array([names.index(c) for c, its in constructs.items() for _ in its])
    iu = np.triu_indices(p, 1)
    r_obs = R[iu]
    if estimator == "DWLS":
        v = poly.avar.loc[items, items].to_numpy()[iu]
        if not np.all(np.isfinite(v) & (v > 0)):
            raise ValueError("ordinal CFA: the polychoric correlations' sampling variances are not all positive")
        w = 1.0 / v
    else:
        w = np.ones_like(r_obs)
    sw = np.sqrt(w)
    ku = np.triu_indices(k, 1)

    def implied(theta):
        lam = theta[:p]
        phi = np.eye(k)
        phi[ku] = theta[p:]
        phi[(ku[1], ku[0])] = theta[p:]
        return np.outer(lam, lam) * phi[np.ix_(fac, fac)], phi

    def resid(theta):
        return sw * (r_obs - implied(theta)[0][iu])

    start = np.concatenate([np.full(p, 0.7), np.full(len(ku[0]), 0.3)])
    res = optimize.least_squares(resid, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    warn: list[str] = list(poly.warnings) if own else []
    grad = res.jac.T @ res.fun
    converged = bool(res.status > 0 and np.all(np.isfinite(res.x)) and np.max(np.abs(grad)) < 1e-6)
    if not converged:
        warn.append(f"ordinal CFA ({estimator}): did not converge ({res.message}); estimates are unreliable")
    theta = res.x.copy()
    # a factor's sign is not identified: make each factor's first loading positive
    for j in range(k):
        sel = np.where(fac == j)[0]
        if theta[sel[0]] < 0:
            theta[sel] *= -1
            for m, (a, b) in enumerate(zip(*ku)):
                if a == j or b == j:
                    theta[p + m] *= -1
    sigma, phi = implied(theta)
    lam = theta[:p]
    rows = [{"construct": names[fac[i]], "item": it, "loading": float(lam[i]), "error_var": float(1 - lam[i] ** 2)}
            for i, it in enumerate(items)]
    loadings = pd.DataFrame(rows)
    latent_corr = pd.DataFrame(phi, index=names, columns=names)
    bad = singular_sample(f"ordinal CFA ({estimator}): ", poly.R.loc[items, items], "polychoric correlation")
    bad += improper(f"ordinal CFA ({estimator}): ", std_loadings=loadings[["item", "loading"]],
                   error_var=loadings.set_index("item")["error_var"], item_var=pd.Series(1.0, index=items),
                   latent_cov=latent_corr)
    resid_corr = r_obs - sigma[iu]
    n_params = p + len(ku[0])
    # lavaan's categorical srmr: the p unit-diagonal residuals (all 0) count among the p(p+1)/2 elements
    fit = {"estimator": estimator, "n": poly.n, "f_min": float(np.sum(w * resid_corr ** 2)),
           "srmr": float(np.sqrt(np.sum(resid_corr ** 2) / (p * (p + 1) / 2))), "n_params": n_params,
           "df": int(len(r_obs) - n_params)}
    return OrdinalCFA(constructs=dict(constructs), estimator=estimator, loadings=loadings, latent_corr=latent_corr,
                      fit=fit, poly=poly, converged=converged, warnings=warn + bad, admissible=not bad)


def ordinal_omega(cfa: OrdinalCFA) -> pd.DataFrame:
    """Ordinal omega per construct of a fitted :class:`OrdinalCFA` (module docstring; Green & Yang 2009).

    Returns construct, omega_ordinal, n_items.
    """
    rows = []
    for c, its in cfa.constructs.items():
        lam = cfa.loadings.set_index("item").loc[its, "loading"].to_numpy()
        common = np.outer(lam, lam)               # phi_cc = 1
        total = cfa.poly.R.loc[its, its].to_numpy()
        num = den = 0.0
        for a in range(len(its)):
            for b in range(len(its)):
                t1, t2 = cfa.poly.thresholds[its[a]], cfa.poly.thresholds[its[b]]
                marg = ndtr(t1).sum() * ndtr(t2).sum()
                num += bvn_cdf(t1[:, None], t2[None, :], common[a, b]).sum() - marg
                den += bvn_cdf(t1[:, None], t2[None, :], total[a, b]).sum() - marg
        rows.append({"construct": c, "omega_ordinal": float(num / den), "n_items": len(its)})
    return pd.DataFrame(rows, columns=["construct", "omega_ordinal", "n_items"])

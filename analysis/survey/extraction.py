"""Exploratory one-factor extractions of one construct, as SPSS's FACTOR procedure reports them.

Many papers report the loadings of SPSS "Analyze > Dimension Reduction > Factor" run per construct instead of a
CFA. The procedure's default extraction is principal components; principal axis factoring and ML are options.
All three work on the item *correlation* matrix R (k x k) and return one loading per item:

* ``pca``: first principal component, λ = √μ₁ · v₁ (μ₁, v₁ the largest eigenvalue of R and its unit
  eigenvector).
  Σλ² = μ₁, so AVE = mean λ² = μ₁/k. Two items correlating r: μ₁ = 1 + r, λ = √((1 + r)/2) for both.
* ``paf``: principal axis factoring (SPSS PAF): initial communalities h² = SMC = 1 - 1/diag(R⁻¹); repeat
  "put h² on the diagonal of R, λ = √μ₁ v₁ of that reduced matrix, h² = λ²" until the largest change of a
  communality is below ``tol`` (SPSS ECONVERGE .001) or ``max_iter`` iterations (SPSS ITERATE 25) are done.
  With three items and a proper solution this converges to the exact one-factor fit r_ij = λ_iλ_j.
* ``ml``: one-factor maximum-likelihood factor analysis: minimise F = log|Σ| + tr(R Σ⁻¹) - log|R| - k over
  Σ = λλᵀ + Ψ (Ψ diagonal, ψ_i >= 0.005), the standardized solution of a one-construct CFA.

The sign is fixed so that Σλ >= 0 (most items load positively; a reversed item that was not recoded loads
negatively), as SPSS prints the component matrix of a construct whose items mostly agree.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize

METHODS = ("pca", "paf", "ml")
PAF_MAX_ITER, PAF_TOL = 25, 1e-3       # SPSS FACTOR defaults: ITERATE(25), ECONVERGE(.001)


@dataclass(frozen=True)
class Extraction:
    """One extraction: loadings (item order of R), eigenvalue μ₁ of the (reduced) matrix, iterations, converged."""

    method: str
    loadings: np.ndarray
    eigenvalue: float
    iterations: int
    converged: bool


def _first_pair(m: np.ndarray) -> tuple[float, np.ndarray]:
    ev, vec = np.linalg.eigh(m)
    v = vec[:, -1]
    return float(ev[-1]), v if v.sum() >= 0 else -v


def pca_loadings(R: np.ndarray) -> Extraction:
    """First principal component loadings λ = √μ₁ v₁ of the correlation matrix R.

    Examples
    --------
    Two items correlating .656 (the BI case, docs/paper_reproduction.md): λ = √((1 + .656)/2) = .910 each:

    >>> import numpy as np
    >>> from analysis.survey.extraction import pca_loadings
    >>> np.round(pca_loadings(np.array([[1, .656], [.656, 1]])).loadings, 3).tolist()
    [0.91, 0.91]
    """
    R = _check(R)
    mu, v = _first_pair(R)
    return Extraction("pca", np.sqrt(max(mu, 0.0)) * v, mu, 0, True)


def paf_loadings(R: np.ndarray, max_iter: int = PAF_MAX_ITER, tol: float = PAF_TOL) -> Extraction:
    """Principal axis factoring, one factor, SPSS's iteration (module docstring). ``converged`` is False when
    ``max_iter`` iterations did not bring the communalities' change below ``tol`` or a communality exceeded 1
    (a Heywood case, which SPSS also reports).

    Examples
    --------
    Three items with r_ij = λ_iλ_j for λ = (.9, .8, .7) converge to those loadings:

    >>> import numpy as np
    >>> from analysis.survey.extraction import paf_loadings
    >>> lam = np.array([.9, .8, .7]); R = np.outer(lam, lam); np.fill_diagonal(R, 1)
    >>> np.round(paf_loadings(R, max_iter=500, tol=1e-9).loadings, 3).tolist()
    [0.9, 0.8, 0.7]
    """
    R = _check(R)
    h2 = 1.0 - 1.0 / np.diag(np.linalg.inv(R))
    lam, mu = np.zeros(len(R)), 0.0
    for it in range(1, max_iter + 1):
        reduced = R.copy()
        np.fill_diagonal(reduced, h2)
        mu, v = _first_pair(reduced)
        lam = np.sqrt(max(mu, 0.0)) * v
        new = lam ** 2
        done = float(np.max(np.abs(new - h2))) < tol
        h2 = new
        if done:
            return Extraction("paf", lam, mu, it, bool(np.all(h2 <= 1.0)))
    return Extraction("paf", lam, mu, max_iter, False)


def ml_loadings(R: np.ndarray) -> Extraction:
    """One-factor ML factor analysis of R (module docstring); standardized loadings, Σλ >= 0.

    The optimiser's status and the stationarity of the result (gradient norm) are checked; ``converged`` says
    whether both hold."""
    R = _check(R)
    k = len(R)
    _, logdet_r = np.linalg.slogdet(R)
    start = np.sqrt(np.clip(1.0 - 1.0 / np.diag(np.linalg.inv(R)), 0.05, 0.95))

    def f(x):
        lam, psi = x[:k], x[k:]
        sig = np.outer(lam, lam) + np.diag(psi)
        sign, logdet = np.linalg.slogdet(sig)
        if sign <= 0:
            return 1e10
        return logdet + np.trace(R @ np.linalg.inv(sig)) - logdet_r - k

    x0 = np.concatenate([start, 1.0 - start ** 2])
    bounds = [(-1.5, 1.5)] * k + [(0.005, 1.5)] * k
    res = optimize.minimize(f, x0, method="L-BFGS-B", bounds=bounds, options={"ftol": 1e-14, "gtol": 1e-10,
                                                                                 "maxiter": 5000})
    lam, psi = res.x[:k], res.x[k:]
    scale = np.sqrt(lam ** 2 + psi)          # standardize by the implied SD (the implied diagonal ~ 1 at the optimum)
    std = lam / scale
    if std.sum() < 0:
        std = -std
    grad = optimize.approx_fprime(res.x, f, 1e-7)
    free = (res.x[k:] > 0.0051)              # components at their bound need no zero gradient
    stationary = float(np.max(np.abs(np.concatenate([grad[:k], grad[k:][free]])))) < 1e-4 if k else True
    return Extraction("ml", std, float((std ** 2).sum()), int(res.nit), bool(res.success) and stationary)


def extract(R: np.ndarray, method: str) -> Extraction:
    """Dispatch on ``method`` (pca | paf | ml)."""
    if method == "pca":
        return pca_loadings(R)
    if method == "paf":
        return paf_loadings(R)
    if method == "ml":
        return ml_loadings(R)
    raise ValueError(f"unknown extraction {method!r} (one of {', '.join(METHODS)})")


def _check(R) -> np.ndarray:
    R = np.asarray(R, float)
    if R.ndim != 2 or R.shape[0] != R.shape[1] or R.shape[0] < 2:
        raise ValueError("an extraction needs a square correlation matrix of at least 2 items")
    if not np.allclose(np.diag(R), 1.0):
        raise ValueError("an extraction needs a correlation matrix (unit diagonal)")
    return R


def construct_loadings(scored, constructs: dict[str, list[str]], method: str, label: str = ""
                       ) -> tuple["pd.DataFrame", list[str]]:
    """Per construct, the extraction ``method`` of its items' Pearson correlation matrix (complete rows), as SPSS
    FACTOR run once per construct reports it. Returns (frame construct, item, loading; warnings, tagged ``label``)."""
    import pandas as pd

    rows, warn = [], []
    for c, items in constructs.items():
        R = scored[items].dropna().corr().to_numpy()
        ex = extract(R, method)
        if not ex.converged:
            tag = f"{method.upper()} loadings{' ' + label if label else ''} of {c}"
            warn.append(f"{tag}: extraction did not converge (or a communality exceeded 1); the loadings are "
                        "unreliable")
        rows += [{"construct": c, "item": it, "loading": float(v)} for it, v in zip(items, ex.loadings)]
    return pd.DataFrame(rows, columns=["construct", "item", "loading"]), warn

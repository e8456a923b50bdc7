"""Is a fitted factor model's solution admissible? One check for every fit (ML CFA, one SEM, ordinal CFA,
multi-group CFA), each problem one warning line.

A solution is improper (a "Heywood case", Dillon, Kumar & Mulani 1987; Kolenikov & Bollen 2012) when

* an item's residual (error) variance theta_ii <= 0. The ML fits bound variances below at 0 (semopy) or at a tiny
  positive number (the invariance fit), where lavaan lets them go negative; a variance within
  ``BOUND = 1e-6 * s_ii`` of zero (s_ii the item's observed variance) is therefore a variance at its bound: the
  unbounded optimum is negative (lavaan: "some estimated ov variances are negative");
* a standardized loading |lambda_std| >= 1 (the item's common part exceeds its variance; reported for an item
  whose residual variance is not already reported);
* a latent variance psi_ff <= 0 (at its bound, as above, relative to the variance it could have: 1e-6 times the
  largest item variance of the model);
* the latent covariance (or correlation) matrix Psi is not positive definite: its smallest eigenvalue <= 0 (at or
  below BOUND x its largest variance: singular up to rounding, as when a disturbance sits at its bound), which
  includes any latent |correlation| > 1 (lavaan: "covariance matrix of latent variables is not positive
  definite"); the largest latent correlation is named;
* the residual covariance matrix Theta, when it has covariances, is not positive definite (lavaan: "the covariance
  matrix of the residuals of the observed variables (theta) is not positive definite").

Estimates are reported, not repaired: the warnings say which parameter is improper and the numbers stay as fitted.

Before any of that, the data: a (nearly) singular sample matrix — two items correlating |r| >= .999, as an item
entered twice, or an item a linear combination of others — is named in every fit (:func:`singular_sample`; lavaan
warns "correlation between variables PU2 and PU1 is (nearly) 1.0" or finds no solution). semopy would replace such a
covariance matrix by a nearest positive-definite one and say so only in a log line; that line becomes a warning too
(:func:`analysis.survey.cfa.semopy_said`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

BOUND = 1e-6   # a variance within BOUND x (its scale) of zero is at its bound 0


def improper(tag: str, *, std_loadings: pd.DataFrame, error_var: pd.Series, item_var: pd.Series,
             latent_cov: pd.DataFrame | None = None, residual_cov: pd.DataFrame | None = None) -> list[str]:
    """The warnings of the module docstring for one fitted model, each prefixed by `tag` ("CFA final: ").

    Parameters
    ----------
    tag : str
        Prefix of every warning (what was fitted).
    std_loadings : DataFrame
        item, loading (standardized, std.all); one row per loading.
    error_var : Series
        item -> residual variance theta_ii (in the item's units); every item of `std_loadings`.
    item_var : Series
        item -> observed variance s_ii (the scale of the bound test; 1 for correlations).
    latent_cov : DataFrame, optional
        Latent covariance (or correlation) matrix Psi, factors x factors.
    residual_cov : DataFrame, optional
        Residual covariance matrix Theta, items x items; checked for positive definiteness when it has covariances.

    Returns
    -------
    list of str

    Examples
    --------
    An error variance below zero, a loading above one and two factors correlating 1.2:

    >>> import pandas as pd
    >>> from analysis.survey.admissibility import improper
    >>> lo = pd.DataFrame({"item": ["x1", "x2", "y1"], "loading": [0.9, 1.02, 0.8]})
    >>> ev = pd.Series({"x1": -0.01, "x2": 0.05, "y1": 0.3})
    >>> psi = pd.DataFrame([[1.0, 1.2], [1.2, 1.0]], index=["X", "Y"], columns=["X", "Y"])
    >>> for w in improper("CFA: ", std_loadings=lo, error_var=ev, item_var=pd.Series(1.0, index=ev.index),
    ...                   latent_cov=psi):
    ...     print(w)
    CFA: Heywood case: error variance of x1 = -0.01 (<= 0)
    CFA: Heywood case: standardized loading of x2 = 1.020 (|lambda| >= 1)
    CFA: latent covariance matrix is not positive definite (largest latent correlation X-Y = 1.200)
    """
    out = []
    for r in std_loadings.itertuples():   # item by item, in the model's order
        ev = error_var[r.item]
        if ev <= BOUND * item_var[r.item]:
            # a variance at its bound is zero up to optimiser noise (~1e-18); print it as such
            shown = 0.0 if abs(ev) < 1e-10 else ev
            out.append(f"{tag}Heywood case: error variance of {r.item} = {shown:.4g} (<= 0)")
        elif np.isfinite(r.loading) and abs(r.loading) >= 1.0:
            out.append(f"{tag}Heywood case: standardized loading of {r.item} = {r.loading:.3f} (|lambda| >= 1)")
    if latent_cov is not None and len(latent_cov):
        psi = latent_cov.to_numpy(float)
        scale = BOUND * float(np.max(item_var.to_numpy(float))) if len(item_var) else 0.0
        for c in latent_cov.index:
            if latent_cov.loc[c, c] <= scale:
                v = latent_cov.loc[c, c]
                out.append(f"{tag}Heywood case: latent variance of {c} = {0.0 if abs(v) < 1e-10 else v:.4g} (<= 0)")
        if len(psi) > 1 and np.min(np.linalg.eigvalsh(psi)) <= BOUND * np.max(np.abs(np.diag(psi))):
            sd = np.sqrt(np.abs(np.diag(psi)))
            with np.errstate(divide="ignore", invalid="ignore"):
                corr = psi / np.outer(sd, sd)
            corr = np.nan_to_num(corr)
            # the upper triangle only: the fitted psi can be asymmetric in its last bits, which made the pair's
            # order (X-Y or Y-X) vary between reruns of the same fit
            i, j = np.unravel_index(np.argmax(np.triu(np.abs(corr), 1)), corr.shape)
            out.append(f"{tag}latent covariance matrix is not positive definite (largest latent correlation "
                       f"{latent_cov.index[i]}-{latent_cov.index[j]} = {corr[i, j]:.3f})")
    if residual_cov is not None and len(residual_cov) > 1:
        th = residual_cov.to_numpy(float)
        if np.any(th[~np.eye(len(th), dtype=bool)] != 0) and np.min(np.linalg.eigvalsh(th)) <= 0:
            out.append(f"{tag}residual covariance matrix is not positive definite (smallest eigenvalue "
                       f"{np.min(np.linalg.eigvalsh(th)):.4g})")
    return out


NEAR_ONE = 0.999   # |r| of two items at or above which the sample matrix counts as (nearly) singular
SINGULAR = 1e-8    # smallest eigenvalue of the item correlation matrix at or below which it is singular


def singular_sample(tag: str, S: pd.DataFrame, what: str = "sample covariance") -> list[str]:
    """Warnings for a (nearly) singular sample matrix `S` (items x items, a covariance or correlation matrix) before
    any estimate is read from a fit to it: each pair of items correlating |r| >= NEAR_ONE is named (lavaan:
    "correlation between variables PU2 and PU1 is (nearly) 1.0"), else a smallest eigenvalue of the correlation
    matrix <= SINGULAR (an item a linear combination of others) is said. semopy replaces a matrix that is not
    positive definite by a nearest positive-definite one without a word in its result; lavaan refuses to fit it or
    warns. The estimates stay as fitted; the warning says they rest on redundant items.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.admissibility import singular_sample
    >>> S = pd.DataFrame([[1.0, 1.0, 0.3], [1.0, 1.0, 0.3], [0.3, 0.3, 1.0]], index=list("abc"), columns=list("abc"))
    >>> singular_sample("CFA: ", S)
    ['CFA: sample covariance matrix (nearly) singular: items a and b correlate 1.0000 (|r| >= 0.999); the estimates rest on redundant items (drop or merge one of them)']
    """
    m = S.to_numpy(float)
    d = np.sqrt(np.clip(np.diag(m), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.nan_to_num(m / np.outer(d, d))
    items = list(S.index)
    out = []
    for i, j in zip(*np.triu_indices(len(items), 1)):
        if abs(r[i, j]) >= NEAR_ONE:
            out.append(f"{tag}{what} matrix (nearly) singular: items {items[i]} and {items[j]} correlate "
                       f"{r[i, j]:.4f} (|r| >= {NEAR_ONE:g}); the estimates rest on redundant items (drop or merge "
                       f"one of them)")
    if not out and len(items) > 1:
        smallest = float(np.min(np.linalg.eigvalsh(r)))
        if smallest <= SINGULAR:
            out.append(f"{tag}{what} matrix singular (smallest eigenvalue of the item correlations {smallest:.3g}): "
                       f"an item is a linear combination of others; the estimates rest on redundant items")
    return out

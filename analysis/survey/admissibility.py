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

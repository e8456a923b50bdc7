"""omega of one construct from its one-factor (congeneric) ML model, vectorised over stacks of covariance matrices
(the bootstrap of :mod:`analysis.survey.htmt` fits thousands at once).

Model: S ~ lambda lambda' + Theta (factor variance 1). ML estimates by the fixed-point iteration of Joreskog (1967):
given Theta, lambda = Theta^{1/2} v sqrt(max(e - 1, 0)) with (e, v) the largest eigenpair of
Theta^{-1/2} S Theta^{-1/2} (power steps from the previous v); then Theta = diag(S - lambda lambda'), bounded below
by 0.005 diag(S) (as R's ``factanal``); stopped when max |Delta Theta| / diag S < 1e-10 and the eigen-residual
|S* v - e v| < 1e-9 e (at most 2000 iterations; a stack element that does not converge gets NaN -- a counted
bootstrap failure).

omega = (sum lambda)^2 / (1' S 1)  (semTools ``compRelSEM`` with ``obs.var = TRUE`` on a one-factor model).

Three items identify the model exactly: lambda_i^2 = s_ij s_ik / s_jk in closed form (no bound: an improper
solution, lambda_i^2 > s_ii, is used as lavaan would report it).

Two items do not identify a one-factor model; with equal loadings (essential tau-equivalence) lambda^2 = s_12 and
omega = 4 s_12 / 1'S1, which is Cronbach's alpha of the two items.
"""
from __future__ import annotations

import numpy as np

THETA_FLOOR = 0.005
TOL = 1e-10
MAX_ITER = 2000


def one_factor_loadings(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lambda (B, k), converged (B,)) of the one-factor ML model for covariance stacks S (B, k, k), k >= 4
    (the iteration of the module docstring, run only on the stack elements not yet converged)."""
    S = np.asarray(S, float)
    d = np.diagonal(S, axis1=-2, axis2=-1)
    theta = d * 0.5
    lam = np.zeros_like(d)
    done = np.zeros(d.shape[0], bool)
    act = np.arange(d.shape[0])
    v = np.ones_like(d) / np.sqrt(d.shape[1])
    for _ in range(MAX_ITER):
        if len(act) == 0:
            break
        Sa, da, ta, va = S[act], d[act], theta[act], v[act]
        t_is = 1.0 / np.sqrt(ta)
        Sstar = Sa * t_is[:, :, None] * t_is[:, None, :]
        # the largest eigenpair by power steps from the previous eigenvector (it moves little between iterations;
        # a full eigh per iteration cost 20x more); convergence also requires the eigen-residual to vanish
        for _k in range(3):
            w = np.einsum("bij,bj->bi", Sstar, va)
            va = w / np.sqrt(np.einsum("bi,bi->b", w, w))[:, None]
        w = np.einsum("bij,bj->bi", Sstar, va)
        e1 = np.einsum("bi,bi->b", va, w)
        resid = np.max(np.abs(w - e1[:, None] * va), axis=1)
        lam_new = np.sqrt(ta) * va * np.sqrt(np.clip(e1 - 1.0, 0.0, None))[:, None]
        theta_new = np.maximum(da - lam_new ** 2, THETA_FLOOR * da)
        step = np.max(np.abs(theta_new - ta) / da, axis=1)
        theta[act], lam[act], v[act] = theta_new, lam_new, va
        fin = (step < TOL) & (resid < 1e-9 * e1)
        done[act[fin]] = True
        act = act[~fin]
    return lam, done


def _three(S: np.ndarray) -> np.ndarray:
    """(B, 3) loadings of the just-identified three-item model: lambda_i^2 = s_ij s_ik / s_jk (exact fit; NaN
    where a product is not positive -- no one-factor solution with real loadings)."""
    s01, s02, s12 = S[:, 0, 1], S[:, 0, 2], S[:, 1, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        l2 = np.stack([s01 * s02 / s12, s01 * s12 / s02, s02 * s12 / s01], axis=1)
        lam = np.sqrt(np.where(l2 > 0, l2, np.nan))
    # signs: loading 0 positive, the others follow the sign of their covariance with item 0
    return lam * np.stack([np.ones_like(s01), np.sign(s01), np.sign(s02)], axis=1)


def omega_stack(S: np.ndarray) -> np.ndarray:
    """omega of the module docstring for each covariance matrix of the stack S (B, k, k); NaN where the ML iteration
    did not converge.

    Examples
    --------
    A one-factor covariance with loadings .8, .7, .6 and unit item variances is reproduced exactly, so
    omega = (2.1)^2 / (3 + 2 (.56 + .48 + .42)) = 4.41 / 5.92:

    >>> import numpy as np
    >>> from analysis.survey.omega import omega_stack
    >>> lam = np.array([0.8, 0.7, 0.6])
    >>> S = np.outer(lam, lam)
    >>> np.fill_diagonal(S, 1.0)
    >>> round(float(omega_stack(S[None])[0]), 6), round(4.41 / 5.92, 6)
    (0.744932, 0.744932)
    """
    S = np.asarray(S, float)
    tot = S.sum(axis=(-2, -1))
    if S.shape[-1] == 2:
        return 4.0 * S[:, 0, 1] / tot
    if S.shape[-1] == 3:
        return _three(S).sum(axis=1) ** 2 / tot
    lam, ok = one_factor_loadings(S)
    return np.where(ok, lam.sum(axis=1) ** 2 / tot, np.nan)

"""Hierarchical OLS regressions (paper Section 5.2.2, Table 5), shaped like SPSS's "Model Summary" with
"Change Statistics" and the "Coefficients" table.

Per step s (predictor blocks entered cumulatively):
  R^2, adjusted R^2 = 1 - (1 - R^2)(n - 1)/(n - k - 1), Delta R^2 = R^2_s - R^2_{s-1} (R^2_0 = 0),
  F change = (Delta R^2 / df1) / ((1 - R^2_s) / df2), df1 = predictors added, df2 = n - k_s - 1, p from F(df1, df2)
  (the nested pair step s-1 vs step s, as SPSS).
Per predictor: B, SE B, beta = B sd(x)/sd(y), t, p (two-tailed, df2), 95 % t-CI B +- t_{.975,df2} SE, and a
case-resampling bootstrap CI of B (percentile by default, BCa on request), vectorised over resamples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

CONSTANT = "(Constant)"
SINGULAR = 1e-12  # a pivot below this share of the largest one marks a (numerically) singular design


def _cross(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A^T B over the cases axis (-2) of stacked arrays, by elementwise products and a sum in case order.

    Not ``@``/``einsum``/LAPACK: their summation order depends on the BLAS kernel numpy picks at run time, and
    the last bits would differ between machines (the same reason as in :mod:`pedas.exact_lstsq`).
    """
    return (A[..., :, :, None] * B[..., :, None, :]).sum(axis=-3)


def _solve(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solutions X of A X = B for stacked small systems (A: (..., m, m), B: (..., m, r)) by Gauss-Jordan
    elimination with partial pivoting in elementwise numpy operations; (X, singular) where `singular` marks the
    systems whose smallest pivot is below SINGULAR x their largest (their rows of X are NaN)."""
    batch = np.broadcast_shapes(np.shape(A)[:-2], np.shape(B)[:-2])
    m, r = np.shape(A)[-1], np.shape(B)[-1]
    A = np.broadcast_to(np.asarray(A, dtype=float), batch + (m, m)).reshape(-1, m, m).copy()
    X = np.broadcast_to(np.asarray(B, dtype=float), batch + (m, r)).reshape(-1, m, r).copy()
    at = np.arange(A.shape[0])
    piv_abs = np.empty((A.shape[0], m))
    for c in range(m):
        # partial pivoting: swap row c with the row of largest |A[., c]| at or below it
        p = c + np.argmax(np.abs(A[:, c:, c]), axis=1)
        A[at, c], A[at, p] = A[at, p].copy(), A[at, c].copy()
        X[at, c], X[at, p] = X[at, p].copy(), X[at, c].copy()
        piv = A[:, c, c].copy()
        piv_abs[:, c] = np.abs(piv)
        piv[piv == 0.0] = 1.0
        A[:, c, :] /= piv[:, None]
        X[:, c, :] /= piv[:, None]
        for i in range(m):
            if i != c:
                f = A[:, i, c][:, None].copy()  # a copy: the next line zeroes A[:, i, c]
                A[:, i, :] -= f * A[:, c, :]
                X[:, i, :] -= f * X[:, c, :]
    singular = piv_abs.min(axis=1) <= SINGULAR * piv_abs.max(axis=1)
    X[singular] = np.nan
    return X.reshape(batch + (m, r)), singular.reshape(batch)


@dataclass(frozen=True)
class ModelSpec:
    """A hierarchical model: `dv` and the predictor `steps` (blocks added cumulatively).

    Examples
    --------
    >>> from analysis.survey.regression import ModelSpec
    >>> m = ModelSpec.from_dict({"name": "4", "dv": "BI", "steps": ["ATT", "SN", "PBC"]})
    >>> m.steps
    (('ATT',), ('SN',), ('PBC',))
    >>> m.predictors(2)
    ['ATT', 'SN']
    """

    name: str
    dv: str
    steps: tuple[tuple[str, ...], ...]
    label: str = ""

    @classmethod
    def from_dict(cls, d: dict) -> "ModelSpec":
        try:
            steps = tuple(tuple([s] if isinstance(s, str) else s) for s in d["steps"])
            return cls(name=str(d["name"]), dv=str(d["dv"]), steps=steps, label=str(d.get("label", "")))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"bad regression model spec {d!r}: needs name, dv and steps ({exc})") from None

    def predictors(self, step: int) -> list[str]:
        """All predictors in the model at 1-based `step`."""
        return [p for block in self.steps[:step] for p in block]


def validate_models(models: list[ModelSpec], available) -> None:
    """ValueError (one line) for an unknown construct, a repeated predictor, the DV as predictor or no steps."""
    avail = list(available)
    for m in models:
        if not m.steps or any(not block for block in m.steps):
            raise ValueError(f"model {m.name}: every step needs at least one predictor")
        allp = m.predictors(len(m.steps))
        for v in [m.dv] + allp:
            if v not in avail:
                raise ValueError(f"model {m.name}: unknown construct {v!r} (known: {', '.join(avail)})")
        if m.dv in allp:
            raise ValueError(f"model {m.name}: the dependent variable {m.dv} is also a predictor")
        if len(set(allp)) != len(allp):
            raise ValueError(f"model {m.name}: a predictor is entered twice")


def ols(y: np.ndarray, X: np.ndarray) -> dict:
    """Ordinary least squares with an intercept.

    Parameters
    ----------
    y : ndarray, shape (n,)
        Dependent variable.
    X : ndarray, shape (n, k)
        Predictors, without the constant column.

    Returns
    -------
    dict
        b, se, t, p (arrays of k + 1, the constant first; p two-tailed on df_resid), r2, adj_r2 =
        1 - (1 - r2)(n - 1)/df_resid, df_resid = n - k - 1; resid (y - X b) and inv ((X'X)^-1 of the design with
        the constant, for leverages). Equal to statsmodels' OLS.

    Examples
    --------
    x = 1..4, y = 1, 3, 2, 4: Sxy = 4, Sxx = Syy = 5, so b = 4/5 = .8, intercept 2.5 - .8 x 2.5 = .5,
    R^2 = 4^2/(5 x 5) = .64, adjusted 1 - .36 x 3/2 = .46; SSE = 5 x .36 = 1.8, SE(b) = sqrt(1.8/2/5) = .424,
    t = .8/.424 = 1.886 on 2 df, whose two-tailed p is 1 - t/sqrt(2 + t^2) = .2:

    >>> import numpy as np
    >>> from analysis.survey.regression import ols
    >>> fit = ols(np.array([1.0, 3.0, 2.0, 4.0]), np.array([[1.0], [2.0], [3.0], [4.0]]))
    >>> np.round(fit["b"], 3).tolist(), round(fit["r2"], 3), round(fit["adj_r2"], 3), fit["df_resid"]
    ([0.5, 0.8], 0.64, 0.46, 2)
    >>> round(float(fit["se"][1]), 3), round(float(fit["t"][1]), 3), round(float(fit["p"][1]), 3)
    (0.424, 1.886, 0.2)
    """
    n, k = X.shape
    Xc = np.column_stack([np.ones(n), X])
    XtX = _cross(Xc, Xc)
    # normal equations with the inverse beside them (the covariance needs it): [b | inv] = XtX^-1 [Xty | I]
    sol, singular = _solve(XtX, np.column_stack([_cross(Xc, y[:, None]), np.eye(k + 1)]))
    if singular:
        raise ValueError("the regression design is singular (a predictor is constant or collinear)")
    b, inv = sol[:, 0], sol[:, 1:]
    resid = y - (Xc * b).sum(axis=1)
    df2 = n - k - 1
    sse = float((resid * resid).sum())
    sst = float(((y - y.mean()) ** 2).sum())
    r2 = 1.0 - sse / sst
    sigma2 = sse / df2
    se = np.sqrt(sigma2 * np.diag(inv))
    t = b / se
    p = 2.0 * stats.t.sf(np.abs(t), df2)
    return {"b": b, "se": se, "t": t, "p": p, "r2": r2, "adj_r2": 1.0 - (1.0 - r2) * (n - 1) / df2, "df_resid": df2,
            "resid": resid, "inv": inv}


def f_change(r2_new: float, r2_old: float, df1: int, df2: int) -> tuple[float, float]:
    """SPSS's F change of a nested pair of models and its p.

    F = (Delta R^2 / df1) / ((1 - R^2_new) / df2), p from F(df1, df2).

    Parameters
    ----------
    r2_new, r2_old : float
        R^2 of the larger model and of the nested one (0 for the first step).
    df1 : int
        Number of predictors added.
    df2 : int
        Residual degrees of freedom of the larger model, n - k - 1.

    Returns
    -------
    f, p : float

    Examples
    --------
    R^2 from .2 to .5 by one predictor with 20 residual df: F = (.3/1)/(.5/20) = 12 (= t^2, t = 3.46 on 20 df):

    >>> from analysis.survey.regression import f_change
    >>> f, p = f_change(0.5, 0.2, 1, 20)
    >>> round(f, 3), round(p, 4)
    (12.0, 0.0025)
    """
    f = ((r2_new - r2_old) / df1) / ((1.0 - r2_new) / df2)
    return float(f), float(stats.f.sf(f, df1, df2))


def bootstrap_coefs(y: np.ndarray, X: np.ndarray, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, k+1) OLS coefficients on case resamples, solved as one stacked batch.

    Resamples whose design is singular (e.g. a predictor constant in the resample) give NaN rows.

    Parameters
    ----------
    y : ndarray, shape (n,)
    X : ndarray, shape (n, k)
        Predictors without the constant.
    n_boot : int
        Number of resamples.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n_boot, k + 1)
        The constant first, NaN rows for singular resamples.

    Examples
    --------
    y = 1 + 2x exactly: every resample with two distinct x values finds (1, 2); a resample that draws one x
    value four times cannot and is NaN:

    >>> import numpy as np
    >>> from analysis.survey.regression import bootstrap_coefs
    >>> x = np.array([[0.0], [1.0], [2.0], [3.0]])
    >>> coefs = bootstrap_coefs(1 + 2 * x[:, 0], x, 200, np.random.default_rng(1))
    >>> coefs.shape
    (200, 2)
    >>> ok = np.isfinite(coefs).all(axis=1)
    >>> bool(np.allclose(coefs[ok], [1.0, 2.0])), bool(np.isnan(coefs[~ok]).all())
    (True, True)
    """
    n, k = X.shape
    Xc = np.column_stack([np.ones(n), X])
    idx = rng.integers(0, n, size=(n_boot, n))
    Xb = Xc[idx]                      # (B, n, k+1)
    yb = y[idx]                       # (B, n)
    coefs, _ = _solve(_cross(Xb, Xb), _cross(Xb, yb[..., None]))
    return coefs[..., 0]


def _jackknife(y: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(n, k+1) leave-one-out OLS coefficients (for the BCa acceleration)."""
    n = len(y)
    keep = ~np.eye(n, dtype=bool)
    Xc = np.column_stack([np.ones(n), X])
    Xj = np.stack([Xc[m] for m in keep])
    yj = np.stack([y[m] for m in keep])
    coefs, _ = _solve(_cross(Xj, Xj), _cross(Xj, yj[..., None]))
    return coefs[..., 0]


def bootstrap_ci(boot: np.ndarray, est: np.ndarray, level: float = 0.95, method: str = "percentile",
                 jack: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-coefficient confidence interval from bootstrap draws.

    Parameters
    ----------
    boot : ndarray, shape (B, k)
        Bootstrap estimates, one row per resample; rows with a NaN (singular resamples) are left out.
    est : ndarray, shape (k,)
        The estimates on the full sample (BCa's bias correction).
    level : float
        Confidence level, default 0.95.
    method : {"percentile", "bca"}
        Percentile interval, or BCa (Efron 1987), which needs `jack`.
    jack : ndarray, shape (n, k), optional
        Leave-one-out estimates (BCa's acceleration).

    Returns
    -------
    low, high : ndarray, shape (k,)

    Examples
    --------
    Draws 0, 1, ..., 100: the 2.5th and 97.5th percentiles are 2.5 and 97.5 (linear interpolation), and a NaN
    draw changes nothing:

    >>> import numpy as np
    >>> from analysis.survey.regression import bootstrap_ci
    >>> boot = np.vstack([np.arange(101.0).reshape(-1, 1), [[np.nan]]])
    >>> low, high = bootstrap_ci(boot, np.array([50.0]))
    >>> np.round(low, 3).tolist(), np.round(high, 3).tolist()
    ([2.5], [97.5])
    """
    a = (1.0 - level) / 2.0
    ok = boot[np.all(np.isfinite(boot), axis=1)]
    if method == "percentile":
        lo, hi = np.percentile(ok, [100 * a, 100 * (1 - a)], axis=0)
        return lo, hi
    if method != "bca":
        raise ValueError(f"unknown bootstrap CI method {method!r} (percentile or bca)")
    z0 = stats.norm.ppf(np.clip((ok < est).mean(axis=0), 1e-10, 1 - 1e-10))
    d = jack.mean(axis=0) - jack
    num, den = (d ** 3).sum(axis=0), 6.0 * ((d ** 2).sum(axis=0)) ** 1.5
    acc = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    lo, hi = np.empty(len(est)), np.empty(len(est))
    for j in range(len(est)):
        qs = []
        for z in (stats.norm.ppf(a), stats.norm.ppf(1 - a)):
            adj = stats.norm.cdf(z0[j] + (z0[j] + z) / (1 - acc[j] * (z0[j] + z)))
            qs.append(np.percentile(ok[:, j], 100 * adj))
        lo[j], hi[j] = qs
    return lo, hi


def hierarchical_regression(data: pd.DataFrame, model: ModelSpec, *, n_boot: int = 2000, seed: int = 20240101,
                            model_index: int = 0, level: float = 0.95, boot_method: str = "percentile"
                            ) -> pd.DataFrame:
    """All steps of one model on the composites in `data` (complete rows of the model's variables).

    Returns one row per step and term (the constant included): model, step, dv, predictor, r2, adj_r2, delta_r2,
    f_change, df1, df2, p_change, b, se_b, beta, t, p, ci_low, ci_high, boot_ci_low, boot_ci_high, n, label.
    Bootstrap draws are seeded per (seed, model_index, step), so a model's CIs do not depend on the others.

    Examples
    --------
    One step, one predictor (the data of :func:`ols`): Delta R^2 = R^2 = .64, F change = (.64/1)/(.36/2) = 3.556
    = t^2 with the t-test's p = .2, and beta = B sd(x)/sd(y) = .8 (equal SDs):

    >>> import pandas as pd
    >>> from analysis.survey.regression import ModelSpec, hierarchical_regression
    >>> data = pd.DataFrame({"x": [1, 2, 3, 4], "y": [1, 3, 2, 4]})
    >>> out = hierarchical_regression(data, ModelSpec("1", "y", (("x",),)), n_boot=0)
    >>> out["predictor"].tolist()
    ['(Constant)', 'x']
    >>> out.loc[1, ["delta_r2", "f_change", "p_change", "b", "beta", "p"]].astype(float).round(3).tolist()
    [0.64, 3.556, 0.2, 0.8, 0.8, 0.2]
    """
    allp = model.predictors(len(model.steps))
    d = data[[model.dv] + allp].dropna()
    n = len(d)
    if n < len(allp) + 2:
        raise ValueError(f"model {model.name}: n = {n} is smaller than predictors + 2 = {len(allp) + 2}")
    for v in [model.dv] + allp:
        if d[v].std(ddof=1) == 0 or d[v].nunique() < 2:
            raise ValueError(f"model {model.name}: {v} is constant in the sample; regression is undefined")
    y = d[model.dv].to_numpy(float)
    sd_y = y.std(ddof=1)
    rows, r2_old = [], 0.0
    for s in range(1, len(model.steps) + 1):
        preds = model.predictors(s)
        X = d[preds].to_numpy(float)
        if np.linalg.matrix_rank(np.column_stack([np.ones(n), X])) < len(preds) + 1:
            raise ValueError(f"model {model.name} step {s}: predictors are perfectly collinear")
        fit = ols(y, X)
        df1, df2 = len(model.steps[s - 1]), fit["df_resid"]
        fc, pc = f_change(fit["r2"], r2_old, df1, df2)
        tcrit = stats.t.ppf(0.5 + level / 2, df2)
        if n_boot and n_boot > 0:
            rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(model_index), s]))
            boot = bootstrap_coefs(y, X, int(n_boot), rng)
            jack = _jackknife(y, X) if boot_method == "bca" else None
            blo, bhi = bootstrap_ci(boot, fit["b"], level, boot_method, jack)
        else:
            blo = bhi = np.full(len(preds) + 1, np.nan)
        sds = np.concatenate([[np.nan], X.std(axis=0, ddof=1)])
        for j, term in enumerate([CONSTANT] + preds):
            b, se = fit["b"][j], fit["se"][j]
            rows.append({"model": model.name, "step": s, "dv": model.dv, "predictor": term,
                         "r2": fit["r2"], "adj_r2": fit["adj_r2"], "delta_r2": fit["r2"] - r2_old,
                         "f_change": fc, "df1": df1, "df2": df2, "p_change": pc,
                         "b": b, "se_b": se, "beta": b * sds[j] / sd_y if j else float("nan"),
                         "t": fit["t"][j], "p": fit["p"][j], "ci_low": b - tcrit * se, "ci_high": b + tcrit * se,
                         "boot_ci_low": blo[j], "boot_ci_high": bhi[j], "n": n, "label": model.label})
        r2_old = fit["r2"]
    return pd.DataFrame(rows)


#: the columns of :func:`hierarchical_regression`'s rows
REGRESSION_COLUMNS = ["model", "step", "dv", "predictor", "r2", "adj_r2", "delta_r2", "f_change", "df1", "df2",
                      "p_change", "b", "se_b", "beta", "t", "p", "ci_low", "ci_high", "boot_ci_low", "boot_ci_high",
                      "n", "label"]


def run_models(data: pd.DataFrame, models: list[ModelSpec], **kw) -> pd.DataFrame:
    """`hierarchical_regression` for every model, concatenated (validates the specs first)."""
    validate_models(models, data.columns)
    frames = [hierarchical_regression(data, m, model_index=i, **kw) for i, m in enumerate(models)]
    # a model file without regressions (a measurement model only) has an empty table, not an error
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=REGRESSION_COLUMNS)

"""Diagnostics of the hierarchical OLS regressions (analysis.survey.regression) a reviewer asks for, per model and step:

* residual normality: Shapiro-Wilk W of the residuals (scipy's ``shapiro``, Royston's algorithm as R's
  ``shapiro.test``);
* heteroscedasticity: the studentized Breusch-Pagan test (Koenker 1981; R ``lmtest::bptest`` default):
  BP = n R^2 of the regression of the squared residuals on the step's predictors, chi^2 on k df;
* influence: Cook's distance D_i = e_i^2 h_i / (p s^2 (1 - h_i)^2) (p = k + 1 coefficients, s^2 = SSE / (n - p),
  h_i the leverage; R ``cooks.distance``); a case is influential when D_i > 4/n (the common rule of thumb,
  Bollen & Jackman 1990);
* collinearity: VIF_j = 1 / (1 - R_j^2), R_j^2 of predictor j on the step's other predictors (R ``car::vif``;
  1 for a step with one predictor);
* the standardized coefficient's confidence interval: the t-interval of B scaled by sd(x)/sd(y) (= the t-interval
  of the coefficient of lm() on z-scores);
* Cohen's f^2 of the step, ΔR^2 / (1 - R^2_step) (Selya et al. 2012), with its confidence interval from the
  noncentral F distribution of the step's F change (Steiger & Fouladi 1997; Smithson 2003): the noncentrality
  lambda whose F(df1, df2, lambda) has the observed F change as its (1 + level)/2 and (1 - level)/2 quantile, and
  f^2 = lambda / (df1 + df2 + 1) (Cohen 1988's lambda = f^2 (u + v + 1)); deterministic, no resamples.

Every number comes from :func:`analysis.survey.regression.ols`, the regression the tables report.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from analysis.survey.regression import ModelSpec, ols

#: the rule of thumb for an influential case: Cook's D above INFLUENCE / n
INFLUENCE = 4.0

STEP_COLUMNS = ["model", "step", "dv", "added", "n", "k", "r2", "delta_r2", "f_change", "df1", "df2", "f2",
                "f2_ci_low", "f2_ci_high", "shapiro_w", "shapiro_p", "bp", "bp_df", "bp_p", "cooks_max",
                "cooks_cut", "n_influential", "influential", "vif_max"]
COEF_COLUMNS = ["model", "step", "dv", "predictor", "b", "se_b", "beta", "beta_ci_low", "beta_ci_high", "t", "p",
                "vif"]


def breusch_pagan(resid: np.ndarray, X: np.ndarray) -> tuple[float, int, float]:
    """Koenker's studentized Breusch-Pagan test of the residuals on the predictors `X` (n, k; without the constant).

    Returns (BP = n R^2 of e^2 on X, df = k, p from chi^2(k)), as R's ``lmtest::bptest(model)``.

    Examples
    --------
    A response whose spread grows with x is heteroscedastic (R: ``bptest(lm(y ~ x))`` gives BP = 5.0491, df = 1,
    p = .02464):

    >>> import numpy as np
    >>> from analysis.survey.diagnostics import breusch_pagan
    >>> from analysis.survey.regression import ols
    >>> x = np.arange(1.0, 9.0)[:, None]
    >>> y = np.array([1, -1, 2, -2, 3, -3, 4, -4.0])
    >>> bp, df, p = breusch_pagan(ols(y, x)["resid"], x)
    >>> round(bp, 4), df, round(p, 5)
    (5.0491, 1, 0.02464)
    """
    n = len(resid)
    fit = ols(resid * resid, X)
    bp = n * fit["r2"]
    k = X.shape[1]
    return float(bp), int(k), float(stats.chi2.sf(bp, k))


def cooks_distance(fit: dict, X: np.ndarray) -> np.ndarray:
    """Cook's distance of every case of the OLS `fit` (:func:`ols`) of the predictors `X` (without the constant).

    Examples
    --------
    The point far off the line of the others has by far the largest distance (R's ``cooks.distance`` alike):

    >>> import numpy as np
    >>> from analysis.survey.diagnostics import cooks_distance
    >>> from analysis.survey.regression import ols
    >>> x = np.array([[1.0], [2.0], [3.0], [4.0], [5.0]])
    >>> y = np.array([1.0, 2.1, 2.9, 4.2, 9.0])
    >>> np.round(cooks_distance(ols(y, x), x), 3).tolist()
    [0.573, 0.001, 0.069, 0.323, 2.234]
    """
    n, k = X.shape
    Xc = np.column_stack([np.ones(n), X])
    h = ((Xc @ fit["inv"]) * Xc).sum(axis=1)
    e = fit["resid"]
    p = k + 1
    s2 = float((e * e).sum()) / (n - p)
    return e * e * h / (p * s2 * (1.0 - h) ** 2)


def vif(X: np.ndarray) -> np.ndarray:
    """Variance inflation factor of each column of `X` (n, k): 1 / (1 - R^2) of it on the other columns (with a
    constant); 1 for a single column.

    Examples
    --------
    >>> import numpy as np
    >>> from analysis.survey.diagnostics import vif
    >>> X = np.array([[1, 2], [2, 1], [3, 4], [4, 3], [5, 6.0]])    # as car::vif
    >>> np.round(vif(X), 4).tolist()
    [3.0833, 3.0833]
    """
    k = X.shape[1]
    if k == 1:
        return np.ones(1)
    out = np.empty(k)
    for j in range(k):
        r2 = ols(X[:, j], np.delete(X, j, axis=1))["r2"]
        out[j] = 1.0 / (1.0 - r2) if r2 < 1.0 else np.inf
    return out


def f2_ci(f_obs: float, df1: int, df2: int, level: float = 0.95) -> tuple[float, float]:
    """Confidence interval of Cohen's f^2 from the observed F (on df1, df2) by inverting the noncentral F:
    lambda_L and lambda_U with P(F <= f_obs; df1, df2, lambda) = (1 + level)/2 and (1 - level)/2 (0 where no
    lambda >= 0 solves it), f^2 = lambda / (df1 + df2 + 1).

    Examples
    --------
    F = 12 on (1, 20): f^2 = F df1/df2 = .6, its 95 % interval from the noncentral F (R: ``uniroot`` on
    ``pf(12, 1, 20, ncp)``, divided by 22):

    >>> from analysis.survey.diagnostics import f2_ci
    >>> [round(x, 4) for x in f2_ci(12.0, 1, 20)]
    [0.0653, 1.4572]
    """
    from scipy.optimize import brentq

    if not (np.isfinite(f_obs) and df1 >= 1 and df2 >= 1):
        return float("nan"), float("nan")
    n_eff = df1 + df2 + 1

    def limit(target: float) -> float:
        def g(lam: float) -> float:
            return float(stats.ncf.cdf(f_obs, df1, df2, lam) if lam > 0 else stats.f.cdf(f_obs, df1, df2)) - target
        if g(0.0) < 0.0:
            return 0.0
        hi = max(10.0, 2.0 * f_obs * df1)
        while g(hi) > 0.0:
            hi *= 2.0
        return brentq(g, 0.0, hi, xtol=1e-12, rtol=4 * np.finfo(float).eps, maxiter=500) / n_eff

    a = (1.0 - level) / 2.0
    return float(limit(1.0 - a)), float(limit(a))


def _step_rows(d: pd.DataFrame, model: ModelSpec, level: float) -> tuple[list[dict], list[dict]]:
    y = d[model.dv].to_numpy(float)
    n = len(y)
    sd_y = y.std(ddof=1)
    steps, coefs, r2_old = [], [], 0.0
    for s in range(1, len(model.steps) + 1):
        preds = model.predictors(s)
        X = d[preds].to_numpy(float)
        fit = ols(y, X)
        df1, df2 = len(model.steps[s - 1]), int(fit["df_resid"])
        delta = fit["r2"] - r2_old
        f_change = (delta / df1) / ((1.0 - fit["r2"]) / df2)
        lo, hi = f2_ci(f_change, df1, df2, level)
        w, pw = stats.shapiro(fit["resid"]) if n >= 3 else (np.nan, np.nan)
        bp, bp_df, bp_p = breusch_pagan(fit["resid"], X)
        cd = cooks_distance(fit, X)
        cut = INFLUENCE / n
        infl = [str(i) for i, v in zip(d.index, cd) if v > cut]
        v = vif(X)
        steps.append({"model": model.name, "step": s, "dv": model.dv, "added": ", ".join(model.steps[s - 1]),
                      "n": n, "k": len(preds), "r2": fit["r2"], "delta_r2": delta, "f_change": f_change,
                      "df1": df1, "df2": df2, "f2": delta / (1.0 - fit["r2"]), "f2_ci_low": lo, "f2_ci_high": hi,
                      "shapiro_w": float(w), "shapiro_p": float(pw), "bp": bp, "bp_df": bp_df, "bp_p": bp_p,
                      "cooks_max": float(cd.max()), "cooks_cut": cut, "n_influential": len(infl),
                      "influential": ", ".join(infl), "vif_max": float(v.max())})
        tcrit = stats.t.ppf(0.5 + level / 2.0, df2)
        for j, term in enumerate(preds, start=1):
            scale = X[:, j - 1].std(ddof=1) / sd_y
            b, se = fit["b"][j], fit["se"][j]
            coefs.append({"model": model.name, "step": s, "dv": model.dv, "predictor": term, "b": b, "se_b": se,
                          "beta": b * scale, "beta_ci_low": (b - tcrit * se) * scale,
                          "beta_ci_high": (b + tcrit * se) * scale, "t": fit["t"][j], "p": fit["p"][j],
                          "vif": v[j - 1]})
        r2_old = fit["r2"]
    return steps, coefs


def regression_diagnostics(data: pd.DataFrame, models: list[ModelSpec], level: float = 0.95
                           ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(steps, coefficients) of every model's steps on `data` (composites and covariates, indexed by participant;
    each model on the complete rows of its variables, as :func:`analysis.survey.regression.hierarchical_regression`).

    steps: one row per model and step with :data:`STEP_COLUMNS` (the module docstring's statistics; `influential`
    the ids of the cases with D > 4/n). coefficients: one row per step and predictor with :data:`COEF_COLUMNS`.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.diagnostics import regression_diagnostics
    >>> from analysis.survey.regression import ModelSpec
    >>> data = pd.DataFrame({"x": [1, 2, 3, 4, 5, 6], "z": [2, 1, 4, 3, 6, 5], "y": [1, 3, 2, 5, 4, 7.0]},
    ...                     index=[f"P{i}" for i in range(1, 7)])
    >>> steps, coefs = regression_diagnostics(data, [ModelSpec("1", "y", (("x",), ("z",)))])
    >>> steps[["step", "added", "k", "n_influential"]].values.tolist()
    [[1, 'x', 1, 0], [2, 'z', 2, 1]]
    >>> coefs[["step", "predictor"]].values.tolist()
    [[1, 'x'], [2, 'x'], [2, 'z']]
    """
    steps, coefs = [], []
    for m in models:
        d = data[[m.dv] + m.predictors(len(m.steps))].dropna()
        s, c = _step_rows(d, m, level)
        steps += s
        coefs += c
    return pd.DataFrame(steps, columns=STEP_COLUMNS), pd.DataFrame(coefs, columns=COEF_COLUMNS)

"""Confirmatory factor analysis (measurement model, paper Section 5.2.1) with semopy, maximum likelihood.

Estimation: semopy's ``MLW`` objective (the Wishart ML discrepancy on the biased sample covariance S, which has
the same minimiser as lavaan's ``estimator="ML"``) with a tight tolerance; fit indices are computed here from S
and the implied covariance so that they follow lavaan's definitions (`fit_indices`):

* F_ML = log|Sigma| + tr(S Sigma^-1) - log|S| - p,  chi2 = N * F_ML (lavaan, ``likelihood="normal"``)
* df = p(p+1)/2 - free parameters; baseline = independence model, chi2_b = N (sum log s_ii - log|S|)
* CFI = 1 - max(chi2 - df, 0) / max(chi2 - df, chi2_b - df_b, 0);  TLI = (chi2_b/df_b - chi2/df) / (chi2_b/df_b - 1)
* RMSEA = sqrt(max(chi2 - df, 0) / (df N));  SRMR (lavaan's default "srmr_bentler"): residuals (s_ij - sigma_ij)
  scaled by sqrt(s_ii s_jj), root mean square over the p(p+1)/2 elements i <= j.

Standardized loadings are lavaan's ``std.all``: lambda * sqrt(psi_ff) / sqrt(sigma_ii) (implied variance).
On Holzinger-Swineford this reproduces lavaan's published output (tests/analysis/test_cfa.py).
Non-convergence, Heywood cases (negative or boundary variances, |std loading| >= 1, non-positive-definite
latent covariance), a (nearly) singular sample covariance matrix (two items correlating |r| >= .999, which semopy
would silently replace by a nearest positive-definite matrix) and semopy's own log lines become warnings, never
silence.
"""
from __future__ import annotations

import warnings as _warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np
import pandas as pd
from scipy import stats

from analysis.survey.admissibility import improper, singular_sample

SOLVERS = (("SLSQP", {"ftol": 1e-12, "maxiter": 2000}), ("L-BFGS-B", {"ftol": 1e-14, "gtol": 1e-10, "maxiter": 20000}))


@dataclass
class CFAResult:
    """One fitted measurement model.

    loadings: construct, item, estimate (unstandardized), se, loading (std.all), error_var
    fit: dict chi2, df, p, cfi, tli, rmsea, srmr, n, chi2_baseline, df_baseline, n_params
    latent_corr: construct x construct correlation of the latent factors; psi: their covariance
    S / sigma: observed (biased, divisor N) and implied covariance of the items (DataFrames)
    """

    constructs: dict[str, list[str]]
    loadings: pd.DataFrame
    fit: dict
    latent_corr: pd.DataFrame
    psi: pd.DataFrame
    S: pd.DataFrame
    sigma: pd.DataFrame
    converged: bool
    warnings: list[str] = field(default_factory=list)


def model_description(constructs: dict[str, list[str]]) -> str:
    """semopy/lavaan syntax, one ``F =~ x1 + x2`` line per construct (first loading fixed to 1 by semopy).

    Examples
    --------
    >>> from analysis.survey.cfa import model_description
    >>> print(model_description({"PU": ["PU1", "PU2"], "BI": ["BI1", "BI2"]}))
    PU =~ PU1 + PU2
    BI =~ BI1 + BI2
    """
    return "\n".join(f"{c} =~ {' + '.join(items)}" for c, items in constructs.items())


def fit_indices(S: np.ndarray, sigma: np.ndarray, n: int, n_params: int) -> dict:
    """lavaan-convention ML fit indices (the formulas of the module docstring).

    Parameters
    ----------
    S : ndarray, shape (p, p)
        Sample covariance of the items, biased (divisor N).
    sigma : ndarray, shape (p, p)
        Model-implied covariance.
    n : int
        Sample size N.
    n_params : int
        Number of free parameters; df = p(p + 1)/2 - n_params.

    Returns
    -------
    dict
        chi2, df, p, cfi, tli, rmsea, srmr, n, chi2_baseline, df_baseline, n_params (p, TLI, RMSEA NaN at df 0).

    Examples
    --------
    Two items correlating .5 (|S| = .75), N = 100. A model that reproduces S exactly (2 parameters, df 1) has
    chi2 = 0, CFI = 1, RMSEA = SRMR = 0, and TLI = (chi2_b/1 - 0)/(chi2_b/1 - 1) = 1.036 -- TLI can exceed 1;
    the baseline chi2_b = N (log 1 + log 1 - log .75) = 28.768 on 1 df:

    >>> import numpy as np
    >>> from analysis.survey.cfa import fit_indices
    >>> S = np.array([[1.0, 0.5], [0.5, 1.0]])
    >>> fit = fit_indices(S, S, n=100, n_params=2)
    >>> {k: round(fit[k], 3) for k in ("chi2", "df", "cfi", "tli", "rmsea", "srmr", "chi2_baseline")}
    {'chi2': 0.0, 'df': 1, 'cfi': 1.0, 'tli': 1.036, 'rmsea': 0.0, 'srmr': 0.0, 'chi2_baseline': 28.768}

    The independence model (Sigma = diag S) is the baseline itself: chi2 = chi2_b = 28.768 on 1 df,
    RMSEA = sqrt((28.768 - 1)/(1 x 100)) = .527, SRMR = sqrt(.5^2/3) = .289 (see :func:`srmr`):

    >>> fit = fit_indices(S, np.eye(2), n=100, n_params=2)
    >>> {k: round(fit[k], 3) for k in ("chi2", "chi2_baseline", "rmsea", "srmr")}
    {'chi2': 28.768, 'chi2_baseline': 28.768, 'rmsea': 0.527, 'srmr': 0.289}
    """
    p = S.shape[0]
    _, logdet_sigma = np.linalg.slogdet(sigma)
    _, logdet_s = np.linalg.slogdet(S)
    f_ml = logdet_sigma + np.trace(S @ np.linalg.inv(sigma)) - logdet_s - p
    chi2 = max(n * f_ml, 0.0)
    df = p * (p + 1) // 2 - n_params
    chi2_b = n * (np.sum(np.log(np.diag(S))) - logdet_s)
    df_b = p * (p - 1) // 2
    pval = float(stats.chi2.sf(chi2, df)) if df > 0 else float("nan")
    d_m, d_b = max(chi2 - df, 0.0), max(chi2_b - df_b, 0.0)
    denom = max(d_m, d_b)
    cfi = 1.0 - d_m / denom if denom > 0 else 1.0
    tli = ((chi2_b / df_b - chi2 / df) / (chi2_b / df_b - 1.0)) if df > 0 and df_b > 0 else float("nan")
    rmsea = float(np.sqrt(d_m / (df * n))) if df > 0 else float("nan")
    return {"chi2": float(chi2), "df": int(df), "p": pval, "cfi": float(cfi), "tli": float(tli), "rmsea": rmsea,
            "srmr": srmr(S, sigma), "n": int(n), "chi2_baseline": float(chi2_b), "df_baseline": int(df_b),
            "n_params": int(n_params)}


#: Hu & Bentler (1999) cut-offs of good fit for continuous indicators under ML (their combination rules aside)
HU_BENTLER = {"cfi": (">=", 0.95), "tli": (">=", 0.95), "rmsea": ("<=", 0.06), "srmr": ("<=", 0.08)}


def rmsea_ci(chi2: float, df: int, n: int, level: float = 0.90) -> tuple[float, float]:
    """Confidence interval of the RMSEA by lavaan's method (Browne & Cudeck 1993; lavaan ``lav_fit_rmsea_ci``).

    The noncentrality lambda of a noncentral chi-square on `df` degrees of freedom is found where the observed
    `chi2` is its (1 + level)/2 quantile (lower limit) and its (1 - level)/2 quantile (upper limit):
    P(X <= chi2; df, lambda_L) = (1 + level)/2, P(X <= chi2; df, lambda_U) = (1 - level)/2; a limit whose equation
    has no root at lambda >= 0 is 0. Each becomes an RMSEA as the point estimate does, sqrt(lambda / (df N)) with
    lavaan's N for ``likelihood = "normal"`` ML (chi2 = N F_ML, not (N - 1) F_ML). lavaan searches the upper root
    in [0, max(N, 4 chi2)] with ``uniroot``'s default tolerance (about 1e-4 on lambda); the roots here are found
    to machine precision (Brent's method), so the limits can differ from lavaan's printout in the 5th decimal.

    Parameters
    ----------
    chi2 : float
        The model's chi-square (N F_ML).
    df : int
        Its degrees of freedom.
    n : int
        Sample size N.
    level : float
        Confidence level, default .90 (the RMSEA's customary interval).

    Returns
    -------
    low, high : float
        NaN for df < 1.

    Examples
    --------
    chi2 = df: the point estimate is 0 and so is the lower limit; with chi2 = 2 df both limits are above 0 (lavaan
    prints .000, .061 and .038, .103):

    >>> from analysis.survey.cfa import rmsea_ci
    >>> [round(x, 4) for x in rmsea_ci(20.0, 20, 200)]
    [0.0, 0.0607]
    >>> [round(x, 4) for x in rmsea_ci(40.0, 20, 200)]
    [0.0379, 0.1025]
    """
    from scipy.optimize import brentq

    if not df >= 1 or not np.isfinite(chi2) or n <= 0:
        return float("nan"), float("nan")

    def cdf_minus(target: float):
        return lambda lam: float(stats.ncx2.cdf(chi2, df, lam)) - target

    def limit(target: float, upper: float) -> float:
        f = cdf_minus(target)
        if f(0.0) < 0.0:        # even lambda = 0 puts chi2 above the quantile: the limit is 0
            return 0.0
        # the cdf falls in lambda; widen the bracket until it changes sign (lavaan's first bracket, then doubled)
        hi = max(upper, 1.0)
        while f(hi) > 0.0:
            hi *= 2.0
        lam = brentq(f, 0.0, hi, xtol=1e-14, rtol=4 * np.finfo(float).eps, maxiter=500)
        return float(np.sqrt(lam / (df * n)))

    a = (1.0 - level) / 2.0
    return limit(1.0 - a, chi2), limit(a, max(n, 4.0 * chi2))


def judge_fit(fit: dict, cutoffs: dict = HU_BENTLER) -> dict[str, bool]:
    """Index -> whether `fit` meets its cut-off in `cutoffs` (default :data:`HU_BENTLER`); NaN never meets it.

    Examples
    --------
    >>> from analysis.survey.cfa import judge_fit
    >>> judge_fit({"cfi": 0.907, "tli": 0.883, "rmsea": 0.081, "srmr": 0.110})
    {'cfi': False, 'tli': False, 'rmsea': False, 'srmr': False}
    >>> judge_fit({"cfi": 0.96, "tli": 0.95, "rmsea": 0.05, "srmr": 0.08})
    {'cfi': True, 'tli': True, 'rmsea': True, 'srmr': True}
    """
    out = {}
    for k, (op, bound) in cutoffs.items():
        x = float(fit.get(k, float("nan")))
        out[k] = bool(np.isfinite(x) and (x >= bound if op == ">=" else x <= bound))
    return out


def srmr(S: np.ndarray, sigma: np.ndarray) -> float:
    """Standardized root mean square residual, lavaan's ``srmr_bentler`` (no mean structure).

    Root mean square of (s_ij - sigma_ij)/sqrt(s_ii s_jj) over the p(p + 1)/2 elements i <= j.

    Parameters
    ----------
    S, sigma : ndarray, shape (p, p)
        Sample and model-implied covariance.

    Returns
    -------
    float

    Examples
    --------
    Two items correlating .5 and a model that implies none: residuals 0, .5, 0 over 3 elements,
    SRMR = sqrt(.25/3) = .289:

    >>> import numpy as np
    >>> from analysis.survey.cfa import srmr
    >>> round(srmr(np.array([[1.0, 0.5], [0.5, 1.0]]), np.eye(2)), 3)
    0.289
    """
    d = 1.0 / np.sqrt(np.diag(S))
    r = (S - sigma) * np.outer(d, d)
    iu = np.triu_indices(S.shape[0])
    return float(np.sqrt(np.mean(r[iu] ** 2)))


@contextmanager
def semopy_said(tag: str, out: list[str]) -> Iterator[None]:
    """semopy's own log lines while the block runs (it logs on the root logger, e.g. "Sample covariance matrix is
    not PD ... semopy now will run nearPD subroutines"), appended to `out` once each as ``<tag>semopy: <line>``
    instead of being printed: a repair semopy makes is one of the fit's warnings."""
    import logging

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            line = f"{tag}semopy: {' '.join(record.getMessage().split())}"
            if line not in out:
                out.append(line)

    root = logging.getLogger()
    saved = root.handlers[:]
    root.handlers = [Keep(logging.WARNING)]
    try:
        yield
    finally:
        root.handlers = saved


def _fit_semopy(desc: str, data: pd.DataFrame):
    import semopy  # heavy import kept local

    last = None
    for solver, options in SOLVERS:
        model = semopy.Model(desc)
        try:
            with _warnings.catch_warnings():
                _warnings.simplefilter("ignore")
                res = model.fit(data, obj="MLW", solver=solver, options=dict(options))
        except Exception as exc:  # numerical failure inside the optimiser: try the next solver
            last = (None, None, f"{solver}: {exc}")
            continue
        ok = bool(res.success) and np.all(np.isfinite(res.x))
        last = (model, res, solver)
        if ok:
            return model, res, True, solver
    model, res, solver = last
    return model, res, False, solver


def fit_cfa(data: pd.DataFrame, constructs: dict[str, list[str]], *, label: str = "") -> CFAResult:
    """Fit the correlated-factors CFA of `constructs` (construct -> items) to the item columns of `data`.

    Rows with missing answers are dropped (ML on complete cases). Raises ValueError for an item that is not a
    column, a construct with fewer than two items or fewer rows than items.
    """
    items = [i for its in constructs.values() for i in its]
    tag = f"CFA {label}: " if label else "CFA: "
    miss = [i for i in items if i not in data.columns]
    if miss:
        raise ValueError(f"{tag}item(s) not in the data: {', '.join(miss)}")
    for c, its in constructs.items():
        if len(its) < 2:
            raise ValueError(f"{tag}construct {c} needs at least 2 items, has {len(its)}")
    x = data[items].dropna().astype(float)
    n, p = x.shape
    if n <= p:
        raise ValueError(f"{tag}{n} complete rows for {p} items; the sample covariance matrix is singular")
    said: list[str] = []
    with semopy_said(tag, said):
        model, res, converged, solver = _fit_semopy(model_description(constructs), x)
        se = _standard_errors(model) if model is not None else {}
    if model is None:
        raise ValueError(f"{tag}estimation failed ({solver})")
    warn: list[str] = []
    if not converged:
        warn.append(f"{tag}did not converge ({solver}: {getattr(res, 'message', '')}); estimates are unreliable")
    obs = list(model.names_lambda[0])
    lat = list(model.names_lambda[1])
    lam = np.asarray(model.mx_lambda, float)
    psi = np.asarray(model.mx_psi, float)
    theta = np.asarray(model.mx_theta, float)
    sigma = np.asarray(model.calc_sigma()[0], float)
    S = np.asarray(model.mx_cov, float)

    rows = []
    for c, its in constructs.items():
        j = lat.index(c)
        for it in its:
            i = obs.index(it)
            # std.all; undefined (NaN) when the latent variance is improper (reported as a Heywood case)
            std = lam[i, j] * np.sqrt(psi[j, j]) / np.sqrt(sigma[i, i]) if psi[j, j] > 0 else np.nan
            rows.append({"construct": c, "item": it, "estimate": lam[i, j], "se": se.get((it, c), np.nan),
                         "loading": float(std), "error_var": theta[i, i]})
    loadings = pd.DataFrame(rows)

    sd_lat = np.sqrt(np.clip(np.diag(psi), 1e-300, None))
    corr = psi / np.outer(sd_lat, sd_lat)
    order = list(constructs)
    idx = [lat.index(c) for c in order]
    latent_corr = pd.DataFrame(corr[np.ix_(idx, idx)], index=order, columns=order)
    psi_df = pd.DataFrame(psi[np.ix_(idx, idx)], index=order, columns=order)
    oidx = [obs.index(i) for i in items]
    S_df = pd.DataFrame(S[np.ix_(oidx, oidx)], index=items, columns=items)
    sig_df = pd.DataFrame(sigma[np.ix_(oidx, oidx)], index=items, columns=items)
    fit = fit_indices(S, sigma, n, len(model.param_vals))
    # the data's own covariance: semopy's mx_cov is already its near-PD repair of a singular one
    warn = singular_sample(tag, x.cov(ddof=0)) + said + warn + heywood_cases(loadings, psi_df, S_df, tag)
    if fit["df"] <= 0:
        warn.append(f"{tag}model has {fit['df']} degrees of freedom; fit indices are undefined")
    return CFAResult(constructs=dict(constructs), loadings=loadings, fit=fit, latent_corr=latent_corr, psi=psi_df,
                     S=S_df, sigma=sig_df, converged=converged, warnings=warn)


def _standard_errors(model) -> dict:
    """(item, construct) -> SE of the unstandardized loading, from semopy's inspect (NaN where fixed/unavailable)."""
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            est = model.inspect()
    except Exception:
        return {}
    out = {}
    for _, r in est[est["op"] == "~"].iterrows():
        try:
            out[(r["lval"], r["rval"])] = float(r["Std. Err"])
        except (TypeError, ValueError):
            out[(r["lval"], r["rval"])] = float("nan")
    return out


def heywood_cases(loadings: pd.DataFrame, psi: pd.DataFrame, S: pd.DataFrame, tag: str = "") -> list[str]:
    """Warnings for improper solutions: error variance <= 0 (or at its bound), |std loading| >= 1,
    latent variance <= 0 or a latent covariance matrix that is not positive definite
    (:func:`analysis.survey.admissibility.improper`).

    Examples
    --------
    >>> import numpy as np
    >>> import pandas as pd
    >>> from analysis.survey.cfa import heywood_cases
    >>> lo = pd.DataFrame({"item": ["x1", "x2"], "loading": [0.9, 1.02], "error_var": [-0.01, 0.05]})
    >>> psi = pd.DataFrame([[1.0]], index=["F"], columns=["F"])
    >>> S = pd.DataFrame(np.eye(2), index=["x1", "x2"], columns=["x1", "x2"])
    >>> for w in heywood_cases(lo, psi, S, "CFA final: "):
    ...     print(w)
    CFA final: Heywood case: error variance of x1 = -0.01 (<= 0)
    CFA final: Heywood case: standardized loading of x2 = 1.020 (|lambda| >= 1)
    """
    items = list(loadings["item"])
    return improper(tag, std_loadings=loadings[["item", "loading"]],
                    error_var=pd.Series(loadings["error_var"].to_numpy(float), index=items),
                    item_var=pd.Series(np.diag(S.loc[items, items].to_numpy(float)), index=items), latent_cov=psi)


def flag_items(loadings: pd.DataFrame, scored: pd.DataFrame, constructs: dict[str, list[str]], *,
               min_loading: float = 0.7, cross_margin: float = 0.0) -> pd.DataFrame:
    """The deletion rules per item (paper Section 5.2.1), from the initial-stage loadings.

    flag_low: std loading < `min_loading` (Hair 2014); flag_negative: std loading < 0; flag_cross: the item
    correlates with another construct's composite at least as strongly (+ `cross_margin`) as with the mean of the
    other items of its own construct (corrected item-rest correlation) -- the item-level discriminant problem the
    paper reports for ATT vs PU. Returns loadings plus own_r, cross_construct, cross_r, the flags and `rule`
    (the names of the rules that fire, ';'-joined).
    """
    comp = {c: scored[its].mean(axis=1) for c, its in constructs.items()}
    rows = []
    for _, r in loadings.iterrows():
        item, c = r["item"], r["construct"]
        rest = [i for i in constructs[c] if i != item]
        own = float(scored[item].corr(scored[rest].mean(axis=1))) if rest else float("nan")
        cross = {o: float(scored[item].corr(v)) for o, v in comp.items() if o != c}
        best = max(cross, key=lambda o: abs(cross[o])) if cross else ""
        cross_r = cross.get(best, float("nan"))
        low = bool(r["loading"] < min_loading)
        neg = bool(r["loading"] < 0)
        xflag = bool(cross and abs(cross_r) + cross_margin >= abs(own)) if np.isfinite(own) else False
        rules = [name for name, on in (("lambda<%.2g" % min_loading, low), ("negative_lambda", neg),
                                        ("cross_construct", xflag)) if on]
        rows.append({**r.to_dict(), "own_r": own, "cross_construct": best, "cross_r": cross_r,
                     "flag_low": low, "flag_negative": neg, "flag_cross": xflag, "rule": ";".join(rules)})
    return pd.DataFrame(rows)

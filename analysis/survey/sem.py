"""The study's regressions as one structural equation model, and the indirect effects its paths imply.

* Structure (:func:`structural_paths`): for every dependent variable of the model file's regressions, the union of
  the predictors of the *last* step of each regression with that dv (the paper's study: PU ~ PEoU;
  ATT ~ PEoU + PU; BI ~ ATT + PU + SN + PBC). Covariates (participant attributes) enter as observed exogenous
  variables. The structure must be recursive (no variable predicts itself through a chain).
* Latent SEM (:func:`fit_sem`): the measurement model of the model file plus these paths, semopy ``MLW``
  (= lavaan ML); fit indices in lavaan's conventions (:func:`analysis.survey.cfa.fit_indices`), standardized paths
  (std.all), R^2 = 1 - standardized residual variance of each endogenous variable. Every fit is checked for
  admissibility (:mod:`analysis.survey.admissibility`): item residual variances at their bound 0, |std loading|
  >= 1, R^2 = 1, and the implied latent covariance matrix; each problem is a warning and ``admissible`` is False.
* Indirect effects (:func:`indirect_effects`): every directed chain x -> m1 -> ... -> y of length >= 2 in the path
  graph; its standardized effect is the product of the standardized paths on it (Alwin & Hauser 1975); the total
  indirect effect of x on y is the sum over its chains. Computed on the latent SEM and on the composite path model;
  the bootstrap CI (BCa, seeded) uses the composite path model, whose ML path estimates are the per-equation OLS
  estimates (a recursive model with uncorrelated disturbances), so 2000 resamples are one vectorised solve.
"""
from __future__ import annotations

import warnings as _warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.survey.admissibility import improper, singular_sample
from analysis.survey.bootstrap import bootstrap
from analysis.survey.cfa import fit_indices, model_description, semopy_said


def structural_paths(model) -> dict[str, list[str]]:
    """dv -> its predictors (union over the last steps of the regressions with that dv, in order of appearance).

    Examples
    --------
    >>> from analysis.survey.sem import structural_paths
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> structural_paths(load(REPO_ROOT / "studies" / "pedas_paper").model)
    {'PU': ['PEoU'], 'ATT': ['PEoU', 'PU'], 'BI': ['ATT', 'PU', 'SN', 'PBC']}
    """
    out: dict[str, list[str]] = {}
    for m in model.regressions:
        preds = out.setdefault(m.dv, [])
        for p in m.steps[-1]:
            if p not in preds:
                preds.append(p)
    _check_recursive(out)
    return out


def _check_recursive(paths: dict[str, list[str]]) -> None:
    state: dict[str, int] = {}

    def visit(v, stack):
        if state.get(v) == 1:
            raise ValueError(f"the regressions form a loop ({' -> '.join(stack + [v])}); one SEM needs a recursive "
                             f"structure")
        if state.get(v) == 2:
            return
        state[v] = 1
        for p in paths.get(v, []):
            visit(p, stack + [v])
        state[v] = 2

    for v in paths:
        visit(v, [])


def sem_description(measurement: dict[str, list[str]], paths: dict[str, list[str]]) -> str:
    """semopy/lavaan syntax of the SEM: the measurement lines, then one ``dv ~ x1 + x2`` line per dv.

    Examples
    --------
    >>> from analysis.survey.sem import sem_description
    >>> print(sem_description({"X": ["x1", "x2"], "Y": ["y1", "y2"]}, {"Y": ["X", "age"]}))
    X =~ x1 + x2
    Y =~ y1 + y2
    Y ~ X + age
    """
    lines = [model_description(measurement)] + [f"{dv} ~ {' + '.join(p)}" for dv, p in paths.items()]
    return "\n".join(lines)


def chains(paths: dict[str, list[str]]) -> list[tuple[str, ...]]:
    """Every directed chain (x, m1, ..., y) with at least one mediator, in a stable order.

    Examples
    --------
    >>> from analysis.survey.sem import chains
    >>> for c in chains({"PU": ["PEoU"], "ATT": ["PEoU", "PU"], "BI": ["ATT", "PU"]}):
    ...     print(" -> ".join(c))
    PEoU -> PU -> ATT
    PEoU -> PU -> ATT -> BI
    PEoU -> PU -> BI
    PEoU -> ATT -> BI
    PU -> ATT -> BI
    """
    children: dict[str, list[str]] = {}
    for dv, preds in paths.items():
        for p in preds:
            children.setdefault(p, []).append(dv)
    out: list[tuple[str, ...]] = []

    def walk(chain):
        for c in children.get(chain[-1], []):
            nxt = chain + (c,)
            if len(nxt) >= 3:
                out.append(nxt)
            walk(nxt)

    for start in dict.fromkeys(p for preds in paths.values() for p in preds):
        walk((start,))
    return out


@dataclass
class SEMResult:
    """paths: dv, predictor, estimate, se, std (std.all), p, hypothesis; r2: variable, r2; fit: lavaan-style
    indices; description: the model syntax; admissible: no improper estimate (a residual variance at its bound,
    |std loading| >= 1, a latent covariance matrix that is not positive definite; see :func:`_admissibility`)."""

    description: str
    paths: pd.DataFrame
    r2: pd.DataFrame
    fit: dict
    converged: bool
    warnings: list[str] = field(default_factory=list)
    admissible: bool = True


def fit_sem(data: pd.DataFrame, measurement: dict[str, list[str]], paths: dict[str, list[str]],
            hypotheses=()) -> SEMResult:
    """Fit the latent SEM (module docstring) to the item (and covariate) columns of `data` (complete rows)."""
    import semopy

    desc = sem_description(measurement, paths)
    items = [i for v in measurement.values() for i in v]
    observed = items + [p for preds in paths.values() for p in preds if p not in measurement and p not in items]
    x = data[list(dict.fromkeys(observed))].dropna().astype(float)
    warn: list[str] = []
    said: list[str] = []
    model = semopy.Model(desc)
    with _warnings.catch_warnings(), semopy_said("SEM: ", said):
        _warnings.simplefilter("ignore")
        res = model.fit(x, obj="MLW", solver="SLSQP", options={"ftol": 1e-12, "maxiter": 5000})
        converged = bool(res.success) and bool(np.all(np.isfinite(res.x)))
        if not converged:
            res = model.fit(x, obj="MLW", solver="L-BFGS-B", options={"ftol": 1e-14, "gtol": 1e-10, "maxiter": 20000})
            converged = bool(res.success) and bool(np.all(np.isfinite(res.x)))
        est = model.inspect(std_est=True)
    if not converged:
        warn.append(f"SEM: did not converge ({getattr(res, 'message', '')}); estimates are unreliable")
    hyp = {(h.predictor, h.dv): h.hypothesis for h in hypotheses}
    rows = []
    for dv, preds in paths.items():
        for p in preds:
            r = est[(est["lval"] == dv) & (est["op"] == "~") & (est["rval"] == p)].iloc[0]
            rows.append({"dv": dv, "predictor": p, "estimate": float(r["Estimate"]), "se": _num(r["Std. Err"]),
                         "std": float(r["Est. Std"]), "p": _num(r["p-value"]), "hypothesis": hyp.get((p, dv), "")})
    r2 = []
    for dv in paths:
        r = est[(est["lval"] == dv) & (est["op"] == "~~") & (est["rval"] == dv)].iloc[0]
        r2.append({"variable": dv, "r2": 1.0 - float(r["Est. Std"])})
    sigma = np.asarray(model.calc_sigma()[0], float)
    S = np.asarray(model.mx_cov, float)
    obs = list(model.names_lambda[0])
    exo = [v for v in obs if v not in items]
    fit = fit_indices(S, sigma, len(x), len(model.param_vals) + len(exo) * (len(exo) + 1) // 2)
    for r in rows:
        if abs(r["std"]) >= 1.0:
            warn.append(f"SEM: standardized path {r['predictor']} -> {r['dv']} = {r['std']:.3f} (|beta| >= 1: "
                        f"the predictors are nearly collinear at the latent level)")
    bad = [f"SEM: R^2 of {r['variable']} = {r['r2']:.4f} (residual variance at its bound)" for r in r2
           if r["r2"] >= 1.0 - 1e-6]
    if min(np.linalg.eigvalsh(sigma)) <= 0:
        bad.append("SEM: the implied covariance matrix is not positive definite")
    bad += _admissibility(model, est, measurement, S)
    bad = singular_sample("SEM: ", x.cov(ddof=0)) + said + bad
    return SEMResult(description=desc, paths=pd.DataFrame(rows), r2=pd.DataFrame(r2), fit=fit, converged=converged,
                     warnings=warn + bad, admissible=not bad)


def _admissibility(model, est: pd.DataFrame, measurement: dict[str, list[str]], S: np.ndarray) -> list[str]:
    """The SEM's improper estimates (:func:`analysis.survey.admissibility.improper`): item error variances at or
    below 0, |std loading| >= 1, and the latent covariance matrix the model implies,
    Cov(eta) = (I - B)^-1 Psi (I - B)^-T, with a variance at or below 0 or not positive definite (an endogenous
    construct's disturbance at its bound is the R^2 = 1 warning)."""
    items = [i for v in measurement.values() for i in v]
    obs = list(model.names_lambda[0])
    theta = np.asarray(model.mx_theta, float)
    ev = pd.Series([theta[obs.index(i), obs.index(i)] for i in items], index=items)
    var = pd.Series([S[obs.index(i), obs.index(i)] for i in items], index=items)
    lo = est[(est["op"] == "~") & est["lval"].isin(items) & est["rval"].isin(list(measurement))]
    std = pd.DataFrame({"item": items, "loading": [float(lo.loc[lo["lval"] == i, "Est. Std"].iloc[0]) for i in items]})
    eta = list(model.names_beta[0])
    B = np.asarray(model.mx_beta, float)
    inv = np.linalg.inv(np.eye(len(eta)) - B)
    cov = inv @ np.asarray(model.mx_psi, float) @ inv.T
    lat = [c for c in measurement if c in eta]
    idx = [eta.index(c) for c in lat]
    cov = pd.DataFrame(cov[np.ix_(idx, idx)], index=lat, columns=lat)
    return improper("SEM: ", std_loadings=std, error_var=ev, item_var=var, latent_cov=cov)


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _std_paths(X: np.ndarray, cols: list[str], paths: dict[str, list[str]]) -> np.ndarray:
    """Standardized OLS coefficients of every path, for stacked samples X (B, n, p) -> (B, n_paths).
    beta = b sd(x)/sd(y): the OLS of z-scored variables."""
    mu = X.mean(axis=1, keepdims=True)
    sd = X.std(axis=1, ddof=1, keepdims=True)
    Z = (X - mu) / sd
    out = []
    for dv, preds in paths.items():
        A = Z[:, :, [cols.index(p) for p in preds]]
        y = Z[:, :, cols.index(dv)]
        XtX = np.einsum("bni,bnj->bij", A, A)
        Xty = np.einsum("bni,bn->bi", A, y)
        with np.errstate(invalid="ignore"):
            try:
                beta = np.linalg.solve(XtX, Xty[..., None])[..., 0]
            except np.linalg.LinAlgError:
                beta = np.full(Xty.shape, np.nan)
        out.append(beta)
    return np.concatenate(out, axis=1)


def indirect_effects(comp: pd.DataFrame, paths: dict[str, list[str]], *, latent: SEMResult | None = None,
                     n_boot: int = 2000, seed: int = 20240101, level: float = 0.95) -> pd.DataFrame:
    """Specific and total indirect effects (standardized) of the path graph on the composite (and covariate)
    columns of `comp`, with BCa bootstrap CIs; ``std_latent`` from the latent SEM when given.

    Returns chain (``x -> m -> y``; ``x => y (total indirect)`` for the sums), x, y, std, b (the unstandardized
    product of OLS coefficients), ci_low, ci_high (of std), n_boot, n_failed, std_latent.
    """
    cols = list(dict.fromkeys([v for dv, preds in paths.items() for v in (dv, *preds)]))
    X = comp[cols].dropna().to_numpy(float)
    plist = [(dv, p) for dv, preds in paths.items() for p in preds]
    ch = chains(paths)
    if not ch:
        return pd.DataFrame(columns=["chain", "x", "y", "std", "b", "ci_low", "ci_high", "n_boot", "n_failed",
                                     "std_latent"])
    pairs = list(dict.fromkeys((c[0], c[-1]) for c in ch))

    def effects(B: np.ndarray) -> np.ndarray:
        coef = _std_paths(B, cols, paths)
        idx = {pp: k for k, pp in enumerate(plist)}
        spec = [np.prod([coef[:, idx[(c[i + 1], c[i])]] for i in range(len(c) - 1)], axis=0) for c in ch]
        tot = [sum(spec[k] for k, c in enumerate(ch) if (c[0], c[-1]) == pr) for pr in pairs]
        return np.stack(spec + tot, axis=1)

    names = [" -> ".join(c) for c in ch] + [f"{x} => {y} (total indirect)" for x, y in pairs]
    res = bootstrap(X, effects, names, n_boot=n_boot, seed=seed, level=level, method="bca", vectorised=True)
    tab = res.table()
    tab.insert(1, "x", [c[0] for c in ch] + [x for x, _ in pairs])
    tab.insert(2, "y", [c[-1] for c in ch] + [y for _, y in pairs])
    tab = tab.rename(columns={"statistic": "chain", "estimate": "std"}).drop(columns="method")
    lat = []
    if latent is not None:
        s = {(r.dv, r.predictor): r.std for r in latent.paths.itertuples()}
        spec = [float(np.prod([s[(c[i + 1], c[i])] for i in range(len(c) - 1)])) for c in ch]
        lat = spec + [sum(spec[k] for k, c in enumerate(ch) if (c[0], c[-1]) == pr) for pr in pairs]
    tab["std_latent"] = lat if lat else np.nan
    b = _b_paths(X, cols, paths)
    spec_b = [float(np.prod([b[(c[i + 1], c[i])] for i in range(len(c) - 1)])) for c in ch]
    tab.insert(4, "b", spec_b + [sum(spec_b[k] for k, c in enumerate(ch) if (c[0], c[-1]) == pr) for pr in pairs])
    return tab


def _b_paths(X: np.ndarray, cols: list[str], paths: dict[str, list[str]]) -> dict[tuple[str, str], float]:
    """(dv, predictor) -> unstandardized OLS coefficient (with intercept) of the composite path model."""
    out = {}
    for dv, preds in paths.items():
        A = np.column_stack([np.ones(len(X))] + [X[:, cols.index(p)] for p in preds])
        coef, *_ = np.linalg.lstsq(A, X[:, cols.index(dv)], rcond=None)
        out.update({(dv, p): float(c) for p, c in zip(preds, coef[1:])})
    return out


def composite_path_std(comp: pd.DataFrame, paths: dict[str, list[str]]) -> pd.DataFrame:
    """dv, predictor, std: the standardized paths of the composite path model (OLS per equation)."""
    cols = list(dict.fromkeys([v for dv, preds in paths.items() for v in (dv, *preds)]))
    X = comp[cols].dropna().to_numpy(float)
    coef = _std_paths(X[None], cols, paths)[0]
    plist = [(dv, p) for dv, preds in paths.items() for p in preds]
    return pd.DataFrame([{"dv": dv, "predictor": p, "std_composite": float(c)} for (dv, p), c in zip(plist, coef)])

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


@dataclass(frozen=True)
class ModelSpec:
    """A hierarchical model: `dv` and the predictor `steps` (blocks added cumulatively)."""

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
    """OLS with intercept. X (n, k) without constant. Returns b, se, t, p, r2, adj_r2, df_resid (b[0] = constant)."""
    n, k = X.shape
    Xc = np.column_stack([np.ones(n), X])
    b, *_ = np.linalg.lstsq(Xc, y, rcond=None)
    resid = y - Xc @ b
    df2 = n - k - 1
    sse = float(resid @ resid)
    sst = float(((y - y.mean()) ** 2).sum())
    r2 = 1.0 - sse / sst
    sigma2 = sse / df2
    cov = sigma2 * np.linalg.inv(Xc.T @ Xc)
    se = np.sqrt(np.diag(cov))
    t = b / se
    p = 2.0 * stats.t.sf(np.abs(t), df2)
    return {"b": b, "se": se, "t": t, "p": p, "r2": r2, "adj_r2": 1.0 - (1.0 - r2) * (n - 1) / df2, "df_resid": df2}


def f_change(r2_new: float, r2_old: float, df1: int, df2: int) -> tuple[float, float]:
    """SPSS F change of a nested pair and its p: ((Delta R^2/df1) / ((1 - R^2_new)/df2))."""
    f = ((r2_new - r2_old) / df1) / ((1.0 - r2_new) / df2)
    return float(f), float(stats.f.sf(f, df1, df2))


def bootstrap_coefs(y: np.ndarray, X: np.ndarray, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """(n_boot, k+1) OLS coefficients on case resamples, solved as one stacked batch.

    Resamples whose design is singular (e.g. a predictor constant in the resample) give NaN rows.
    """
    n, k = X.shape
    Xc = np.column_stack([np.ones(n), X])
    idx = rng.integers(0, n, size=(n_boot, n))
    Xb = Xc[idx]                      # (B, n, k+1)
    yb = y[idx]                       # (B, n)
    XtX = np.einsum("bni,bnj->bij", Xb, Xb)
    Xty = np.einsum("bni,bn->bi", Xb, yb)
    cond = np.linalg.cond(XtX)
    bad = ~np.isfinite(cond) | (cond > 1e12)
    XtX[bad] = np.eye(k + 1)
    coefs = np.linalg.solve(XtX, Xty[..., None])[..., 0]
    coefs[bad] = np.nan
    return coefs


def _jackknife(y: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(n, k+1) leave-one-out OLS coefficients (for the BCa acceleration)."""
    n = len(y)
    keep = ~np.eye(n, dtype=bool)
    Xc = np.column_stack([np.ones(n), X])
    Xj = np.stack([Xc[m] for m in keep])
    yj = np.stack([y[m] for m in keep])
    XtX = np.einsum("bni,bnj->bij", Xj, Xj)
    Xty = np.einsum("bni,bn->bi", Xj, yj)
    return np.linalg.solve(XtX, Xty[..., None])[..., 0]


def bootstrap_ci(boot: np.ndarray, est: np.ndarray, level: float = 0.95, method: str = "percentile",
                 jack: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-coefficient CI from bootstrap draws `boot` (B, k): percentile, or BCa (Efron 1987) with `jack`."""
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


def run_models(data: pd.DataFrame, models: list[ModelSpec], **kw) -> pd.DataFrame:
    """`hierarchical_regression` for every model, concatenated (validates the specs first)."""
    validate_models(models, data.columns)
    frames = [hierarchical_regression(data, m, model_index=i, **kw) for i, m in enumerate(models)]
    return pd.concat(frames, ignore_index=True)

"""Collinearity and common-method-bias checks.

* VIF of each predictor in the last step of each regression: VIF_j = 1 / (1 - R^2_j), R^2_j of predictor j
  regressed (OLS with intercept) on the other predictors of that step; flagged at >= 5 (Hair et al. 2019).
* Full-collinearity VIF (Kock & Lynn 2012; Kock 2015): every construct composite regressed on all other composites,
  VIF = 1 / (1 - R^2); a value above 3.3 signals pathological collinearity or common-method bias.
* Harman's single-factor test (Podsakoff et al. 2003): the share of the total item variance that the first
  unrotated principal component of the item correlation matrix explains, lambda_1 / p; common-method bias is
  suspected when it exceeds 50 %.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

VIF_LIMIT = 5.0
FULL_VIF_LIMIT = 3.3
HARMAN_LIMIT = 0.5


def _r2(y: np.ndarray, X: np.ndarray) -> float:
    A = np.column_stack([np.ones(len(y)), X])
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ beta
    tss = np.sum((y - y.mean()) ** 2)
    if tss <= 0:
        raise ValueError("VIF: a variable without variance")
    return float(1.0 - res @ res / tss)


def vif(data: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """variable, r2, vif of each of `columns` against the others (complete rows).

    Examples
    --------
    Two predictors correlating .6 and a third uncorrelated with both: R^2 = .36, VIF = 1/(1 - .36) = 1.5625:

    >>> import pandas as pd
    >>> from analysis.survey.method_bias import vif
    >>> d = pd.DataFrame({"a": [1, 2, 3, 4], "b": [2, 1, 4, 3], "c": [1, -1, -1, 1]})
    >>> vif(d, ["a", "b", "c"]).round(4)
      variable    r2     vif
    0        a  0.36  1.5625
    1        b  0.36  1.5625
    2        c  0.00  1.0000
    """
    x = data[columns].dropna().to_numpy(float)
    rows = []
    for j, c in enumerate(columns):
        others = np.delete(x, j, axis=1)
        r2 = _r2(x[:, j], others) if others.shape[1] else 0.0
        rows.append({"variable": c, "r2": r2, "vif": float(1.0 / (1.0 - r2)) if r2 < 1 else float("inf")})
    return pd.DataFrame(rows, columns=["variable", "r2", "vif"])


def regression_vif(data: pd.DataFrame, models) -> pd.DataFrame:
    """model, dv, variable, r2, vif, above_limit for the predictors of the last step of each regression with at
    least two predictors (`models`: :class:`analysis.survey.regression.ModelSpec` or the model file's regressions)."""
    frames = []
    for m in models:
        preds = [p for b in m.steps for p in b] if hasattr(m, "predictors") else list(m.steps[-1])
        preds = list(dict.fromkeys(preds))
        if len(preds) < 2:
            continue
        v = vif(data, preds)
        v.insert(0, "model", str(m.name))
        v.insert(1, "dv", m.dv)
        frames.append(v)
    out = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
        columns=["model", "dv", "variable", "r2", "vif"])
    out["above_limit"] = out["vif"] >= VIF_LIMIT
    return out


def full_collinearity_vif(comp: pd.DataFrame) -> pd.DataFrame:
    """construct, r2, vif, above_3_3 (Kock's full-collinearity VIF of every composite)."""
    out = vif(comp, list(comp.columns)).rename(columns={"variable": "construct"})
    out["above_3_3"] = out["vif"] > FULL_VIF_LIMIT
    return out


def harman(scored: pd.DataFrame, items: list[str]) -> dict:
    """Harman's single-factor test: {n_items, first_share, eigenvalue_1, above_50, n_components_eigen_gt_1}.

    Examples
    --------
    Two perfectly correlated items and one independent one: eigenvalues 2, 1, 0, first share 2/3:

    >>> import pandas as pd
    >>> from analysis.survey.method_bias import harman
    >>> d = pd.DataFrame({"a": [1, 2, 3, 4], "b": [1, 2, 3, 4], "c": [1, -1, -1, 1]})
    >>> h = harman(d, ["a", "b", "c"])
    >>> round(h["first_share"], 3), h["above_50"]
    (0.667, True)
    """
    R = scored[items].dropna().corr().to_numpy()
    ev = np.sort(np.linalg.eigvalsh(R))[::-1]
    share = float(ev[0] / len(items))
    return {"n_items": len(items), "eigenvalue_1": float(ev[0]), "first_share": share,
            "above_50": bool(share > HARMAN_LIMIT), "n_components_eigen_gt_1": int(np.sum(ev > 1.0))}

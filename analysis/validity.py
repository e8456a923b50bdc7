"""Discriminant validity and the inter-construct correlation matrix (paper Table 4).

* `composite_correlations`: Pearson r between construct composites with two-tailed p (t test, n - 2 df) and the
  paper's stars (* p < .05, ** p < .01).
* `fornell_larcker`: per pair, sqrt(AVE) of both constructs vs their correlation; pass when |r| is below both.
  The criterion is judged on the *composite* correlations, because that is what the paper's Table 4 puts beside
  sqrt(AVE); the latent (CFA) correlation is reported beside it with its own verdict (`pass_latent`).
* `htmt`: heterotrait-monotrait ratio (Henseler, Ringle & Sarstedt 2015): mean heterotrait-heteromethod item
  correlation over the geometric mean of the two mean monotrait-heteromethod correlations, on absolute
  correlations (semTools ``htmt(absolute=TRUE)``); flagged at 0.85 (strict) and 0.90 (liberal).
"""
from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats

HTMT_STRICT, HTMT_LIBERAL = 0.85, 0.90


def stars(p: float, levels: tuple[float, float] = (0.05, 0.01)) -> str:
    """The paper's significance marks: '**' p < levels[1], '*' p < levels[0], '' otherwise (also for a missing p).
    Table 4 uses the default (.05, .01); Table 5 marks beta at (.05, .001)."""
    if not np.isfinite(p):
        return ""
    return "**" if p < levels[1] else "*" if p < levels[0] else ""


def pearson_p(r: float, n: int) -> float:
    """Two-tailed p of a Pearson correlation r on n pairs (t = r sqrt((n-2)/(1-r^2)), n - 2 df)."""
    if n < 3 or not np.isfinite(r):
        return float("nan")
    if abs(r) >= 1.0:
        return 0.0
    t = r * np.sqrt((n - 2) / (1.0 - r * r))
    return float(2.0 * stats.t.sf(abs(t), n - 2))


def composite_correlations(comp: pd.DataFrame) -> pd.DataFrame:
    """Long table a, b, r, p, n, stars for every pair of composite columns (a before b in column order)."""
    rows = []
    for a, b in combinations(comp.columns, 2):
        pair = comp[[a, b]].dropna()
        r = float(pair[a].corr(pair[b]))
        p = pearson_p(r, len(pair))
        rows.append({"a": a, "b": b, "r": r, "p": p, "n": len(pair), "stars": stars(p)})
    return pd.DataFrame(rows, columns=["a", "b", "r", "p", "n", "stars"])


def fornell_larcker(corr: pd.DataFrame, reliability: pd.DataFrame, latent_corr: pd.DataFrame | None = None
                    ) -> pd.DataFrame:
    """Per pair: a, b, r, sqrt_ave_a, sqrt_ave_b, pass (|r| < both sqrt(AVE)), r_latent, pass_latent."""
    sq = reliability.set_index("construct")["sqrt_ave"]
    rows = []
    for _, c in corr.iterrows():
        a, b, r = c["a"], c["b"], c["r"]
        lim = min(sq[a], sq[b])
        rl = float(latent_corr.loc[a, b]) if latent_corr is not None else float("nan")
        rows.append({"a": a, "b": b, "r": r, "sqrt_ave_a": float(sq[a]), "sqrt_ave_b": float(sq[b]),
                     "pass": bool(abs(r) < lim), "r_latent": rl,
                     "pass_latent": bool(abs(rl) < lim) if np.isfinite(rl) else False})
    return pd.DataFrame(rows)


def htmt(scored: pd.DataFrame, constructs: dict[str, list[str]], absolute: bool = True) -> pd.DataFrame:
    """Long table a, b, htmt, above_085, above_090 for every construct pair (items of `scored`)."""
    items = [i for its in constructs.values() for i in its]
    R = scored[items].corr().to_numpy()
    if absolute:
        R = np.abs(R)
    pos = {i: k for k, i in enumerate(items)}

    def mono(c):
        idx = [pos[i] for i in constructs[c]]
        if len(idx) < 2:
            return float("nan")
        sub = R[np.ix_(idx, idx)]
        return float(sub[np.triu_indices(len(idx), 1)].mean())

    mono_mean = {c: mono(c) for c in constructs}
    rows = []
    for a, b in combinations(constructs, 2):
        het = R[np.ix_([pos[i] for i in constructs[a]], [pos[i] for i in constructs[b]])].mean()
        den = mono_mean[a] * mono_mean[b]
        h = float(het / np.sqrt(den)) if den > 0 else float("nan")
        rows.append({"a": a, "b": b, "htmt": h, "above_085": bool(h > HTMT_STRICT),
                     "above_090": bool(h > HTMT_LIBERAL)})
    return pd.DataFrame(rows, columns=["a", "b", "htmt", "above_085", "above_090"])

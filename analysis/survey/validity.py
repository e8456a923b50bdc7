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
    Table 4 uses the default (.05, .01); Table 5 marks beta at (.05, .001).

    Examples
    --------
    >>> from analysis.survey.validity import stars
    >>> stars(0.03), stars(0.005), stars(0.05), stars(float("nan"))
    ('*', '**', '', '')
    >>> stars(0.005, (0.05, 0.001))                     # Table 5: ** only below .001
    '*'
    """
    if not np.isfinite(p):
        return ""
    return "**" if p < levels[1] else "*" if p < levels[0] else ""


def pearson_p(r: float, n: int) -> float:
    """Two-tailed p of a Pearson correlation.

    t = r sqrt((n - 2) / (1 - r^2)) on n - 2 degrees of freedom (as scipy's ``pearsonr``).

    Parameters
    ----------
    r : float
        The correlation.
    n : int
        Number of pairs.

    Returns
    -------
    float
        p; NaN for n < 3 or a missing r, 0 for |r| = 1.

    Examples
    --------
    r = .5 on 3 pairs: t = .5 sqrt(1/.75) = 1/sqrt(3) on 1 df, where t is Cauchy:
    p = 2 (1/2 - atan(1/sqrt(3))/pi) = 2 (1/2 - 1/6) = 2/3:

    >>> from analysis.survey.validity import pearson_p
    >>> round(pearson_p(0.5, 3), 3)
    0.667
    >>> pearson_p(0.0, 10), pearson_p(1.0, 10)
    (1.0, 0.0)
    """
    if n < 3 or not np.isfinite(r):
        return float("nan")
    if abs(r) >= 1.0:
        return 0.0
    t = r * np.sqrt((n - 2) / (1.0 - r * r))
    return float(2.0 * stats.t.sf(abs(t), n - 2))


def composite_correlations(comp: pd.DataFrame) -> pd.DataFrame:
    """Pearson correlations of every pair of composite columns (Table 4), pairwise complete rows.

    Parameters
    ----------
    comp : DataFrame
        Participant x construct composites.

    Returns
    -------
    DataFrame
        a, b, r, p (:func:`pearson_p`), n, stars (:func:`stars`); one row per pair, a before b in column order.

    Examples
    --------
    Deviations (-1, 0, 1) and (-1, 1, 0): r = 1 / sqrt(2 x 2) = .5, and p = 2/3 as in :func:`pearson_p`:

    >>> import pandas as pd
    >>> from analysis.survey.validity import composite_correlations
    >>> composite_correlations(pd.DataFrame({"X": [1, 2, 3], "Y": [1, 3, 2]})).round(3)
       a  b    r      p  n stars
    0  X  Y  0.5  0.667  3
    """
    rows = []
    for a, b in combinations(comp.columns, 2):
        pair = comp[[a, b]].dropna()
        r = float(pair[a].corr(pair[b]))
        p = pearson_p(r, len(pair))
        rows.append({"a": a, "b": b, "r": r, "p": p, "n": len(pair), "stars": stars(p)})
    return pd.DataFrame(rows, columns=["a", "b", "r", "p", "n", "stars"])


def fornell_larcker(corr: pd.DataFrame, reliability: pd.DataFrame, latent_corr: pd.DataFrame | None = None
                    ) -> pd.DataFrame:
    """The Fornell-Larcker criterion per construct pair: pass when |r| is below the sqrt(AVE) of both constructs.

    Parameters
    ----------
    corr : DataFrame
        Columns a, b, r (as :func:`composite_correlations`).
    reliability : DataFrame
        Columns construct, sqrt_ave.
    latent_corr : DataFrame, optional
        Construct x construct latent (CFA) correlations, judged beside the composite ones.

    Returns
    -------
    DataFrame
        a, b, r, sqrt_ave_a, sqrt_ave_b, pass, r_latent, pass_latent (NaN / False without `latent_corr`).

    Examples
    --------
    X-Y: .60 < min(.8, .7) passes; X-Z: |-.85| >= min(.8, .9) fails (the sign does not matter):

    >>> import pandas as pd
    >>> from analysis.survey.validity import fornell_larcker
    >>> corr = pd.DataFrame({"a": ["X", "X"], "b": ["Y", "Z"], "r": [0.6, -0.85]})
    >>> rel = pd.DataFrame({"construct": ["X", "Y", "Z"], "sqrt_ave": [0.8, 0.7, 0.9]})
    >>> fornell_larcker(corr, rel)[["a", "b", "r", "sqrt_ave_a", "sqrt_ave_b", "pass"]]
       a  b     r  sqrt_ave_a  sqrt_ave_b   pass
    0  X  Y  0.60         0.8         0.7   True
    1  X  Z -0.85         0.8         0.9  False
    """
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
    """Heterotrait-monotrait ratio (Henseler, Ringle & Sarstedt 2015) of every construct pair.

    HTMT = mean heterotrait-heteromethod item correlation / sqrt(mean monotrait correlation of a x that of b),
    on absolute correlations by default (semTools ``htmt(absolute = TRUE)``).

    Parameters
    ----------
    scored : DataFrame
        Participant x item answers (after reverse scoring).
    constructs : dict
        Construct -> its items (the retained ones).
    absolute : bool
        Use |r| (default True).

    Returns
    -------
    DataFrame
        a, b, htmt, above_085 (> 0.85, strict), above_090 (> 0.90, liberal).

    Examples
    --------
    Items that agree perfectly within each construct (monotrait correlations 1) and correlate .5 across: HTMT is
    that correlation, .5:

    >>> import pandas as pd
    >>> from analysis.survey.validity import htmt
    >>> items = pd.DataFrame({"x1": [1, 2, 3], "x2": [1, 2, 3], "y1": [1, 3, 2], "y2": [1, 3, 2]})
    >>> htmt(items, {"X": ["x1", "x2"], "Y": ["y1", "y2"]}).round(3)
       a  b  htmt  above_085  above_090
    0  X  Y   0.5      False      False

    The same two items (r = .8) under two names: heterotrait mean (1 + .8 + .8 + 1)/4 = .9 over
    sqrt(.8 x .8) = .8 gives 1.125, flagged:

    >>> items = pd.DataFrame({"x1": [1, 2, 3, 4], "x2": [1, 3, 2, 4]}).assign(y1=lambda d: d.x1, y2=lambda d: d.x2)
    >>> htmt(items, {"X": ["x1", "x2"], "Y": ["y1", "y2"]}).round(3)
       a  b   htmt  above_085  above_090
    0  X  Y  1.125       True       True
    """
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

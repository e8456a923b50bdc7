"""Paired comparison of two conditions measured on the same participants (a drive KPI without and with the assistance,
a score after two drives), as R's ``t.test(paired = TRUE)`` and ``wilcox.test(paired = TRUE)`` report it, and the
condition x group mixed ANOVA of such pairs.

* :func:`wilcoxon_signed_rank`: the Wilcoxon signed-rank test of the differences, as :mod:`analysis.ranks` computes it
  for every rank test of the tool (values compared at their resolution, 1e-9 of the largest |value| by default, before
  ranking; zero differences dropped; exact only without ties and zeros and for fewer than 50 differences, else the
  normal approximation with continuity and tie correction -- R's ``wilcox.test(x, y, paired = TRUE)`` defaults).
* :func:`paired_comparison`: n, both means and SDs, the mean difference a - b with its t-interval, the paired t-test,
  Cohen's d_z = mean(a - b) / sd(a - b), and the Wilcoxon test.
* :func:`mixed_anova`: condition (within) x group (between) ANOVA (pingouin ``mixed_anova``; with two conditions the
  interaction is the one-way ANOVA of the differences across groups), partial eta^2.
"""
from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats

def wilcoxon_signed_rank(diff, resolution: float | None = None) -> dict:
    """Two-sided Wilcoxon signed-rank test of the paired differences `diff` (:func:`analysis.ranks.wilcoxon_signed_rank`
    of diff against 0; `resolution` default: :data:`analysis.ranks.RELATIVE_RESOLUTION` x max |diff|).

    Returns a dict: v (sum of the positive ranks, R's V), n (non-zero differences), zeros (their count), ties
    (bool), p, method ("exact", "normal", or "" without a non-zero difference).

    Examples
    --------
    No ties: the exact distribution (R: V = 18, p = .1563):

    >>> from analysis.survey.paired import wilcoxon_signed_rank
    >>> r = wilcoxon_signed_rank([1.5, 2.0, -0.5, 3.0, 4.0, -1.0])
    >>> r["v"], r["method"], round(r["p"], 4)
    (18.0, 'exact', 0.1562)

    A tie and a zero: the normal approximation with continuity and tie correction (R: V = 12, p = .2785):

    >>> r = wilcoxon_signed_rank([1.0, 1.0, -2.0, 3.0, 0.0, 4.0])
    >>> r["v"], r["n"], r["zeros"], r["method"], round(r["p"], 4)
    (12.0, 5, 1, 'normal', 0.2785)
    """
    from analysis import ranks

    d = np.asarray(diff, dtype=float)
    if np.isnan(d).any():
        raise ValueError("the differences have missing values; drop the incomplete pairs first")
    zero = np.zeros_like(d)
    res = ranks.resolution_of(d, resolution) if d.size else 1.0
    zeros = int((ranks.on_grid(d, res, origin=0.0) == 0).sum())
    r = ranks.wilcoxon_signed_rank(d, zero, res)
    method = "" if r.n == 0 else ("exact" if "exact" in r.method else "normal")
    ties = bool(r.n) and not _untied(d, res)
    return {"v": r.statistic, "n": r.n, "zeros": zeros, "ties": ties, "p": r.p, "method": method}


def _untied(d: np.ndarray, res: float) -> bool:
    """No two non-zero differences of `d` tie at resolution `res`."""
    from analysis import ranks

    g = np.abs(ranks.on_grid(d, res, origin=0.0))
    g = g[g != 0]
    return len(np.unique(g)) == len(g)


#: the columns of :func:`paired_comparison`'s result
PAIRED = ["n", "mean_a", "sd_a", "mean_b", "sd_b", "mean_diff", "sd_diff", "ci_low", "ci_high", "t", "df", "p_t",
          "dz", "v", "n_wilcoxon", "zeros", "ties", "p_wilcoxon", "wilcoxon_method"]


def paired_comparison(a, b, level: float = 0.95, resolution: float | None = None) -> dict:
    """Paired comparison of `a` and `b` (one value per participant each, same order; pairs with a missing value
    left out): the :data:`PAIRED` fields.

    The mean difference is a - b with its t-interval mean +- t_{(1+level)/2, n-1} sd/sqrt(n); t = mean / (sd/sqrt n)
    on n - 1 df (R ``t.test(a, b, paired = TRUE)``); d_z = mean / sd; the Wilcoxon test of :func:`wilcoxon_signed_rank`
    on the differences, their resolution 1e-9 x the largest |value| of a and b unless `resolution` is given.

    Examples
    --------
    B is higher by 1, 2 and 3: mean difference -2, sd 1, t = -2/(1/sqrt 3) = -3.464 on 2 df, d_z = -2:

    >>> from analysis.survey.paired import paired_comparison
    >>> r = paired_comparison([1.0, 3.0, 2.0], [2.0, 5.0, 5.0])
    >>> r["mean_diff"], round(r["t"], 3), r["df"], r["dz"], r["v"], r["wilcoxon_method"]
    (-2.0, -3.464, 2, -2.0, 0.0, 'exact')
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ok = ~(np.isnan(a) | np.isnan(b))
    a, b = a[ok], b[ok]
    d = a - b
    n = int(d.size)
    mean = float(d.mean()) if n else float("nan")
    sd = float(d.std(ddof=1)) if n > 1 else float("nan")
    if n > 1 and sd > 0:
        se = sd / np.sqrt(n)
        t = mean / se
        half = float(stats.t.ppf(0.5 + level / 2.0, n - 1)) * se
        p_t = float(2.0 * stats.t.sf(abs(t), n - 1))
    else:
        t = half = p_t = float("nan")
    if resolution is None and n:
        from analysis.ranks import resolution_of

        resolution = resolution_of(np.concatenate([a, b]))
    w = wilcoxon_signed_rank(d, resolution)
    return {"n": n, "mean_a": float(a.mean()) if n else float("nan"), "sd_a": float(a.std(ddof=1)) if n > 1 else
            float("nan"), "mean_b": float(b.mean()) if n else float("nan"),
            "sd_b": float(b.std(ddof=1)) if n > 1 else float("nan"), "mean_diff": mean, "sd_diff": sd,
            "ci_low": mean - half, "ci_high": mean + half, "t": float(t), "df": n - 1, "p_t": p_t,
            "dz": mean / sd if n > 1 and sd > 0 else float("nan"), "v": w["v"], "n_wilcoxon": w["n"],
            "zeros": w["zeros"], "ties": w["ties"], "p_wilcoxon": w["p"], "wilcoxon_method": w["method"]}


#: the columns of :func:`mixed_anova`'s result
MIXED_ANOVA = ["source", "ss", "df1", "df2", "ms", "f", "p", "np2"]


def mixed_anova(data: pd.DataFrame, dv: str = "value", within: str = "condition", between: str = "group",
                subject: str = "participant") -> pd.DataFrame:
    """Mixed ANOVA of `dv`: `within` (repeated) x `between` (a participant attribute), complete participants only.

    Rows: the between factor, the within factor and their interaction (pingouin ``mixed_anova``; R
    ``aov(dv ~ within * between + Error(subject / within))`` alike), with SS, df of the effect and of its error
    term, F, p and partial eta^2. A between factor with fewer than two levels among the participants, or an error term
    without variance (F not finite): ValueError.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.paired import mixed_anova
    >>> d = pd.DataFrame({"participant": [p for p in "abcdef" for _ in (0, 1)],
    ...                   "group": [g for g in "xxxyyy" for _ in (0, 1)], "condition": ["c", "t"] * 6,
    ...                   "value": [5, 3, 6, 4, 7, 4, 5, 5, 6, 5, 4, 4.0]})
    >>> mixed_anova(d)[["source", "df1", "df2"]].values.tolist()
    [['group', 1, 4], ['condition', 1, 4], ['condition × group', 1, 4]]
    """
    import pingouin as pg  # imported when a comparison runs: the command line stays light

    d = data[[subject, between, within, dv]].dropna()
    k = d[within].nunique()
    counts = d.groupby(subject)[within].nunique()
    d = d[d[subject].isin(counts.index[counts == k])]
    if d[between].nunique() < 2:
        raise ValueError(f"the mixed ANOVA needs two or more levels of {between} among complete participants")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # F of an error term without variance: refused below
        t = pg.mixed_anova(data=d, dv=dv, within=within, between=between, subject=subject, effsize="np2",
                           correction=False)
    if not np.isfinite(t["F"].to_numpy(float)).all():
        raise ValueError(f"the mixed ANOVA of {dv} has an error term without variance (too few participants per "
                         f"{between})")
    names = {between: between, within: within, "Interaction": f"{within} × {between}"}
    rows = []
    for _, r in t.iterrows():
        rows.append({"source": names.get(r["Source"], r["Source"]), "ss": float(r["SS"]), "df1": int(r["DF1"]),
                     "df2": int(r["DF2"]), "ms": float(r["MS"]), "f": float(r["F"]), "p": float(r["p_unc"]),
                     "np2": float(r["np2"])})
    return pd.DataFrame(rows, columns=MIXED_ANOVA)

"""Reliability per construct (paper Table 3, columns C-alpha, CR, AVE).

* Cronbach's alpha = k/(k-1) (1 - sum var_i / var_sum) with the Feldt (1965) CI:
  [1 - (1-alpha) F_{1-g/2}(n-1, (n-1)(k-1)),  1 - (1-alpha) F_{g/2}(n-1, (n-1)(k-1))]  (as pingouin).
* Composite reliability (Hair et al. 2014): CR = (sum lambda)^2 / ((sum lambda)^2 + sum(1 - lambda^2))
  from standardized loadings; AVE = mean lambda^2; sqrt(AVE) for Fornell-Larcker.  This is the convention the
  paper's Table 3 uses (its CR/AVE follow from its printed loadings).
* omega (semTools ``compRelSEM`` default, ``obs.var=TRUE``): (sum lambda_unstd)^2 psi / 1'S1, i.e. the model's
  common variance of the unit-weighted sum over the *observed* variance of that sum.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats


def alpha_from_cov(cov: np.ndarray) -> float:
    """Cronbach's α from an item covariance (or correlation) matrix: k/(k-1) (1 - tr Σ / 1'Σ1)."""
    cov = np.asarray(cov, float)
    k = cov.shape[0]
    return float(k / (k - 1) * (1 - np.trace(cov) / cov.sum()))


def cronbach_alpha(items: pd.DataFrame, ci: float = 0.95) -> tuple[float, float, float]:
    """Cronbach's alpha of the item columns with the Feldt (1965) confidence interval.

    alpha = k/(k-1) (1 - sum var_i / var_sum) with sample variances (n - 1) of the k items and of their sum;
    interval [1 - (1-alpha) F(1-g/2; n-1, (n-1)(k-1)), 1 - (1-alpha) F(g/2; n-1, (n-1)(k-1))], g = 1 - ci
    (as pingouin's ``cronbach_alpha``).

    Parameters
    ----------
    items : DataFrame
        One column per item, one row per respondent; rows with a missing answer are left out.
    ci : float
        Confidence level of the interval, default 0.95.

    Returns
    -------
    alpha, ci_low, ci_high : float

    Raises
    ------
    ValueError
        Fewer than 2 items or 2 complete rows, or a sum score without variance.

    Examples
    --------
    Two identical items: each has variance 2.5, their sum 2x has variance 10, so alpha = 2 (1 - 5/10) = 1, and
    the interval of a perfect alpha is the point 1:

    >>> import pandas as pd
    >>> from analysis.survey.reliability import cronbach_alpha
    >>> same = pd.DataFrame({"a": [1, 2, 3, 4, 5], "b": [1, 2, 3, 4, 5]})
    >>> tuple(round(v, 3) for v in cronbach_alpha(same))
    (1.0, 1.0, 1.0)

    Item variances 1 and 1, sum scores 2, 5, 5 with variance 3: alpha = 2 (1 - 2/3) = 2/3:

    >>> items = pd.DataFrame({"a": [1, 2, 3], "b": [1, 3, 2]})
    >>> round(cronbach_alpha(items)[0], 3)
    0.667
    """
    x = items.dropna().to_numpy(float)
    n, k = x.shape
    if k < 2:
        raise ValueError("Cronbach's alpha needs at least 2 items")
    if n < 2:
        raise ValueError("Cronbach's alpha needs at least 2 respondents")
    var_items = x.var(axis=0, ddof=1).sum()
    var_sum = x.sum(axis=1).var(ddof=1)
    if var_sum <= 0:
        raise ValueError("Cronbach's alpha is undefined: the sum score has no variance")
    alpha = k / (k - 1) * (1.0 - var_items / var_sum)
    g = 1.0 - ci
    df1, df2 = n - 1, (n - 1) * (k - 1)
    low = 1.0 - (1.0 - alpha) * stats.f.ppf(1.0 - g / 2, df1, df2)
    high = 1.0 - (1.0 - alpha) * stats.f.ppf(g / 2, df1, df2)
    return float(alpha), float(low), float(high)


def composite_reliability(std_loadings) -> float:
    """Composite reliability (Hair et al. 2014) from standardized loadings.

    CR = (sum lambda)^2 / ((sum lambda)^2 + sum(1 - lambda^2)): the error variance of a standardized item is
    1 - lambda^2.

    Parameters
    ----------
    std_loadings : array_like
        The standardized loadings (lavaan ``std.all``) of one construct's items.

    Returns
    -------
    float

    Examples
    --------
    Two loadings .8: (1.6)^2 = 2.56 over 2.56 + 2 (1 - .64) = 3.28, CR = .780:

    >>> from analysis.survey.reliability import composite_reliability
    >>> round(composite_reliability([0.8, 0.8]), 3)
    0.78
    """
    lam = np.asarray(std_loadings, float)
    s2 = lam.sum() ** 2
    return float(s2 / (s2 + np.sum(1.0 - lam ** 2)))


def average_variance_extracted(std_loadings) -> float:
    """Average variance extracted: the mean squared standardized loading (Fornell & Larcker 1981; Hair 2014).

    Parameters
    ----------
    std_loadings : array_like
        The standardized loadings of one construct's items.

    Returns
    -------
    float
        AVE; its square root is what Fornell-Larcker sets against the correlations.

    Examples
    --------
    >>> from analysis.survey.reliability import average_variance_extracted
    >>> round(average_variance_extracted([0.8, 0.8]), 3)        # .8^2
    0.64
    >>> round(average_variance_extracted([0.6, 0.8]), 3)        # (.36 + .64) / 2, the .5 threshold
    0.5
    """
    lam = np.asarray(std_loadings, float)
    return float(np.mean(lam ** 2))


def omega_semtools(unstd_loadings, latent_var: float, S_items) -> float:
    """McDonald's omega as semTools ``compRelSEM`` computes it by default (``obs.var = TRUE``).

    omega = (sum lambda)^2 psi / (1' S 1): the model's common variance of the unit-weighted sum of the items
    over the observed variance of that sum.

    Parameters
    ----------
    unstd_loadings : array_like
        Unstandardized loadings of the construct's items.
    latent_var : float
        Variance psi of the latent factor.
    S_items : array_like
        Observed covariance matrix of the items (k x k).

    Returns
    -------
    float

    Examples
    --------
    Loadings 1 and 1 on a factor of variance 1 give a common variance of the sum of (1 + 1)^2 = 4; with item
    variances 2 and covariance 1 the sum has variance 2 + 2 + 2 x 1 = 6, so omega = 4/6:

    >>> from analysis.survey.reliability import omega_semtools
    >>> round(omega_semtools([1.0, 1.0], 1.0, [[2.0, 1.0], [1.0, 2.0]]), 3)
    0.667
    """
    lam = np.asarray(unstd_loadings, float)
    S = np.asarray(S_items, float)
    return float(lam.sum() ** 2 * latent_var / S.sum())


def reliability_table(scored: pd.DataFrame, cfa, ci: float = 0.95) -> pd.DataFrame:
    """One row per construct of the fitted `cfa` (a :class:`analysis.survey.cfa.CFAResult`): construct, alpha,
    alpha_ci_low, alpha_ci_high, cr, ave, sqrt_ave, omega, n_items, n."""
    rows = []
    for c, its in cfa.constructs.items():
        lo = cfa.loadings[cfa.loadings["construct"] == c].set_index("item").loc[its]
        alpha, a_lo, a_hi = cronbach_alpha(scored[its], ci)
        ave = average_variance_extracted(lo["loading"])
        rows.append({"construct": c, "alpha": alpha, "alpha_ci_low": a_lo, "alpha_ci_high": a_hi,
                     "cr": composite_reliability(lo["loading"]), "ave": ave, "sqrt_ave": float(np.sqrt(ave)),
                     "omega": omega_semtools(lo["estimate"], cfa.psi.loc[c, c], cfa.S.loc[its, its]),
                     "n_items": len(its), "n": int(scored[its].dropna().shape[0])})
    return pd.DataFrame(rows)

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


def cronbach_alpha(items: pd.DataFrame, ci: float = 0.95) -> tuple[float, float, float]:
    """(alpha, ci_low, ci_high) of the item columns (complete rows), Feldt CI at level `ci`."""
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
    """Hair CR = (sum lambda)^2 / ((sum lambda)^2 + sum(1 - lambda^2)) from standardized loadings."""
    lam = np.asarray(std_loadings, float)
    s2 = lam.sum() ** 2
    return float(s2 / (s2 + np.sum(1.0 - lam ** 2)))


def average_variance_extracted(std_loadings) -> float:
    """AVE = mean of squared standardized loadings (Fornell & Larcker 1981; Hair 2014)."""
    lam = np.asarray(std_loadings, float)
    return float(np.mean(lam ** 2))


def omega_semtools(unstd_loadings, latent_var: float, S_items) -> float:
    """semTools compRelSEM omega (obs.var=TRUE): (sum lambda)^2 psi / (1' S 1), S = observed item covariance."""
    lam = np.asarray(unstd_loadings, float)
    S = np.asarray(S_items, float)
    return float(lam.sum() ** 2 * latent_var / S.sum())


def reliability_table(scored: pd.DataFrame, cfa, ci: float = 0.95) -> pd.DataFrame:
    """One row per construct of the fitted `cfa` (a :class:`analysis.cfa.CFAResult`): construct, alpha,
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

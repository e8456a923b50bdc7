"""The CFA's global fit as a reviewer reads it: chi^2, CFI, TLI, RMSEA with its 90 % confidence interval
(:func:`analysis.survey.cfa.rmsea_ci`, lavaan's method) and SRMR per stage, judged against Hu & Bentler's (1999)
cut-offs (CFI, TLI >= .95, RMSEA <= .06, SRMR <= .08; :data:`analysis.survey.cfa.HU_BENTLER`) in one sentence.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis import apa
from analysis.survey.cfa import HU_BENTLER, judge_fit, rmsea_ci

STAGES = {"initial": "Initial (every scaled item)", "final": "Final (retained items)"}
NAMES = {"cfi": "CFI", "tli": "TLI", "rmsea": "RMSEA", "srmr": "SRMR"}
CUTOFFS = "CFI ≥ .95, TLI ≥ .95, RMSEA ≤ .06, SRMR ≤ .08"


def _bounded(x: float, digits: int = 3) -> str:
    """A value bounded by 1 as APA prints it (:func:`analysis.apa.num`): no leading zero, a true minus sign."""
    return apa.num(x, digits, bounded=True)


def fit_indices_table(fit: pd.DataFrame, level: float = 0.90) -> pd.DataFrame:
    """One row per stage of ``fit.csv`` (stage, chi2, df, p, cfi, tli, rmsea, srmr, n) with words as headers: the
    RMSEA's `level` interval beside it and which of the four indices meet Hu & Bentler's cut-offs.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.fit_report import fit_indices_table
    >>> fit = pd.DataFrame([{"stage": "final", "chi2": 40.0, "df": 20, "p": 0.005, "cfi": 0.96, "tli": 0.95,
    ...                      "rmsea": 0.0709, "srmr": 0.05, "n": 200}])
    >>> row = fit_indices_table(fit).iloc[0]
    >>> round(float(row["RMSEA 90 % CI LL"]), 4), round(float(row["RMSEA 90 % CI UL"]), 4), row["Cut-offs met"]
    (0.0379, 0.1025, 'CFI, TLI, SRMR')
    """
    pct = f"{100 * level:g} %"
    rows = []
    for _, r in fit.iterrows():
        lo, hi = rmsea_ci(float(r["chi2"]), int(r["df"]), int(r["n"]), level)
        met = [NAMES[k] for k, ok in judge_fit(r.to_dict()).items() if ok]
        rows.append({"Stage": STAGES.get(str(r["stage"]), str(r["stage"])), "N": int(r["n"]), "χ²": float(r["chi2"]),
                     "df": int(r["df"]), "p": float(r["p"]), "CFI": float(r["cfi"]), "TLI": float(r["tli"]),
                     "RMSEA": float(r["rmsea"]), f"RMSEA {pct} CI LL": lo, f"RMSEA {pct} CI UL": hi,
                     "SRMR": float(r["srmr"]), "Cut-offs met": ", ".join(met) or "none"})
    return pd.DataFrame(rows)


def fit_sentence(row: dict | pd.Series, what: str = "The final measurement model", level: float = 0.90) -> str:
    """One APA sentence on a stage's fit (a row of ``fit.csv``) judged against Hu & Bentler's (1999) cut-offs.

    Examples
    --------
    >>> import textwrap
    >>> from analysis.survey.fit_report import fit_sentence
    >>> print(textwrap.fill(fit_sentence({"chi2": 175.97, "df": 137, "p": 0.0138, "cfi": 0.907, "tli": 0.883,
    ...                                   "rmsea": 0.0843, "srmr": 0.110, "n": 40}), 100))
    The final measurement model fitted poorly by Hu and Bentler's (1999) cut-offs (CFI ≥ .95, TLI ≥ .95,
    RMSEA ≤ .06, SRMR ≤ .08): χ²(137) = 175.97, p = .014, CFI = .907, TLI = .883, RMSEA = .084, 90 % CI
    [.040, .119], SRMR = .110; none of the four indices meets its cut-off; the RMSEA interval reaches
    above .10, so poor fit in the population cannot be ruled out.
    """
    r = dict(row)
    lo, hi = rmsea_ci(float(r["chi2"]), int(r["df"]), int(r["n"]), level)
    ok = judge_fit(r)
    met = [NAMES[k] for k, v in ok.items() if v]
    missed = [NAMES[k] for k, v in ok.items() if not v]
    verdict = ("fitted well" if not missed else "fitted poorly" if not met else "fitted acceptably only in part")
    stats_text = (f"χ²({int(r['df'])}) = {float(r['chi2']):.2f}, {apa.p_text(float(r['p']))}, "
                  f"CFI = {_bounded(r['cfi'])}, "
                  f"TLI = {_bounded(r['tli'])}, RMSEA = {_bounded(r['rmsea'])}, {100 * level:g} % CI "
                  f"[{_bounded(lo)}, {_bounded(hi)}], SRMR = {_bounded(r['srmr'])}")
    if not missed:
        tail = "all four indices meet their cut-offs"
    elif not met:
        tail = "none of the four indices meets its cut-off"
    else:
        tail = f"{' and '.join(met)} {'meets' if len(met) == 1 else 'meet'} {'its' if len(met) == 1 else 'their'} " \
               f"cut-off{'' if len(met) == 1 else 's'}, {' and '.join(missed)} {'does' if len(missed) == 1 else 'do'} not"
    if np.isfinite(hi) and hi > 0.10:
        tail += "; the RMSEA interval reaches above .10, so poor fit in the population cannot be ruled out"
    return f"{what} {verdict} by Hu and Bentler's (1999) cut-offs ({CUTOFFS}): {stats_text}; {tail}."

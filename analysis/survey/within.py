"""Within-subjects comparisons of conditions: every participant is measured under each condition (e.g. three
takeover warnings driven in a Latin square, a questionnaire score or a drive KPI after each drive).

:func:`compare_within` takes one dependent variable as a tidy long frame (one row per participant and condition,
optionally the period in which the condition was driven) and returns a :class:`WithinComparison` of tidy frames:

- ``descriptives``: per condition n, mean, SD (n - 1), median, quartiles and IQR (linear interpolation, R's type 7),
  min, max, on every row given;
- ``anova``: the one-way repeated-measures ANOVA (pingouin ``rm_anova``): F = MS_condition / MS_error on
  (k - 1, (n - 1)(k - 1)) df, partial eta^2 = SS_c / (SS_c + SS_error), generalised eta^2 (Olejnik & Algina 2003)
  = SS_c / (SS_c + SS_subjects + SS_error); Mauchly's W and its p (pingouin ``sphericity``); the Greenhouse-Geisser
  and Huynh-Feldt epsilons (pingouin ``epsilon``; HF capped at 1 as pingouin and car's corrected p do) and the
  p-values of F on (eps (k - 1), eps (n - 1)(k - 1)) df;
- ``friedman``: Friedman's chi^2 with the tie correction on k - 1 df and Kendall's W = chi^2 / (n (k - 1)) (R's
  ``friedman.test``, :func:`analysis.ranks.friedman`);
- ``posthoc``: every pair of conditions a < b (in the conditions' order), the paired t-test (pingouin
  ``pairwise_tests``) and the Wilcoxon signed-rank test as R's ``wilcox.test(a, b, paired = TRUE)``
  (:func:`analysis.ranks.wilcoxon_signed_rank`: V = the rank sum of the positive differences, zero differences
  dropped, the exact distribution only without ties and zeros, else the normal approximation with continuity and
  tie correction), Holm's correction over the pairs of each test, Cohen's d_z = mean(a - b) / SD(a - b) (pingouin
  ``effsize="cohen_dz"``). Both rank tests compare values at the variable's resolution (:mod:`analysis.ranks`), so
  values the data tie stay tied through float noise;
- ``mixed`` and ``mixed_fit``: the linear mixed model value ~ C(condition) + C(period) + (1 | participant)
  (statsmodels ``MixedLM``, REML) on every row: fixed effects with SE, Wald z, normal p and 95 % CI; the
  random-intercept and residual variances, convergence and whether the random-intercept variance is on the
  boundary (a ``warning`` text, never silent).

rm-ANOVA, Friedman and the paired tests need complete cases: participants missing a condition are left out of them
(``dropped``, and a warning); the descriptives and the mixed model use every row. pingouin and statsmodels are the
test extra's packages, imported when a comparison runs. docs/acceptance_statistics.md, "Within-subjects
comparisons", records the decisions and the comparison with R.
"""
from __future__ import annotations

import warnings as _warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from study.common.errors import UserError

GTOL = 1e-10             # BFGS gradient tolerance of the REML fit (statsmodels' default 1e-5 stops ~1e-4 short)
BOUNDARY_THETA = 1e-4    # sd(random intercept) / sd(residual) below this is a boundary fit (lme4's isSingular tol)
MIN_COMPLETE = 3         # participants with every condition needed by rm-ANOVA, Friedman and the paired tests

DESCRIPTIVES = ["variable", "condition", "n", "mean", "sd", "median", "q1", "q3", "iqr", "min", "max"]
ANOVA = ["variable", "source", "n", "ss", "ss_error", "df1", "df2", "ms", "ms_error", "f", "p", "np2", "ng2",
         "mauchly_w", "mauchly_chi2", "mauchly_df", "mauchly_p", "eps_gg", "eps_hf", "p_gg", "p_hf"]
FRIEDMAN = ["variable", "source", "n", "k", "chi2", "df", "p", "kendall_w"]
POSTHOC = ["variable", "a", "b", "test", "n", "mean_diff", "statistic", "df", "p", "p_holm", "dz"]
MIXED = ["variable", "term", "effect", "level", "coef", "se", "z", "p", "ci_low", "ci_high"]
MIXED_FIT = ["variable", "formula", "n_obs", "n_groups", "var_intercept", "var_residual", "icc", "reml_criterion",
             "converged", "boundary", "optimizer", "warning"]


@dataclass(frozen=True)
class WithinComparison:
    """The within-subjects comparison of one dependent variable (every frame starts with ``variable``, so the
    frames of several variables stack with ``pd.concat``).

    Attributes
    ----------
    variable : str
        Name of the dependent variable.
    conditions : tuple of str
        The conditions in their order (the first is the mixed model's reference).
    n_participants, n_complete : int
        Participants with any row; participants with every condition (the sample of anova, friedman, posthoc).
    dropped : tuple of str
        Participants left out of the complete-case tests (a condition missing).
    descriptives, anova, friedman, posthoc, mixed, mixed_fit : DataFrame
        Columns as the module constants DESCRIPTIVES, ANOVA, FRIEDMAN, POSTHOC, MIXED, MIXED_FIT.
    warnings : tuple of str
        Dropped participants and rows, mixed-model convergence and boundary, statsmodels' own warnings.
    """
    variable: str
    conditions: tuple[str, ...]
    n_participants: int
    n_complete: int
    dropped: tuple[str, ...]
    descriptives: pd.DataFrame
    anova: pd.DataFrame
    friedman: pd.DataFrame
    posthoc: pd.DataFrame
    mixed: pd.DataFrame
    mixed_fit: pd.DataFrame
    warnings: tuple[str, ...]

    def tables(self) -> dict[str, pd.DataFrame]:
        """Name -> frame of the six tables."""
        return {"descriptives": self.descriptives, "anova": self.anova, "friedman": self.friedman,
                "posthoc": self.posthoc, "mixed": self.mixed, "mixed_fit": self.mixed_fit}


def _prepare(data: pd.DataFrame, dv: str, subject: str, within: str, period: str | None,
             conditions) -> tuple[pd.DataFrame, tuple[str, ...], list[str]]:
    """(rows as columns participant, condition, value[, period]; the conditions in order; warnings) or UserError."""
    wanted = [subject, within, dv] + ([period] if period else [])
    if missing := [c for c in wanted if c not in data.columns]:
        raise UserError(f"within-subjects data lack column(s) {', '.join(missing)}")
    if len(set(wanted)) < len(wanted):
        raise UserError(f"within-subjects columns must differ: {', '.join(wanted)}")
    d = pd.DataFrame({"participant": data[subject].astype(str).to_numpy(),
                      "condition": data[within].astype(str).to_numpy()})
    if data[subject].isna().any() or data[within].isna().any():
        raise UserError(f"within-subjects data have rows without {subject} or {within}")
    value = pd.to_numeric(data[dv], errors="coerce")
    bad = data[dv].notna().to_numpy() & value.isna().to_numpy()
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"{dv} must be numeric: {d['participant'][i]} {d['condition'][i]} has {data[dv].iloc[i]!r}")
    d["value"] = value.to_numpy(dtype=float)
    if not np.isfinite(d["value"].fillna(0.0)).all():
        raise UserError(f"{dv} has infinite values")
    if period:
        if data[period].isna().any():
            raise UserError(f"within-subjects data have rows without {period}")
        d["period"] = data[period].to_numpy()
    if conditions is None:
        col = data[within]
        conditions = ([str(c) for c in col.cat.categories if (col == c).any()]
                      if isinstance(col.dtype, pd.CategoricalDtype) else list(pd.unique(d["condition"])))
    conditions = tuple(str(c) for c in conditions)
    if unknown := sorted(set(d["condition"]) - set(conditions)):
        raise UserError(f"{within} {', '.join(unknown)} not among the conditions {', '.join(conditions)}")
    if len(set(conditions)) != len(conditions) or len(conditions) < 2:
        raise UserError(f"a within-subjects comparison needs two or more distinct conditions, got "
                        f"{', '.join(conditions) or 'none'}")
    dup = d.duplicated(["participant", "condition"], keep=False)
    if dup.any():
        first = d[dup].iloc[0]
        raise UserError(f"{first['participant']} has {dup.sum()} rows of {within} {first['condition']}; "
                        f"one row per {subject} and {within} is expected")
    notes = []
    if (empty := d["value"].isna()).any():
        notes.append(f"{dv}: {int(empty.sum())} row(s) without a value left out")
        d = d[~empty].reset_index(drop=True)
    d["condition"] = pd.Categorical(d["condition"], categories=list(conditions))
    return d, conditions, notes


def _descriptives(d: pd.DataFrame, variable: str, conditions) -> pd.DataFrame:
    rows = []
    for c in conditions:
        x = d.loc[d["condition"] == c, "value"]
        q1, q3 = (x.quantile(0.25), x.quantile(0.75)) if len(x) else (np.nan, np.nan)
        rows.append({"variable": variable, "condition": c, "n": int(len(x)), "mean": x.mean(),
                     "sd": x.std(ddof=1) if len(x) > 1 else np.nan, "median": x.median(), "q1": q1, "q3": q3,
                     "iqr": q3 - q1, "min": x.min(), "max": x.max()})
    return pd.DataFrame(rows, columns=DESCRIPTIVES)


def _anova(pg, c: pd.DataFrame, variable: str, k: int) -> pd.DataFrame:
    """rm-ANOVA with both effect sizes, Mauchly, GG and HF on the complete cases `c`."""
    args = dict(data=c, dv="value", within="condition", subject="participant")
    partial = pg.rm_anova(**args, correction=True, detailed=True, effsize="np2")
    general = pg.rm_anova(**args, correction=True, detailed=True, effsize="ng2")
    effect, error = partial.iloc[0], partial.iloc[1]
    f, df1, df2 = float(effect["F"]), float(effect["DF"]), float(error["DF"])
    eps_gg = float(pg.epsilon(**args, correction="gg"))
    eps_hf = float(pg.epsilon(**args, correction="hf"))
    if k > 2:
        sph = pg.sphericity(**args)
        w, chi2, sdf, sp = float(sph.W), float(sph.chi2), float(sph.dof), float(sph.pval)
        p_gg = float(effect["p_GG_corr"])
    else:  # one difference: sphericity holds by construction, no test (as afex)
        w, chi2, sdf, sp = np.nan, np.nan, np.nan, np.nan
        p_gg = float(effect["p_unc"])
    return pd.DataFrame([{
        "variable": variable, "source": "condition", "n": int(c["participant"].nunique()),
        "ss": float(effect["SS"]), "ss_error": float(error["SS"]), "df1": df1, "df2": df2,
        "ms": float(effect["MS"]), "ms_error": float(error["MS"]), "f": f, "p": float(effect["p_unc"]),
        "np2": float(effect["np2"]), "ng2": float(general.iloc[0]["ng2"]),
        "mauchly_w": w, "mauchly_chi2": chi2, "mauchly_df": sdf, "mauchly_p": sp, "eps_gg": eps_gg,
        "eps_hf": eps_hf, "p_gg": p_gg,
        # pingouin corrects by GG only; the HF-corrected p is the same F on the HF-scaled df
        "p_hf": float(stats.f.sf(f, eps_hf * df1, eps_hf * df2)),
    }], columns=ANOVA)


def _friedman(c: pd.DataFrame, variable: str, k: int, resolution: float | None) -> pd.DataFrame:
    """R's friedman.test at the variable's resolution (:func:`analysis.ranks.friedman`)."""
    from analysis.ranks import friedman

    wide = c.pivot(index="participant", columns="condition", values="value")
    fr = friedman(wide.to_numpy(dtype=float), resolution)
    return pd.DataFrame([{"variable": variable, "source": "condition", "n": fr.n, "k": k, "chi2": fr.statistic,
                          "df": float(k - 1), "p": fr.p, "kendall_w": fr.estimate}], columns=FRIEDMAN)


def _posthoc(pg, c: pd.DataFrame, variable: str, resolution: float | None) -> pd.DataFrame:
    """The paired t-tests (pingouin) and R's paired wilcox.test at the variable's resolution
    (:func:`analysis.ranks.wilcoxon_signed_rank`: V = the rank sum of the positive differences a - b) of every
    pair, each test Holm-corrected over the pairs."""
    from analysis.ranks import wilcoxon_signed_rank

    wide = c.pivot(index="participant", columns="condition", values="value")
    with _warnings.catch_warnings():
        # a pair without any difference gives NaN statistics; pingouin/scipy warn about it, the NaN stays
        _warnings.simplefilter("ignore", RuntimeWarning)
        pt = pg.pairwise_tests(data=c, dv="value", within="condition", subject="participant",
                               parametric=True, padjust="holm", effsize="cohen_dz")
    pairs = list(zip(pt["A"].astype(str), pt["B"].astype(str)))
    diff = [float((wide[a] - wide[b]).mean()) for a, b in pairs]
    holm = pt["p_corr"] if "p_corr" in pt else pt["p_unc"]  # one pair: pingouin adjusts nothing, Holm(p) = p
    t = pd.DataFrame({"variable": variable, "a": [a for a, _ in pairs], "b": [b for _, b in pairs], "test": "t",
                      "n": len(wide), "mean_diff": diff, "statistic": pt["T"].astype(float),
                      "df": pt["dof"].astype(float), "p": pt["p_unc"].astype(float), "p_holm": holm.astype(float),
                      "dz": pt["cohen_dz"].astype(float)})
    tests = [wilcoxon_signed_rank(wide[a], wide[b], resolution) for a, b in pairs]
    p = np.array([r.p for r in tests])
    w = t.assign(test="wilcoxon", statistic=[r.statistic for r in tests], df=np.nan, p=p, p_holm=_holm(p))
    return pd.concat([t, w], ignore_index=True)[POSTHOC]


def _holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values (R's p.adjust(method = "holm")); NaN stays NaN and is not counted."""
    out = np.full(len(p), np.nan)
    ok = np.flatnonzero(~np.isnan(p))
    order = ok[np.argsort(p[ok], kind="stable")]
    m = len(order)
    running = 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (m - i) * p[j]))
        out[j] = running
    return out


def _design(d: pd.DataFrame, conditions, period: bool) -> tuple[pd.DataFrame, list[tuple[str, str, str]]]:
    """Fixed-effects design: intercept, treatment dummies of condition (reference = first condition) and of period
    (reference = first period in sorted order); and (term, effect, level) of each column."""
    cols = {"(Intercept)": np.ones(len(d))}
    labels = [("(Intercept)", "intercept", "")]
    for c in conditions[1:]:
        cols[f"condition[{c}]"] = (d["condition"] == c).to_numpy(dtype=float)
        labels.append((f"condition[{c}]", "condition", c))
    if period:
        for p in sorted(pd.unique(d["period"]))[1:]:
            cols[f"period[{p}]"] = (d["period"] == p).to_numpy(dtype=float)
            labels.append((f"period[{p}]", "period", str(p)))
    return pd.DataFrame(cols, index=d.index), labels


def _mixed(sm, d: pd.DataFrame, variable: str, conditions, period: bool) -> tuple[pd.DataFrame, pd.DataFrame,
                                                                                  list[str]]:
    """REML fit of value ~ C(condition) [+ C(period)] + (1 | participant) on every row of `d`.

    A random-intercept variance on the boundary (REML optimum at 0) is a fit statsmodels' optimisers do not
    finish: they stop short of 0 and report no convergence. So the restricted log-likelihood is also evaluated at
    the boundary (relative variance BOUNDARY_THETA**2 / 100); if it is at least the fitted one, the REML solution is
    the boundary one, whose fixed effects and residual variance are ordinary least squares (V = sigma^2 I), and
    those are reported with ``boundary`` true (lme4 reports such a fit as singular, with the same numbers).
    """
    from statsmodels.regression.mixed_linear_model import MixedLMParams

    X, labels = _design(d, conditions, period)
    formula = "value ~ C(condition)" + (" + C(period)" if period else "") + " + (1 | participant)"
    if np.linalg.matrix_rank(X.to_numpy()) < X.shape[1]:
        what = "condition and period are confounded" if period else "a condition has no rows"
        raise UserError(f"{variable}: the mixed model {formula} cannot be estimated: {what}")
    y = d["value"].to_numpy()
    model = sm.MixedLM(y, X, groups=d["participant"].to_numpy())
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        try:
            res, optimizer = model.fit(reml=True, method=["bfgs"], gtol=GTOL), f"REML, bfgs gtol={GTOL:g}"
            if not res.converged:  # statsmodels' default chain of optimisers before giving up
                res, optimizer = model.fit(reml=True), "REML, statsmodels default optimisers"
            edge = MixedLMParams.from_components(np.asarray(res.fe_params),
                                                 cov_re=np.array([[BOUNDARY_THETA**2 / 100]]))
            llf_edge = float(model.loglike(edge, profile_fe=True))
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise UserError(f"{variable}: the mixed model {formula} could not be fitted: {exc}") from None
    k_fe = X.shape[1]
    var_u, var_e, llf = float(np.asarray(res.cov_re)[0, 0]), float(res.scale), float(res.llf)
    at_edge = llf_edge >= llf - 1e-9 * max(1.0, abs(llf))
    problems, notes = [], []
    if at_edge or var_u <= 0 or np.sqrt(var_u / var_e) < BOUNDARY_THETA:
        stopped = "" if res.converged else f" (statsmodels stopped at {var_u:.3g} without converging)"
        ols = sm.OLS(y, X).fit(use_t=False)
        coef, se, z, p = (np.asarray(a, dtype=float) for a in (ols.params, ols.bse, ols.tvalues, ols.pvalues))
        ci = np.asarray(ols.conf_int())
        var_u, var_e, llf, converged, boundary = 0.0, float(ols.scale), max(llf, llf_edge), True, True
        optimizer += "; boundary: ordinary least squares"
        problems.append(f"the random-intercept variance is on the boundary (0){stopped}: participants do not differ "
                        "beyond the residual; the fixed effects are ordinary least squares")
    else:
        coef, se = np.asarray(res.fe_params, dtype=float), np.asarray(res.bse_fe, dtype=float)
        z, p = np.asarray(res.tvalues, dtype=float)[:k_fe], np.asarray(res.pvalues, dtype=float)[:k_fe]
        ci = np.asarray(res.conf_int())[:k_fe]
        converged, boundary = bool(res.converged), False
        for w in caught:
            text = f"{variable} mixed model: {' '.join(str(w.message).split())}"
            if text not in notes:
                notes.append(text)
        if not converged:
            problems.append("the REML fit did not converge")
    notes += [f"{variable} mixed model: {text}" for text in problems]
    fixed = pd.DataFrame({
        "variable": variable, "term": [t for t, _, _ in labels], "effect": [e for _, e, _ in labels],
        "level": [lv for _, _, lv in labels], "coef": coef, "se": se, "z": z, "p": p, "ci_low": ci[:, 0],
        "ci_high": ci[:, 1]}, columns=MIXED)
    fit = pd.DataFrame([{
        "variable": variable, "formula": formula, "n_obs": int(len(d)), "n_groups": int(d["participant"].nunique()),
        "var_intercept": var_u, "var_residual": var_e, "icc": var_u / (var_u + var_e),
        "reml_criterion": -2.0 * llf, "converged": converged, "boundary": boundary, "optimizer": optimizer,
        "warning": "; ".join(problems)}], columns=MIXED_FIT)
    return fixed, fit, notes


def compare_within(data: pd.DataFrame, dv: str = "value", subject: str = "participant",
                   within: str = "condition", period: str | None = None, conditions=None,
                   variable: str | None = None, resolution: float | None = None) -> WithinComparison:
    """Compare the conditions of one dependent variable within subjects.

    Parameters
    ----------
    data : DataFrame
        Long frame, one row per participant and condition; other columns are ignored.
    dv, subject, within : str
        Columns of the value, the participant and the condition.
    period : str, optional
        Column of the period (1st, 2nd, ... drive) of the row; the mixed model then adjusts for it as a factor
        (in a Latin square the order effects). Without it the model is value ~ C(condition) + (1 | participant).
    conditions : sequence of str, optional
        The conditions in order (the first is the mixed model's reference, the pairs follow this order). Default:
        the categories of a categorical `within` column, else the order of first appearance.
    variable : str, optional
        Name in the output's ``variable`` column (default `dv`).
    resolution : float, optional
        The step at which values tie for the rank tests (Friedman, Wilcoxon; :mod:`analysis.ranks`), e.g. 1/6 for a
        mean of six whole-number items; default: 1e-9 of the largest magnitude.

    Returns
    -------
    WithinComparison

    Raises
    ------
    UserError
        Missing columns, non-numeric values, a participant with two rows of one condition, fewer than two
        conditions, fewer than 3 participants with every condition, a value that does not vary, a mixed model whose
        condition and period columns are confounded.

    Examples
    --------
    Three participants, two conditions; B is higher by 1, 2 and 3, so d_z = 2 / 1 = 2 and t = 2 / (1 / sqrt(3)):

    >>> import pandas as pd
    >>> from analysis.survey.within import compare_within
    >>> d = pd.DataFrame({"participant": ["p1", "p1", "p2", "p2", "p3", "p3"], "condition": ["A", "B"] * 3,
    ...                   "value": [1.0, 2.0, 3.0, 5.0, 2.0, 5.0]})
    >>> r = compare_within(d)
    >>> r.posthoc.loc[r.posthoc["test"] == "t", ["a", "b", "mean_diff", "statistic", "dz"]].round(4)
       a  b  mean_diff  statistic   dz
    0  A  B       -2.0    -3.4641 -2.0
    """
    import pingouin as pg  # imported when a comparison runs: the command line stays light
    import statsmodels.api as sm

    variable = variable or dv
    d, conditions, notes = _prepare(data, dv, subject, within, period, conditions)
    k = len(conditions)
    if d.groupby("participant", observed=True)["value"].nunique().max() < 2:
        raise UserError(f"{variable} does not vary within participants")
    counts = d.groupby("participant")["condition"].nunique()
    complete = sorted(counts.index[counts == k])
    dropped = tuple(sorted(counts.index[counts < k]))
    if len(complete) < MIN_COMPLETE:
        raise UserError(f"{variable}: {len(complete)} participant(s) have every condition; rm-ANOVA and Friedman "
                        f"need at least {MIN_COMPLETE}")
    if dropped:
        notes.append(f"{variable}: {len(dropped)} participant(s) without every condition left out of rm-ANOVA, "
                     f"Friedman and the paired tests (kept in the descriptives and the mixed model): "
                     f"{', '.join(dropped)}")
    c = d[d["participant"].isin(complete)].sort_values(["participant", "condition"]).reset_index(drop=True)
    fixed, fit, mixed_notes = _mixed(sm, d, variable, conditions, period is not None)
    return WithinComparison(
        variable=variable, conditions=conditions, n_participants=int(counts.size), n_complete=len(complete),
        dropped=dropped, descriptives=_descriptives(d, variable, conditions), anova=_anova(pg, c, variable, k),
        friedman=_friedman(c, variable, k, resolution), posthoc=_posthoc(pg, c, variable, resolution), mixed=fixed,
        mixed_fit=fit,
        warnings=tuple(notes + mixed_notes))

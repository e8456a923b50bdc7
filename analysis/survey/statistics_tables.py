"""The survey statistics a journal reviewer asks for, as tables and a figure of the report's survey part:

* ``fit_indices``: the CFA's global fit per stage with the RMSEA's 90 % interval, judged against Hu & Bentler (1999)
  in the note (:mod:`analysis.survey.fit_report`), with the final solution's admissibility problems beside it;
* ``regression_diagnostics``: per model and step, Cohen's f^2 with its 95 % interval (noncentral F), Shapiro-Wilk,
  Breusch-Pagan, Cook's distance and the cases above 4/n, the largest VIF (:mod:`analysis.survey.diagnostics`);
* ``regression_diagnostics_coefficients``: per step and predictor B, SE, beta with its 95 % interval, t, p, VIF;
* ``figures/path_diagram``: the structural model of the model file with its betas (:mod:`analysis.survey.path_diagram`).

Headers are words and symbols; the CSVs keep full precision.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from analysis.render import write_table
from analysis.survey.diagnostics import INFLUENCE, regression_diagnostics
from analysis.survey.fit_report import fit_indices_table, fit_sentence
from analysis.survey.path_diagram import path_edges, plot_path_diagram, r2_texts
from analysis.survey.regression import ModelSpec

STEP_HEADERS = {"model": "Model", "step": "Step", "dv": "Dependent variable", "added": "Predictors added",
                "n": "n", "delta_r2": "ΔR²", "f2": "f²", "f2_ci_low": "f² 95 % CI LL", "f2_ci_high": "f² 95 % CI UL",
                "shapiro_w": "Shapiro–Wilk W", "shapiro_p": "p (W)", "bp": "Breusch–Pagan χ²", "bp_df": "df (BP)",
                "bp_p": "p (BP)", "cooks_max": "Max Cook's D", "n_influential": "Cases D > 4/n",
                "vif_max": "Max VIF"}
COEF_HEADERS = {"model": "Model", "step": "Step", "dv": "Dependent variable", "predictor": "Predictor", "b": "B",
                "se_b": "SE", "beta": "β", "beta_ci_low": "β 95 % CI LL", "beta_ci_high": "β 95 % CI UL", "t": "t",
                "p": "p", "vif": "VIF"}


def models_of(settings: dict) -> list[ModelSpec]:
    """The regression models an analysis ran (its ``settings["models"]``, covariates expanded)."""
    return [ModelSpec(str(m["name"]), str(m["dv"]), tuple(tuple(b) for b in m["steps"]), str(m.get("label", "")))
            for m in settings.get("models", [])]


def write_survey_statistics(res, out: str | Path, covariates: pd.DataFrame | None = None) -> list[Path]:
    """Write the module docstring's tables into `out` and the path diagram into `out`/figures for the
    :class:`analysis.survey.acceptance.SurveyAnalysis` `res`; `covariates`: the covariate columns its models use
    (indexed by participant; :func:`analysis.survey.acceptance.covariate_frame`). Returns the paths written."""
    out = Path(out)
    paths = []
    fit = res.fit
    final = fit[fit["stage"] == "final"]
    # the fit of an improper solution is read with its admissibility problems beside it
    improper = [w.split(": ", 1)[1] for w in res.warnings if w.startswith("CFA final: ")]
    notes = ([fit_sentence(final.iloc[0])] if len(final) else []) + (
        [f"Problems of the final solution: {'; '.join(improper)}."] if improper else []) + [
        "RMSEA interval by lavaan's method (noncentral χ², N as in χ² = N F_ML). Cut-offs of Hu and Bentler (1999): "
        "CFI ≥ .95, TLI ≥ .95, RMSEA ≤ .06, SRMR ≤ .08."]
    paths += write_table(fit_indices_table(fit), out, "fit_indices",
                         "Global fit of the measurement model (maximum likelihood CFA)", notes)
    models = models_of(res.settings)
    if not models:
        return paths
    data = res.composites if covariates is None or not len(covariates.columns) else \
        res.composites.join(covariates)
    steps, coefs = regression_diagnostics(data, models)
    lines = [f"Model {r.model}, step {r.step}: {r.influential}" for r in steps.itertuples() if r.influential]
    cut = ", ".join(sorted({f"{c:.3f}".lstrip("0") for c in steps["cooks_cut"]}))
    notes = ["f² = ΔR² / (1 − R²) of the step (Cohen's local f²); its 95 % CI inverts the noncentral F of the step's "
             "F change (λ = f² (df1 + df2 + 1)). Shapiro–Wilk on the residuals; Breusch–Pagan studentized (Koenker), "
             f"χ² on the step's predictors. Influential: Cook's D > {INFLUENCE:g}/n (= {cut})."
             ] + ([f"Cases with D > {INFLUENCE:g}/n: " + "; ".join(lines) + "."] if lines else [])
    paths += write_table(steps[list(STEP_HEADERS)].rename(columns=STEP_HEADERS), out, "regression_diagnostics",
                         "Assumption checks of the hierarchical regressions", notes)
    paths += write_table(coefs[list(COEF_HEADERS)].rename(columns=COEF_HEADERS), out,
                         "regression_diagnostics_coefficients",
                         "Coefficients of the hierarchical regressions with the 95 % CI of β and the VIF",
                         ["β = B sd(x) / sd(y); its 95 % CI is the t-interval of B scaled alike. VIF = 1 / (1 − R²) "
                          "of a predictor on the step's other predictors (1 with one predictor)."])
    edges = path_edges(res.regressions, res.hypotheses, models)
    if len(edges):
        paths += plot_path_diagram(edges, r2_texts(res.regressions, models), out / "figures")
    return paths

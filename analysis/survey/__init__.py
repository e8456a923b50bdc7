"""Survey statistics: scoring, descriptives, CFA, reliability, validity, regressions and hypotheses (the paper's
Section 5.2 for any study's model file), the extended statistics (ordinal CFA, omega, HTMT2, SEM, invariance, method
bias, SPSS-style extractions, bootstrap) and the power of the next study (docs/acceptance_statistics.md,
docs/power.md)."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "acceptance": ("SurveyAnalysis", "analyze_survey", "analyze_store", "survey_plan", "responses_from_store",
                   "attributes_from_store", "covariate_frame", "covariates_of"),
    "extended": ("ExtendedAnalysis", "analyze_extended"),
    "scoring": ("score_responses", "composites", "resolve_instrument", "check_not_constant"),
    "scores": ("compute_scores", "instrument_scores", "score_occasions", "scored_items"),
    "descriptives": ("item_descriptives",),
    "cfa": ("fit_cfa", "fit_indices", "srmr", "heywood_cases", "flag_items", "model_description"),
    "reliability": ("cronbach_alpha", "alpha_from_cov", "composite_reliability", "average_variance_extracted",
                    "omega_semtools", "reliability_table"),
    "validity": ("composite_correlations", "fornell_larcker", "pearson_p", "stars"),
    "regression": ("ModelSpec", "ols", "f_change", "hierarchical_regression", "run_models", "bootstrap_coefs"),
    "hypotheses": ("judge_hypotheses", "load_hypotheses", "supported"),
    "ordinal": ("polychoric", "fit_ordinal_cfa", "ordinal_omega"),
    "omega": ("omega_stack", "one_factor_loadings"),
    "htmt": ("htmt2", "reliability_bootstrap"),
    "sem": ("fit_sem", "indirect_effects", "structural_paths"),
    "invariance": ("InvarianceResult",),
    "method_bias": ("vif", "regression_vif", "full_collinearity_vif", "harman"),
    "extraction": ("construct_loadings",),
    "bootstrap": ("BootResult", "interval"),
    "sample_size": ("study_plan", "mc_power", "required_n", "f2_power", "rmsea_power", "rmsea_n"),
    "tables": ("render_table", "render_all"),
    "within": ("WithinComparison", "compare_within"),
})

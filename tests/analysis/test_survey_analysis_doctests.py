"""The examples in the docstrings of the acceptance statistics modules run and print the numbers they show.

`doctest` on a list of modules rather than `--doctest-modules` over the tree (which would import every module,
CLI and benchmark included). The option flags are the ones `[tool.pytest.ini_options] doctest_optionflags`
declares, so `pytest --doctest-modules analysis/survey/reliability.py` checks the same thing.
"""
from __future__ import annotations

import doctest
import importlib
import io

import pytest

MODULES = ["analysis.survey.reliability", "analysis.survey.validity", "analysis.survey.regression", "analysis.survey.cfa",
           "analysis.survey.hypotheses", "analysis.survey.scoring", "analysis.survey.descriptives", "analysis.render",
           "analysis.survey.acceptance", "analysis.survey.testing", "analysis.survey.fit_report",
           "analysis.survey.diagnostics", "analysis.survey.paired", "analysis.drives.paired",
           "analysis.survey.path_diagram", "study.survey.scores"]


def _flags(config) -> int:
    try:
        names = config.getini("doctest_optionflags")
    except ValueError:  # the doctest plugin is disabled (-p no:doctest)
        names = ["NORMALIZE_WHITESPACE", "ELLIPSIS"]
    flags = 0
    for name in names:
        flags |= doctest.OPTIONFLAGS_BY_NAME[name]
    return flags


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, pytestconfig):
    module = importlib.import_module(name)
    tests = [t for t in doctest.DocTestFinder().find(module) if t.examples]
    assert tests, f"{name} has no docstring examples"
    out = io.StringIO()
    runner = doctest.DocTestRunner(optionflags=_flags(pytestconfig))
    for t in tests:
        runner.run(t, out=out.write)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, out.getvalue()


def test_the_public_statistics_functions_have_examples():
    """Each public statistics function named in the docs carries a runnable example."""
    wanted = {"analysis.survey.reliability": ["cronbach_alpha", "composite_reliability", "average_variance_extracted",
                                       "omega_semtools"],
              "analysis.survey.validity": ["stars", "pearson_p", "composite_correlations", "fornell_larcker", "htmt"],
              "analysis.survey.regression": ["ols", "f_change", "bootstrap_coefs", "bootstrap_ci",
                                      "hierarchical_regression"],
              "analysis.survey.cfa": ["fit_indices", "srmr", "heywood_cases", "model_description"],
              "analysis.survey.hypotheses": ["judge_hypotheses", "load_hypotheses", "supported"],
              "analysis.survey.scoring": ["composites", "score_responses", "check_not_constant", "resolve_instrument"],
              "analysis.survey.descriptives": ["item_descriptives"],
              "analysis.survey.acceptance": ["SurveyAnalysis", "survey_plan", "covariate_frame", "table_titles"],
              "analysis.survey.testing": ["simulate_study_responses", "simulate_study_participants", "participant_ids"]}
    parser = doctest.DocTestParser()
    for mod, names in wanted.items():
        module = importlib.import_module(mod)
        for n in names:
            doc = getattr(module, n).__doc__ or ""
            assert parser.get_examples(doc), f"{mod}.{n} has no example"
            assert "Examples\n" in doc, f"{mod}.{n}: no numpydoc Examples section"

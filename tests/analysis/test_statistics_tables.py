"""The survey part's reviewer tables and the path diagram (analysis.survey.statistics_tables) on the lane-keeping
example data: what is written, headers as words, notes that agree with the tables, the diagram's paths."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from analysis.survey.acceptance import analyze_survey, covariate_frame, covariates_of
from analysis.survey.path_diagram import path_edges
from analysis.survey.statistics_tables import models_of, write_survey_statistics
from study.folder.definition import load

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "lane_keeping"
SYMBOLS = {"M_diff", "d_z"}     # the only headers with an underscore: the symbols M_diff and d_z


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    study = load(REPO / "studies" / "lane_keeping")
    answers = pd.read_csv(DATA / "survey.csv", dtype={"participant_id": str}).drop(columns="AGE")
    people = pd.read_csv(DATA / "participants.csv", dtype={"participant_id": str})
    res = analyze_survey(answers, study, attributes=people, n_boot=0)
    cov = covariate_frame(people, study, covariates_of(study), res.composites.index)[0]
    out = tmp_path_factory.mktemp("survey")
    return res, out, write_survey_statistics(res, out, cov)


def test_tables_and_figure_are_written_with_words_as_headers(written):
    res, out, paths = written
    names = {p.name for p in paths}
    for stem in ("fit_indices", "regression_diagnostics", "regression_diagnostics_coefficients"):
        assert {f"{stem}.csv", f"{stem}.md", f"{stem}.tex"} <= names
        header = pd.read_csv(out / f"{stem}.csv").columns
        assert not [h for h in header if "_" in h and h not in SYMBOLS], header
    assert (out / "figures" / "path_diagram.png").stat().st_size > 5000
    assert (out / "figures" / "path_diagram.pdf").exists()


def test_fit_table_and_sentence(written):
    res, out, _ = written
    fit = pd.read_csv(out / "fit_indices.csv")
    assert list(fit["Stage"]) == ["Initial (every scaled item)", "Final (retained items)"]
    row = fit.iloc[1]
    assert row["RMSEA 90 % CI LL"] <= row["RMSEA"] <= row["RMSEA 90 % CI UL"]
    md = (out / "fit_indices.md").read_text()
    assert "Hu and Bentler's (1999)" in md and f"χ²({int(row['df'])})" in md


def test_diagnostics_notes_name_the_influential_cases(written):
    res, out, _ = written
    steps = pd.read_csv(out / "regression_diagnostics.csv")
    md = (out / "regression_diagnostics.md").read_text()
    assert len(steps) == sum(len(m.steps) for m in models_of(res.settings))
    assert "Cook's D > 4/n (= .167)" in md                                # n = 24
    assert steps["Cases D > 4/n"].sum() > 0 and "LK-21" in md
    coefs = pd.read_csv(out / "regression_diagnostics_coefficients.csv")
    assert (coefs["β 95 % CI LL"] < coefs["β"]).all() and (coefs["β"] < coefs["β 95 % CI UL"]).all()
    assert (coefs["VIF"] >= 1).all()


def test_path_diagram_draws_each_predictor_of_each_models_last_step(written):
    res, _, _ = written
    edges = path_edges(res.regressions, res.hypotheses, models_of(res.settings))
    assert sorted(zip(edges["source"], edges["target"])) == [("EE", "BI"), ("PE", "BI"), ("SI", "BI"), ("age", "BI")]
    assert set(edges["hypothesis"]) == {"H1", "H2", "H3", ""}
    h = res.hypotheses.set_index("hypothesis")
    for e in edges[edges["hypothesis"] != ""].itertuples():
        assert e.beta == pytest.approx(h.loc[e.hypothesis, "beta"])


def test_mixed_anova_refuses_an_error_term_without_variance():
    from analysis.survey.paired import mixed_anova

    # the difference is 2 in group x and 3 in group y for everybody: no within-group error variance, F infinite
    d = pd.DataFrame({"participant": list("aabbccdd"), "group": list("xxxxyyyy"), "condition": ["c", "t"] * 4,
                      "value": [5, 3, 6, 4, 7, 4, 5, 2.0]})
    with pytest.raises(ValueError, match="without variance"):
        mixed_anova(d)

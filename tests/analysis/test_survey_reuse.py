"""One fitted model per run: `analyze_survey(reuse=)` and `analyze_extended(survey=)` take the CFA of an earlier
analysis of the same answers and write the same files as a fresh fit; other answers or models are refused."""
from __future__ import annotations

from pathlib import Path

import pytest

from analysis.paper.published import PAPER_STUDY_DIR, paper_study
from analysis.paper.synthetic import simulate_paper_responses
from analysis.survey import cfa as _cfa
from analysis.survey.acceptance import SurveyAnalysis, analyze_survey
from analysis.survey.extended import analyze_extended

STUDY = paper_study()


def _files(d: Path) -> dict[str, bytes]:
    # timings.json holds wall-clock seconds, the one file that differs between reruns
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.name != "timings.json"}


@pytest.fixture(scope="module")
def answers():
    return simulate_paper_responses(40, seed=11)


@pytest.fixture(scope="module")
def base(answers):
    return analyze_survey(answers, STUDY, n_boot=50, seed=3)


def _count_fits(monkeypatch) -> list[str]:
    calls: list[str] = []
    real = _cfa.fit_cfa

    def counting(*a, **kw):
        calls.append(kw.get("label", ""))
        return real(*a, **kw)

    monkeypatch.setattr(_cfa, "fit_cfa", counting)
    return calls


def test_pca_loadings_reuse_the_cfa_and_write_the_same_files(answers, base, tmp_path, monkeypatch):
    fresh = analyze_survey(answers, STUDY, n_boot=0, loadings="pca")
    calls = _count_fits(monkeypatch)
    reused = analyze_survey(answers, STUDY, n_boot=0, loadings="pca", reuse=base)
    assert calls == []
    fresh.write(tmp_path / "fresh")
    reused.write(tmp_path / "reused")
    assert _files(tmp_path / "fresh") == _files(tmp_path / "reused")
    # the base's CFA loadings are untouched by the extraction
    assert base.loadings.equals(analyze_survey(answers, STUDY, n_boot=50, seed=3).loadings)


def test_extended_builds_on_the_survey_analysis(answers, base, tmp_path, monkeypatch):
    fresh = analyze_extended(answers, STUDY, n_boot=30, seed=2, workers=1)
    calls = _count_fits(monkeypatch)
    reused = analyze_extended(answers, STUDY, n_boot=30, seed=2, workers=1, survey=base)
    assert calls == []   # the final ML CFA is the survey's
    fresh.write(tmp_path / "fresh")
    reused.write(tmp_path / "reused")
    assert _files(tmp_path / "fresh") == _files(tmp_path / "reused")
    assert "ml_cfa" in reused.timings


def test_a_survey_analysis_of_other_answers_is_refused(answers, base, tmp_path):
    other = simulate_paper_responses(40, seed=12)
    with pytest.raises(ValueError, match="fitted to other answers"):
        analyze_extended(other, STUDY, n_boot=0, workers=1, survey=base)
    with pytest.raises(ValueError, match="fitted to other answers"):
        analyze_survey(answers, STUDY, n_boot=0, listwise=False, reuse=base)
    base.write(tmp_path / "written")
    with pytest.raises(ValueError, match="no fitted models"):
        analyze_extended(answers, STUDY, n_boot=0, workers=1, survey=SurveyAnalysis.read(tmp_path / "written"))
    with pytest.raises(ValueError, match="no fitted models"):
        analyze_survey(answers, STUDY, n_boot=0, reuse=SurveyAnalysis.read(tmp_path / "written"))


def test_another_measurement_model_is_refused(answers, base):
    text = (PAPER_STUDY_DIR / "model.lav").read_text(encoding="utf-8")
    other = text.replace("PU =~ PU1 + PU2 + PU3 + PU4", "PU =~ PU1 + PU2 + PU3")
    assert other != text
    with pytest.raises(ValueError, match="another measurement model"):
        analyze_survey(answers, STUDY, n_boot=0, model=other, reuse=base)

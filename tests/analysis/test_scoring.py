"""Scoring: reverse scoring from the instrument, listwise deletion, composites, input validation."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.survey.descriptives import item_descriptives
from analysis.paper.published import paper_study
from analysis.paper.synthetic import simulate_paper_responses
from analysis.survey.scoring import check_not_constant, composites, score_responses
from analysis.survey.testing import simulate_study_responses
from pedas.paths import REPO_ROOT
from study.folder.definition import load

INST = paper_study().instrument()


def score(raw, **kw):
    return score_responses(raw, INST, **kw)


@pytest.fixture
def raw():
    return simulate_paper_responses(12, seed=4)


def test_peou3_is_reversed_and_nothing_else(raw):
    s = score(raw)
    assert s.reverse_items == ["PEoU3"]
    assert np.array_equal(s.scored["PEoU3"].to_numpy(), 6 - raw["PEoU3"].to_numpy())
    others = [c for c in s.scored.columns if c != "PEoU3"]
    assert np.array_equal(s.scored[others].to_numpy(), raw[others].to_numpy(float))


def test_reverse_scoring_is_an_involution(raw):
    items = raw[INST.scaled_items]
    pd.testing.assert_frame_equal(INST.reverse(INST.reverse(items)), items)


def test_seven_point_items_of_another_study():
    """lane_keeping: 7-point items, EE3 reversed x -> 8 - x, answers 1..7 accepted and 8 refused."""
    study = load(REPO_ROOT / "studies" / "lane_keeping")
    raw = simulate_study_responses(study, 24, seed=2)
    s = score_responses(raw, study.instrument())
    assert s.reverse_items == ["EE3"] and list(s.constructs) == ["PE", "EE", "SI", "BI"]
    assert np.array_equal(s.scored["EE3"].to_numpy(), 8 - raw["EE3"].to_numpy())
    assert raw["PE1"].max() > 5  # the 7-point scale is used, not the paper's 5
    with pytest.raises(ValueError, match="outside 1..7"):
        score_responses(raw.assign(PE1=8), study.instrument())


def test_listwise_drops_incomplete_rows(raw):
    raw = raw.copy()
    raw.loc[2, "SN1"] = np.nan
    s = score(raw)
    assert s.n == 11 and s.dropped == [raw.loc[2, "participant_id"]] and s.n_input == 12
    s2 = score(raw, listwise=False)
    assert s2.n == 12


def test_composites_are_means_of_retained_items(raw):
    s = score(raw)
    comp = composites(s.scored, {"PEoU": ["PEoU1", "PEoU2", "PEoU4"]})
    assert np.allclose(comp["PEoU"], s.scored[["PEoU1", "PEoU2", "PEoU4"]].mean(axis=1))


def test_descriptives_use_n_minus_1(raw):
    s = score(raw)
    d = item_descriptives(s.scored, s.raw, s.constructs, s.reverse_items).set_index("item")
    assert d.loc["PU1", "sd"] == pytest.approx(np.std(raw["PU1"], ddof=1))
    assert d.loc["PU1", "n"] == 12 and bool(d.loc["PEoU3", "reversed"])
    assert d.loc["PEoU3", "mean"] == pytest.approx(6 - d.loc["PEoU3", "mean_raw"])


@pytest.mark.parametrize("mutate,match", [
    (lambda d: d.drop(columns=["BI2"]), "lack item column"),
    (lambda d: d.assign(PU1=7), "outside 1..5"),
    (lambda d: d.assign(PU1=2.5), "outside 1..5"),
    (lambda d: d.assign(PU1="x"), "numbers on the item's scale"),
    (lambda d: d.assign(participant_id="P001"), "duplicate participant_id"),
])
def test_bad_input(raw, mutate, match):
    with pytest.raises(ValueError, match=match):
        score(mutate(raw))


def test_constant_column_is_named():
    with pytest.raises(ValueError, match="item b is constant"):
        check_not_constant(pd.DataFrame({"a": [1, 2], "b": [3, 3]}))


def test_simulated_answers_are_the_same_under_every_blas_kernel():
    """The default generator draws its factors without BLAS (analysis.survey.mvn): the same answers whatever kernel
    OpenBLAS picks."""
    from tests.conftest import python_under_kernel

    code = ("import hashlib, sys; from analysis.paper.synthetic import simulate_paper_responses; "
            "sys.stdout.write(hashlib.sha256(simulate_paper_responses(60, 3).to_csv().encode()).hexdigest())")
    outs = {k: python_under_kernel(k, code) for k in ("Prescott", "Sandybridge", "Haswell", "SkylakeX")}
    assert len(set(outs.values())) == 1, outs

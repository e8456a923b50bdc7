"""The shipped standard instruments (studies/instruments/): each codebook passes the check, cites its publication,
and scores a worked example as its publication's rule gives it (SUS: Brooke's own example; the others hand-worked
from the published rule quoted in the instrument's TOML file)."""
from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

from analysis.survey.scores import compute_scores
from study.folder.instrument import Instrument
from study.folder.instrument_library import LIBRARY, shipped
from study.common.problems import Problems
from study.folder.scores import parse_scores


def library_study(name: str):
    """A minimal study definition that includes the shipped instrument `name` only (its scores parsed from it)."""
    from study.folder.definition import from_files
    from study.folder.instrument_library import included_files

    toml = (f'[study]\nid = "lib"\ntitle = "t"\n[participants]\nid_pattern = "^P[0-9]+$"\nid_example = "P1"\n'
            f'[[conditions]]\nname = "a"\n[files]\nprotocols = ["p.json"]\n[instrument]\ninclude = ["{name}"]\n')
    files = {"study.toml": toml, "p.json": '{"name": "p", "phases": [{"name": "q", "planned_minutes": 5}]}'}
    files.update(included_files(tomllib.loads(toml)))
    return from_files(files)


def scores_of(name: str, answers: dict[str, list]) -> dict[str, float]:
    """{score: value} of one participant's answers (item -> value) to the shipped instrument `name`."""
    study = library_study(name)
    ins = next(iter(study.instruments.values()))
    problems = Problems()
    specs = parse_scores(study, problems)
    assert not problems
    wide = pd.DataFrame([{"participant_id": "P1", **answers}])
    out = compute_scores(wide, specs, ins)
    return dict(zip(out["score"], out["value"]))


def test_every_instrument_is_shipped_with_its_source_and_a_clean_codebook():
    assert shipped() == ["jian_trust", "nasa_tlx_raw", "nasa_tlx_weighted", "ssq", "sus", "van_der_laan"]
    for name in shipped():
        meta = tomllib.loads((LIBRARY / f"{name}.toml").read_text())["instrument"]
        assert meta["name"] == name and meta["version"] == 1
        assert any(str(y) in meta["source"] for y in (1988, 1993, 1996, 1997, 2000)), name
        problems = Problems()
        ins = Instrument.from_csv(name, (LIBRARY / f"{name}.csv").read_text(), f"{name}.csv", problems=problems)
        assert not problems, problems
        assert ins.items["source"].str.len().min() > 0


def test_sus_brooke_worked_example_is_55():
    # Brooke (1996), reproduced in Tullis & Albert, Fig. 6.8: contributions 4,1,1,4,1,2,1,1,4,3 (total 22) -> 55.
    # Ticks: odd items contribute x - 1, even items 5 - x, so the ticks are:
    ticks = [5, 4, 2, 1, 2, 3, 2, 4, 5, 2]
    contributions = [x - 1 if k % 2 == 0 else 5 - x for k, x in enumerate(ticks)]
    assert contributions == [4, 1, 1, 4, 1, 2, 1, 1, 4, 3] and sum(contributions) == 22
    assert scores_of("sus", {f"SUS{k + 1}": x for k, x in enumerate(ticks)}) == {"sus": 55.0}
    best = {f"SUS{k + 1}": 5 if k % 2 == 0 else 1 for k in range(10)}
    worst = {f"SUS{k + 1}": 1 if k % 2 == 0 else 5 for k in range(10)}
    assert scores_of("sus", best) == {"sus": 100.0} and scores_of("sus", worst) == {"sus": 0.0}


TLX = ["TLX_MD", "TLX_PD", "TLX_TD", "TLX_OP", "TLX_EF", "TLX_FR"]


def test_nasa_tlx_raw_is_the_mean_of_the_six_ratings():
    ratings = dict(zip(TLX, [70, 20, 50, 30, 60, 40]))
    assert scores_of("nasa_tlx_raw", ratings) == {"tlx_raw": 45.0}        # 270 / 6


def test_nasa_tlx_weighted_is_sum_of_tally_times_rating_over_15():
    ratings = dict(zip(TLX, [70, 20, 50, 30, 60, 40]))
    tallies = dict(zip([f"TLX_W_{k[4:]}" for k in TLX], [5, 0, 3, 2, 4, 1]))   # 15 comparisons
    # 5*70 + 0*20 + 3*50 + 2*30 + 4*60 + 1*40 = 840; 840 / 15 = 56
    assert scores_of("nasa_tlx_weighted", {**ratings, **tallies}) == {"tlx_weighted": 56.0}
    with pytest.raises(ValueError, match=r"weights of P1 add up to 14, not 15"):
        scores_of("nasa_tlx_weighted", {**ratings, **tallies, "TLX_W_MD": 4})


def test_van_der_laan_usefulness_and_satisfying():
    # boxes from left (-2) to right (+2); items 3, 6, 8 mirrored (Bad-Good, Irritating-Likeable, Undesirable-Desirable)
    boxes = [-1, -2, 1, 0, -2, 2, -1, 1, 0]
    # usefulness: items 1,3,5,7,9 -> +1, +1, +2, +1, 0 -> 5/5; satisfying: items 2,4,6,8 -> +2, 0, +2, +1 -> 5/4
    got = scores_of("van_der_laan", {f"VDL{k + 1}": x for k, x in enumerate(boxes)})
    assert got == {"vdl_usefulness": 1.0, "vdl_satisfying": 1.25}
    best = {f"VDL{k + 1}": 2 if k + 1 in (3, 6, 8) else -2 for k in range(9)}
    assert scores_of("van_der_laan", best) == {"vdl_usefulness": 2.0, "vdl_satisfying": 2.0}


def test_jian_trust_reverses_the_five_distrust_items():
    ticks = [2, 1, 3, 2, 1, 6, 5, 6, 5, 6, 6, 4]
    # reversed 8 - x: 6, 7, 5, 6, 7 (31); items 6-12: 38; (31 + 38) / 12 = 5.75; distrust (2+1+3+2+1) / 5 = 1.8
    got = scores_of("jian_trust", {f"JT{k + 1}": x for k, x in enumerate(ticks)})
    assert got == pytest.approx({"trust": 5.75, "distrust": 1.8})


SSQ_ALL = {f"SSQ{k}": 3 for k in range(1, 17)}


def test_ssq_weighted_subscales_and_total():
    # every symptom severe: 7 symptoms x 3 per subscale -> 21 x weight; total (21 + 21 + 21) x 3.74
    assert scores_of("ssq", SSQ_ALL) == pytest.approx({"ssq_nausea": 200.34, "ssq_oculomotor": 159.18,
                                                       "ssq_disorientation": 292.32, "ssq_total": 235.62})
    one = dict.fromkeys(SSQ_ALL, 0) | {"SSQ1": 1, "SSQ2": 2, "SSQ4": 1, "SSQ5": 1, "SSQ8": 1, "SSQ13": 1, "SSQ15": 1}
    # N: discomfort 1 + nausea 1 + stomach 1 = 3; O: discomfort 1 + fatigue 2 + eyestrain 1 + focusing 1 = 5;
    # D: focusing 1 + nausea 1 + dizzy closed 1 = 3; total (3 + 5 + 3) x 3.74
    assert scores_of("ssq", one) == pytest.approx({"ssq_nausea": 3 * 9.54, "ssq_oculomotor": 5 * 7.58,
                                                   "ssq_disorientation": 3 * 13.92, "ssq_total": 11 * 3.74})


def test_a_missing_answer_leaves_the_score_missing_and_tidy_rows_keep_their_order():
    study = library_study("jian_trust")
    ins = next(iter(study.instruments.values()))
    specs = parse_scores(study, Problems())
    rows = [{"participant_id": "P1", **{f"JT{k}": 4 for k in range(1, 13)}},
            {"participant_id": "P2", **{f"JT{k}": 4 for k in range(1, 13)}, "JT7": np.nan},
            {"participant_id": "P3", **{f"JT{k}": 7 for k in range(1, 13)}, "JT1": np.nan}]
    out = compute_scores(pd.DataFrame(rows), specs, ins)
    assert out.columns.tolist() == ["participant_id", "score", "value"]
    assert out[["participant_id", "score"]].values.tolist() == [["P1", "trust"], ["P1", "distrust"],
                                                                ["P2", "trust"], ["P2", "distrust"],
                                                                ["P3", "trust"], ["P3", "distrust"]]
    np.testing.assert_array_equal(out["value"], [4.0, 4.0, np.nan, 4.0, np.nan, np.nan])   # no prorating

"""Scores out: `survey scores` writes every declared score of the takeover study (studies/takeover: SUS, raw TLX,
trust) per participant and occasion with the rated condition, as CSV and SPSS .sav with labels; the values are the
ones `analyze within` compares and the R reference's; the exports, de-identified too, carry the same table."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pyreadstat

from study.store.store import Store
from tests.conftest import REPO

DATA = REPO / "tests" / "data" / "takeover"
SCORES = ["sus", "tlx_raw", "trust"]


def test_survey_scores_writes_every_score_per_occasion_as_analyze_within_takes_them(cli, tmp_db, tmp_path):
    from analysis.within.data import score_values
    from study.folder.within_spec import within_spec
    from study.store.studies import definition

    items = pd.read_csv(DATA / "items.csv").rename(columns={"participant": "participant_id"})
    roster = tmp_path / "roster.csv"
    items.drop_duplicates("participant_id")[["participant_id", "order"]].assign(age=30).to_csv(roster, index=False)
    items.to_csv(tmp_path / "items.csv", index=False)
    assert cli("init", "--study", REPO / "studies" / "takeover").code == 0
    assert cli("participant", "import", roster).code == 0
    assert cli("survey", "import", tmp_path / "items.csv", "--ignore-columns", "order,period").code == 0
    r = cli("survey", "scores", "--out", tmp_path / "scores", "--format", "csv,sav")
    assert r.code == 0 and r.out.splitlines() == [f"wrote 56 rows of scores to {tmp_path}/scores/scores.csv",
                                                  f"wrote 56 rows of scores to {tmp_path}/scores/scores.sav"]
    scores = pd.read_csv(tmp_path / "scores" / "scores.csv")
    assert list(scores.columns) == ["participant_id", "occasion", "condition", *SCORES]
    assert (scores["occasion"] == "survey_after_" + scores["condition"]).all()
    # the values analyze within takes (its scores, before the KPIs join them), exactly
    with Store.open(tmp_db, read_only=True) as st:
        study = definition(st)
        data, _ = score_values(st, study, within_spec(study))
    inputs = data.pivot(index=["participant", "condition"], columns="variable",
                                                   values="value")[SCORES].sort_index()
    ours = scores.rename(columns={"participant_id": "participant"}).set_index(["participant", "condition"])
    ours = ours[SCORES].sort_index()
    assert len(inputs) == len(ours) == 56 and ours.index.equals(inputs.index)
    assert float((ours - inputs).abs().max().max()) == 0.0
    # the R reference's scores (tests/data/takeover/scores.csv)
    ref = pd.read_csv(DATA / "scores.csv").set_index(["participant", "condition"]).loc[ours.index]
    assert np.allclose(ours.to_numpy(), ref[["sus", "tlx", "trust"]].to_numpy(), rtol=0, atol=1e-12)
    sav, meta = pyreadstat.read_sav(tmp_path / "scores" / "scores.sav")
    assert len(sav) == 56 and meta.column_names_to_labels["tlx_raw"] == "Raw NASA-TLX (0-100)"
    # the exports carry the scores table, the de-identified one too
    for extra in ((), ("--deidentify",)):
        out = tmp_path / f"export{len(extra)}"
        assert cli("export", "csv", out, *extra).code == 0
        assert pd.read_csv(out / "scores.csv").equals(scores)


def test_a_study_without_scores_is_told_so(cli, paper_db, tmp_path):
    r = cli("survey", "scores", "--out", tmp_path / "s", db=paper_db)
    assert r.code == 2 and r.err.strip() == ('pedas-study: error: the study declares no score ([[scores]] in '
                                             'study.toml, docs/survey.md "Scores")')
    assert not (tmp_path / "s").exists()

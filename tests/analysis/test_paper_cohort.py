"""The reference cohort: the paper's counts, P006, determinism, and loading into a real store."""
from __future__ import annotations

import pandas as pd
import pytest

from analysis.paper import reference_cohort as C
from analysis.paper import published as P
from pedas.paths import REFERENCE_DIR


@pytest.fixture(scope="module")
def cohort():
    return C.make_cohort(seed=C.DEFAULT_SEED)


def test_counts_match_the_paper(cohort):
    p = cohort.participants
    v = lambda q: int(P.value(q, "all", "count", "cohort"))  # noqa: E731
    assert len(p) == v("enrolled") and p["participant_id"].tolist() == [f"P{i:03d}" for i in range(1, 45)]
    assert (p["gender"] == "male").sum() == v("male") and (p["gender"] == "female").sum() == v("female")
    ex = cohort.events[cohort.events["kind"] == "exclusion"]
    assert (ex["reason"] == "motion_sickness").sum() == v("motion_sickness")
    assert set(ex.loc[ex["reason"] == "motion_sickness", "scope"]) == {"all"}
    assert (ex["reason"] == "technical_issue").sum() == v("technical_issues")
    assert set(ex.loc[ex["reason"] == "technical_issue", "scope"]) == {"objective"}
    assert len(cohort.objective_ids()) == v("objective_n")
    # the tables imply 40 survey respondents (audit), one below the text's 41
    assert len(cohort.survey_ids()) == v("survey_n") - 1 == 40


def test_styles_and_eco_familiarity(cohort):
    p = cohort.participants.set_index("participant_id")
    obj = p.loc[cohort.objective_ids(), "style"].value_counts().to_dict()
    assert obj == {"cautious": 7, "normal": 20, "sporty": 7}
    eco = p.loc[cohort.survey_ids(), "eco_familiarity"].value_counts().sort_index()
    shares = P.load_published()
    printed = shares[shares["quantity"] == "eco_familiarity_share"]["value"].values
    assert (eco.values / 40 * 100).tolist() == pytest.approx(list(printed))
    assert ((p["license_years"] <= p["age"] - 16) & (p["license_years"] >= 1)).all()


def test_p006_is_an_included_normal_driver(cohort):
    assert "P006" in cohort.objective_ids() and "P006" in cohort.survey_ids()
    assert cohort.participants.set_index("participant_id").loc["P006", "style"] == "normal"


def test_events_follow_the_protocol(cohort):
    ev = cohort.events
    ph = ev[ev["kind"] == "phase"]
    for pid, g in ph.groupby("participant_id"):
        order = [C.PHASES.index(x) for x in g["phase"]]
        assert order == list(range(len(order)))               # in protocol order, none skipped
        assert (pd.to_datetime(g["ended_at"]) >= pd.to_datetime(g["started_at"])).all()
        if g["outcome"].iloc[-1] == "aborted" and g["phase"].iloc[-1] == "baseline_drive":
            assert len(g) == 2                                  # motion sickness ends the visit
        else:
            assert len(g) == len(C.PHASES)


def test_same_seed_same_files_other_seed_other_cohort(tmp_path):
    a = C.make_cohort(7).write(tmp_path / "a")
    b = C.make_cohort(7).write(tmp_path / "b")
    assert [x.read_bytes() for x in a] == [x.read_bytes() for x in b]
    c = C.make_cohort(8)
    assert not c.participants.equals(C.make_cohort(7).participants)


def test_shipped_cohort_is_the_default_seed(tmp_path):
    paths = C.make_cohort(C.DEFAULT_SEED).write(tmp_path)
    for p in paths:
        assert p.read_bytes() == (REFERENCE_DIR / p.name).read_bytes(), p.name


def test_loads_into_a_real_store(paper_db, cohort):
    from study.store.store import Store

    with Store.open(paper_db, actor="test") as st:
        C.load_into_store(st, cohort)
        assert st.df("SELECT count(*) AS n FROM participants")["n"].iloc[0] == 44
        attrs = st.df("SELECT attribute, count(*) AS n FROM participant_attributes GROUP BY ALL ORDER BY attribute")
        assert dict(zip(attrs["attribute"], attrs["n"])) == {a: 44 for a in ("age", "eco_familiarity", "gender",
                                                                              "license_years", "style")}
        p6 = st.df("SELECT attribute, value FROM participant_attributes WHERE participant_id = 'P006'")
        assert dict(zip(p6["attribute"], p6["value"]))["style"] == "normal"
        ex = st.df("SELECT scope, reason, count(*) AS n FROM exclusions GROUP BY ALL ORDER BY reason")
        assert dict(zip(ex["reason"], ex["n"])) == {"incomplete_survey": 1, "motion_sickness": 3, "technical_issue": 7}
        from study.people.exclusions import included_participants

        assert len(included_participants(st, "objective")) == 34
        assert len(included_participants(st, "subjective")) == 40


def test_cli_cohort(cli, tmp_path):
    res = cli("paper", "cohort", "--out", tmp_path / "c", "--seed", "3")
    assert res.code == 0, res.err
    assert (tmp_path / "c" / "participants.csv").exists() and (tmp_path / "c" / "events.csv").exists()


def test_a_store_of_another_study_is_refused(tmp_db, cohort):
    from pedas_study.cli import main
    from study.store.store import Store

    assert main([f"--db={tmp_db}", "init", "--study", "studies/lane_keeping"]) == 0
    with Store.open(tmp_db, actor="test") as st:
        with pytest.raises(ValueError, match="belongs to study pedas_paper"):
            C.load_into_store(st, cohort)
        assert st.one("SELECT count(*) FROM participants") == 0

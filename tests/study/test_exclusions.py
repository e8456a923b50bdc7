"""Exclusion scopes and the one function analyses use."""
import shutil
from pathlib import Path

import pandas as pd
from hypothesis import HealthCheck, given, settings, strategies as st_
import pytest

from study.common.errors import UserError
from study.people.exclusions import apply_exclusions, exclude, included_participants, revoke
from study.people.participants import add_participant
from study.store.store import Store
from tests.conftest import PAPER_STUDY, initialised_store


@pytest.fixture(scope="module")
def paper_store_file(tmp_path_factory) -> Path:
    """An empty store of the paper's study, copied by tests that need many fresh stores."""
    return initialised_store(tmp_path_factory.mktemp("paper") / "template.duckdb", PAPER_STUDY, tmp_path_factory)


@pytest.fixture
def st(paper_db):
    with Store.open(paper_db) as s:
        for i in range(1, 7):
            add_participant(s, f"P{i:03d}")
        yield s


def test_scopes(st):
    exclude(st, "P001", "all", "motion_sickness")
    exclude(st, "P002", "objective", "technical_issue", note="HUD froze")
    exclude(st, "P003", "subjective", "incomplete_survey")
    assert included_participants(st, "objective") == ["P003", "P004", "P005", "P006"]
    assert included_participants(st, "subjective") == ["P002", "P004", "P005", "P006"]
    assert included_participants(st, "all") == ["P004", "P005", "P006"]


def test_paper_counts(paper_db):
    """44 volunteers, 3 motion sickness (all), 7 technical issues (objective) -> N=41 subjective, N=34 objective."""
    with Store.open(paper_db) as st:
        with st.transaction():
            for i in range(1, 45):
                add_participant(st, f"P{i:03d}")
            for i in range(1, 4):
                exclude(st, f"P{i:03d}", "all", "motion_sickness")
            for i in range(4, 11):
                exclude(st, f"P{i:03d}", "objective", "technical_issue")
        n_sub = len(included_participants(st, "subjective"))
        n_obj = len(included_participants(st, "objective"))
    assert (n_sub, n_obj) == (41, 34)


def test_apply_to_frame(st):
    exclude(st, "P002", "objective", "technical_issue")
    df = pd.DataFrame({"participant_id": ["P001", "P002", "P003"], "kwh": [1.0, 2.0, 3.0]})
    assert apply_exclusions(st, df, "objective")["participant_id"].tolist() == ["P001", "P003"]
    assert len(apply_exclusions(st, df, "subjective")) == 3


def test_refusals(st):
    with pytest.raises(UserError, match="unknown participant"):
        exclude(st, "P099", "all", "other")
    with pytest.raises(UserError, match="scope must be one of"):
        exclude(st, "P001", "some", "other")
    with pytest.raises(UserError, match="reason must be one of"):
        exclude(st, "P001", "all", "bored")
    exclude(st, "P001", "all", "withdrawn")
    with pytest.raises(UserError, match="already excluded"):
        exclude(st, "P001", "all", "other")
    with pytest.raises(UserError, match="analysis scope"):
        included_participants(st, "everything")


def test_revoke_is_audited(st):
    exclude(st, "P001", "objective", "technical_issue")
    revoke(st, "P001", "objective")
    assert "P001" in included_participants(st, "objective")
    log = st.df("SELECT action FROM audit_log WHERE table_name = 'exclusions' ORDER BY audit_id")
    assert log["action"].tolist() == ["insert", "delete"]
    with pytest.raises(UserError, match="no exclusion"):
        revoke(st, "P001", "objective")


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st_.lists(st_.sets(st_.sampled_from(["all", "objective", "subjective"])), min_size=1, max_size=8))
def test_scope_laws(tmp_path_factory, paper_store_file, scopes_per_participant):
    """included(all) = included(objective) ∩ included(subjective); `all` excludes from both."""
    db = tmp_path_factory.mktemp("laws") / "s.duckdb"
    shutil.copy(paper_store_file, db)
    with Store.open(db) as st:
        with st.transaction():
            for i, scopes in enumerate(scopes_per_participant, start=1):
                add_participant(st, f"P{i:03d}")
                for scope in sorted(scopes):
                    exclude(st, f"P{i:03d}", scope, "other")
        obj, sub, both = (set(included_participants(st, s)) for s in ("objective", "subjective", "all"))
    assert both == obj & sub
    for i, scopes in enumerate(scopes_per_participant, start=1):
        pid = f"P{i:03d}"
        assert (pid in obj) == (not scopes & {"all", "objective"})
        assert (pid in sub) == (not scopes & {"all", "subjective"})


def test_any_study_ids(lk_db):
    """Exclusions know nothing of the paper's ids: the lane-keeping study's LK-01 is excluded like P001."""
    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": 30})
        add_participant(st, "LK-02", {"age": 40})
        exclude(st, "LK-02", "objective", "technical_issue")
        assert included_participants(st, "objective") == ["LK-01"]
        with pytest.raises(UserError, match="unknown participant P001"):
            exclude(st, "P001", "all", "other")

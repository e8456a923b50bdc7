"""Messages that say what is true: a time in the past with its year padded, an unknown participant named as such,
`--collapse-empty` where `analyze survey` takes it, and a huge input file refused before it is read (exit 2, one
line, nothing stored)."""
from __future__ import annotations

from pathlib import Path

import pytest

from study.common.input_size import MAX_INPUT_BYTES
from study.common.times import when

REPO = Path(__file__).resolve().parents[2]
PAPER = REPO / "studies" / "pedas_paper"
EMPTY_CATEGORY = REPO / "tests" / "data" / "admissibility" / "set_b_empty_category.csv"


def test_a_year_one_time_is_printed_with_four_digits(cli, paper_db):
    from datetime import datetime

    assert when(datetime(1, 2, 3, 4, 5, 6), seconds=True) == "0001-02-03 04:05:06"
    assert cli("participant", "add", "P001", db=paper_db).code == 0
    r = cli("session", "schedule", "P001", "--at", "0001-01-01T00:00", db=paper_db)
    assert r.code == 2 and r.err.strip() == "pedas-study: error: 0001-01-01 00:00 is in the past; book a future slot"


def test_resolving_for_an_unknown_participant_says_so(cli, paper_db):
    r = cli("survey", "resolve", "P999", "PU1", "3", db=paper_db)
    assert r.code == 2 and r.err.strip() == "pedas-study: error: unknown participant P999"


def test_collapse_empty_goes_with_extended_on_analyze_survey(cli, tmp_path):
    common = ("analyze", "survey", "--responses", EMPTY_CATEGORY, "--study", PAPER, "--bootstrap", "0")
    r = cli(*common, "--out", tmp_path / "a", "--collapse-empty", db=None)
    assert r.code == 2 and "--collapse-empty is for the ordinal CFA of --extended" in r.err
    r = cli(*common, "--out", tmp_path / "b", "--extended", db=None)
    assert r.code == 2 and "--collapse-empty of `analyze extended` or `analyze survey --extended`" in r.err
    r = cli(*common, "--out", tmp_path / "c", "--extended", "--collapse-empty", db=None)
    assert r.code == 0 and "ordinal CFA: item PU1: empty category 1 among the 32 complete rows collapsed" in r.out


@pytest.mark.parametrize("command", [("participant", "import"), ("survey", "import"), ("analyze", "survey")])
def test_a_huge_input_file_is_refused_before_it_is_read(cli, paper_db, tmp_path, command):
    huge = tmp_path / "huge.csv"
    with open(huge, "wb") as f:  # sparse: no disk used, and reading it would take the whole size in memory
        f.truncate(MAX_INPUT_BYTES + 1)
    counts = _counts(paper_db)
    args = ("--responses", huge, "--out", tmp_path / "out") if command == ("analyze", "survey") else (huge,)
    r = cli(*command, *args, db=paper_db)
    assert r.code == 2 and r.err.strip().splitlines() == [
        f"pedas-study: error: huge.csv is 67,108,865 bytes; a {'survey CSV' if command[0] == 'analyze' else 'CSV file'} "
        "may be at most 67,108,864 bytes (64 MiB: it is read whole)"]
    assert _counts(paper_db) == counts and not (tmp_path / "out").exists()


def _counts(db):
    from study.store.store import Store

    st = Store.open(db, actor="test")
    try:
        return st.counts()
    finally:
        st.close()

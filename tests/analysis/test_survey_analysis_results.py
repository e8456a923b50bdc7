"""`SurveyAnalysis` renders itself (to_markdown / to_latex) and reads back what `write` saved (read)."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from analysis.survey.acceptance import TEXT_COLUMNS, SurveyAnalysis, analyze_survey
from analysis.paper.published import paper_study
from pedas.paths import REFERENCE_DIR

PAPER = ("table3", "table4", "table5")


@pytest.fixture(scope="module")
def reference():
    return analyze_survey(pd.read_csv(REFERENCE_DIR / "survey.csv"), paper_study(), n_boot=50, seed=3)


@pytest.fixture(scope="module")
def holes():
    """Available-case analysis with missing answers: warnings, NaN cells, item n below N."""
    data = pd.read_csv(REFERENCE_DIR / "survey.csv")
    for pid, item in (("P001", "PU2"), ("P002", "SN1"), ("P003", "PU2")):
        data.loc[data["participant_id"] == pid, item] = np.nan
    return analyze_survey(data, paper_study(), n_boot=30, seed=5, listwise=False)


@pytest.fixture(scope="module")
def written(reference, tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    reference.write(out)
    return out


def _files(d) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


def test_to_markdown_and_to_latex_are_the_written_tables(reference, written):
    md = "\n".join((written / f"{t}.md").read_text() for t in PAPER)
    tex = "\n".join((written / f"{t}.tex").read_text() for t in PAPER)
    assert reference.to_markdown() == md
    assert reference.to_latex() == tex
    assert reference.to_markdown("table4") == (written / "table4.md").read_text()
    assert reference.to_latex(["item_flags"]) == (written / "item_flags.tex").read_text()
    assert reference.to_markdown(["table5", "table3"]).startswith("**Hierarchical regression")
    # one blank line between two tables
    assert "\n\n**Inter-construct correlation matrix" in reference.to_markdown()
    assert re.search(r"\\end\{(sideways)?table\*?\}\n\n\\begin\{(sideways)?table", reference.to_latex())


def test_unknown_table_or_format(reference):
    from analysis.survey.tables import render_table

    with pytest.raises(ValueError, match="unknown table 'table6'"):
        reference.to_markdown(["table6"])
    with pytest.raises(ValueError, match="unknown table format 'html'"):
        render_table(reference, "table3", "html")


@pytest.mark.parametrize("which", ["reference", "holes"])
def test_read_round_trip(which, request, tmp_path):
    res = request.getfixturevalue(which)
    res.write(tmp_path / "a")
    back = SurveyAnalysis.read(tmp_path / "a")
    assert back.to_markdown() == res.to_markdown()
    assert back.to_latex() == res.to_latex()
    assert back.to_markdown("item_flags") == res.to_markdown("item_flags")
    # what it reads, it writes again byte for byte
    back.write(tmp_path / "b")
    assert _files(tmp_path / "b") == _files(tmp_path / "a")
    assert (back.n, back.n_input, back.warnings) == (res.n, res.n_input, res.warnings)
    assert back.settings == json.loads(json.dumps(res.settings, default=str))


@pytest.mark.parametrize("which", ["reference", "holes"])
def test_read_gives_the_frames_back(which, request, tmp_path):
    res = request.getfixturevalue(which)
    res.write(tmp_path)
    back = SurveyAnalysis.read(tmp_path)
    for name, frame in res.tables().items():
        got, want = back.tables()[name], frame.copy()
        # a missing text cell is written empty and comes back as ""
        for c in TEXT_COLUMNS[name]:
            if c in want.columns:
                want[c] = want[c].fillna("")
        pd.testing.assert_frame_equal(got, want, check_exact=False, rtol=1e-11, atol=1e-10, obj=name)
    pd.testing.assert_frame_equal(back.composites, res.composites, check_exact=False, rtol=1e-11)
    lat = res.latent_correlations
    pd.testing.assert_frame_equal(back.latent_correlations, lat, check_exact=False, rtol=1e-11, atol=1e-10)


def test_read_a_directory_that_is_not_an_analysis(tmp_path):
    (tmp_path / "fit.csv").write_text("stage\n")
    with pytest.raises(FileNotFoundError, match="missing descriptives.csv, loadings.csv"):
        SurveyAnalysis.read(tmp_path)

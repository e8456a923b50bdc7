"""`pedas-study report --bundle` on the lane-keeping example (24 participants, survey only): the archive's file
list, its README and input hashes, the report document with every image it shows, every figure as PNG, SVG and PDF,
the manuscript outputs (Word with every numbered table and figure, LaTeX whose main-text tables fit a two-column
article), and the same bytes for the same report and store."""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import pandas as pd
import pytest

from analysis.report.bundle import document_images, locked_versions, table_hashes, write_bundle
from analysis.report.manuscript import report_exhibits
from tests.conftest import needs_chromium

REPO = Path(__file__).resolve().parents[2]
LK_STUDY = REPO / "studies" / "lane_keeping"
LK_DATA = REPO / "tests" / "data" / "lane_keeping"


def run(db: Path, *args) -> None:
    from pedas_study.cli import main

    assert main([f"--db={db}", *map(str, args)]) == 0, args


def _store(tmp: Path) -> Path:
    db = tmp / "lk.duckdb"
    run(db, "init", "--study", LK_STUDY)
    people = pd.read_csv(LK_DATA / "participants.csv", dtype={"participant_id": str})
    for r in people.itertuples():
        run(db, "participant", "add", r.participant_id, "--attr", f"age={r.age}")
    run(db, "survey", "import", LK_DATA / "survey.csv")
    return db


@pytest.mark.slow
def test_bundle_contents_and_determinism(tmp_path):
    from study.store.store import Store

    db = _store(tmp_path)
    out = tmp_path / "reports"
    run(db, "report", "--out", out, "--bootstrap", "50", "--cache-dir", tmp_path / "cache", "--bundle")
    zpath = out / "bundle.zip"
    z = zipfile.ZipFile(zpath)
    names = z.namelist()
    assert names == sorted(names)
    for must in ("README.md", "settings.json", "versions.txt", "inputs.sha256", "manuscript/results.docx",
                 "manuscript/latex/results.tex", "manuscript/latex/preamble.tex", "study/study.toml",
                 "study/model.lav", "study/codebook.csv", "index.html"):
        assert must in names, must
    # every figure in three formats, and every image the document shows at the path it shows it from
    figures = {Path(n).stem for n in names if n.startswith("figures/")}
    assert figures and all(f"figures/{s}.{ext}" in names for s in figures for ext in ("png", "svg", "pdf"))
    # likert items, participant flow, path diagram
    assert set(document_images(out)) <= set(names) and len(document_images(out)) == 3
    tables = {Path(n).stem for n in names if n.startswith("tables/") and n.endswith(".csv")}
    assert "survey_hypotheses" in tables and "survey_loadings" in tables
    for stem in tables:  # every table in three forms
        assert {f"tables/{stem}.md", f"tables/{stem}.tex"} <= set(names), stem
    # the study files are the stored ones, byte for byte
    assert z.read("study/model.lav") == (LK_STUDY / "model.lav").read_bytes()
    versions = z.read("versions.txt").decode().splitlines()
    assert versions[0].startswith("python==") and "numpy==" + __import__("numpy").__version__ in versions
    assert versions[1:] == locked_versions()
    readme = z.read("README.md").decode()
    assert "init --study study/" in readme and "--bootstrap 50" in readme
    # the DOCX holds every numbered table and figure of the document, in its order, with its title
    import docx

    exhibits, _ = report_exhibits(out)
    doc = docx.Document(io.BytesIO(z.read("manuscript/results.docx")))
    assert len(doc.tables) == sum(e.kind == "table" for e in exhibits) >= 10
    assert len(doc.inline_shapes) == sum(e.kind == "figure" for e in exhibits) == 3
    texts = [p.text for p in doc.paragraphs]
    labels = [t for t in texts if t in {e.label for e in exhibits}]
    assert labels == [e.label for e in sorted(exhibits, key=lambda e: e.part == "appendix")]
    assert all(texts[texts.index(e.label) + 1] == e.title for e in exhibits)
    assert z.read("manuscript/results.docx") == (out / "manuscript" / "results.docx").read_bytes()
    # input hashes: one line per table plus the total; the total changes when an answer changes
    with Store.open(db, read_only=True) as st:
        h1 = table_hashes(st)
        first = write_bundle(out, st, tmp_path / "first.zip", {"seed": 0, "n_boot": 50, "reference": False})
        again = write_bundle(out, st, tmp_path / "again.zip", {"seed": 0, "n_boot": 50, "reference": False})
    lines = z.read("inputs.sha256").decode().splitlines()
    assert len(lines) == len(h1) and lines[-1].split()[1] == "*"
    assert "responses" in set(h1["table"]) and "audit_log" not in set(h1["table"])
    assert again.path.read_bytes() == first.path.read_bytes()
    assert again.files == tuple(names)
    with Store.open(db) as st:
        st.con.execute("UPDATE responses SET value = 8 - value WHERE participant_id = 'LK-05' AND item_id = 'PE1'")
        h2 = table_hashes(st)
    changed = set(h1.merge(h2, on="table").query("sha256_x != sha256_y")["table"])
    assert changed == {"responses", "*"}


def test_bundle_needs_a_report(tmp_path):
    import pytest
    from study.store.store import Store

    db = _store(tmp_path)
    with Store.open(db, read_only=True) as st, pytest.raises(FileNotFoundError, match="no report tables"):
        write_bundle(tmp_path / "nothing", st, tmp_path / "b.zip", {})
    assert not (tmp_path / "b.zip").exists()


def _report(tmp: Path) -> Path:
    db = _store(tmp)
    out = tmp / "reports"
    run(db, "report", "--out", out, "--bootstrap", "50", "--cache-dir", tmp / "cache", "--bundle")
    return out


@pytest.mark.slow
def test_main_text_tables_fit_a_column_of_a_two_column_article(tmp_path):
    """Every main-text table of the manuscript's LaTeX, compiled in a two-column article: 0 overfull boxes (a table
    in one column or, wide, across both); the appendix tables too."""
    from tests.latex_fit import compile_tables, overfull, pdflatex

    out = _report(tmp_path)
    exhibits, _ = report_exhibits(out)
    for part in ("main", "appendix"):
        tex = [(out / "manuscript" / "latex" / "tables" / f"{e.stem}.tex").read_text(encoding="utf-8")
               for e in exhibits if e.kind == "table" and e.part == part]
        assert tex, part
        if pdflatex() is not None:
            assert overfull(compile_tables(tex, tmp_path / part, part)) == [], part


@pytest.mark.browser
@needs_chromium
def test_bundle_document_opens_with_every_image(tmp_path, browser):
    """The bundle unpacked and its index.html opened in Chromium: every image loads (naturalWidth > 0)."""
    out = _report(tmp_path)
    unpacked = tmp_path / "unpacked"
    zipfile.ZipFile(out / "bundle.zip").extractall(unpacked)
    page = browser.new_page()
    page.goto((unpacked / "index.html").as_uri())
    page.wait_for_load_state("load")
    images = page.eval_on_selector_all("img", "els => els.map(e => [e.getAttribute('src'), e.naturalWidth])")
    assert len(images) == 3 and all(width > 0 for _, width in images), images

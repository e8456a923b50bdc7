"""`pedas-study report --bundle` on the lane-keeping example (24 participants, survey only): the archive's file
list, its README and input hashes, a DOCX with every table, and the same bytes for the same report and store."""
from __future__ import annotations

import io
import zipfile
from pathlib import Path

import pandas as pd

from analysis.report.bundle import locked_versions, table_hashes, write_bundle

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


def test_bundle_contents_and_determinism(tmp_path):
    from study.store.store import Store

    db = _store(tmp_path)
    out = tmp_path / "reports"
    run(db, "report", "--out", out, "--bootstrap", "50", "--cache-dir", tmp_path / "cache", "--bundle")
    zpath = out / "bundle.zip"
    z = zipfile.ZipFile(zpath)
    names = z.namelist()
    assert names == sorted(names)
    for must in ("README.md", "settings.json", "versions.txt", "inputs.sha256", "tables/tables.docx",
                 "study/study.toml", "study/model.lav", "study/codebook.csv", "figures/index.html"):
        assert must in names, must
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
    # the DOCX holds one table per CSV table
    import docx

    doc = docx.Document(io.BytesIO(z.read("tables/tables.docx")))
    assert len(doc.tables) == len(tables)
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

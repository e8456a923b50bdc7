"""A study as a folder of plain files: `study new`, `study check` (every problem with file, line and field) and
storing a study in a store with versions (`init --study`)."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from study.store.store import Store

STUDIES = Path(__file__).resolve().parents[2] / "studies"
LK, PAPER = STUDIES / "lane_keeping", STUDIES / "pedas_paper"


def copy_study(tmp_path: Path, src: Path = LK, name: str = "study") -> Path:
    dst = tmp_path / name
    shutil.copytree(src, dst)
    return dst


def edit(path: Path, old: str, new: str, count: int = 1) -> int:
    """Replace `old` by `new` in a file (it must be there); the 1-based line where `old` started."""
    text = path.read_text(encoding="utf-8")
    assert old in text, (path, old)
    line = text[:text.index(old)].count("\n") + 1
    path.write_text(text.replace(old, new, count), encoding="utf-8")
    return line


def line_of(path: Path, pattern: str) -> int:
    for i, ln in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if re.search(pattern, ln):
            return i
    raise AssertionError(f"{pattern!r} not in {path}")


# ---------------------------------------------------------------------------------------------- study check
def test_shipped_studies_pass_the_check(cli):
    r = cli("study", "check", LK, db=None)
    assert r.code == 0, r.out
    assert r.out.strip() == ("study lane_keeping OK: 3 attributes, conditions hud|no_hud, instrument "
                             "lk_acceptance_v1 (15 items), protocols lk_counterbalanced_v1, model: 4 constructs, "
                             "1 regressions, 3 hypotheses")
    r = cli("study", "check", PAPER, db=None)
    assert r.code == 0 and r.out.startswith("study pedas_paper OK: 5 attributes, conditions baseline|pedas, "
                                            "instrument pedas_acceptance_v1 (33 items), protocols paper_v1, "
                                            "counterbalanced_v1, model: 6 constructs, 4 regressions, 7 hypotheses")


def _bad_regex(d: Path) -> list[str]:
    n = edit(d / "study.toml", 'id_pattern = "^LK-[0-9]{2}$"', 'id_pattern = "^LK-([0-9]{2}$"')
    return [f"study.toml:{n}: participants.id_pattern: not a regular expression"]


def _likert_range(d: Path) -> list[str]:
    n = line_of(d / "codebook.csv", r"^PE1,")
    edit(d / "codebook.csv", "safer.,likert7,1,7,", "safer.,likert7,1,5,")
    n = line_of(d / "codebook.csv", r"^PE2,")
    return [f"codebook.csv:{n}: PE2.response_type: likert7 but scale_min..scale_max has 5 points"]


def _model_names(d: Path) -> list[str]:
    n1 = edit(d / "model.lav", "PE =~ PE1 + PE2 + PE3", "PE =~ PE1 + PE2 + PE9")
    n2 = edit(d / "model.lav", "BI ~ age\n", "BI ~ age + income\n")
    edit(d / "model.lav", "BI ~ age + H1*PE", "BI ~ age + income + H1*PE")
    return [f"model.lav:{n1}: PE: 'PE9' is not a scaled item of the instrument",
            f"model.lav:{n2}: BI: 'income' is neither a construct of the measurement model nor a participant "
            f"attribute"]


def _undeclared_condition(d: Path) -> list[str]:
    n = edit(d / "protocol.json", '"drive": true, "condition": "no_hud"', '"drive": true, "condition": "nohud"')
    return [f"protocol.json:{n}: phases.drive_no_hud.condition: 'nohud' is not a declared condition"]


def _missing_file(d: Path) -> list[str]:
    (d / "model.lav").unlink()
    n = line_of(d / "study.toml", r"^model = ")
    return [f"study.toml:{n}: files.model: file 'model.lav' not found in the study folder"]


def _duplicate_item(d: Path) -> list[str]:
    n = edit(d / "codebook.csv", "\nBI3,BI,", "\nBI2,BI,") + 1
    # BI3 is gone from the codebook, so the model's BI3 is reported as well
    return [f"codebook.csv:{n}: item_id: 'BI2' appears twice"]


def _toml_syntax(d: Path) -> list[str]:
    n = edit(d / "study.toml", "min = 18\n", "min = 18,\n")
    return [f"study.toml:{n}: attributes.min: not valid TOML"]


def _json_syntax(d: Path) -> list[str]:
    n = edit(d / "protocol.json", '"version": 1,', '"version": 1,,')
    return [f"protocol.json:{n}: not valid JSON"]


def _reserved_attribute(d: Path) -> list[str]:
    n = edit(d / "study.toml", 'name = "km_per_year"', 'name = "condition"')
    return [f"study.toml:{n}: attributes[2].name: 'condition' is reserved"]


def _bad_check(d: Path) -> list[str]:
    toml = d / "study.toml"
    n = len(toml.read_text().splitlines()) + 3
    toml.write_text(toml.read_text() + '\n[[checks]]\nsql = "shoe_size > 3"\nmessage = "x"\n')
    return [f"study.toml:{n}: checks[0].sql: Binder Error"]


@pytest.mark.parametrize("breaker", [_bad_regex, _likert_range, _model_names, _undeclared_condition, _missing_file,
                                     _duplicate_item, _toml_syntax, _json_syntax, _reserved_attribute, _bad_check],
                         ids=lambda f: f.__name__.strip("_"))
def test_check_names_file_line_and_field_of_every_problem(cli, tmp_path, breaker):
    d = copy_study(tmp_path)
    expected = breaker(d)
    r = cli("study", "check", d, db=None)
    assert r.code == 2
    lines = r.out.strip().splitlines()
    for want in expected:
        assert any(ln.startswith(f"{d}/{want}") for ln in lines), (want, r.out)
    if breaker is not _duplicate_item:  # exactly the problems made, nothing reported twice or in their wake
        assert len(lines) == len(expected), r.out
    assert r.err.strip() == f"pedas-study: error: {len(lines)} problem(s) in study folder {d}"


def test_check_reports_several_problems_at_once(cli, tmp_path):
    d = copy_study(tmp_path)
    expected = _bad_regex(d) + _likert_range(d) + _undeclared_condition(d)
    r = cli("study", "check", d, db=None)
    assert r.code == 2 and len(r.out.strip().splitlines()) == 3
    assert all(f"{d}/{want}" in r.out for want in expected)


def test_check_of_a_folder_without_study_toml(cli, tmp_path):
    r = cli("study", "check", tmp_path, db=None)
    assert r.code == 2 and "not a study folder (no study.toml" in r.out


# ---------------------------------------------------------------------------------------------- study new
def test_new_writes_a_template_that_passes_the_check_and_serves_a_store(cli, tmp_path):
    d = tmp_path / "My Study"
    r = cli("study", "new", d, db=None)
    assert r.code == 0, r.err
    assert sorted(p.name for p in d.iterdir()) == ["codebook.csv", "model.lav", "protocol.json", "study.toml"]
    assert "#" in (d / "study.toml").read_text() and "#" in (d / "model.lav").read_text()  # commented
    r = cli("study", "check", d, db=None)
    assert r.code == 0 and r.out.startswith("study my_study OK: 3 attributes, conditions control|system, "
                                            "instrument acceptance_v1 (12 items), protocols protocol_v1, "
                                            "model: 3 constructs, 1 regressions, 2 hypotheses"), r.out
    assert "summary" not in r.out            # the template declares the researcher-facing summary
    toml = (d / "study.toml").read_text()
    (d / "study.toml").write_text(toml.replace("summary = ", "# summary = ", 1).replace(
        '\nquestionnaire after the drives."""', '\n# questionnaire after the drives."""'), encoding="utf-8")
    r = cli("study", "check", d, db=None)
    assert r.code == 0 and "no [study] summary" in r.out, r.out
    (d / "study.toml").write_text(toml, encoding="utf-8")
    db = tmp_path / "s.duckdb"
    assert cli("init", "--study", d, db=db).code == 0
    assert 'id_pattern = "^P[0-9]{3,}$"' in (d / "study.toml").read_text()
    assert cli("participant", "add", "P001", "--attr", "age=30", "--attr", "gender=male", db=db).code == 0
    r = cli("participant", "add", "P002", "--attr", "age=20", "--attr", "license_years=9", db=db)
    assert r.code == 2 and "license years impossible" in r.err


@pytest.mark.parametrize("pattern,good,bad", [("^VP[0-9]{2}$", "VP07", "P007"), ("^S-[0-9]{3}$", "S-012", "S012")])
def test_a_lab_s_own_id_scheme(cli, tmp_path, pattern, good, bad):
    """The id pattern is the study's: a lab's own scheme is accepted, the template's P001 then refused."""
    d = tmp_path / "s"
    assert cli("study", "new", d, db=None).code == 0
    toml = d / "study.toml"
    toml.write_text(re.sub(r'id_pattern = "[^"]*"\s*#[^\n]*\nid_example = "P001"',
                           f'id_pattern = "{pattern}"\nid_example = "{good}"', toml.read_text()))
    db = tmp_path / "s.duckdb"
    assert cli("init", "--study", d, db=db).code == 0
    assert cli("participant", "add", good, db=db).code == 0
    r = cli("participant", "add", bad, db=db)
    assert r.code == 2 and f"bad participant id {bad!r}" in r.err
    assert list(cli("participant", "list", "--format", "csv", db=db).out.splitlines()[1:2])[0].startswith(good)


def test_new_refuses_an_existing_folder_with_files(cli, tmp_path):
    d = tmp_path / "taken"
    d.mkdir()
    (d / "notes.txt").write_text("mine")
    r = cli("study", "new", d, db=None)
    assert r.code == 2 and "not an empty folder" in r.err
    assert [p.name for p in d.iterdir()] == ["notes.txt"]
    (tmp_path / "empty").mkdir()
    assert cli("study", "new", tmp_path / "empty", db=None).code == 0


# ---------------------------------------------------------------------------------------------- versions
def _counts(db: Path) -> dict:
    with Store.open(db, read_only=True) as st:
        return st.counts()


def _versions(db: Path) -> list:
    with Store.open(db, read_only=True) as st:
        return st.df("SELECT version, study_id FROM study_definitions ORDER BY version").values.tolist()


def test_same_files_are_unchanged_and_changed_files_of_an_unused_store_a_new_version(cli, tmp_db, tmp_path):
    d = copy_study(tmp_path)
    r = cli("init", "--study", d)
    assert r.code == 0 and "study lane_keeping version 1 stored" in r.out
    before = _counts(tmp_db)
    r = cli("init", "--study", d)
    assert r.code == 0 and "version 1 unchanged" in r.out and _counts(tmp_db) == before
    edit(d / "study.toml", 'title = "Acceptance', 'title = "Acceptance (pilot)')
    # an unused store may even change its codebook: the items are replaced
    edit(d / "codebook.csv", "helps me keep my lane.", "helps me stay in my lane.")
    r = cli("init", "--study", d)
    assert r.code == 0 and "version 2 new version" in r.out, r.err
    assert _versions(tmp_db) == [[1, "lane_keeping"], [2, "lane_keeping"]]
    with Store.open(tmp_db, read_only=True) as st:
        assert st.one("SELECT text FROM items WHERE item_id = 'PE1'") == "The lane-keeping display helps me stay " \
                                                                         "in my lane."
        assert st.one("SELECT count(*) FROM items") == 15


def test_a_store_in_use_needs_new_version(cli, lk_db, tmp_path):
    d = copy_study(tmp_path)
    assert cli("participant", "add", "LK-01", "--age", "70").code == 0
    edit(d / "study.toml", 'title = "Acceptance', 'title = "Acceptance (pilot)')
    before = _counts(lk_db)
    r = cli("init", "--study", d)
    assert r.code == 2 and "holds 1 participants; re-run with --new-version to store it as version 2" in r.err
    assert _counts(lk_db) == before and _versions(lk_db) == [[1, "lane_keeping"]]
    r = cli("init", "--study", d, "--new-version")
    assert r.code == 0 and "version 2 new version" in r.out
    with Store.open(lk_db, read_only=True) as st:
        from study.store.studies import definition
        assert definition(st).title == "Acceptance (pilot) of a lane-keeping head-up display"


@pytest.mark.parametrize("change, msg", [
    (lambda d: edit(d / "study.toml", "max = 90\n", "max = 65\n"),
     "participant LK-01: age must be between 18 and 65, not 70"),
    (lambda d: [edit(d / "study.toml", 'id_pattern = "^LK-[0-9]{2}$"', 'id_pattern = "^LK[0-9]{2}$"'),
                edit(d / "study.toml", 'id_example = "LK-01"', 'id_example = "LK01"')],
     "participant LK-01: bad participant id"),
    (lambda d: edit(d / "codebook.csv", "helps me keep my lane.", "helps me stay in my lane."),
     "instrument lk_acceptance_v1: it already has answers"),
    (lambda d: edit(d / "study.toml", 'name = "km_per_year"', 'name = "km_year"'),
     "unknown participant attribute 'km_per_year'"),
    (lambda d: edit(d / "protocol.json", '"name": "lk_counterbalanced_v1"', '"name": "lk_counterbalanced_v2"'),
     "unknown protocol 'lk_counterbalanced_v1'"),
    (lambda d: edit(d / "protocol.json", '"hud_first":', '"hud_1st":'),
     "protocol lk_counterbalanced_v1 has no order 'hud_first' any more"),
])
def test_a_new_version_that_reinterprets_stored_data_is_refused(cli, lk_db, tmp_path, change, msg):
    from study.people.participants import add_participant
    from study.people.protocol import advance

    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": 70, "km_per_year": 5000})
        advance(st, "LK-01", "familiarisation", at="2026-05-04T09:00")   # assigns the order hud_first
        st.insert("responses", {"participant_id": "LK-01", "instrument": "lk_acceptance_v1", "item_id": "PE1",
                                "value": 6, "occasion": "questionnaire"})
    d = copy_study(tmp_path)
    change(d)
    before = _counts(lk_db)
    r = cli("init", "--study", d, "--new-version")
    assert r.code == 2 and "the new version would re-interpret stored data" in r.err and msg in r.err, r.err
    assert len(r.err.strip().splitlines()) == 1
    assert _counts(lk_db) == before and _versions(lk_db) == [[1, "lane_keeping"]]


def test_a_changed_codebook_in_use_goes_into_a_new_instrument_version(cli, lk_db, tmp_path):
    from study.people.participants import add_participant

    with Store.open(lk_db) as st:
        add_participant(st, "LK-01", {"age": 30})
        st.insert("responses", {"participant_id": "LK-01", "instrument": "lk_acceptance_v1", "item_id": "PE1",
                                "value": 6, "occasion": "questionnaire"})
    d = copy_study(tmp_path)
    edit(d / "codebook.csv", "helps me keep my lane.", "helps me stay in my lane.")
    edit(d / "study.toml", "version = 1", "version = 2")
    r = cli("init", "--study", d, "--new-version")
    assert r.code == 0, r.err
    with Store.open(lk_db, read_only=True) as st:
        texts = dict(st.df("SELECT instrument, text FROM items WHERE item_id = 'PE1'").values.tolist())
        assert st.one("SELECT instrument FROM responses") == "lk_acceptance_v1"
    assert texts == {"lk_acceptance_v1": "The lane-keeping display helps me keep my lane.",
                     "lk_acceptance_v2": "The lane-keeping display helps me stay in my lane."}


def test_another_study_is_refused(cli, lk_db):
    before = _counts(lk_db)
    r = cli("init", "--study", PAPER)
    assert r.code == 2 and "serves study 'lane_keeping', not 'pedas_paper'" in r.err
    assert _counts(lk_db) == before

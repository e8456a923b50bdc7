"""Loading a study folder for a command that reads no drive log (``analyze``, ``plan power``): ``load(folder,
units=False)`` leaves out the checks that read units (log mapping, route, KPIs through the mapping) and so never
builds pint's unit registry, while ``study check``, ``init`` and a plain ``load`` still refuse a unit typo; the
model file is read by semopy's own parser file without importing the semopy package (study.folder.lavaan_parser)."""
from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from study.folder.definition import check, load, parse_model
from study.folder.lavaan_parser import parser
from study.common.problems import Problems, StudyError
from tests.conftest import PAPER_STUDY, REPO

TYPO = "channels.v.unit: unknown unit 'm/sx'"


@pytest.fixture
def typo_study(tmp_path):
    """The paper's study with a unit typo in its log mapping (speed in 'm/sx')."""
    folder = tmp_path / "paper"
    shutil.copytree(PAPER_STUDY, folder)
    mapping = folder / "fcd_map.toml"
    text = mapping.read_text(encoding="utf-8")
    assert text.count('unit = "m/s"\n') >= 1
    mapping.write_text(text.replace('unit = "m/s"\n', 'unit = "m/sx"\n', 1), encoding="utf-8")
    return folder


def test_a_unit_typo_is_still_refused_by_check_load_and_init(typo_study, cli):
    assert any(str(p).startswith("fcd_map.toml:") and TYPO in str(p) for p in check(typo_study))
    with pytest.raises(StudyError, match="unknown unit 'm/sx'"):
        load(typo_study)
    r = cli("study", "check", str(typo_study))
    assert r.code == 2 and TYPO in r.out + r.err
    r = cli("init", "--study", str(typo_study))
    assert r.code != 0 and "unknown unit 'm/sx'" in r.out + r.err


def test_load_without_units_skips_only_the_unit_checks(typo_study):
    """The same folder loads for a command that reads no drive log; every other problem is still refused."""
    study = load(typo_study, units=False)
    assert study.study_id == load(PAPER_STUDY).study_id and study.model == load(PAPER_STUDY).model
    model = typo_study / "model.lav"
    model.write_text(model.read_text(encoding="utf-8") + "\nPU ~ PU\n", encoding="utf-8")
    with pytest.raises(StudyError, match="a variable cannot predict itself"):
        load(typo_study, units=False)


def test_load_without_units_builds_no_unit_registry():
    """A fresh process: load(units=False) of the paper's study imports neither pint nor semopy."""
    code = ("import sys; from study.folder.definition import load; s = load(sys.argv[1], units=False); "
            "assert s.model is not None; print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'pint', 'semopy', 'sympy', 'sklearn'}))")
    p = subprocess.run([sys.executable, "-c", code, str(PAPER_STUDY)], capture_output=True, text=True, cwd=REPO,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "[]"


MODEL_FILES = sorted([*(REPO / "studies").rglob("*.lav"), *(REPO / "tests").rglob("*.lav")])
BAD_LINES = ["PU ~", "=~ a + b", "PU =~ a +", "PU =~ a ++ b", "PU ~~ PEoU", "H1 > 0", "DEFINE(latent) PU",
             "x := a*b", "PU ~ 0.5*PEoU + H1*SN", "PU ~ -PEoU", "bad line with words", "PU =~ a + b; c",
             "PU ~ H1 * PEoU + SN", "a, b ~ c", "PU =~ 1a + b", "ÄÖ ~ x"]


def _outcome(module, line: str):
    """What semopy's parser makes of one line: ('token', kind, groups, rvalues) or the error type."""
    try:
        kind, groups = module.separate_token(line)
    except SyntaxError:
        return ("syntax error",)
    if kind != 0:
        return ("token", kind, groups)
    try:
        return ("token", kind, groups, module.parse_rvalues(groups[2].strip()))
    except Exception as exc:  # noqa: BLE001 - semopy raises a bare Exception for a bad right side
        return ("rvalue error", type(exc).__name__)


def test_the_standalone_parser_is_semopys_parser_file():
    """Not a copy: the standalone module runs semopy/parser.py itself, so it accepts exactly what semopy accepts."""
    import semopy.parser

    from study.folder import lavaan_parser

    own = lavaan_parser._standalone()
    assert own is not semopy.parser and own.__file__ == semopy.parser.__file__
    assert parser() is semopy.parser         # once semopy is imported, its module is used
    assert len(MODEL_FILES) >= 6
    lines = [ln.split("#", 1)[0].strip() for f in MODEL_FILES for ln in f.read_text(encoding="utf-8").splitlines()]
    lines = [ln for ln in lines if ln] + BAD_LINES
    assert {_outcome(semopy.parser, ln)[0] for ln in lines} >= {"token", "syntax error"}
    for line in lines:
        assert _outcome(own, line) == _outcome(semopy.parser, line), line


@pytest.mark.parametrize("path", [p for p in MODEL_FILES if p.parent.name != "r_reference"],
                         ids=lambda p: p.parent.name)
def test_study_model_files_parse_the_same_with_either_parser(path, monkeypatch):
    """parse_model with the standalone file and with the imported semopy.parser: the same AnalysisModel."""
    import semopy.parser

    from study.folder import lavaan_parser

    text = path.read_text(encoding="utf-8")
    with_semopy = parse_model(text, path.name, Problems(), strict=True)
    monkeypatch.delitem(sys.modules, "semopy.parser")
    standalone = parse_model(text, path.name, Problems(), strict=True)
    assert lavaan_parser.parser() is lavaan_parser._standalone() is not semopy.parser
    assert standalone == with_semopy and with_semopy.hypotheses

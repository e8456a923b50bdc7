"""`study check` on broken within-subjects study folders (copies of studies/takeover with one fault each): every
fault is named in one line with file, line and field, and the command exits 2."""
from __future__ import annotations

import shutil

import pytest

from tests.conftest import OUTPUT, REPO

STUDY = REPO / "studies" / "takeover"


def _edit(folder, name, old, new):
    p = folder / name
    text = p.read_text()
    assert old in text, (name, old)
    p.write_text(text.replace(old, new, 1))


BROKEN = {
    "score not declared": ("study.toml", 'scores = ["sus", "tlx_raw", "trust"]', 'scores = ["sus", "tlx", "trust"]',
                           "within.scores: tlx: no instrument of the study declares such a score"),
    "KPI not declared": ("study.toml", 'kpis = ["takeover_time"]', 'kpis = ["reaction_time"]',
                         "within.kpis: reaction_time: not a KPI of the study's KPI file"),
    "one condition compared": ("study.toml", 'conditions = ["none", "visual", "audiovisual"]',
                               'conditions = ["visual"]', "within.conditions: a within-subjects comparison needs two "
                                                          "or more conditions"),
    "questionnaire rates the wrong drive": (
        "protocol.json", '"instrument": "post_drive", "rates": "none"', '"instrument": "post_drive", "rates": "visual"',
        "phases.survey_after_none.rates: rates visual but the drive before it in order none-visual-audiovisual is "
        "drive_none (none)"),
    "a condition never driven": (
        "protocol.json", '{"name": "drive_audiovisual", "planned_minutes": 4, "drive": true, "condition": "audiovisual"}',
        '{"name": "drive_audiovisual", "planned_minutes": 4, "drive": true, "condition": "visual"}',
        "drives visual 2x, audiovisual 0x: a within-subjects comparison needs each compared condition driven once in "
        "every order"),
    "questionnaire of an unknown instrument": (
        "protocol.json", '{"name": "survey_after_visual", "planned_minutes": 6, "instrument": "post_drive"',
        '{"name": "survey_after_visual", "planned_minutes": 6, "instrument": "postdrive"',
        "phases.survey_after_visual.instrument: 'postdrive' is not an instrument of the study"),
}


@pytest.mark.parametrize("fault", list(BROKEN))
def test_study_check_names_the_fault(fault, tmp_path, capsys):
    from pedas_study.cli import main

    folder = tmp_path / "takeover"
    shutil.copytree(STUDY, folder)
    name, old, new, message = BROKEN[fault]
    _edit(folder, name, old, new)
    code = main(["study", "check", str(folder)])
    err = capsys.readouterr()
    text = err.out + err.err
    OUTPUT.mkdir(exist_ok=True)
    with open(OUTPUT / "within_check.txt", "a", encoding="utf-8") as f:
        f.write(f"# {fault}\n{text.replace(str(tmp_path) + '/', '')}\n")
    assert code == 2, text
    assert message in text, text

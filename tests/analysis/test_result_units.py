"""Every generated result sentence that states a measured quantity carries the unit its declaration gives: a study
KPI's ``unit`` in kpis.toml (here a made-up one, so no unit can come from anywhere else), a built-in KPI's from
study.folder.kpi_spec.BUILTIN_UNITS; a dimensionless one (a count, a score) none."""
from __future__ import annotations

import json
import re
import shutil

import pandas as pd
import pytest

from tests.conftest import PAPER_STUDY, REPO
from tests.takeover_logs import make_log

TAKEOVER = REPO / "studies" / "takeover"
PEOPLE = [f"TOR-A{k:02d}" for k in range(1, 7)]


def _takeover_with_made_up_unit(tmp_path):
    """The takeover study with the takeover time declared in 'jiffy' and the built-in mean speed compared too."""
    folder = tmp_path / "takeover"
    shutil.copytree(TAKEOVER, folder)
    kpis = folder / "kpis.toml"
    kpis.write_text(kpis.read_text().replace('unit = "s"', 'unit = "jiffy"'))
    study = folder / "study.toml"
    study.write_text(study.read_text().replace('kpis = ["takeover_time"]', 'kpis = ["takeover_time", "mean_speed_mps"]'))
    return folder


@pytest.fixture(scope="module")
def within_store(tmp_path_factory):
    from pedas_study.cli import main

    tmp = tmp_path_factory.mktemp("units")
    folder = _takeover_with_made_up_unit(tmp)
    db = tmp / "tor.duckdb"

    def run(*args) -> str:
        import contextlib
        import io

        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert main([f"--db={db}", *map(str, args)]) == 0, args
        return buf.getvalue()

    run("init", "--study", folder)
    for pid in PEOPLE:
        run("participant", "add", pid, "--attr", "age=30")
    orders = json.loads((folder / "protocol.json").read_text())["orders"]
    for pid in PEOPLE:
        order = run("session", "assign", pid).strip().rsplit(" ", 1)[-1]
        for phase in orders[order]:
            run("session", "advance", pid, phase)
            if phase.startswith("drive_"):
                condition = phase.removeprefix("drive_")
                path = tmp / f"{pid}_{condition}.csv"
                make_log(pid, condition).to_csv(path, index=False)
                run("drive", "import", pid, condition, path)
    return db


@pytest.mark.slow
def test_within_sentences_carry_the_declared_unit(within_store):
    """Means, SDs, paired differences and the mixed model's effects of the takeover time in the declared (made-up)
    unit, the built-in mean speed in m/s; the F, p and effect sizes have none."""
    from analysis.within.analyze import analyze_store_within, result_sentence
    from study.store.store import Store

    with Store.open(within_store, read_only=True) as st:
        res, _ = analyze_store_within(st)
    assert dict(zip(res.variables["variable"], res.variables["unit"])) == {"takeover_time": "jiffy",
                                                                          "mean_speed_mps": "m/s"}
    text = result_sentence(res, "takeover_time")
    d = res.descriptives[res.descriptives["variable"] == "takeover_time"].set_index("condition")
    assert text.startswith("Takeover time: F(2, 10) = ")
    assert f"none: M = {d.loc['none', 'mean']:.2f} jiffy, SD = {d.loc['none', 'sd']:.2f} jiffy" in text
    diff = res.posthoc[(res.posthoc["variable"] == "takeover_time") & (res.posthoc["test"] == "t")].iloc[0]
    assert f"{diff['a']} − {diff['b']} = {diff['mean_diff']:.2f} jiffy, d_z = " in text
    assert re.search(r"difference from none: visual −\d\.\d\d jiffy, 95 % CI \[−\d\.\d\d, −\d\.\d\d\], p ", text)
    # every number that is not a test statistic, a p, an effect size, a df or a CI bound has the unit after it
    stated = re.findall(r"(?:M|SD) = (−?\d+\.\d+)( jiffy)?", text)
    assert len(stated) == 6 and all(unit for _, unit in stated)
    speed = result_sentence(res, "mean_speed_mps")
    assert re.search(r"none: M = \d+\.\d\d m/s, SD = \d+\.\d\d m/s", speed)


def _paper_study_with_made_up_kpi(tmp_path):
    """The paper's study with one more compared KPI, declared in 'jiffy'."""
    from study.folder.definition import load

    folder = tmp_path / "pedas_paper"
    shutil.copytree(PAPER_STUDY, folder)
    kpis = folder / "kpis.toml"
    text = kpis.read_text().replace('[comparison.columns]\n', '[comparison.columns]\ndrag = "drag"\n')
    kpis.write_text(text + '\n[sql]\ndrag = { sql = "avg(v)", unit = "jiffy", label = "Drag", decimals = 1 }\n')
    return load(folder)


def test_paired_figure_reading_carries_the_declared_unit(tmp_path):
    """The paired comparison of a compared KPI (drives/paired.csv) read out under its figure: both means and the
    difference in the declared unit, to the declared decimals; the figure's title names the KPI."""
    from analysis.report.document import Exhibits, _figure

    study = _paper_study_with_made_up_kpi(tmp_path)
    out = tmp_path / "reports"
    (out / "drives").mkdir(parents=True)
    (out / "figures").mkdir()
    (out / "figures" / "paired_drag.png").write_bytes(b"")
    pd.DataFrame([{"KPI": "Drag (jiffy)", "n": 4, "M baseline": 3.14, "SD baseline": 0.2, "M pedas": 2.52,
                   "SD pedas": 0.3, "M_diff": 0.62, "95 % CI LL": 0.31, "95 % CI UL": 0.93, "t": 6.39, "df": 3.0,
                   "p (t)": 0.0078, "d_z": 3.19}]).to_csv(out / "drives" / "paired.csv", index=False)
    ex = Exhibits({})
    html = _figure(out, "paired_drag", study, ex)
    assert ("Drag: M = 3.1 jiffy with baseline and 2.5 jiffy with pedas; baseline − pedas = 0.6 jiffy, 95 % CI "
            "[0.3, 0.9], t(3) = 6.39, p = .008, d_z = 3.19.") in html
    assert ex.items[0].title.startswith("Drag (jiffy): each participant's value in both compared conditions")

"""The car-following example study (studies/car_following: seven shipped standard measures, two regions of interest)
end to end through the CLI on a temporary store: `study check` (and its one-line refusals of a broken KPI file),
four participants' 20 Hz logs (tests/car_following_logs.py) imported, `analyze drives`, the report, and the report's
drive section in headless Chromium (screenshot tests/output/car_following_report.png). The brake reaction time, the
accelerator-to-brake transition time and the lane departures are compared with the log generator's truth. Every
command and what it printed is written to tests/output/car_following_e2e.txt."""
from __future__ import annotations

import math
import shutil

import numpy as np
import pandas as pd
import pytest

from tests.car_following_logs import LEAD_BRAKES_S, RATE_HZ, departures, reaction_time, release_time, write_log
from tests.conftest import OUTPUT, REPO, needs_chromium
from tests.e2e.test_takeover_e2e import Transcript

STUDY = REPO / "studies" / "car_following"
PEOPLE = ("CF-01", "CF-02", "CF-03", "CF-04")
CONDITIONS = ("no_warning", "fcw")

pytestmark = [pytest.mark.slow]


def test_a_broken_measure_declaration_is_refused_with_file_line_and_reason(tmp_path, capsys):
    folder = tmp_path / "car_following"
    shutil.copytree(STUDY, folder)
    kpis = folder / "kpis.toml"
    text = kpis.read_text(encoding="utf-8")
    kpis.write_text(text.replace('gap_deg = 2.0', 'gap_deg = 45.0')
                    .replace('measure = "sdlp"', 'measure = "sdlp_bias"')
                    .replace('event = "lead_brakes"', 'event = "horn"'), encoding="utf-8")
    run = Transcript(tmp_path / "unused.duckdb", capsys)
    out = run("study", "check", folder, db=False, code=2)
    lines = [ln.replace(str(tmp_path) + "/", "") for ln in out.strip().splitlines()]
    assert "car_following/kpis.toml:8: measures.sdlp.measure: 'sdlp_bias' is not a shipped measure" in lines[0]
    assert lines[1] == "car_following/kpis.toml:9: measures.srr.gap_deg: must be in [0.1, 20] deg, not 45"
    assert lines[2] == ("car_following/kpis.toml:12: measures.brt: needs channel 'horn', which the log mapping "
                        "logmap.toml does not map")
    assert lines[3] == ("car_following/kpis.toml:13: measures.abt: needs channel 'horn', which the log mapping "
                        "logmap.toml does not map")
    assert lines[4] == ("car_following/kpis.toml:18: regions.lead_braking: needs channel 'horn', which the log "
                        "mapping logmap.toml does not map")
    assert lines[5] == "pedas-study: error: 5 problem(s) in study folder car_following" and len(lines) == 6


@pytest.mark.browser
@needs_chromium
def test_car_following_study_end_to_end(tmp_path, capsys, browser):
    db = tmp_path / "cf.duckdb"
    run = Transcript(db, capsys)
    logs = tmp_path / "logs"
    logs.mkdir()
    try:
        assert run("study", "check", STUDY, db=False).startswith("study car_following OK")
        run("init", "--study", STUDY)
        roster = tmp_path / "roster.csv"
        pd.DataFrame({"participant_id": PEOPLE, "age": [25, 31, 44, 52]}).to_csv(roster, index=False)
        run("participant", "import", roster)
        for k, pid in enumerate(PEOPLE):
            order = run("session", "assign", pid).strip().rsplit(" ", 1)[-1]
            for cond in (CONDITIONS if order == "no_warning_first" else CONDITIONS[::-1]):
                run("session", "advance", pid, f"drive_{cond}", quiet=k > 0)
                run("drive", "import", pid, cond, write_log(logs, pid, cond), quiet=k > 0)
        out = run("analyze", "drives", "--out", tmp_path / "drives")
        assert "Drive measures by region of interest" in out
        run("report", "--out", tmp_path / "reports", "--bootstrap", "0", "--cache-dir", tmp_path / "cache")
    finally:
        OUTPUT.mkdir(exist_ok=True)
        (OUTPUT / "car_following_e2e.txt").write_text("\n".join(run.lines) + "\n", encoding="utf-8")

    # the tool against the generator's truth: the brake pedal's first 20 Hz sample at or after onset + reaction time,
    # the accelerator's at or after onset + release time
    def first_sample(delay_s: float) -> float:
        return math.ceil(delay_s * RATE_HZ - 1e-9) / RATE_HZ

    kpis = pd.read_csv(tmp_path / "drives" / "kpis.csv")
    overall = kpis[kpis["segment"] == "overall"].set_index(["participant_id", "condition"])
    for pid in PEOPLE:
        for cond in CONDITIONS:
            truth = first_sample(reaction_time(pid, cond))
            assert overall.loc[(pid, cond), "brt"] == pytest.approx(truth, abs=1e-6)
            assert overall.loc[(pid, cond), "abt"] == pytest.approx(truth - first_sample(release_time(pid, cond)),
                                                                    abs=1e-6)
            assert overall.loc[(pid, cond), "departures"] == departures(pid, cond)
            assert 0.1 < overall.loc[(pid, cond), "sdlp"] < 0.4
    regions = pd.read_csv(tmp_path / "drives" / "regions.csv")
    braking = regions[regions["region"] == "lead_braking"]
    for col in ("brt", "abt"):
        assert np.allclose(braking.set_index(["participant_id", "condition"])[col].sort_index(),
                           overall[col].sort_index())
        assert regions[regions["region"] == "following"][col].isna().all()   # no event in that stretch
    assert LEAD_BRAKES_S > 0

    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.goto((tmp_path / "reports" / "index.html").as_uri())
    methods = page.locator("#methods").locator("xpath=..").inner_text()
    assert "Steering reversals: reversals per minute" in methods and "front bumper to front bumper" in methods
    region = page.locator("#x-drives_region_summary")
    assert region.count() == 1
    assert "lead_braking" in region.inner_text()
    page.locator("#drive-results").scroll_into_view_if_needed()
    page.screenshot(path=str(OUTPUT / "car_following_report.png"), full_page=True)
    page.close()

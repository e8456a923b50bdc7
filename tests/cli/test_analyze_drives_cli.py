"""`pedas-study analyze drives` end to end on a temporary store with hand-built drives."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pedas.constants import KMH
from tests.conftest import OUTPUT, PAPER_STUDY, initialised_store

DT = 0.2


def build_drive(seed: int, condition: str) -> pd.DataFrame:
    """A 4 km drive: 2 km urban (50 km/h, one light at 1 km, red until 90 s) and 2 km highway (100 km/h, a
    slower leader appears at 3 km). Baseline: faster, speeds, stops at the red light. pEDAS: slower, times the
    light, follows the advice; rt controller until the leader is within 100 m, then cf. Seeded variation."""
    rng = np.random.default_rng(seed)
    ped = condition == "pedas"
    v_urban = (47 if ped else 56 + 4 * rng.random()) * KMH
    v_hw = (92 if ped else 108 + 6 * rng.random()) * KMH
    t, s, v = [0.0], [0.0], [0.0]
    light, red_until = 1000.0, 90.0
    while s[-1] < 4000.0:
        urban = s[-1] < 2000.0
        target = v_urban if urban else v_hw
        if ped and s[-1] < light:   # green-wave advice: arrive after the light turned green
            target = 38 * KMH
        if not ped and s[-1] < light and t[-1] < red_until and light - s[-1] < 60.0:
            acc = -min(v[-1] ** 2 / (2 * max(light - 5.0 - s[-1], 0.5)), 3.0) if v[-1] > 0.05 else 0.0
            vn = max(v[-1] + acc * DT, 0.0) if light - 5.0 - s[-1] > 0.05 else 0.0
        else:
            acc = np.clip(target - v[-1], -2.0, 1.5 if not ped else 1.0)
            vn = max(v[-1] + acc * DT, 0.0)
        s.append(s[-1] + (v[-1] + vn) / 2 * DT)
        v.append(vn)
        t.append(t[-1] + DT)
    t, s, v = np.array(t), np.array(s), np.array(v)
    df = pd.DataFrame({"t": t, "s": s, "v": v, "segment": np.where(s < 2000.0, "urban", "highway"),
                       "speed_limit": np.where(s < 2000.0, 50 * KMH, 100 * KMH)})
    df["tl_id"] = np.where(s < light, "TL1", None)
    df["d_tl"] = np.where(s < light, light - s, np.nan)
    df["tl_state"] = np.where(s < light, np.where(t < red_until, "red", "green"), None)
    gap = np.where(s > 2500.0, 250.0 - (s - 2500.0) * 0.15, np.nan)
    df["leader_gap"] = np.clip(gap, 30.0, None)
    df["leader_v"] = np.where(s > 2500.0, 85 * KMH, np.nan)
    if ped:
        df["v_advice"] = np.clip(v * 0.97 + 0.3, 0, None)
        df["controller"] = np.where(df["leader_gap"] < 100.0, "cf", "rt")
    return df


def make_store(db, n=6, styles=("cautious", "normal", "sporty")):
    """A store of the paper's study with `n` participants, both drives each; P002 excluded (objective scope)."""
    from study.logs.importing import import_drive_frame
    from study.people.exclusions import exclude
    from study.people.participants import add_participant
    from study.store.store import Store
    from study.store.studies import register

    with Store.open(db, actor="test") as st:
        register(st, PAPER_STUDY)
        for i in range(1, n + 1):
            pid = f"P{i:03d}"
            add_participant(st, pid, style=styles[i % len(styles)])
            for cond in ("baseline", "pedas"):
                import_drive_frame(st, pid, cond, build_drive(100 * i + (cond == "pedas"), cond))
        exclude(st, "P002", "objective", "technical_issue")


@pytest.fixture(scope="module")
def cohort_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("cohort") / "study.duckdb"
    make_store(db)
    return db


@pytest.mark.slow
def test_analyze_drives_writes_tables_figures_and_bands(cli, cohort_db, tmp_path):
    out = tmp_path / "drives"
    r = cli("analyze", "drives", "--out", out, db=cohort_db)
    assert r.code == 0, r.err
    assert "5 participants with both drives" in r.out and "1 excluded" in r.out
    for name in ("kpis.csv", "per_participant.csv", "summary.csv", "style_table.csv", "style_table.md",
                 "style_table.tex", "participant_table.csv", "participant_table.md", "participant_table.tex",
                 "bands.csv", "band_diagnostics.csv", "objective.md"):
        assert (out / name).stat().st_size > 0, name
    for stem in ("fig9a_savings", "fig9b_savings_urban_by_style", "fig9c_savings_highway_by_style",
                 "fig9d_savings_overall_by_style", "fig10_tl_green", "fig11_driving_behaviour",
                 "fig12_controller_switching"):
        for ext in ("png", "pdf"):
            assert (out / "figures" / f"{stem}.{ext}").stat().st_size > 1000, stem
    per = pd.read_csv(out / "per_participant.csv")
    assert "P002" not in set(per["participant_id"])           # excluded (objective scope)
    # the pEDAS drives are slower and never stop at the red light: savings and fewer red stops
    assert (per["saving_overall_pct"] > 0).all()
    assert (per["red_stops_baseline"] == 1).all() and (per["red_stops_pedas"] == 0).all()
    assert per["red_stop_reduction_pct"].to_numpy() == pytest.approx(100.0)
    assert (per["tl_green_passes_baseline"] == 0).all() and (per["tl_green_passes_pedas"] == 1).all()
    assert per["violation_reduction_pct"].to_numpy() == pytest.approx(100.0)
    # the paired comparison of each compared KPI: tables with words as headers, the paired plots
    paired = pd.read_csv(out / "paired.csv").set_index("KPI")
    assert {"n", "M_diff", "95 % CI LL", "95 % CI UL", "t", "df", "p (t)", "d_z", "W", "p (W)"} <= set(paired.columns)
    assert paired.loc["Battery energy (Wh)", "M_diff"] > 0 and (paired["n"] == 5).all()
    # red stops drop by exactly 1 for everybody: no variance of the differences, no test, said in the note
    assert "Stops at red (count)" not in paired.index
    assert "Stops at red (count)" in (out / "paired.md").read_text()
    assert set(pd.read_csv(out / "paired_by_group.csv")["Effect"]) == {"Style", "Condition", "Condition × style"}
    for stem in ("paired_energy_overall_wh", "paired_rms_jerk"):
        assert (out / "figures" / f"{stem}.png").stat().st_size > 1000, stem
    assert not (out / "figures" / "paired_tl_crossed.png").exists()   # the same in both drives
    # all of them as panels of one figure (the main text's)
    assert (out / "figures" / "paired_kpis.png").stat().st_size > 1000
    tex = (out / "style_table.tex").read_text()
    assert r"\toprule" in tex and r"\bottomrule" in tex
    bands = pd.read_csv(out / "bands.csv")
    assert len(bands) == 4 and set(bands["holds"]) <= {True, False}
    # what lies behind the bands, known from the construction of the drives (5 included participants)
    diag = pd.read_csv(out / "band_diagnostics.csv").set_index("quantity")
    assert diag.loc["red stops, all drives", ["baseline", "pedas"]].tolist() == [5, 0]
    assert diag.loc["red stops with a leader within 30 m (in a queue)", "baseline"] == 0  # no leader in town
    assert pd.isna(diag.loc["red stops with the car-following MPC in charge", "baseline"])  # no MPC in baseline
    assert diag.loc["drives above the limit at all (of 5)", ["baseline", "pedas"]].tolist() == [5, 0]
    # the leader closes in from 250 m from 2.5 km on: within 100 m over the last 500 m of the 2 km highway
    assert diag.loc["highway time with a leader within 100 m", "pedas"] == pytest.approx(25, abs=3)
    assert 85 < diag.loc["mean speed on the highway", "pedas"] < 92
    assert "Behind the bands" in (out / "objective.md").read_text()
    # the replay of the Figs. 11-12 participant, linked from objective.md, its pEDAS drive first
    assert "[replay_P006.html](replay_P006.html)" in (out / "objective.md").read_text()
    page = (out / "replay_P006.html").read_text()
    assert page.index('"condition":"pedas"') < page.index('"condition":"baseline"')
    # keep one copy to look at
    OUTPUT.mkdir(exist_ok=True)
    for stem in ("fig9a_savings", "fig9b_savings_urban_by_style", "fig9c_savings_highway_by_style",
                 "fig9d_savings_overall_by_style", "fig10_tl_green", "fig11_driving_behaviour",
                 "fig12_controller_switching"):
        (OUTPUT / f"drives_{stem}.png").write_bytes((out / "figures" / f"{stem}.png").read_bytes())


@pytest.mark.slow
def test_analyze_drives_other_participant_and_store_unchanged(cli, cohort_db, tmp_path):
    from study.store.store import Store

    with Store.open(cohort_db, read_only=True) as st:
        before = st.con.execute("SELECT count(*), sum(v) FROM drive_samples").fetchone()
    r = cli("analyze", "drives", "--out", tmp_path / "o", "--participant", "P003", db=cohort_db)
    assert r.code == 0, r.err
    assert (tmp_path / "o" / "figures" / "fig11_driving_behaviour.png").exists()
    with Store.open(cohort_db, read_only=True) as st:
        assert st.con.execute("SELECT count(*), sum(v) FROM drive_samples").fetchone() == before


def test_analyze_drives_refuses_missing_store_and_store_without_drives(cli, tmp_db, tmp_path, tmp_path_factory):
    r = cli("analyze", "drives", "--out", tmp_path / "x")
    assert r.code == 2 and "store not found" in r.err and len(r.err.strip().splitlines()) == 1
    initialised_store(tmp_db, PAPER_STUDY, tmp_path_factory)
    r = cli("analyze", "drives", "--out", tmp_path / "x")
    assert r.code == 2 and "no drives" in r.err
    assert not (tmp_path / "x").exists()


def test_analyze_drives_figure_skipped_when_no_pair(cli, paper_db, tmp_path):
    from study.logs.importing import import_drive_frame
    from study.people.participants import add_participant
    from study.store.store import Store

    with Store.open(paper_db, actor="test") as st:
        add_participant(st, "P001", style="normal")
        import_drive_frame(st, "P001", "baseline", build_drive(1, "baseline"))
    r = cli("analyze", "drives", "--out", tmp_path / "y", db=paper_db)
    assert r.code == 0, r.err
    assert "0 participants with both drives" in r.out and "1 without a complete pair" in r.out
    assert "fig9a not drawn" in r.out
    assert len(pd.read_csv(tmp_path / "y" / "kpis.csv")) == 3      # the single drive's KPIs are still there

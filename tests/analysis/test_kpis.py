"""Drive KPIs (analysis.drives.kpis) on hand-made logs with known answers, and SQL vs the pandas peer."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis.drives.testing import kpis_pandas
from pedas_study.bench.kpi import synthetic_sql
from analysis.drives.kpis import KPI_FIELDS, KpiParams, kpis_from_frame, kpis_from_relation
from pedas.constants import KMH

DT = 0.1


def ramp_log(phases, dt=DT, v0=0.0, limit=50 * KMH, segment="urban"):
    """A drive log from phases (duration s, end speed m/s): linear speed ramps, s by the trapezoid rule."""
    v = [v0]
    for dur, v_end in phases:
        n = int(round(dur / dt))
        v.extend(np.linspace(v[-1], v_end, n + 1)[1:])
    v = np.asarray(v)
    t = np.arange(len(v)) * dt
    s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * dt)])
    return pd.DataFrame({"t": t, "s": s, "v": v, "segment": segment, "speed_limit": limit})


def row(k: pd.DataFrame, segment="overall", drive_id=1) -> pd.Series:
    return k[(k["segment"] == segment) & (k["drive_id"] == drive_id)].iloc[0]


# ------------------------------------------------------------------------------------------ energy, distance
def test_constant_speed_known_energy_distance_time():
    n = 1001  # 100 s at 10 m/s, 5 kW drawn
    df = pd.DataFrame({"t": np.arange(n) * DT, "s": np.arange(n) * DT * 10.0, "v": 10.0, "a": 0.0,
                       "segment": "urban", "speed_limit": 50 * KMH, "p_batt": 5000.0})
    r = row(kpis_from_frame(df))
    assert r["energy_wh"] == pytest.approx(5000.0 * 100.0 / 3600.0)          # 138.89 Wh
    assert r["distance_m"] == pytest.approx(1000.0)
    assert r["trip_time_s"] == pytest.approx(100.0)
    assert r["mean_speed_mps"] == pytest.approx(10.0)
    assert r["wh_per_km"] == pytest.approx(138.8889, rel=1e-6)
    assert r["n_intervals"] == n - 1
    assert r["rms_jerk"] == 0.0 and r["mean_abs_a"] == 0.0
    assert r["stops"] == 0 and r["violation_events"] == 0 and r["violation_share"] == 0.0


def test_energy_is_trapezoid_of_battery_power_with_recuperation():
    # power ramps linearly from +10 kW to -10 kW over 10 s: the trapezoid integral is exactly 0
    t = np.arange(101) * DT
    df = pd.DataFrame({"t": t, "s": t * 5.0, "v": 5.0, "segment": "urban", "speed_limit": 14.0,
                       "p_batt": 10_000.0 - 2_000.0 * t})
    assert row(kpis_from_frame(df))["energy_wh"] == pytest.approx(0.0, abs=1e-9)
    df["p_batt"] = 3600.0 * (t <= 5.0)       # 1 Wh/s for 5 s, half an interval at the step
    assert row(kpis_from_frame(df))["energy_wh"] == pytest.approx(5.0 + 0.5 * DT)


def test_segments_split_at_the_left_sample_and_sum_to_overall():
    n = 201
    df = pd.DataFrame({"t": np.arange(n) * DT, "s": np.arange(n) * 1.0, "v": 10.0, "a": 0.0,
                       "segment": ["urban"] * 100 + ["highway"] * 101, "speed_limit": 30.0, "p_batt": 3600.0})
    k = kpis_from_frame(df)
    u, h, o = row(k, "urban"), row(k, "highway"), row(k, "overall")
    assert u["distance_m"] == pytest.approx(100.0) and h["distance_m"] == pytest.approx(100.0)
    assert u["energy_wh"] == pytest.approx(10.0) and h["energy_wh"] == pytest.approx(10.0)
    for col in ("energy_wh", "distance_m", "trip_time_s", "n_intervals"):
        assert o[col] == pytest.approx(u[col] + h[col])
    assert list(k["segment"]) == ["urban", "highway", "overall"]


def test_store_energy_matches_power_model(paper_db):
    """A drive imported without p_batt: the importer fills it from the vehicle model, the KPI integrates it to
    the same Wh as the model's own trace energy (`kpi energy`)."""
    from analysis.drives.kpis import store_kpis
    from pedas.power import trace_energy
    from study.logs.importing import import_drive_frame
    from study.people.participants import add_participant
    from study.store.store import Store

    log = ramp_log([(10, 15.0), (60, 15.0), (10, 0.0)])
    with Store.open(paper_db, actor="test") as st:
        add_participant(st, "P001", style="normal")
        import_drive_frame(st, "P001", "baseline", log)
        k = store_kpis(st)
    want = trace_energy(log["t"], log["v"]).wh
    r = k[(k["participant_id"] == "P001") & (k["segment"] == "overall")].iloc[0]
    assert r["condition"] == "baseline"
    assert r["energy_wh"] == pytest.approx(want, rel=1e-9)
    assert r["distance_m"] == pytest.approx(log["s"].iloc[-1])


def test_store_fills_missing_power_and_acceleration_without_changing_store(paper_db):
    from analysis.drives.kpis import store_kpis
    from pedas.power import trace_energy
    from study.logs.importing import import_drive_frame
    from study.people.participants import add_participant
    from study.store.store import Store

    log = ramp_log([(8, 12.0), (30, 12.0), (8, 0.0)])
    with Store.open(paper_db, actor="test") as st:
        add_participant(st, "P002")
        d = import_drive_frame(st, "P002", "pedas", log)
        st.con.execute("UPDATE drive_samples SET p_batt = NULL, a = NULL WHERE drive_id = ?", [d.drive_id])
        k = store_kpis(st)
        assert st.one("SELECT count(*) FROM drive_samples WHERE p_batt IS NULL") == len(log)
    r = k[k["segment"] == "overall"].iloc[0]
    assert r["energy_wh"] == pytest.approx(trace_energy(log["t"], log["v"]).wh, rel=1e-9)
    assert r["mean_abs_a"] > 0


# ------------------------------------------------------------------------------------------ speeding
def test_log_speeding_on_ten_percent_of_its_distance():
    # 90 s at 10 m/s (900 m), 5 s at 20 m/s = 72 km/h in a 50 zone (100 m); constant speeds, steps in v
    v = np.r_[np.full(450, 10.0), np.full(50, 20.0), np.full(451, 10.0)]
    t = np.arange(len(v)) * DT
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * DT)])        # left-point: each interval at its left speed
    df = pd.DataFrame({"t": t, "s": s, "v": v, "segment": "urban", "speed_limit": 50 * KMH, "a": 0.0})
    r = row(kpis_from_frame(df))
    assert r["distance_m"] == pytest.approx(1000.0)
    assert r["violation_distance_m"] == pytest.approx(100.0)
    assert r["violation_share"] == pytest.approx(0.10)
    assert r["violation_events"] == 1


def test_violation_tolerance_and_minimum_event_duration():
    lim = 50 * KMH
    base = np.full(300, 40 * KMH)
    v = base.copy()
    v[20:40] = lim + 2 * KMH        # within the 3 km/h tolerance: no violation
    v[60:65] = lim + 10 * KMH       # 0.5 s: violating distance, but no event (< 1 s)
    v[100:110] = lim + 10 * KMH     # exactly 1.0 s: an event
    v[200:250] = lim + 4 * KMH      # 5 s: an event
    t = np.arange(len(v)) * DT
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * DT)])
    df = pd.DataFrame({"t": t, "s": s, "v": v, "segment": "urban", "speed_limit": lim, "a": 0.0})
    r = row(kpis_from_frame(df))
    want = (5 + 10) * DT * (lim + 10 * KMH) + 50 * DT * (lim + 4 * KMH)
    assert r["violation_distance_m"] == pytest.approx(want)
    assert r["violation_events"] == 2
    # above 100 km/h the tolerance is 3 %: 120 km/h + 3.6 km/h
    hw = pd.DataFrame({"t": t[:3], "s": [0.0, 3.4, 6.9], "v": np.array([123.5, 124.0, 124.0]) * KMH,
                       "segment": "highway", "speed_limit": 120 * KMH, "a": 0.0})
    r = row(kpis_from_frame(hw))
    assert r["violation_distance_m"] == pytest.approx(3.5)    # only the interval from the 124 km/h sample


def test_violation_running_until_the_end_is_an_event():
    v = np.r_[np.full(10, 10.0), np.full(20, 20.0)]
    df = pd.DataFrame({"t": np.arange(30) * DT, "s": np.arange(30) * 1.5, "v": v, "segment": "urban",
                       "speed_limit": 50 * KMH, "a": 0.0})
    assert row(kpis_from_frame(df))["violation_events"] == 1   # 1.9 s to the last sample


# ------------------------------------------------------------------------------------------ lights, stops
def three_reds_log():
    """Meets three red lights: stops at TL1 and TL3 (waits for green), TL2 turns green before arrival; a final
    stop at a stop sign (no light ahead); creeping in the TL1 queue is not a second stop."""
    log = ramp_log([(5, 10.0), (10, 10.0), (5, 0.0), (4, 0.0), (1, 1.0), (1, 0.0), (6, 0.0),   # stop 1 at TL1
                    (5, 10.0), (20, 10.0),                                                  # TL2 in green
                    (5, 0.0), (10, 0.0),                                                    # stop 2 at TL3
                    (5, 10.0), (10, 10.0), (5, 0.0), (3, 0.0), (5, 10.0), (5, 10.0)])        # stop sign
    t, s = log["t"].to_numpy(), log["s"].to_numpy()
    dep1 = 32.0   # departure from TL1 (end of the stand-still)
    dep2 = 67.0   # departure from TL3
    pos = {"TL1": s[int(round(dep1 / DT))] + 5.0,
           "TL2": s[int(round(50.0 / DT))],
           "TL3": s[int(round(dep2 / DT))] + 5.0}
    green_from = {"TL1": dep1, "TL2": 40.0, "TL3": dep2}
    ids, d, state = [], [], []
    for ti, si in zip(t, s):
        ahead = [k for k, p in pos.items() if p > si]
        if not ahead:
            ids.append(None); d.append(np.nan); state.append(None)
            continue
        k = ahead[0]
        ids.append(k); d.append(pos[k] - si); state.append("green" if ti >= green_from[k] else "red")
    return log.assign(tl_id=ids, d_tl=d, tl_state=state, p_batt=1000.0)


def test_stops_at_two_of_three_reds():
    r = row(kpis_from_frame(three_reds_log()))
    assert r["tl_crossed"] == 3
    assert r["tl_crossed_green"] == 3 and r["tl_crossed_red"] == 0 and r["tl_crossed_yellow"] == 0
    assert r["red_stops"] == 2
    assert r["tl_green_passes"] == 1  # only TL2 was passed in green without stopping
    assert r["stops"] == 3            # TL1 (the creep below 2 m/s does not count again), TL3, stop sign


def test_crossing_state_is_the_state_before_the_change_and_red_running_counts():
    log = ramp_log([(2, 10.0), (20, 10.0)], v0=10.0)
    log["tl_id"] = np.where(log["s"] < 100.0, "A", np.where(log["s"] < 150.0, "B", None))
    log["d_tl"] = np.where(log["s"] < 100.0, 100.0 - log["s"], 150.0 - log["s"])
    log["tl_state"] = np.where(log["s"] < 100.0, "red", "yellow")
    r = row(kpis_from_frame(log))
    assert (r["tl_crossed"], r["tl_crossed_red"], r["tl_crossed_yellow"], r["red_stops"]) == (2, 1, 1, 0)


def test_red_stop_counted_once_per_light_and_only_near_the_line():
    # stands twice at the same red light (queue at 60 m, then at 10 m): one red stop; the first stand-still is
    # beyond 50 m and alone would not count
    log = ramp_log([(5, 10.0), (5, 0.0), (5, 0.0), (6, 8.0), (6, 0.0), (5, 0.0)])   # stands at 58 m, 10 m
    s_line = log["s"].iloc[-1] + 10.0
    log["tl_id"], log["d_tl"], log["tl_state"] = "X", s_line - log["s"], "red"
    r = row(kpis_from_frame(log))
    assert r["red_stops"] == 1 and r["stops"] == 2 and r["tl_crossed"] == 0
    first = log[log["t"] <= 15.0]
    assert first["d_tl"].iloc[-1] == pytest.approx(58.0)
    assert row(kpis_from_frame(first))["red_stops"] == 0


# ------------------------------------------------------------------------------------------ jerk, |a|
def test_rms_jerk_and_mean_abs_acceleration():
    n = 101
    t = np.arange(n) * DT
    a = 0.5 * t - 1.0                   # constant jerk 0.5 m/s^3
    df = pd.DataFrame({"t": t, "s": t * 10, "v": 10.0, "a": a, "segment": "highway", "speed_limit": 30.0})
    r = row(kpis_from_frame(df))
    assert r["rms_jerk"] == pytest.approx(0.5)
    assert r["mean_abs_a"] == pytest.approx(np.abs(a[:-1]).mean())
    # alternating +-1 m/s^2 every sample: |jerk| = 2 / 0.1 = 20 m/s^3
    df["a"] = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    r = row(kpis_from_frame(df))
    assert r["rms_jerk"] == pytest.approx(20.0) and r["mean_abs_a"] == pytest.approx(1.0)


def test_missing_acceleration_is_the_speed_gradient():
    log = ramp_log([(10, 10.0), (10, 10.0)])           # 1 m/s^2 for 10 s, then 0 for 10 s
    r = row(kpis_from_frame(log))
    assert r["mean_abs_a"] == pytest.approx(0.5, abs=0.01)


# ------------------------------------------------------------------------------------------ SQL vs pandas
def random_logs(seed: int, n_drives: int = 4) -> pd.DataFrame:
    import duckdb

    with duckdb.connect() as con:
        return con.execute(synthetic_sql(n_drives * 3000, 3000, seed)).df()


@pytest.mark.parametrize("seed", [1, 7])
def test_sql_equals_pandas_peer_in_both_window_modes(seed):
    import duckdb

    logs = random_logs(seed)
    want = kpis_pandas(logs)
    assert want["stops"].sum() > 0 and want["violation_events"].sum() > 0 and want["red_stops"].sum() > 0
    assert 0 < want["tl_green_passes"].sum() <= want["tl_crossed_green"].sum()
    with duckdb.connect() as con:
        con.register("logs_df", logs)
        con.execute("CREATE TABLE ordered AS SELECT * FROM logs_df ORDER BY drive_id, idx")
        con.execute("CREATE TABLE shuffled AS SELECT * FROM logs_df ORDER BY hash(idx * 31 + drive_id)")
        for src, mode in (("ordered", "stream"), ("ordered", "sorted"), ("shuffled", "auto")):
            got = kpis_from_relation(con, src, mode=mode)
            pd.testing.assert_frame_equal(got[list(KPI_FIELDS)], want, check_dtype=False, rtol=1e-9)


def test_stream_mode_is_refused_for_out_of_order_rows():
    import duckdb

    from analysis.drives.kpis import in_drive_order

    logs = random_logs(3, 2)
    with duckdb.connect() as con:
        con.register("logs_df", logs)
        con.execute("CREATE TABLE ok AS SELECT * FROM logs_df ORDER BY drive_id, idx")
        con.execute("CREATE TABLE bad AS SELECT * FROM logs_df ORDER BY idx, drive_id")   # drives interleaved
        assert in_drive_order(con, "ok") and not in_drive_order(con, "bad")
        con.execute("SET preserve_insertion_order = false")       # scan order no longer guaranteed
        assert not in_drive_order(con, "ok")


def test_params_change_the_definitions():
    v = np.r_[np.full(100, 10.0), np.full(100, 14.5)]            # 52.2 km/h in a 50 zone
    df = pd.DataFrame({"t": np.arange(200) * DT, "s": np.cumsum(v) * DT, "v": v, "segment": "urban",
                       "speed_limit": 50 * KMH, "a": 0.0})
    assert row(kpis_from_frame(df))["violation_events"] == 0
    assert row(kpis_from_frame(df, KpiParams(tol_abs=1 * KMH, tol_rel=0.0)))["violation_events"] == 1

"""The shipped standard driving measures (docs/measures.md): worked examples, synthetic drives with known ground truth,
laws they obey, regions of interest, and the study check of their declaration."""
from __future__ import annotations

import math

import duckdb
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.drives.kpis import kpis_from_frame
from analysis.drives.measures import (FUNCTIONS, drive_arrays, entropy_of, measure_kpis, prediction_errors,
                                      reversals)
from study.folder.kpi_spec import KpiSpecProblems, parse
from study.folder.measure_library import MEASURES

RATE = 100.0   # Hz of the synthetic drives


def drive(seconds: float = 120.0, **channels) -> dict:
    """A drive at 100 Hz (t exact multiples of 10 ms), 10 m/s, with `channels` as functions of t."""
    t = np.arange(int(seconds * RATE)) / RATE
    cols = {"t": t, "s": 10.0 * t, "v": np.full(len(t), 10.0), "a": np.zeros(len(t)),
            "speed_limit": np.full(len(t), 50 / 3.6)}
    cols.update({k: np.asarray(f(t), float) for k, f in channels.items()})
    return drive_arrays(cols)


def value(measure: str, d: dict, sel=slice(None), **options) -> float:
    opts = {**MEASURES[measure].defaults(), **options}
    return FUNCTIONS[measure](d, sel, opts)


# ------------------------------------------------------------------------------------------- worked examples
def test_sdlp_is_the_n_minus_1_standard_deviation_worked_example():
    # lateral positions 0.1, -0.1, 0.2, -0.2 m: mean 0, sum of squares 0.1, / (4 - 1) -> sqrt(0.0333) = 0.182574
    d = drive_arrays({"t": np.arange(4.0), "s": np.arange(4.0), "v": np.ones(4), "a": np.zeros(4),
                      "speed_limit": np.ones(4), "lat_pos": np.array([0.1, -0.1, 0.2, -0.2])})
    assert value("sdlp", d) == pytest.approx(math.sqrt(0.1 / 3), abs=1e-12)
    assert value("lateral_position_mean", d) == pytest.approx(0.0, abs=1e-15)


def test_entropy_of_errors_spread_over_the_nine_bins_is_one_and_of_one_bin_zero():
    alpha = 2.0
    one_per_bin = np.array([-6, -3, -1.5, -0.75, 0, 0.75, 1.5, 3, 6]) * alpha / 1.0
    assert entropy_of(one_per_bin, alpha) == pytest.approx(1.0, abs=1e-12)
    assert entropy_of(np.zeros(20), alpha) == 0.0
    # two bins with 3 and 1 errors: -(3/4 ln 3/4 + 1/4 ln 1/4) / ln 9 = 0.255937
    assert entropy_of(np.array([0, 0, 0, 10 * alpha]), alpha) == pytest.approx(
        -(0.75 * math.log(0.75) + 0.25 * math.log(0.25)) / math.log(9), abs=1e-12)


def test_the_taylor_prediction_is_exact_on_a_line_and_off_by_one_on_n_squared():
    n = np.arange(10.0)
    assert np.allclose(prediction_errors(3 * n + 1), 0.0)
    assert np.allclose(prediction_errors(n ** 2), 1.0)   # theta_p(n) = n^2 - 1 (worked in docs/measures.md)


def test_speed_exceedance_time_distance_and_share():
    # 60 s at 10 m/s under a limit of 50 km/h, then 60 s at 15 m/s (54 km/h): above the limit, and above it plus
    # 3 km/h; not above it plus 5 km/h. The last sample has no interval: 59.99 s of the 119.99 s drive
    d = drive(v=lambda t: np.where(t < 60, 10.0, 15.0))
    d["ds"] = np.append(np.diff(np.cumsum(d["v"]) / RATE), 0.0)
    assert value("speed_exceedance", d) == pytest.approx(59.99, abs=1e-9)
    assert value("speed_exceedance", d, tolerance_kmh=3.0) == pytest.approx(59.99, abs=1e-9)
    assert value("speed_exceedance", d, tolerance_kmh=5.0) == 0.0
    assert value("speed_exceedance", d, statistic="share") == pytest.approx(59.99 / 119.99, abs=1e-9)
    assert value("speed_exceedance", d, statistic="distance_m") == pytest.approx(15.0 * 59.99, abs=1e-6)


def test_speed_mean_sd_and_jerk_worked_examples():
    # speeds 10, 12, 14, 16 m/s: mean 13, SD sqrt(20 / 3) = 2.582; accelerations 0, 1, 1, -1, 0 at 1 s steps: jerks
    # 1, 0, -2, 1 m/s^3, max |j| = 2, RMS sqrt(6 / 4) = 1.2247
    t = np.arange(4.0)
    d = drive_arrays({"t": t, "s": t, "v": np.array([10, 12, 14, 16.0]), "a": np.zeros(4), "speed_limit": t})
    assert value("speed_mean", d) == 13.0
    assert value("speed_sd", d) == pytest.approx(math.sqrt(20 / 3), abs=1e-12)
    t = np.arange(5.0)
    d = drive_arrays({"t": t, "s": t, "v": t, "a": np.array([0, 1, 1, -1, 0.0]), "speed_limit": t})
    assert value("jerk", d, statistic="max_abs") == 2.0
    assert value("jerk", d, statistic="rms") == pytest.approx(math.sqrt(6 / 4), abs=1e-12)


def test_accelerator_to_brake_transition_worked_example():
    # 10 Hz; the event rises at sample 2 (0.2 s). Accelerator 20, 20, 20, 18, 6, 0.5, 0, ...: first at or below 1 %
    # at sample 5 (0.5 s); brake 0, ..., 2, 7, 30, 40: first at or above 5 % at sample 7 (0.7 s). Transition
    # 0.7 - 0.5 = 0.2 s (= brake reaction 0.5 s - accelerator release 0.3 s); with the brake at 1.5 %: sample 6, 0.1 s
    t = np.arange(10) / 10.0
    d = drive_arrays({"t": t, "s": t, "v": np.ones(10), "a": np.zeros(10), "speed_limit": np.ones(10),
                      "tor": np.array([0, 0, 1, 1, 1, 1, 1, 1, 1, 1.0]),
                      "accel_pedal": np.array([20, 20, 20, 18, 6, 0.5, 0, 0, 0, 0.0]),
                      "brake_pedal": np.array([0, 0, 0, 0, 0, 0, 2, 7, 30, 40.0])})
    assert value("accelerator_to_brake_time", d, event="tor") == pytest.approx(0.2, abs=1e-12)
    assert value("accelerator_to_brake_time", d, event="tor", brake_threshold_pct=1.5) == pytest.approx(0.1, abs=1e-12)
    assert value("brake_reaction_time", d, event="tor") == pytest.approx(0.5, abs=1e-12)
    assert value("accelerator_release_time", d, event="tor") == pytest.approx(0.3, abs=1e-12)


# ------------------------------------------------------------------------------------------- ground truth
@pytest.mark.parametrize("freq", [0.1, 0.25, 0.5, 1.0])
def test_srr_of_a_sine_counts_one_reversal_between_consecutive_extrema(freq):
    # a 120 s sine of amplitude 10 deg has 2 * freq * 120 extrema, hence 2 * freq * 120 - 1 reversals above a 2 deg gap
    d = drive(steering_angle=lambda t: 10.0 * np.sin(2 * np.pi * freq * t + 0.3))
    truth = (2 * freq * 120 - 1) / (119.99 / 60)
    assert value("steering_reversal_rate", d) == pytest.approx(truth, rel=0.02)


def test_srr_is_zero_on_a_constant_signal_and_on_a_sine_below_the_gap():
    assert value("steering_reversal_rate", drive(steering_angle=lambda t: 0 * t + 5.0)) == 0.0
    small = drive(steering_angle=lambda t: 0.8 * np.sin(2 * np.pi * 0.5 * t))   # 1.6 deg peak to peak
    assert value("steering_reversal_rate", small, gap_deg=2.0) == 0.0
    assert value("steering_reversal_rate", small, gap_deg=1.0) > 50


def test_reversal_count_on_a_hand_worked_series():
    # stationary points 3, 1, 4, 3.5, 6 (the ends are none): upward reversals 1 -> 4 and 3.5 -> 6 (2.5 >= 2),
    # downward 3 -> 1 (exactly the gap); 4 -> 3.5 is below it
    y = np.array([-1, 0, 3, 1, 4, 3.5, 6, 5.0])
    assert reversals(y, 2.0) == 3
    assert reversals(y, 2.6) == 1


def test_time_headway_of_a_lead_at_a_known_time_gap_and_the_option_conversions():
    # 20 m/s behind a lead vehicle 30 m ahead (time gap 1.5 s)
    d = drive(v=lambda t: 0 * t + 20.0, leader_gap=lambda t: 0 * t + 30.0)
    assert value("time_headway", d, option="C") == pytest.approx(1.5)
    # headway = gap + vehicle length (front to front: the lead's; rear to rear: the subject's)
    assert value("time_headway", d, option="A", lead_length_m=4.0) == pytest.approx((30 + 4.0) / 20)
    assert value("time_headway", d, option="B", subject_length_m=5.0) == pytest.approx((30 + 5.0) / 20)
    assert value("time_headway", d, option="C", statistic="share_below", threshold_s=2.0) == 1.0
    assert value("distance_gap", d) == 30.0


def test_headway_ignores_samples_without_lead_and_above_the_maximum():
    gap = lambda t: np.where(t < 30, np.nan, np.where(t < 60, 300.0, 10.0))   # none, 30 s (ignored), 1 s
    d = drive(leader_gap=gap)
    assert value("time_headway", d, option="C", statistic="mean") == pytest.approx(1.0)
    assert value("time_headway", d, option="C", statistic="share_below", threshold_s=1.5) == pytest.approx(1.0)
    none = drive(leader_gap=lambda t: np.full(len(t), np.nan))
    assert math.isnan(value("time_headway", none))


def test_ttc_of_a_closing_lead():
    # gap 40 m closing at 2 m/s: TTC = 20 s at the start, 40 - 2 t over 2 = 20 - t; 15 s logged -> min 5.01 s
    d = drive(15.0, leader_gap=lambda t: 40 - 2 * t, leader_v=lambda t: 0 * t + 8.0)
    assert value("ttc", d) == pytest.approx(20 - 14.99, abs=1e-9)
    # below 10 s from t = 10.01 s to the last sample (14.99 s, whose interval ends the drive): 4.98 s
    assert value("ttc", d, statistic="time_below_s", threshold_s=10.0) == pytest.approx(4.98, abs=1e-9)
    opening = drive(leader_gap=lambda t: 0 * t + 40, leader_v=lambda t: 0 * t + 12.0)
    assert math.isnan(value("ttc", opening))


def test_brake_reaction_and_accelerator_release_after_a_known_delay():
    d = drive(tor=lambda t: (t >= 30.0) & (t < 35.0), brake_pedal=lambda t: np.where(t >= 31.3, 60.0, 0.0),
              accel_pedal=lambda t: np.where(t >= 30.45, 0.0, 25.0))
    assert value("brake_reaction_time", d, event="tor") == pytest.approx(1.3, abs=1e-9)
    assert value("accelerator_release_time", d, event="tor") == pytest.approx(0.45, abs=1e-9)
    assert math.isnan(value("brake_reaction_time", d, event="tor", max_s=1.0))   # no response within 1 s
    assert value("brake_applications", d) == 1.0
    assert value("accelerator_to_brake_time", d, event="tor") == pytest.approx(1.3 - 0.45, abs=1e-9)


@pytest.mark.parametrize("rate", [100.0, 60.0, 20.0])
@pytest.mark.parametrize("release_s, brake_s", [(0.45, 1.3), (0.3, 0.3), (0.8, 2.4)])
def test_accelerator_to_brake_transition_of_a_known_release_and_brake(rate, release_s, brake_s):
    """The accelerator released `release_s` and the brake pressed `brake_s` after an event at 12.34 s: the tool
    returns the time between the first samples at or after the two instants, within one sample step of the truth
    brake_s - release_s (exactly it where both instants are samples)."""
    onset = 12.34
    t = np.arange(int(30 * rate)) / rate
    d = drive_arrays({"t": t, "s": 10 * t, "v": np.full(len(t), 10.0), "a": np.zeros(len(t)),
                      "speed_limit": np.full(len(t), 14.0), "tor": (t >= onset).astype(float),
                      "accel_pedal": np.where(t >= onset + release_s, 0.0, 30.0),
                      "brake_pedal": np.where(t >= onset + brake_s, 50.0, 0.0)})
    i_on, i_rel, i_brk = np.searchsorted(t, [onset, onset + release_s, onset + brake_s])   # first sample at or after
    got = value("accelerator_to_brake_time", d, event="tor")
    assert got == t[i_brk] - t[i_rel]
    assert abs(got - (brake_s - release_s)) < 1.0 / rate
    on_grid = all(abs(x * rate - round(x * rate)) < 1e-9 for x in (onset, onset + release_s, onset + brake_s))
    if on_grid:
        assert got == pytest.approx(brake_s - release_s, abs=1e-9)


def test_accelerator_to_brake_transition_is_null_without_a_movement_from_one_pedal_to_the_other():
    tor = lambda t: ((t >= 30.0) & (t < 31.0)) | ((t >= 60.0) & (t < 61.0))       # two events
    brake = lambda t: np.where((t >= 31.0) & (t < 40.0), 50.0, 0.0)              # after the first only
    on_then_off = lambda t: np.where((t >= 30.5) & (t < 50.0), 0.0, 25.0)
    d = drive(tor=tor, brake_pedal=brake, accel_pedal=on_then_off)
    assert value("accelerator_to_brake_time", d, event="tor") == pytest.approx(0.5, abs=1e-9)
    # the second event: released at 60 s (50 s on), never braked again -> NULL; the mean is the first event's
    assert value("accelerator_to_brake_time", d, event="tor", statistic="mean") == pytest.approx(0.5, abs=1e-9)
    # not on the accelerator at the event (brake reaction time defined, release time 0 s)
    off = drive(tor=tor, brake_pedal=brake, accel_pedal=lambda t: 0 * t)
    assert value("brake_reaction_time", off, event="tor") == pytest.approx(1.0, abs=1e-9)
    assert value("accelerator_release_time", off, event="tor") == 0.0
    assert math.isnan(value("accelerator_to_brake_time", off, event="tor"))
    # braked (two-footed) at 31 s before releasing at 31.5 s
    late = drive(tor=tor, brake_pedal=brake, accel_pedal=lambda t: np.where(t >= 31.5, 0.0, 25.0))
    assert math.isnan(value("accelerator_to_brake_time", late, event="tor"))
    # the brake beyond max_s (1 s after the onset is not within 0.9 s), the accelerator never released
    assert math.isnan(value("accelerator_to_brake_time", d, event="tor", max_s=0.9))
    held = drive(tor=tor, brake_pedal=brake, accel_pedal=lambda t: 0 * t + 25.0)
    assert math.isnan(value("accelerator_to_brake_time", held, event="tor"))
    # released and braking within the same sample: 0 s, shorter than the sample step
    same = drive(tor=tor, brake_pedal=brake, accel_pedal=lambda t: np.where(t >= 31.0, 0.0, 25.0))
    assert value("accelerator_to_brake_time", same, event="tor") == 0.0


def test_lane_departures_with_known_excursions():
    # the vehicle centre 1.0 m off the lane centre (edge at 1.9 m > 1.75 m) for 0.5 s, 1.0 s and 2.0 s
    def lat(t):
        out = ((t >= 10) & (t < 10.5)) | ((t >= 20) & (t < 21)) | ((t >= 30) & (t < 32))
        return np.where(out, 1.0, 0.2)
    d = drive(lat_pos=lat)
    assert value("lane_departure", d) == 3
    assert value("lane_departure", d, min_duration_s=0.75) == 2
    assert value("lane_departure", d, statistic="duration_total_s") == pytest.approx(3.5, abs=1e-9)
    assert value("lane_departure", d, statistic="duration_mean_s", min_duration_s=0.75) == pytest.approx(1.5)
    assert value("lane_departure", d, vehicle_width_m=1.0) == 0      # edge at 1.5 m: inside


# ------------------------------------------------------------------------------------------- laws
@pytest.mark.parametrize("offset", [-0.7, 0.0, 1.3])
def test_sdlp_is_invariant_to_a_constant_offset(offset):
    rng = np.random.default_rng(4)
    x = rng.normal(0, 0.25, 5000)
    a = drive(50.0, lat_pos=lambda t: x)
    b = drive(50.0, lat_pos=lambda t: x + offset)
    assert value("sdlp", a) == pytest.approx(value("sdlp", b), abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([0.0, 0.5, 1.0, 3.0, 20.0, 60.0]), min_size=40, max_size=40),
       st.lists(st.sampled_from([0.0, 2.0, 5.0, 10.0, 60.0]), min_size=40, max_size=40),
       st.integers(1, 30), st.sampled_from([0.5, 1.0, 3.0]), st.sampled_from([2.0, 5.0, 10.0]),
       st.sampled_from([0.5, 1.0, 10.0]), st.sampled_from(["first", "mean"]))
def test_transition_time_is_brake_reaction_minus_accelerator_release(accel, brake, onset, acc_pct, brk_pct, max_s,
                                                                     statistic):
    """With the same event, thresholds and max_s: wherever the transition time is defined it equals the brake
    reaction time minus the accelerator release time, and it is defined exactly when both are, the release is after
    the onset and the brake not before the release (one event, 10 Hz pedal traces drawn at random)."""
    t = np.arange(40) / 10.0
    d = drive_arrays({"t": t, "s": t, "v": np.ones(40), "a": np.zeros(40), "speed_limit": np.ones(40),
                      "tor": (np.arange(40) >= onset).astype(float), "accel_pedal": np.array(accel),
                      "brake_pedal": np.array(brake)})
    opts = {"event": "tor", "max_s": max_s, "statistic": statistic}
    brt = value("brake_reaction_time", d, threshold_pct=brk_pct, **opts)
    art = value("accelerator_release_time", d, threshold_pct=acc_pct, **opts)
    abt = value("accelerator_to_brake_time", d, accel_threshold_pct=acc_pct, brake_threshold_pct=brk_pct, **opts)
    defined = math.isfinite(brt) and math.isfinite(art) and art > 0 and brt >= art
    assert math.isfinite(abt) == defined
    if defined:
        assert abt == pytest.approx(brt - art, abs=1e-12)


def test_srr_scales_with_the_frequency_of_a_sine_above_the_gap():
    rates = [value("steering_reversal_rate", drive(steering_angle=lambda t: 5 * np.sin(2 * np.pi * f * t)))
             for f in (0.2, 0.4, 0.8)]
    assert rates[1] / rates[0] == pytest.approx(2.0, rel=0.02)
    assert rates[2] / rates[1] == pytest.approx(2.0, rel=0.02)


def test_entropy_is_higher_for_noisy_steering_than_for_smooth_steering():
    rng = np.random.default_rng(7)
    noise = rng.normal(0, 1.0, 12000)
    smooth = drive(steering_angle=lambda t: 5 * np.sin(2 * np.pi * 0.1 * t))
    noisy = drive(steering_angle=lambda t: 5 * np.sin(2 * np.pi * 0.1 * t) + np.cumsum(noise) * 0.05)
    for method in ("boer2005", "nakayama1999"):
        alpha = 0.05
        assert value("steering_entropy", noisy, method=method, alpha_deg=alpha) > \
            value("steering_entropy", smooth, method=method, alpha_deg=alpha)


def test_rms_jerk_measure_agrees_with_the_built_in_kpi():
    t = np.arange(3000) / 10.0
    v = 10 + 3 * np.sin(0.2 * t)
    frame = pd.DataFrame({"t": t, "s": np.cumsum(v) / 10, "v": v, "a": 0.6 * np.cos(0.2 * t) + 0.01 * np.sin(3 * t),
                          "segment": "urban", "speed_limit": 20.0, "tl_id": None, "tl_state": None})
    spec = parse('builtins = ["jerk"]\n[measures]\nj = { measure = "jerk", statistic = "rms" }\n')
    out = kpis_from_frame(frame, sql_kpis=spec.user_kpis)
    row = out[out["segment"] == "overall"].iloc[0]
    assert row["j"] == pytest.approx(row["rms_jerk"], rel=1e-9)


# ------------------------------------------------------------------------------------------- regions
def test_regions_by_position_time_segment_and_event_and_null_where_not_reached():
    t = np.arange(12000) / RATE
    frame = pd.DataFrame({"drive_id": 1, "idx": np.arange(len(t)), "t": t, "s": 10 * t, "v": 10.0, "a": 0.0,
                          "speed_limit": 14.0, "segment": np.where(t < 60, "town", "rural"),
                          "lat_pos": np.where(t < 60, 0.1, -0.3) + 0.05 * np.sin(t),
                          "tor": ((t >= 70) & (t < 71)).astype(float)})
    spec = parse('[measures]\nmlp = { measure = "lateral_position_mean" }\n[regions]\n'
                 'first_km = { s_from = 0, s_to = 1000 }\nlate = { t_from = 100, t_to = 200 }\n'
                 'rural = { segment = "rural" }\nafter_tor = { event = "tor", after_s = 10 }\n'
                 'beyond = { s_from = 5000, s_to = 6000 }\nnowhere = { segment = "urban" }\n')
    con = duckdb.connect()
    con.register("samples_in", frame)
    _, reg = measure_kpis(con, "samples_in", spec.measures, spec.regions)
    got = dict(zip(reg["region"], reg["mlp"]))
    lat = frame["lat_pos"].to_numpy()
    assert got["first_km"] == pytest.approx(lat[:10000].mean())     # s = 10 t < 1000 m: the first 100 s
    assert got["late"] == pytest.approx(-0.3 + 0.05 * np.sin(t[10000:]).mean())
    assert got["rural"] == pytest.approx(-0.3 + 0.05 * np.sin(t[6000:]).mean())
    assert got["after_tor"] == pytest.approx(-0.3 + 0.05 * np.sin(t[7000:8000]).mean())
    assert math.isnan(got["beyond"]) and math.isnan(got["nowhere"])


def test_measures_stream_across_record_batches(monkeypatch):
    import analysis.drives.measures as m

    monkeypatch.setattr(m, "_BATCH_ROWS", 777)   # drives split across many batches
    rng = np.random.default_rng(3)
    frames = [pd.DataFrame({"drive_id": k, "idx": np.arange(2000), "t": np.arange(2000) / 10, "s": np.arange(2000.0),
                            "v": 10.0, "a": 0.0, "speed_limit": 14.0, "segment": "a",
                            "lat_pos": rng.normal(0, 0.1 * (k + 1), 2000)}) for k in range(5)]
    con = duckdb.connect()
    con.register("samples_in", pd.concat(frames, ignore_index=True))
    spec = parse('[measures]\nsdlp = { measure = "sdlp" }\n')
    seg, _ = measure_kpis(con, "samples_in", spec.measures)
    assert seg["drive_id"].tolist() == list(range(5))
    assert np.allclose(seg["sdlp"], [f["lat_pos"].std(ddof=1) for f in frames], rtol=1e-12)


# ------------------------------------------------------------------------------------------- the declaration
def test_the_check_names_line_and_one_reason():
    text = ('[measures]\nsrr = { measure = "steering_reversal_rate", gap_deg = 50 }\n'
            'x = { measure = "nope" }\n'
            'thw = { measure = "time_headway" }\n'
            'brt = { measure = "brake_reaction_time", event = "tor", colour = 1 }\n'
            '[regions]\nr = { s_from = 10, s_to = 5 }\nq = { s_from = 1, t_to = 3 }\n')
    probs = KpiSpecProblems()
    assert parse(text, probs, mapped=("logmap.toml", {"t", "v", "s", "steering_angle", "brake_pedal", "tor"})) is None
    got = {(line, fld): msg for line, fld, msg in probs}
    assert got[(2, "measures.srr.gap_deg")] == "must be in [0.1, 20] deg, not 50"
    assert got[(3, "measures.x.measure")].startswith("'nope' is not a shipped measure")
    assert got[(4, "measures.thw")] == "needs channel 'leader_gap', which the log mapping logmap.toml does not map"
    assert got[(5, "measures.brt.colour")].startswith("is not an option of brake_reaction_time")
    assert got[(7, "regions.r")] == "s_to must be above s_from"
    assert (8, "regions.q") in got
    assert len(probs) == 6


def test_every_measure_has_a_methods_sentence_with_its_defaults():
    for name, m in MEASURES.items():
        opts = {o.name: "tor" for o in m.options if o.kind == "channel"}
        text = m.sentence(opts)
        assert text.startswith(m.title) and m.source in text and "{" not in text, name


def test_measures_are_kpis_for_within_and_comparison(tmp_path, capsys):
    import shutil

    from pedas_study.cli import main
    from tests.conftest import REPO

    folder = tmp_path / "cf"
    shutil.copytree(REPO / "studies" / "car_following", folder)
    with open(folder / "study.toml", "a", encoding="utf-8") as f:
        f.write('\n[within]\nconditions = ["no_warning", "fcw"]\nkpis = ["brt", "srr"]\n')
    with open(folder / "kpis.toml", "a", encoding="utf-8") as f:
        f.write('\n[comparison]\ncontrol = "no_warning"\ntreatment = "fcw"\n'
                '[comparison.columns]\nbrt = "brt"\n[comparison.reductions]\nbrt_reduction = "brt"\n')
    assert main(["study", "check", str(folder)]) == 0, capsys.readouterr().err
    (folder / "study.toml").write_text((folder / "study.toml").read_text().replace('"brt", "srr"', '"brt", "nope"'))
    code = main(["study", "check", str(folder)])
    assert code == 2 and "within.kpis" in capsys.readouterr().out


def test_region_summary_shows_each_measure_with_its_decimals():
    """region_summary.md rounds by the measure's unit (SDLP in m: 1 decimal) or its declared ``decimals``."""
    from analysis.drives.measure_tables import _cells

    spec = parse('[measures]\nsdlp = { measure = "sdlp" }\nmlp = { measure = "lateral_position_mean", decimals = 4 }\n'
                 '[regions]\nr = { s_from = 0, s_to = 10 }\n')
    summary = pd.DataFrame({"region": ["r"], "condition": ["hud"], "sdlp_n": [2], "sdlp_mean": [0.30000000000000004],
                            "sdlp_sd": [0.049999999999999996], "mlp_n": [2], "mlp_mean": [0.12345678],
                            "mlp_sd": [float("nan")]})
    _, rows = _cells(summary, spec)
    assert rows == [["r", "hud", "0.3 (0.0), 2", "0.1235 (–), 2"]]

"""Any simulator's drive logs and any route: log mappings (units with pint, extra channels), route files (joined
by position), plausibility checks (--force), energy source, SUMO FCD import and the paper's generated route file.

The lab's log is generated here: a seeded 60 Hz drive over the lane-keeping study's 5 km route (studies/lane_keeping
/route.toml) in the lab's own columns time_s, speed_kmh, pos_m, accel_pedal, brake_pedal, power_kW, lat_pos_m."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from functools import lru_cache

import numpy as np
import pandas as pd
import pytest

from study.folder.definition import check as check_study
from study.logs.stored import drive_samples, list_channels
from study.logs.importing import import_drive_file, import_drive_frame
from study.logs.validation import validate_drive
from study.common.errors import UserError
from study.folder.logmap import load_mapping
from study.folder.route_file import load_route
from study.store.store import Store
from tests.conftest import LK_STUDY, PAPER_STUDY

LAB_COLUMNS = ["time_s", "speed_kmh", "pos_m", "accel_pedal", "brake_pedal", "power_kW", "lat_pos_m"]


def lk_route():
    return load_route((LK_STUDY / "route.toml").read_text(encoding="utf-8"), "route.toml")


@lru_cache(maxsize=8)
def _lab_log(seed: int, rate: float, end_m: float) -> pd.DataFrame:
    from pedas.route import braking_envelope

    route = lk_route()
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    b, a_max = 1.5, 1.2
    grid = np.arange(0.0, route.length + 1.0)
    k = np.clip(np.searchsorted(route.s_from, grid, side="right") - 1, 0, len(route.s_from) - 1)
    target = braking_envelope(grid, 0.95 * route.speed_limit[k], b).tolist()  # slow down in time for a lower limit
    noise = rng.normal(0, 0.05, int(2 * route.length / 5.0 * rate)).tolist()
    t, s, v, acc = [0.0], [0.0], [0.0], [0.0]
    while s[-1] < end_m:
        a = min(max((target[int(s[-1])] - v[-1]) / 2.0, -b), a_max) + noise[len(t)]
        vn = max(0.0, v[-1] + a * dt)
        s.append(s[-1] + 0.5 * (v[-1] + vn) * dt)
        v.append(vn)
        acc.append(a)
        t.append(len(t) * dt)
    v, acc = np.array(v), np.array(acc)
    force = 1500 * acc + 0.5 * 1.2 * 0.7 * v ** 2 + 1500 * 9.81 * 0.01
    power_kw = np.where(force > 0, force * v / 0.9, force * v * 0.6) / 1000.0
    lat = np.cumsum(rng.normal(0, 0.003, v.size))
    return pd.DataFrame({"time_s": np.round(t, 6), "speed_kmh": np.round(v * 3.6, 4), "pos_m": np.round(s, 4),
                         "accel_pedal": np.round(np.clip(acc / a_max * 100, 0, 100), 2),
                         "brake_pedal": np.round(np.clip(-acc / b * 100, 0, 100), 2),
                         "power_kW": np.round(power_kw, 4), "lat_pos_m": np.round(lat - lat.mean(), 4)})


def lab_log(seed: int = 1, rate: float = 60.0, end_m: float = 4990.0) -> pd.DataFrame:
    """A lab's drive over the 5 km route: speed follows 95 % of the limit (braking ahead of lower limits at
    1.5 m/s^2, accelerating at most 1.2 m/s^2) with noise; power from a simple longitudinal model (kW)."""
    return _lab_log(seed, rate, end_m).copy()


def snapshot(db):
    with Store.open(db) as st:
        return (st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso"),
                st.columns("drive_samples"))


def add(db, *ids):
    from study.store.studies import definition

    with Store.open(db) as st:
        for pid in ids:
            st.insert("participants", {"participant_id": pid, "protocol": definition(st).protocol().name})


def init(db, folder):
    from study.store.studies import register

    with Store.open(db) as st:
        register(st, folder)
    return db


@pytest.fixture
def lk_db(tmp_db):
    init(tmp_db, LK_STUDY)
    add(tmp_db, "LK-01", "LK-02")
    return tmp_db


@pytest.fixture
def paper_db(tmp_db):
    return init(tmp_db, PAPER_STUDY)


@pytest.fixture
def lab_csv(tmp_path):
    path = tmp_path / "LK-01_hud.csv"
    lab_log(1).to_csv(path, index=False)
    return path


# ------------------------------------------------------------------------ the lab's logs through the mapping
def test_lab_log_imports_with_the_study_mapping(cli, lk_db, lab_csv):
    raw = pd.read_csv(lab_csv)
    r = cli("drive", "import", "LK-01", "hud", lab_csv)
    assert r.code == 0, r.err
    assert f"imported drive 1, {len(raw)} samples" in r.out
    assert "energy: measured; channels: accel_pedal, brake_pedal, lat_pos" in r.out
    with Store.open(lk_db) as st:
        ch = list_channels(st)
        assert ch[["channel", "unit"]].values.tolist() == [["accel_pedal", "%"], ["brake_pedal", "%"],
                                                            ["lat_pos", "m"]]
        back = drive_samples(st, "LK-01", "hud", channels=True)
        row = st.df("SELECT route, file_name, meta FROM drives").iloc[0]
        # queryable by name in SQL as well
        assert st.one("SELECT max(abs(lat_pos)) FROM drive_samples") == pytest.approx(raw["lat_pos_m"].abs().max())
    np.testing.assert_allclose(back["v"], raw["speed_kmh"] / 3.6, rtol=1e-15)
    np.testing.assert_allclose(back["p_batt"], raw["power_kW"] * 1000.0, rtol=1e-12)
    np.testing.assert_array_equal(back["lat_pos"], raw["lat_pos_m"])
    np.testing.assert_array_equal(back["accel_pedal"], raw["accel_pedal"])
    # limits and segments joined by position from route.toml (km/h there, m/s here)
    expect = np.select([raw["pos_m"] < 1400, raw["pos_m"] < 1900, raw["pos_m"] < 4300], [50, 30, 100], 50) / 3.6
    np.testing.assert_allclose(back["speed_limit"], expect, rtol=1e-12)
    assert back["segment"].unique().tolist() == ["town", "school_zone", "rural", "village"]
    # the next light ahead by position; none after the last one (1250 m)
    first = back.iloc[0]
    assert (first["tl_id"], first["d_tl"]) == ("TL1", 620.0)
    assert back.loc[back["s"] > 1250, "tl_id"].isna().all()
    assert back["ft"].isna().all() and back["a"].notna().all()  # no vehicle model declared: no forces
    meta = json.loads(row["meta"])
    assert row["route"] == "lk-5km" and row["file_name"] == "LK-01_hud.csv"
    assert meta["energy_source"] == "measured" and meta["log_mapping"] == "logmap.toml"
    assert meta["units"]["v"] == "km/h" and meta["from_route"] == ["speed_limit", "segment", "tl_id", "d_tl"]
    # same file again: nothing changes
    assert "unchanged" in cli("drive", "import", "LK-01", "hud", lab_csv).out
    r = cli("drive", "channels", "--format", "csv")
    assert r.code == 0 and r.out.splitlines()[0] == "channel,unit,description,added_at"


def test_second_drive_reuses_channels_and_replace_works(lk_db, tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    lab_log(1).to_csv(a, index=False)
    lab_log(2).to_csv(b, index=False)
    with Store.open(lk_db) as st:
        import_drive_file(st, "LK-01", "hud", a)
        cols = st.columns("drive_samples")
        r = import_drive_file(st, "LK-01", "no_hud", b)
        assert r.channels == ("accel_pedal", "brake_pedal", "lat_pos")
        assert st.columns("drive_samples") == cols and st.one("SELECT count(*) FROM drive_channels") == 3
        lab_log(3).to_csv(a, index=False)
        r = import_drive_file(st, "LK-01", "hud", a, replace=True)
        assert r.status == "replaced"
        n = st.one("SELECT count(*) FROM drive_samples WHERE lat_pos IS NOT NULL")
        assert n == len(pd.read_csv(a)) + len(pd.read_csv(b))


def test_parquet_with_map_option_and_unit_conversion(lk_db, tmp_path):
    """--map FILE for another format; mph, ms and ft are converted; an extra channel may be stored in `to`."""
    raw = lab_log(4)
    other = pd.DataFrame({"ms": raw["time_s"] * 1000.0, "mph": raw["speed_kmh"] / 1.609344,
                          "dist_ft": raw["pos_m"] / 0.3048, "lat_ft": raw["lat_pos_m"] / 0.3048,
                          "W": raw["power_kW"] * 1000.0})
    log = tmp_path / "other.parquet"
    other.to_parquet(log)
    mp = tmp_path / "other.toml"
    mp.write_text('[log]\nformat = "parquet"\nrate_hz = 60\n'
                  '[channels.t]\ncolumn = "ms"\nunit = "ms"\n'
                  '[channels.v]\ncolumn = "mph"\nunit = "mph"\n'
                  '[channels.s]\ncolumn = "dist_ft"\nunit = "ft"\n'
                  '[channels.p_batt]\ncolumn = "W"\nunit = "W"\n'
                  '[channels.lat_pos]\ncolumn = "lat_ft"\nunit = "ft"\nto = "m"\n')
    with Store.open(lk_db) as st:
        r = import_drive_file(st, "LK-02", "hud", log, mapping=mp)
        back = drive_samples(st, "LK-02", "hud", channels=["lat_pos"])
        assert list_channels(st)["unit"].tolist() == ["m"]
    assert r.status == "imported" and r.channels == ("lat_pos",)
    np.testing.assert_allclose(back["t"], raw["time_s"], atol=1e-9)
    np.testing.assert_allclose(back["v"], raw["speed_kmh"] / 3.6, rtol=1e-12)
    np.testing.assert_allclose(back["s"], raw["pos_m"], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(back["lat_pos"], raw["lat_pos_m"], atol=1e-12)


def test_channel_unit_conflict_refused(lk_db, lab_csv, tmp_path):
    with Store.open(lk_db) as st:
        import_drive_file(st, "LK-01", "hud", lab_csv)
    text = (LK_STUDY / "logmap.toml").read_text().replace('column = "lat_pos_m"\nunit = "m"',
                                                          'column = "lat_pos_m"\nunit = "ft"')
    mp = tmp_path / "ft.toml"
    mp.write_text(text)
    log = tmp_path / "LK-02.csv"
    lab_log(5).to_csv(log, index=False)
    before = snapshot(lk_db)
    with Store.open(lk_db) as st, pytest.raises(UserError, match=r'channel lat_pos is stored in m, this log '
                                                                 r'mapping gives it in ft: add to = "m"'):
        import_drive_file(st, "LK-02", "hud", log, mapping=mp)
    assert snapshot(lk_db) == before


def test_refused_import_leaves_schema_and_channels_unchanged(lk_db, lab_csv):
    before = snapshot(lk_db)
    with Store.open(lk_db) as st:
        with pytest.raises(UserError, match="unknown participant LK-09"):
            import_drive_file(st, "LK-09", "hud", lab_csv)
        with pytest.raises(UserError, match="unknown condition 'baseline'"):
            import_drive_file(st, "LK-01", "baseline", lab_csv)
    assert snapshot(lk_db) == before


# ------------------------------------------------------------------------ plausibility
def test_kmh_read_as_ms_is_refused_with_one_line(cli, lk_db, tmp_path):
    """A speed in km/h read as m/s: on the 50 km/h town section the values (~47) pass the 70 m/s bound, the
    distance check does not."""
    lab_csv = tmp_path / "LK-01_hud.csv"
    lab_log(1, end_m=1300.0).to_csv(lab_csv, index=False)
    mp = tmp_path / "wrong.toml"
    mp.write_text((LK_STUDY / "logmap.toml").read_text().replace('unit = "km/h"', 'unit = "m/s"'))
    before = snapshot(lk_db)
    r = cli("drive", "import", "LK-01", "hud", lab_csv, "--map", mp)
    assert r.code == 2
    lines = r.err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"pedas-study: error: {lab_csv}: channel v (column speed_kmh, m/s) row ")
    assert "looks like a speed in km/h read as m/s" in lines[0] and "--force REASON" in lines[0]
    assert snapshot(lk_db) == before
    # a justified exception: imported, the reason and the overridden problem recorded
    r = cli("drive", "import", "LK-01", "hud", lab_csv, "--map", mp, "--force", "speed logger test run")
    assert r.code == 0 and "imported with --force despite: channel v" in r.err
    with Store.open(lk_db) as st:
        meta = json.loads(st.one("SELECT meta FROM drives"))
    assert meta["forced"]["reason"] == "speed logger test run"
    assert "km/h read as m/s" in meta["forced"]["overridden"][0]
    assert cli("drive", "import", "LK-02", "hud", lab_csv, "--force", " ").code == 2


def test_kmh_canonical_log_on_the_urban_route_refused(paper_db, tmp_path):
    """A canonical log whose v is in km/h (50 km/h town driving: v ~ 48 'm/s', within 0..70)."""
    n, dt = 600, 0.1
    v_ms = np.full(n, 13.3)
    s = np.arange(n) * dt * 13.3
    log = pd.DataFrame({"t": np.arange(n) * dt, "s": s, "v": v_ms * 3.6})  # no limit/segment: from the route
    path = tmp_path / "kmh.csv"
    log.to_csv(path, index=False)
    add(paper_db, "P001")
    with Store.open(paper_db) as st:
        with pytest.raises(UserError, match="^" + re.escape(str(path))
                           + r": column v row \d+: the integral of v dt since row 1 is "
                           r".* m \(ratio 3\.6, .*looks like a speed in km/h read as m/s"):
            import_drive_file(st, "P001", "baseline", path)
        assert st.one("SELECT count(*) FROM drives") == 0
        log.assign(v=v_ms).to_csv(path, index=False)
        r = import_drive_file(st, "P001", "baseline", path)
        back = drive_samples(st, "P001", "baseline")
    assert r.status == "imported" and r.energy_source == "modelled (Nissan Leaf parameters)"
    assert set(back["segment"]) == {"urban"} and np.allclose(back["speed_limit"], 13.89)
    assert back["p_batt"].notna().all()


@pytest.mark.parametrize("change, msg", [
    (lambda d: d.assign(time_s=d["time_s"] * 1000), r"channel t \(column time_s, s\) rows 1-\d+: median sampling "
                                                     r"interval 16\.667 s, .*60 Hz.*looks like a time in ms read as s"),
    (lambda d: d.drop(index=range(3000, 3060)), r"channel t \(column time_s, s\) row 3001: gap of 1\.01667 s"),
    (lambda d: d.assign(time_s=d["time_s"].where(d.index != 100, 1.0)), r"channel t \(column time_s, s\) row 101: "
                                                                         r"time step -0\.65 s is not positive"),
    (lambda d: d.assign(speed_kmh=d["speed_kmh"].where(d.index != 7, "fast")),
     r"channel v \(column speed_kmh, km/h\) row 8: 'fast' is not a number"),
    (lambda d: d.assign(pos_m=d["pos_m"] + 100), r"channel s \(column pos_m, m\) row \d+: position 50\d\d(\.\d+)? m is "
                                                  r"outside route lk-5km \(0–5000 m\)"),
    (lambda d: d.drop(columns="lat_pos_m"), r"the log has no column 'lat_pos_m' \(mapped to channel lat_pos"),
])
def test_bad_lab_logs_name_file_channel_and_row(lk_db, tmp_path, change, msg):
    path = tmp_path / "bad.csv"
    change(lab_log(1)).to_csv(path, index=False)
    before = snapshot(lk_db)
    with Store.open(lk_db) as st, pytest.raises(UserError, match="^" + re.escape(str(path)) + ": " + msg):
        import_drive_file(st, "LK-01", "hud", path)
    assert snapshot(lk_db) == before


def test_log_without_position_integrates_v(lk_db, tmp_path):
    """No s channel: s is the integral of v dt; a km/h speed read as m/s then makes the log longer than the route."""
    text = (LK_STUDY / "logmap.toml").read_text().replace('[channels.s]\ncolumn = "pos_m"\nunit = "m"\n', "")
    assert "[channels.s]" not in text
    mp = tmp_path / "nopos.toml"
    mp.write_text(text)
    log = tmp_path / "nopos.csv"
    raw = lab_log(6)
    raw.to_csv(log, index=False)
    with Store.open(lk_db) as st:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace('unit = "km/h"', 'unit = "m/s"'))
        with pytest.raises(UserError, match="^" + re.escape(str(log)) + r": channel s \(integrated from v\) row \d+: position .* is "
                                            r"outside route lk-5km"):
            import_drive_file(st, "LK-01", "hud", log, mapping=bad)
        r = import_drive_file(st, "LK-01", "hud", log, mapping=mp)
        back = drive_samples(st, "LK-01", "hud")
        meta = json.loads(st.one("SELECT meta FROM drives"))
    assert r.status == "imported" and meta["s"] == "integrated from v"
    np.testing.assert_allclose(back["s"], raw["pos_m"], atol=0.5)  # the logger's position, up to rounding


# ------------------------------------------------------------------------ energy
def test_no_power_and_no_model_leaves_energy_unavailable(lk_db, lab_csv, tmp_path):
    text = (LK_STUDY / "logmap.toml").read_text()
    mp = tmp_path / "nopower.toml"
    mp.write_text(text.replace('[channels.p_batt]\ncolumn = "power_kW"\nunit = "kW"\n', ""))
    assert "p_batt" not in mp.read_text()
    with Store.open(lk_db) as st:
        r = import_drive_file(st, "LK-01", "hud", lab_csv, mapping=mp)
        back = drive_samples(st, "LK-01", "hud")
        meta = json.loads(st.one("SELECT meta FROM drives"))
    assert r.energy_source == "unavailable" == meta["energy_source"]
    assert back["p_batt"].isna().all() and back["ft"].isna().all() and back["fb"].isna().all()


def test_simulated_frame_stored_unchanged(paper_db):
    """A complete simulated drive (all columns) is stored exactly as given: nothing joined or filled."""
    from pedas.drive import LOG_COLUMNS

    rng = np.random.default_rng(3)
    n = 400
    v = np.clip(12 + np.cumsum(rng.normal(0, 0.1, n)), 0, 30)
    df = pd.DataFrame({"t": np.arange(n) * 0.2, "s": np.concatenate([[0.0], np.cumsum(v[:-1] * 0.2)]), "v": v,
                       "segment": "urban", "speed_limit": 13.89, "a": rng.normal(0, 0.3, n),
                       "grade": rng.normal(0, 0.01, n), "ft": rng.normal(500, 50, n), "fb": 0.0,
                       "p_batt": rng.normal(8000, 500, n), "tl_id": "TL1", "tl_state": "green",
                       "d_tl": 300.0 - np.arange(n) * 0.5, "leader_gap": np.nan, "leader_v": np.nan,
                       "v_advice": 12.0, "controller": "rt", "hud_arrow": 0, "hud_in_band": True,
                       "warning": False})[list(LOG_COLUMNS)]
    add(paper_db, "P001")
    with Store.open(paper_db) as st:
        r = import_drive_frame(st, "P001", "pedas", df, seed=1, meta={"style": "normal"})
        back = drive_samples(st, "P001", "pedas")
    assert r.filled_columns == () and r.energy_source == "simulated"
    pd.testing.assert_frame_equal(back[["t", "s", "v", "a", "grade", "ft", "p_batt", "d_tl"]],
                                  df[["t", "s", "v", "a", "grade", "ft", "p_batt", "d_tl"]], check_exact=True)
    assert back["tl_id"].tolist() == df["tl_id"].tolist()


# ------------------------------------------------------------------------ mapping, route and study checks
@pytest.mark.parametrize("edit, msg", [
    (lambda t: t.replace('unit = "km/h"', 'unit = "kmh/x"'), "channels.v.unit: unknown unit 'kmh/x'"),
    (lambda t: t.replace('unit = "km/h"', 'unit = "kW"'), "channels.v.unit: unit 'kW' is not a unit of m/s "
                                                          "(v needs a speed)"),
    (lambda t: t.replace("[channels.lat_pos]", "[channels.order]"), "channels.order: channel name 'order' is an "
                                                                    "SQL keyword"),
    (lambda t: t.replace("[channels.lat_pos]", "[channels.idx]"), "channels.idx: channel name 'idx' is a column of "
                                                                  "the drive log itself"),
    (lambda t: t.replace("[channels.lat_pos]", "[channels.LatPos]"), "channel name 'LatPos' must be lower-case"),
    (lambda t: t.replace('column = "lat_pos_m"', 'column = "pos_m"'), "column 'pos_m' is already mapped to "
                                                                      "channel s"),
    (lambda t: t.replace('format = "csv"', 'format = "xlsx"'), "log.format: 'xlsx' is not one of"),
    (lambda t: t.replace("rate_hz = 60", "rate_hz = -1"), "log.rate_hz: must be a positive number"),
])
def test_mapping_problems_are_study_check_problems(tmp_path, edit, msg):
    folder = tmp_path / "lk"
    shutil.copytree(LK_STUDY, folder)
    (folder / "logmap.toml").write_text(edit((folder / "logmap.toml").read_text()))
    problems = [str(p) for p in check_study(folder)]
    assert any(p.startswith("logmap.toml:") and msg in p for p in problems), problems
    with pytest.raises(UserError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        load_mapping((folder / "logmap.toml").read_text(), "logmap.toml")


@pytest.mark.parametrize("file, edit, where, msg", [
    ("route.toml", lambda t: t.replace("s_from = 1900", "s_from = 1950"), "route.toml:24",
     "sections[2].s_from: must equal s_to of the section before (1900): sections are contiguous"),
    ("route.toml", lambda t: t.replace("speed_limit = 100", "speed_limit = 300"), "route.toml:",
     "above 70 m/s: check speed_unit"),
    ("route.toml", lambda t: t.replace('speed_unit = "km/h"', 'speed_unit = "km"'), "route.toml:8",
     "route.speed_unit: unit 'km' is not a unit of m/s"),
    ("route.toml", lambda t: t.replace("s = 4650", "s = 5650"), "route.toml:",
     "stops[0].s: 5650 lies outside the route (0–5000)"),
    ("route.toml", lambda t: t.replace('["red", 27]', '["blue", 27]'), "route.toml:",
     "lights[0].phases: a list of [state, seconds]"),
    ("study.toml", lambda t: t.replace('route = "route.toml"', ""), "logmap.toml:",
     "channels.speed_limit: not mapped and the study declares no route"),
    ("study.toml", lambda t: t + '\n[drives]\nenergy_model = "tesla_s"\n', "study.toml:",
     "drives.energy_model: unknown vehicle model 'tesla_s' (known: nissan_leaf)"),
])
def test_route_and_settings_problems(tmp_path, file, edit, where, msg):
    folder = tmp_path / "lk"
    shutil.copytree(LK_STUDY, folder)
    (folder / file).write_text(edit((folder / file).read_text()))
    problems = [str(p) for p in check_study(folder)]
    assert any(p.startswith(where) and msg in p for p in problems), problems


def test_shipped_studies_check_clean():
    assert check_study(LK_STUDY) == [] and check_study(PAPER_STUDY) == []


def test_route_join_fills_only_absent_columns():
    route = lk_route()
    frame = pd.DataFrame({"s": [0.0, 1399.9, 1400.0, 4300.0, 5000.0]})
    out, added = route.join(frame)
    assert added == ("speed_limit", "segment", "tl_id", "d_tl")
    assert out["segment"].tolist() == ["town", "town", "school_zone", "village", "village"]
    np.testing.assert_allclose(out["speed_limit"] * 3.6, [50, 50, 30, 50, 50])
    assert out["tl_id"].fillna("-").tolist() == ["TL1", "-", "-", "-", "-"]  # lights at 620 and 1250 m
    assert out["d_tl"].iloc[0] == 620.0 and out["d_tl"].iloc[1:].isna().all()
    kept, added = route.join(frame.assign(segment="mine", speed_limit=1.0, tl_state="red"))
    assert added == () and kept["segment"].eq("mine").all()
    with pytest.raises(UserError, match="row 2: position 5001 m is outside route lk-5km"):
        route.join(pd.DataFrame({"s": [10.0, 5001.0]}))


def test_segments_must_be_the_routes_labels(paper_db, tmp_path):
    add(paper_db, "P001")
    n = 100
    log = pd.DataFrame({"t": np.arange(n) * 0.1, "v": 10.0, "s": np.arange(n) * 1.0, "segment": "rural",
                        "speed_limit": 13.89})
    path = tmp_path / "rural.csv"
    log.to_csv(path, index=False)
    with Store.open(paper_db) as st, pytest.raises(UserError, match="^rural.csv: column segment row 1: 'rural' "
                                                                    "is not one of urban|highway"):
        import_drive_file(st, "P001", "baseline", path)


def test_validate_drive_unchanged_for_canonical_logs():
    """No mapping: messages name columns as before."""
    df = pd.DataFrame({"t": [0.0, 0.1], "s": [0.0, 1.0], "v": [10.0, 80.0], "segment": "urban",
                       "speed_limit": 13.89})
    with pytest.raises(UserError, match="^column v row 2: speed 80 m/s outside 0..70 m/s$"):
        validate_drive(df)


# ------------------------------------------------------------------------ the paper's route and SUMO FCD
@pytest.mark.sumo
def test_paper_route_file_is_generated_from_the_network(tmp_path):
    from pedas.route_study import study_route, write_route_file

    out = write_route_file(tmp_path / "route.toml")
    assert out.read_bytes() == (PAPER_STUDY / "route.toml").read_bytes()
    rf = load_route(out.read_text(), "route.toml")
    route = study_route()
    assert rf.length == pytest.approx(route.length, abs=1e-3)
    assert [tl.id for tl in rf.lights] == [tl.tl_id for tl in route.lights]
    assert [tl.phases for tl in rf.lights] == [tl.phases for tl in route.lights]
    # the route's limits and segments agree with the route description on its grid (away from section ends)
    grid = pd.DataFrame({"s": route.s})
    joined, _ = rf.join(grid)
    inside = np.ones(route.s.size, bool)
    for a in rf.s_from:
        inside &= np.abs(route.s - a) > 1.0
    np.testing.assert_allclose(joined["speed_limit"][inside], route.speed_limit[inside])
    assert (joined["segment"].astype(str).to_numpy()[inside] == route.segment[inside]).all()


def run_sumo_fcd(tmp_path, seconds: int = 60):
    """A short SUMO run of the study network: the ego and one other car from the start of the route (FCD XML)."""
    from pedas.network import binary, build_network
    from pedas.route_study import ego_edges

    routes = tmp_path / "r.rou.xml"
    routes.write_text(f'<routes><vType id="car" length="4.45"/><route id="r" edges="{" ".join(ego_edges())}"/>'
                      '<vehicle id="ego" type="car" route="r" depart="0" departSpeed="0"/>'
                      '<vehicle id="other" type="car" route="r" depart="8" departSpeed="0"/></routes>')
    fcd = tmp_path / "fcd.xml"
    subprocess.run([str(binary("sumo")), "-n", str(build_network()), "-r", str(routes), "--end", str(seconds),
                    "--step-length", "0.1", "--fcd-output", str(fcd), "--fcd-output.attributes",
                    "x,y,speed,pos,lane,odometer,acceleration,slope", "--no-step-log", "true",
                    "--xml-validation", "never", "--no-warnings", "true"], check=True, capture_output=True,
                   timeout=120)
    return fcd


@pytest.mark.sumo
def test_sumo_fcd_import_with_the_paper_mapping(cli, paper_db, tmp_path):
    fcd = run_sumo_fcd(tmp_path)
    add(paper_db, "P001")
    r = cli("drive", "import", "P001", "baseline", fcd)
    assert r.code == 2 and "fcd.xml holds 2 vehicles (ego, other): name one with --vehicle" in r.err
    r = cli("drive", "import", "P001", "baseline", fcd, "--vehicle", "ego")
    assert r.code == 0, r.err
    assert "imported drive 1, 600 samples" in r.out and "energy: modelled (Nissan Leaf parameters)" in r.out
    from study.logs.fcd import read_fcd

    raw = read_fcd(fcd, "ego")
    with Store.open(paper_db) as st:
        back = drive_samples(st, "P001", "baseline")
        row = st.df("SELECT route, meta FROM drives").iloc[0]
    np.testing.assert_allclose(back["s"], raw["pos"].iloc[0] + raw["odometer"], atol=1e-9)
    np.testing.assert_allclose(back["v"], raw["speed"])
    np.testing.assert_allclose(back["grade"], np.radians(raw["slope"]))
    assert set(back["segment"]) == {"urban"} and back["p_batt"].notna().all()
    assert back["tl_id"].iloc[0] == "TL1" and back["d_tl"].iloc[0] == pytest.approx(342.5 - back["s"].iloc[0])
    meta = json.loads(row["meta"])
    assert row["route"] == "study-13.2km" and meta["vehicle"] == "ego" and meta["format"] == "sumo-fcd"

"""Event KPIs and query KPIs a study declares (study.folder.kpi_spec, analysis.drives.user_kpis): takeover times on
hand-built drives worked by hand, a query KPI with a window and a sub-query, the refusals of `study check`, and the
declared label and unit in the rendered tables.

The study is the lane-keeping study with two more channels in its log mapping (``takeover_request`` and
``hands_on``, 0/1 columns of the lab's log), imported through the mapping, plus one drive imported as a frame
(:func:`study.logs.importing.import_drive_frame`) whose ``warning`` column (a standard boolean column) starts an event."""
from __future__ import annotations

import re
import shutil

import numpy as np
import pandas as pd
import pytest

from study.common.errors import UserError
from study.folder.kpi_spec import KpiSpecProblems, parse
from tests.conftest import LK_STUDY

RATE = 60.0          # Hz, the lab's logger (studies/lane_keeping/logmap.toml)
N = 9300             # samples: 155 s at 13 m/s, 0.37 m .. 2015 m (town, school_zone from 1400 m, rural from 1900 m)

MAPPING_EXTRA = '''
[channels.takeover_request]
column = "takeover_req"
unit = "1"
description = "the simulator asks the driver to take over (1) or not (0)"

[channels.hands_on]
column = "hands_on_wheel"
unit = "1"
description = "capacitive steering-wheel sensor: hands on (1) or off (0)"
'''

# the first takeover time as a query: a window (lag) finds the rising edges, sub-queries take the first one
TAKEOVER_QUERY = """
WITH edges AS (
    SELECT t FROM (SELECT t, takeover_request > 0 AS req,
                          lag(takeover_request > 0) OVER (ORDER BY idx) AS req_before FROM samples)
    WHERE req AND NOT req_before
)
SELECT min(t) FILTER (WHERE hands_on > 0 AND t >= (SELECT min(t) FROM edges)) - (SELECT min(t) FROM edges)
FROM samples
"""

KPIS = f'''builtins = ["time"]
group_by = ["condition"]
channels = ["lat_pos", "takeover_request", "hands_on"]

[sql]
sdlp = {{ sql = "stddev_samp(lat_pos)", per_segment = true, unit = "m", label = "SDLP" }}

[sql.takeover_query]
query = """{TAKEOVER_QUERY}"""
unit = "s"
label = "Takeover time (query)"

[sql.departures]   # entries of the lateral position beyond 0.5 m: a window over a sub-query
query = """
SELECT count(*) FROM (SELECT lat_pos > 0.5 AS out, lag(lat_pos > 0.5) OVER (ORDER BY idx) AS before FROM samples)
WHERE out AND NOT before"""
per_segment = true
label = "Lane departures"

[events]
takeover_time = {{ from = "takeover_request", to = "hands_on", unit = "s", label = "Takeover time" }}
takeover_mean = {{ from = "takeover_request", to = "hands_on", statistic = "mean" }}
takeover_max = {{ from = "takeover_request", to = "hands_on", statistic = "max" }}
requests = {{ from = "takeover_request", to = "hands_on", statistic = "count", per_segment = true }}
warning_reaction = {{ from = "warning", to = "v < 5", label = "Reaction to the warning" }}
'''


def takeover_folder(tmp_path, kpis: str = KPIS):
    """The lane-keeping study with the two takeover channels mapped and `kpis` as its KPI file."""
    folder = tmp_path / "takeover_study"
    shutil.copytree(LK_STUDY, folder)
    (folder / "logmap.toml").write_text((folder / "logmap.toml").read_text() + MAPPING_EXTRA)
    (folder / "kpis.toml").write_text(kpis)
    return folder


def flags(*runs) -> np.ndarray:
    """0/1 over the N samples, 1 on each half-open index run (first, stop)."""
    x = np.zeros(N)
    for a, b in runs:
        x[a:b] = 1.0
    return x


def lab_log(request, hands, lat=None) -> pd.DataFrame:
    """A drive in the lab's CSV format at 60 Hz and 13 m/s: t = idx / 60 s (idx 600 is t = 10.0 s)."""
    t = np.arange(N) / RATE
    return pd.DataFrame({"time_s": t, "speed_kmh": 13.0 * 3.6, "pos_m": 13.0 * t + 0.37, "accel_pedal": 20.0,
                         "brake_pedal": 0.0, "power_kW": 8.0, "lat_pos_m": np.zeros(N) if lat is None else lat,
                         "takeover_req": request, "hands_on_wheel": hands})


# (participant, condition) -> the lab log, and what it holds, worked by hand
DRIVES = {
    # one request at t = 10.0 s (idx 600), hands on at 11.35 s (idx 681): 1.35 s; three lane departures, two in
    # town (idx 1000, 3000: 217 m, 650 m) and one in the school zone (idx 8000: 1733.7 m)
    ("LK-01", "hud"): lab_log(flags((600, 900)), flags((681, N)),
                              0.6 * flags((1000, 1060)) + 0.7 * flags((3000, 3030)) + 0.8 * flags((8000, 8060))),
    # no request at all
    ("LK-01", "no_hud"): lab_log(flags(), flags((0, N))),
    # two requests: t = 10.0 s (town) answered at 11.35 s, t = 120.0 s (idx 7200, 1560.4 m: school zone) answered
    # at 122.2 s (idx 7332): 1.35 s and 2.2 s
    ("LK-02", "hud"): lab_log(flags((600, 660), (7200, 7300)), flags((681, 900), (7332, N))),
    # the request is on at the drive's first sample (no observed onset: no event) and again from t = 50 s, but the
    # hands never come back after 40 s: one event without a response
    ("LK-02", "no_hud"): lab_log(flags((0, 60), (3000, 3100)), flags((0, 2400))),
}


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """The takeover study's store with the drives of DRIVES (imported through the log mapping) and one LK-03 hud
    drive imported as a frame: warning at t = 20.0 s, then braking at 3 m/s^2."""
    from pedas_study.cli import main
    from study.logs.importing import import_drive_frame
    from study.store.store import Store

    tmp = tmp_path_factory.mktemp("events")
    db = tmp / "events.duckdb"
    assert main([f"--db={db}", "init", "--study", str(takeover_folder(tmp))]) == 0
    for pid in ("LK-01", "LK-02", "LK-03"):
        assert main([f"--db={db}", "participant", "add", pid, "--attr", "age=30"]) == 0
    for (pid, cond), log in DRIVES.items():
        path = tmp / f"{pid}_{cond}.csv"
        log.to_csv(path, index=False)
        assert main([f"--db={db}", "drive", "import", pid, cond, str(path)]) == 0
    t = np.arange(601) / 20.0                                      # 30 s at 20 Hz
    v = np.where(t < 20.0, 10.0, np.maximum(10.0 - 3.0 * (t - 20.0), 0.0))   # brakes at 3 m/s^2 from 20 s
    s = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 / 20.0)]) + 1.0
    # v = 5.05 m/s at 21.65 s, 4.9 m/s at 21.70 s: the first sample with v < 5 is at 21.70 s
    frame = pd.DataFrame({"t": t, "s": s, "v": v, "warning": t >= 20.0})
    with Store.open(db) as st:
        import_drive_frame(st, "LK-03", "hud", frame)
    return db


def kpis_of(db, spec=None) -> pd.DataFrame:
    from analysis.drives.kpis import store_kpis
    from study.store.store import Store

    with Store.open(db, read_only=True) as st:
        return store_kpis(st, spec=spec)


def test_takeover_time_worked_by_hand(store):
    k = kpis_of(store)
    o = k[k["segment"] == "overall"].set_index(["participant_id", "condition"])
    first, mean, most, n = (o[c] for c in ("takeover_time", "takeover_mean", "takeover_max", "requests"))
    # LK-01 hud: request at 10.0 s, hands on at 11.35 s
    assert first["LK-01", "hud"] == pytest.approx(1.35, abs=1e-12)
    assert (mean["LK-01", "hud"], most["LK-01", "hud"], n["LK-01", "hud"]) == (pytest.approx(1.35, abs=1e-12),
                                                                            pytest.approx(1.35, abs=1e-12), 1)
    # no request: no takeover time (NULL), zero requests
    assert pd.isna(first["LK-01", "no_hud"]) and pd.isna(mean["LK-01", "no_hud"]) and n["LK-01", "no_hud"] == 0
    # two requests, 1.35 s and 2.2 s: the first, the mean 1.775 s, the longest 2.2 s, two events
    assert first["LK-02", "hud"] == pytest.approx(1.35, abs=1e-12)
    assert mean["LK-02", "hud"] == pytest.approx((1.35 + 2.2) / 2, abs=1e-12)
    assert most["LK-02", "hud"] == pytest.approx(2.2, abs=1e-12)
    assert n["LK-02", "hud"] == 2
    # a request on at the first sample is no event; the one at 50 s is never answered: NULL, one event
    assert pd.isna(first["LK-02", "no_hud"]) and pd.isna(most["LK-02", "no_hud"]) and n["LK-02", "no_hud"] == 1
    # the frame-imported drive: warning (a boolean column) at 20.0 s, v < 5 m/s (a condition) first at 21.70 s
    assert o.loc[("LK-03", "hud"), "warning_reaction"] == pytest.approx(1.70, abs=1e-12)
    assert pd.isna(o.loc[("LK-01", "hud"), "warning_reaction"])       # the lab's logs have no warning column
    assert pd.isna(n["LK-03", "hud"])       # no request channel in that log: not logged, which is not 0 requests


def test_events_per_segment_belong_to_the_segment_of_their_onset(store):
    k = kpis_of(store).set_index(["participant_id", "condition", "segment"])
    assert k.loc[("LK-02", "hud", "town"), "requests"] == 1
    assert k.loc[("LK-02", "hud", "school_zone"), "requests"] == 1
    assert k.loc[("LK-02", "hud", "rural"), "requests"] == 0
    # not declared per segment: empty in the segment rows
    assert k.loc[("LK-02", "hud", "town"), ["takeover_time", "takeover_query"]].isna().all()


def test_query_kpi_with_window_and_subquery_by_hand(store):
    k = kpis_of(store).set_index(["participant_id", "condition", "segment"])
    q = k["takeover_query"].xs("overall", level="segment")
    assert q["LK-01", "hud"] == pytest.approx(1.35, abs=1e-12)
    assert q["LK-02", "hud"] == pytest.approx(1.35, abs=1e-12)
    assert pd.isna(q["LK-01", "no_hud"]) and pd.isna(q["LK-02", "no_hud"])
    # per segment, `samples` holds the segment's rows: two departures in town, one in the school zone
    dep = k.loc[("LK-01", "hud"), "departures"]
    assert (dep["overall"], dep["town"], dep["school_zone"], dep["rural"]) == (3, 2, 1, 0)
    assert k.loc[("LK-02", "hud", "overall"), "departures"] == 0


def test_query_kpi_more_than_one_row_is_refused_and_no_view_stays(store):
    from analysis.drives.kpis import store_kpis
    from study.store.store import Store

    spec = parse('builtins = ["time"]\nchannels = ["hands_on"]\n[sql]\n'
                 'hands = { query = "SELECT t FROM samples WHERE hands_on > 0 ORDER BY idx LIMIT 2" }\n')
    assert spec is not None            # the check cannot know the rows: the run refuses them
    with Store.open(store, read_only=True) as st:
        with pytest.raises(UserError, match=r"KPI hands \(drive \d+\): its query returned 2 rows"):
            store_kpis(st, spec=spec)
        import duckdb

        with pytest.raises(duckdb.CatalogException):
            st.con.execute("SELECT * FROM samples")


def test_an_unchecked_query_is_checked_before_it_runs(store):
    """A KPI built in code (not from a KPI file) gets the same check before it touches the store."""
    from dataclasses import replace

    from study.folder.kpi_spec import SqlKpi

    spec = parse('builtins = ["time"]\n')
    spec = replace(spec, sql=(SqlKpi("n", "SELECT count(*) FROM drives", query=True),))
    with pytest.raises(UserError, match="KPI n: reads table drives"):
        kpis_of(store, spec)


def test_label_and_unit_head_the_markdown_and_latex_tables(store, cli, tmp_path):
    r = cli("analyze", "drives", "--out", tmp_path / "o", db=store)
    assert r.code == 0, r.err
    md = (tmp_path / "o" / "kpi_table.md").read_text()
    tex = (tmp_path / "o" / "kpi_table.tex").read_text()
    # a long header is set on two lines (\makecell): read it as one
    tex = re.sub(r"\\makecell\[b\]\{(.*?)\}", lambda m: m.group(1).replace(" \\\\ ", " "), tex)
    header = next(ln for ln in md.splitlines() if ln.startswith("|"))
    for heading in ("SDLP (m) mean (SD)", "Lane departures mean (SD)", "takeover mean (s) mean (SD)",
                    "requests mean (SD)", "distance (m) mean (SD)"):   # identifiers as words
        assert heading in header, heading
        assert heading in tex, heading
    # the takeover times of these drives are one value throughout: left out with a line saying so, each by its
    # declared label with its value in the declared unit (to the unit's decimals)
    assert "Takeover time" not in header
    assert ("Constant across all drives and left out: Takeover time (query) = 1.35 s, Takeover time = 1.35 s, "
            "Reaction to the warning = 1.70 s.") in md
    assert "SDLP (m) mean (SD)" in r.out
    # the CSV files keep the KPI names
    kpis = pd.read_csv(tmp_path / "o" / "kpis.csv")
    assert list(kpis.columns[6:]) == ["distance_m", "trip_time_s", "mean_speed_mps", "sdlp", "takeover_query",
                                      "departures", "takeover_time", "takeover_mean", "takeover_max", "requests",
                                      "warning_reaction"]
    table = pd.read_csv(tmp_path / "o" / "kpi_table.csv")
    assert "takeover_time_mean" in table.columns
    hud = table[(table["condition"] == "hud") & (table["segment"] == "overall")].iloc[0]
    assert hud["takeover_time_mean"] == pytest.approx(1.35, abs=1e-12)   # LK-01, LK-02 (LK-03 has no request)


# ------------------------------------------------------------------------------------------ refusals
BASE = 'builtins = ["time"]\nchannels = ["lat_pos", "takeover_request", "hands_on"]\n\n'


@pytest.mark.parametrize("entry,reason", [
    ('[sql.bad]\nquery = "SELECT count(*) FROM drives"\n', "reads table drives: a KPI query reads only samples"),
    ('[sql.bad]\nquery = "SELECT count(*) FROM read_csv(\'x\')"\n', "calls read_csv(): a KPI query reads only samples"),
    ('[sql.bad]\nquery = "DELETE FROM samples"\n', "must be a read-only SELECT or WITH query, not DELETE"),
    ('[sql.bad]\nquery = "SELECT max(t) FROM samples; SELECT min(t) FROM samples"\n',
     "must be one statement (a SELECT or WITH query), found 2"),
    ('[sql.bad]\nquery = "SELECT min(t), max(t) FROM samples"\n', "must return one column (the KPI), found 2"),
    ('[sql.bad]\nquery = "ATTACH \'other.duckdb\' AS other"\n', "must be a read-only SELECT or WITH query, not ATTACH"),
    ('[sql.bad]\nquery = "SELECT count(*) FROM duckdb_tables"\n', "reads table duckdb_tables"),
    ('[sql.bad]\nquery = "SELECT count(*) FROM glob(\'*\')"\n', "calls glob()"),
    ('[sql.bad]\nquery = "COPY samples TO \'x.csv\'"\n', "not COPY"),
    ('[sql.bad]\nquery = "SELECT avg(random()) FROM samples"\n', "calls random(), which changes from run to run"),
    ('[sql.bad]\nquery = "SELECT 42"\n', "does not read samples"),
    ('[sql.bad]\nquery = "SELECT any_value(segment) FROM samples"\n', "must return a number, not VARCHAR"),
    ('[events.bad]\nfrom = "takeover_request"\nto = "avg(hands_on) > 0"\n', "is an aggregate"),
    ('[events.bad]\nfrom = "segment"\nto = "hands_on"\n', "'segment' is VARCHAR"),
    ('[events.bad]\nfrom = "takeover_request"\nto = "(SELECT 1)"\n', "must be one condition per sample"),
    ('[events.bad]\nfrom = "takeover_request"\nto = "hands_on"\nstatistic = "median"\n',
     "'median' is not one of first|mean|max|count"),
    ('[events.bad]\nfrom = "takeover_request"\nto = "hands_on"\ndecimals = 11\n',
     "must be a whole number from 0 to 10, not 11"),
    ('[sql.bad]\nsql = "count(*)"\ndecimals = 2.5\n', "must be a whole number from 0 to 10, not 2.5"),
    ('[sql.bad]\nquery = "SELECT max(t) FROM samples"\ndecimals = -1\n', "must be a whole number from 0 to 10"),
    ('[sql.bad]\nsql = "count(*)"\ndecimals = "2"\n', "must be a whole number from 0 to 10, not '2'"),
])
def test_study_check_refuses_bad_query_and_event_kpis(cli, tmp_path, entry, reason):
    folder = takeover_folder(tmp_path, BASE + entry)
    r = cli("study", "check", folder, db=None)
    assert r.code == 2
    lines = [ln for ln in (r.out + r.err).splitlines() if "kpis.toml:" in ln]
    assert len(lines) == 1, r.out + r.err
    where, fld, message = lines[0].split(": ", 2)          # file:line: field: message
    assert fld.split(".")[:2] in (["sql", "bad"], ["events", "bad"]), lines[0]
    assert reason in message
    # the line named is the one that holds the refused text
    line_no = int(where.rsplit(":", 1)[1])
    key = fld.split(".")[2] if fld.count(".") == 2 else ("query" if fld.startswith("sql") else None)
    text = (folder / "kpis.toml").read_text().splitlines()[line_no - 1]
    assert key is None or text.startswith(key), (line_no, text)


def test_init_refuses_a_study_with_a_bad_query_kpi(cli, tmp_path, tmp_db):
    folder = takeover_folder(tmp_path, BASE + '[sql.bad]\nquery = "SELECT count(*) FROM drive_samples"\n')
    r = cli("init", "--study", folder, db=tmp_db)
    assert r.code == 2 and len(r.err.strip().splitlines()) == 1
    assert "kpis.toml" in r.err and "reads table drive_samples" in r.err


def test_query_and_event_forms_parse():
    probs = KpiSpecProblems()
    spec = parse(KPIS, probs)
    assert spec is not None, probs
    assert [k.name for k in spec.sql] == ["sdlp", "takeover_query", "departures"]
    assert [k.query for k in spec.sql] == [False, True, True]
    assert [(k.name, k.statistic, k.unit) for k in spec.events] == [
        ("takeover_time", "first", "s"), ("takeover_mean", "mean", "s"), ("takeover_max", "max", "s"),
        ("requests", "count", ""), ("warning_reaction", "first", "s")]
    assert spec.headings["takeover_time"] == "Takeover time (s)" and spec.headings["sdlp"] == "SDLP (m)"
    assert spec.headings["departures"] == "Lane departures"
    # a name is declared once across [sql] and [events]; sql and query exclude each other
    probs = KpiSpecProblems()
    assert parse(BASE + '[sql]\nx = "count(*)"\n[events]\nx = { from = "hands_on", to = "hands_on" }\n'
                 '[sql.y]\nsql = "count(*)"\nquery = "SELECT count(*) FROM samples"\n', probs) is None
    assert sorted(f for _, f, _ in probs) == ["events.x", "sql.y"]


def test_kpis_are_shown_with_the_decimals_of_their_unit_and_stored_in_full():
    """For reading, a time in s has 2 decimals (2.200000000000003 s reads 2.20), a distance in m 1, a share 3, a
    count none; the CSV files keep the full value."""
    from analysis.drives.tables import _summary_cells
    from study.folder.kpi_spec import KpiSpec

    spec = KpiSpec(builtins=("distance", "violations"))
    t = pd.DataFrame({"condition": ["hud"], "n": [3], "distance_m_mean": [2250.6715463999994],
                      "distance_m_sd": [14.18], "trip_time_s_mean": [2.200000000000003], "trip_time_s_sd": [0.0],
                      "violation_share_mean": [0.01234], "violation_share_sd": [0.0],
                      "violation_events_mean": [2.0], "violation_events_sd": [1.0]})
    _, rows = _summary_cells(t, spec)
    assert rows[0][2:] == ["2250.7 (14.2)", "2.20 (0.00)", "0.012 (0.000)", "2 (1)"]


def test_a_kpi_declares_its_own_decimals_over_those_of_its_unit():
    """``decimals = 3`` on a KPI in s shows it with 3 (the unit's default: 2); a measure takes the key too (it is no
    option of the measure); 0 is a declaration, not a missing one."""
    from analysis.drives.tables import _summary_cells

    spec = parse(BASE + '[events]\ntakeover_time = { from = "takeover_request", to = "hands_on", decimals = 3 }\n'
                        'reaction = { from = "takeover_request", to = "hands_on" }\n'
                        '[sql]\nsdlp = { sql = "stddev_samp(lat_pos)", unit = "m", decimals = 0 }\n'
                        '[measures]\nsrr = { measure = "sdlp", decimals = 4 }\n')
    assert spec is not None
    assert [spec.decimals(k) for k in ("takeover_time", "reaction", "sdlp", "srr", "trip_time_s")] == [3, 2, 0, 4, 2]
    t = pd.DataFrame({"condition": ["hud"], "n": [2], "takeover_time_mean": [1.3499999999999996],
                      "takeover_time_sd": [0.0], "reaction_mean": [1.3499999999999996], "reaction_sd": [0.0],
                      "sdlp_mean": [0.2849], "sdlp_sd": [0.01]})
    _, rows = _summary_cells(t, spec)
    assert rows[0][2:] == ["1.350 (0.000)", "1.35 (0.00)", "0 (0)"]


def test_analyze_drives_prints_kpis_without_float_noise_and_the_csv_keeps_them(store, cli, tmp_path):
    """The 20 Hz takeover time 11.35 s - 10.0 s is 1.3499999999999996 in binary: printed 1.35, stored in full."""
    r = cli("analyze", "drives", "--out", tmp_path / "o", db=store)
    assert r.code == 0, r.err
    assert not re.search(r"\d\.\d{6,}", r.out), r.out
    for md in (tmp_path / "o").glob("*.md"):
        assert not re.search(r"\d\.\d{6,}", md.read_text()), md.name
    row = next(ln for ln in r.out.splitlines() if ln.startswith("| hud | overall"))
    heads = next(ln for ln in r.out.splitlines() if ln.startswith("| Condition")).split(" | ")
    assert row.split(" | ")[heads.index("Takeover time (s) mean (SD)")].startswith("1.35 (")
    kpis = pd.read_csv(tmp_path / "o" / "kpis.csv")
    full = kpis[(kpis["participant_id"] == "LK-01") & (kpis["condition"] == "hud")
                & (kpis["segment"] == "overall")]["takeover_time"].iloc[0]
    assert full == 11.35 - 10.0 != 1.35                   # the CSV keeps the value as computed

"""Objective KPIs of drive logs, per drive and per segment (urban, highway, overall), in DuckDB SQL.

One window pass over ``drive_samples`` (neighbours of each sample in drive and idx order) turns each sample into the
interval to the next sample and flags the few change points (violation on/off, stop/moving, traffic-light change,
red-light stand-still). The intervals are summed per drive and segment; the change points ride along in the same
group-by as short lists and are resolved by small windows over them. No Python loop per row.

Definitions (units SI unless the column name says otherwise; see docs/kpis.md for the reasoning):

* interval ``i`` = samples ``i -> i+1`` of a drive, attributed to the segment of sample ``i`` (left point).
* ``energy_wh``: battery energy, trapezoid of ``p_batt`` (W) over ``t`` (s), / 3600. Positive = drawn from the
  battery; recuperation counts negative.
* ``distance_m`` = sum of ``s[i+1] - s[i]``; ``trip_time_s`` = sum of ``t[i+1] - t[i]``; ``mean_speed_mps`` =
  distance / time.
* speed-limit violation at sample ``i``: ``v > speed_limit + tol`` with ``tol = max(tol_abs, tol_rel * speed_limit)``
  (default 3 km/h, 3 %: the German enforcement deduction). ``violation_distance_m`` = distance of intervals whose
  left sample violates; ``violation_share`` = that / distance; ``violation_events`` = entries into violation whose
  episode (entry sample to the first non-violating sample, or the drive's end) lasts at least ``min_event_s``.
* TL crossing: ``tl_id`` changes from a light X to another value or NULL; its state is ``tl_state`` at the last
  sample before the change (``tl_crossed_green`` / ``_yellow`` / ``_red``), its segment that sample's segment.
* ``tl_green_passes``: crossings in green on an approach without a red stop — the light passed on a green wave,
  the count the paper's Fig. 10 shows ("empty entries: the driver stopped at all lights").
* red stop: ``v < v_stop`` while ``tl_state = 'red'`` and ``d_tl < red_stop_dist`` — counted once per approach to a
  light (an approach = a run of samples with the same ``tl_id``).
* stop: ``v`` drops below ``v_stop`` (0.5 m/s) after having been above ``v_moving`` (2 m/s) — hysteresis, so
  creeping in a queue is one stop.
* ``rms_jerk`` = sqrt(time-weighted mean of ((a[i+1] - a[i]) / dt)^2) in m/s^3; ``mean_abs_a`` = time-weighted mean
  of ``|a[i]|`` in m/s^2. Where ``a`` is not logged, :func:`fill_acceleration` (central differences of ``v``)
  fills it before the SQL runs.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from pedas.constants import KMH
from pedas.vocabulary import SEGMENTS as ROUTE_SEGMENTS

SEGMENTS = (*ROUTE_SEGMENTS, "overall")  # KPI rows: each route segment and the whole drive

#: The columns of drive_samples the KPIs read.
KPI_COLUMNS = ("drive_id", "idx", "t", "s", "v", "segment", "speed_limit", "a", "p_batt",
               "tl_id", "tl_state", "d_tl")

#: Output columns of :func:`kpis_from_relation`, in order.
KPI_FIELDS = ("drive_id", "segment", "n_intervals", "energy_wh", "distance_m", "trip_time_s", "mean_speed_mps",
              "wh_per_km", "violation_distance_m", "violation_share", "violation_events", "tl_crossed",
              "tl_crossed_green", "tl_crossed_yellow", "tl_crossed_red", "tl_green_passes", "red_stops", "stops",
              "rms_jerk", "mean_abs_a")


@dataclass(frozen=True)
class KpiParams:
    """Thresholds of the KPI definitions (module docstring); every value is documented in docs/kpis.md."""
    tol_abs: float = 3.0 * KMH      # m/s, absolute speeding tolerance (German enforcement deduction <= 100 km/h)
    tol_rel: float = 0.03           # share of the limit, tolerance above 100 km/h (same rule)
    min_event_s: float = 1.0        # s, a violation episode shorter than this is not an event
    v_stop: float = 0.5             # m/s, below = standing
    v_moving: float = 2.0           # m/s, above = moving (hysteresis for stop counting)
    red_stop_dist: float = 50.0     # m, stand-still closer than this to a red light's stop line = red stop

    def sql_params(self) -> dict:
        return asdict(self)


# The KPI query. `p0` reads each sample with its neighbours; in "stream" mode the neighbours come from an
# un-partitioned window over the relation's own order (checked first by `in_drive_order`), in "sorted" mode from
# PARTITION BY drive_id ORDER BY idx. Neighbours from another drive are masked in both modes. The change points
# (a few % of the rows) are collected as lists in the same group-by (one scan; a second filtered scan cost ~20 %
# more CPU) and resolved by small windows after unnesting.
_KPI_SQL = """
WITH p0 AS NOT MATERIALIZED (
    SELECT drive_id, idx, t, s, v, segment, speed_limit, a, p_batt, tl_id, tl_state, d_tl,
           lead(drive_id) OVER {w} = drive_id AS same_next,
           lag(drive_id) OVER {w} = drive_id  AS same_prev,
           lead(t) OVER {w} AS t_n, lead(s) OVER {w} AS s_n, lead(p_batt) OVER {w} AS p_n,
           lead(a) OVER {w} AS a_n, lead(tl_id) OVER {w} AS tl_n,
           lag(v > speed_limit + greatest($tol_abs, $tol_rel * speed_limit)) OVER {w} AS viol_p,
           lag((CASE WHEN v < $v_stop THEN 1 WHEN v > $v_moving THEN 2 END)::UTINYINT) OVER {w} AS st_p
    FROM {src} {where}
    {window}
),
p1 AS NOT MATERIALIZED (
    SELECT drive_id, idx, t, v, segment, tl_id, tl_state, d_tl, a,
           CASE WHEN same_next THEN t_n - t END                    AS dt,
           CASE WHEN same_next THEN s_n - s END                    AS ds,
           CASE WHEN same_next THEN (p_batt + p_n) / 2.0 END       AS p_mid,
           CASE WHEN same_next THEN a_n END                        AS a1,
           v > speed_limit + greatest($tol_abs, $tol_rel * speed_limit) AS viol,   -- speeding at sample i
           CASE WHEN same_prev THEN viol_p END                     AS viol_prev,
           (CASE WHEN v < $v_stop THEN 1 WHEN v > $v_moving THEN 2 END)::UTINYINT AS st,  -- 1 stand, 2 move
           CASE WHEN same_prev THEN st_p END                       AS st_prev,
           CASE WHEN same_next THEN tl_n END                       AS tl_next
    FROM p0
),
p2 AS NOT MATERIALIZED (  -- change-point flags
    SELECT *,
           viol IS DISTINCT FROM viol_prev                          AS viol_chg,
           st IS NOT NULL AND st IS DISTINCT FROM st_prev           AS st_chg,
           -- last sample before the light ahead changes: a crossing (the drive's last sample is none)
           tl_id IS NOT NULL AND dt IS NOT NULL AND tl_id IS DISTINCT FROM tl_next AS tl_cross,
           v < $v_stop AND tl_state = 'red' AND d_tl < $red_stop_dist AND tl_id IS NOT NULL AS red_cand
    FROM p1
),
groups AS (
    SELECT drive_id, segment,
           count(dt)                                                AS n_intervals,
           sum(p_mid * dt) / 3600.0                                 AS energy_wh,
           sum(ds)                                                  AS distance_m,
           sum(dt)                                                  AS trip_time_s,
           sum(ds) FILTER (WHERE viol)                              AS violation_distance_m,
           sum((a1 - a) * (a1 - a) / dt) FILTER (WHERE dt > 0)      AS jerk2_dt,   -- (da/dt)^2 dt
           sum(dt) FILTER (WHERE a1 IS NOT NULL AND a IS NOT NULL AND dt > 0) AS jerk_time,
           sum(abs(a) * dt)                                         AS abs_a_dt,
           sum(dt) FILTER (WHERE a IS NOT NULL)                     AS a_time,
           max(t)                                                   AS t_last,
           -- the change points (a few % of the rows) ride along in the same scan
           list(struct_pack(idx := idx, t := t, viol := viol, tl_state := tl_state, viol_chg := viol_chg,
                            st := st, st_chg := st_chg, tl_cross := tl_cross, red_cand := red_cand))
             FILTER (WHERE viol_chg OR st_chg OR tl_cross OR red_cand) AS pts
    FROM p2
    GROUP BY drive_id, segment
),
pts AS MATERIALIZED (  -- change points only, ordered within each drive by the windows below
    SELECT drive_id, segment, unnest(pts, recursive := true) FROM groups
),
drive_end AS (
    SELECT drive_id, max(t_last) AS t_end FROM groups GROUP BY drive_id
),
viol_ep AS (   -- violation episodes: entry point to the next change point (or the drive's end)
    SELECT p.drive_id, p.segment, p.viol,
           coalesce(lead(p.t) OVER (PARTITION BY p.drive_id ORDER BY p.idx), e.t_end) - p.t AS dur
    FROM pts p JOIN drive_end e USING (drive_id)
    WHERE p.viol_chg
),
viol_ev AS (
    SELECT drive_id, segment, count(*) AS violation_events
    FROM viol_ep WHERE viol AND dur >= $min_event_s GROUP BY ALL
),
stop_pts AS (
    SELECT drive_id, segment, st, lag(st) OVER (PARTITION BY drive_id ORDER BY idx) AS st_before
    FROM pts WHERE st_chg
),
stop_ev AS (
    SELECT drive_id, segment, count(*) AS stops
    FROM stop_pts WHERE st = 1 AND st_before = 2 GROUP BY ALL
),
cross_ev AS (
    SELECT drive_id, segment,
           count(*)                                    AS tl_crossed,
           count(*) FILTER (WHERE tl_state = 'green')  AS tl_crossed_green,
           count(*) FILTER (WHERE tl_state = 'yellow') AS tl_crossed_yellow,
           count(*) FILTER (WHERE tl_state = 'red')    AS tl_crossed_red
    FROM pts WHERE tl_cross GROUP BY ALL
),
approach AS (  -- approach number = crossings before this sample (a light's stand-stills share one number)
    SELECT drive_id, segment, idx, red_cand, tl_cross, tl_state,
           coalesce(sum(tl_cross::INT) OVER (PARTITION BY drive_id ORDER BY idx
                                              ROWS BETWEEN UNBOUNDED PRECEDING AND 1 PRECEDING), 0) AS appr
    FROM pts WHERE tl_cross OR red_cand
),
red_ev AS (
    SELECT drive_id, segment, count(*) AS red_stops
    FROM (SELECT drive_id, appr, arg_min(segment, idx) AS segment
          FROM approach WHERE red_cand GROUP BY drive_id, appr)
    GROUP BY ALL
),
green_pass AS (  -- crossed in green on an approach without a red stop (the paper's Fig. 10)
    SELECT a.drive_id, a.segment, count(*) AS tl_green_passes
    FROM approach a
    LEFT JOIN (SELECT DISTINCT drive_id, appr FROM approach WHERE red_cand) r
           ON a.drive_id = r.drive_id AND a.appr = r.appr
    WHERE a.tl_cross AND a.tl_state = 'green' AND r.appr IS NULL
    GROUP BY ALL
),
seg AS (
    SELECT g.drive_id, g.segment, g.n_intervals, g.energy_wh, g.distance_m, g.trip_time_s,
           coalesce(g.violation_distance_m, 0) AS violation_distance_m,
           coalesce(v.violation_events, 0) AS violation_events,
           coalesce(c.tl_crossed, 0) AS tl_crossed, coalesce(c.tl_crossed_green, 0) AS tl_crossed_green,
           coalesce(c.tl_crossed_yellow, 0) AS tl_crossed_yellow, coalesce(c.tl_crossed_red, 0) AS tl_crossed_red,
           coalesce(gp.tl_green_passes, 0) AS tl_green_passes,
           coalesce(r.red_stops, 0) AS red_stops, coalesce(s.stops, 0) AS stops,
           g.jerk2_dt, g.jerk_time, g.abs_a_dt, g.a_time
    FROM groups g
    LEFT JOIN viol_ev v USING (drive_id, segment)
    LEFT JOIN cross_ev c USING (drive_id, segment)
    LEFT JOIN red_ev r USING (drive_id, segment)
    LEFT JOIN stop_ev s USING (drive_id, segment)
    LEFT JOIN green_pass gp USING (drive_id, segment)
    WHERE g.segment IN ('urban', 'highway')
),
rolled AS (
    SELECT * FROM seg
    UNION ALL
    SELECT drive_id, 'overall', sum(n_intervals), sum(energy_wh), sum(distance_m), sum(trip_time_s),
           sum(violation_distance_m), sum(violation_events), sum(tl_crossed), sum(tl_crossed_green),
           sum(tl_crossed_yellow), sum(tl_crossed_red), sum(tl_green_passes), sum(red_stops), sum(stops),
           sum(jerk2_dt),
           sum(jerk_time), sum(abs_a_dt), sum(a_time)
    FROM seg GROUP BY drive_id
)
SELECT drive_id, segment, n_intervals::BIGINT AS n_intervals, energy_wh, distance_m, trip_time_s,
       distance_m / nullif(trip_time_s, 0)                        AS mean_speed_mps,
       energy_wh / nullif(distance_m / 1000.0, 0)                 AS wh_per_km,
       violation_distance_m,
       violation_distance_m / nullif(distance_m, 0)               AS violation_share,
       violation_events::BIGINT AS violation_events, tl_crossed::BIGINT AS tl_crossed,
       tl_crossed_green::BIGINT AS tl_crossed_green, tl_crossed_yellow::BIGINT AS tl_crossed_yellow,
       tl_crossed_red::BIGINT AS tl_crossed_red, tl_green_passes::BIGINT AS tl_green_passes,
       red_stops::BIGINT AS red_stops, stops::BIGINT AS stops,
       sqrt(jerk2_dt / nullif(jerk_time, 0))                      AS rms_jerk,
       abs_a_dt / nullif(a_time, 0)                               AS mean_abs_a
FROM rolled
ORDER BY drive_id, CASE segment WHEN 'urban' THEN 0 WHEN 'highway' THEN 1 ELSE 2 END
"""

_ORDER_CHECK_SQL = """
SELECT count(*) FILTER (WHERE pd = drive_id AND pi >= idx) AS backwards,
       count(*) FILTER (WHERE pd IS DISTINCT FROM drive_id) AS runs,
       count(DISTINCT drive_id)                             AS drives
FROM (SELECT drive_id, idx, lag(drive_id) OVER () AS pd, lag(idx) OVER () AS pi FROM {src} {where})
"""


def _check_name(src: str) -> str:
    if not src.replace("_", "").replace(".", "").isalnum():
        raise ValueError(f"not a relation name: {src!r}")
    return src


_RANGE = "WHERE drive_id >= $lo AND drive_id < $hi"  # one chunk of drives (parameters lo, hi)


def kpi_sql(src: str = "drive_samples", mode: str = "sorted", chunk: bool = False) -> str:
    """The KPI query over the relation ``src`` (a table or view with :data:`KPI_COLUMNS`); parameters are the
    fields of :class:`KpiParams` (``$tol_abs`` ...). ``mode="sorted"`` windows ``PARTITION BY drive_id ORDER BY
    idx`` (any row order); ``mode="stream"`` reads neighbours in the relation's own order, which must be grouped
    by drive and ascending in idx (:func:`in_drive_order`). ``chunk``: only the drives with ``$lo <= drive_id <
    $hi`` (a filter keeps the rows' order, so a chunk of a relation in drive order is in drive order)."""
    if mode == "sorted":
        w, window = "w", "WINDOW w AS (PARTITION BY drive_id ORDER BY idx)"
    elif mode == "stream":
        w, window = "()", ""
    else:
        raise ValueError(f"mode must be sorted or stream, not {mode!r}")
    return _KPI_SQL.format(src=_check_name(src), w=w, window=window, where=_RANGE if chunk else "")


def in_drive_order(con, src: str, lo_hi: tuple[int, int] | None = None) -> bool:
    """Whether ``src`` (or its drives ``lo <= drive_id < hi``) scans in drive order: each drive's rows contiguous
    and idx strictly ascending."""
    if not con.execute("SELECT current_setting('preserve_insertion_order')").fetchone()[0]:
        return False  # scans may reorder rows: un-partitioned windows would see an arbitrary order
    sql = _ORDER_CHECK_SQL.format(src=_check_name(src), where=_RANGE if lo_hi else "")
    backwards, runs, drives = con.execute(sql, dict(zip(("lo", "hi"), lo_hi or ()))).fetchone()
    return backwards == 0 and runs == drives


def kpis_from_relation(con, src: str, params: KpiParams | None = None, mode: str = "auto",
                       workers: int = 1) -> pd.DataFrame:
    """KPIs (one row per drive and segment, columns :data:`KPI_FIELDS`) of the samples in relation ``src`` on the
    DuckDB connection ``con``. NULL ``p_batt`` -> NULL energy, NULL ``a`` -> no jerk/|a| contribution.
    ``mode="auto"`` streams when the relation is already in drive order (one cheap check scan), else sorts.

    ``workers`` > 1 splits the drives into that many chunks of about equal rows and runs them at once, each on its
    own cursor: the streaming window is one thread per query, so this is what puts more cores to work. The
    relation must then be visible to other cursors (a table or view, not a TEMP one). Same result as one chunk.
    """
    from concurrent.futures import ThreadPoolExecutor

    params = params or KpiParams()
    chunks = _drive_chunks(con, src, workers) if workers > 1 else [None]

    def run(lo_hi):
        c = con.cursor() if lo_hi else con
        try:
            m = mode if mode != "auto" else ("stream" if in_drive_order(c, src, lo_hi) else "sorted")
            values = {**params.sql_params(), **dict(zip(("lo", "hi"), lo_hi or ()))}
            return c.execute(kpi_sql(src, m, chunk=lo_hi is not None), values).df()
        finally:
            if lo_hi:
                c.close()

    if len(chunks) == 1:
        parts = [run(chunks[0])]
    else:
        with ThreadPoolExecutor(len(chunks)) as pool:
            parts = list(pool.map(run, chunks))
    return pd.concat(parts, ignore_index=True)[list(KPI_FIELDS)]


def _drive_chunks(con, src: str, n: int) -> list[tuple[int, int] | None]:
    """Up to ``n`` drive-id ranges [lo, hi) with about equal numbers of rows (one aggregate scan)."""
    sizes = con.execute(f"SELECT drive_id, count(*) AS n FROM {_check_name(src)} GROUP BY drive_id "
                        "ORDER BY drive_id").df()
    if len(sizes) < 2:
        return [None]
    ids, cum = sizes["drive_id"].to_numpy(), sizes["n"].cumsum().to_numpy()
    cuts = sorted({int(ids[np.searchsorted(cum, cum[-1] * k / n)]) for k in range(1, n)} - {int(ids[0])})
    bounds = [int(ids[0])] + cuts + [int(ids[-1]) + 1]
    return list(zip(bounds[:-1], bounds[1:]))


def kpis_from_frame(samples: pd.DataFrame, params: KpiParams | None = None, con=None) -> pd.DataFrame:
    """KPIs of a drive-log DataFrame (columns as drive_samples; ``drive_id`` defaults to 1, ``idx`` to row order,
    missing optional columns to NULL). Uses an in-memory DuckDB unless ``con`` is given."""
    import duckdb

    df = _complete_columns(samples)
    own = con is None
    con = con or duckdb.connect()
    try:
        con.register("kpi_input_df", df)
        con.execute("CREATE OR REPLACE TEMP VIEW kpi_input AS SELECT * FROM kpi_input_df")
        return kpis_from_relation(con, "kpi_input", params)
    finally:
        con.unregister("kpi_input_df")
        if own:
            con.close()


def _complete_columns(samples: pd.DataFrame) -> pd.DataFrame:
    df = samples.copy()
    if "drive_id" not in df:
        df["drive_id"] = 1
    if "idx" not in df:
        df["idx"] = df.groupby("drive_id").cumcount()
    for col in ("a", "p_batt", "d_tl"):
        if col not in df:
            df[col] = np.nan
        df[col] = pd.to_numeric(df[col]).astype("float64")
    if df["a"].isna().any():
        df = df.sort_values(["drive_id", "idx"], kind="stable")
        fa = pd.concat([pd.Series(fill_acceleration(g["t"].to_numpy(float), g["v"].to_numpy(float)), index=g.index)
                        for _, g in df.groupby("drive_id", sort=False)])
        df["a"] = df["a"].fillna(fa)
    for col in ("segment", "tl_id", "tl_state"):
        if col not in df:
            df[col] = None
        df[col] = df[col].astype(object).where(df[col].notna(), None)
    return df[list(KPI_COLUMNS)]


def fill_acceleration(t, v) -> np.ndarray:
    """Acceleration (m/s^2) of a speed trace where the log has none: central differences (``numpy.gradient``),
    the same rule as the vehicle power model (``pedas.power.trace_power``); 0 for a single sample."""
    t, v = np.asarray(t, float), np.asarray(v, float)
    return np.gradient(v, t) if len(v) > 1 else np.zeros_like(v)


# ---------------------------------------------------------------------------------------------------- the store
def store_kpis(st, drive_ids=None, params: KpiParams | None = None) -> pd.DataFrame:
    """KPIs of the drives in the store ``st`` (a :class:`study.store.Store`), optionally only ``drive_ids``.

    Drives whose ``p_batt`` or ``a`` is (partly) NULL get them from the vehicle power model
    (``pedas.power.fill_drive_columns``) in a temporary table first; the store is not changed. The samples are
    copied into a temporary table in drive order so that the KPI query can stream.
    Joined with the drives table: columns participant_id, condition, then :data:`KPI_FIELDS`.
    """
    con = st.con
    where = ""
    if drive_ids is not None:
        ids = list(drive_ids)
        if not ids:
            return pd.DataFrame(columns=["participant_id", "condition", *KPI_FIELDS])
        con.execute("CREATE OR REPLACE TEMP TABLE kpi_drive_sel AS SELECT unnest($ids) AS drive_id", {"ids": ids})
        where = " WHERE drive_id IN (SELECT drive_id FROM kpi_drive_sel)"
    con.execute(f"""CREATE OR REPLACE TEMP VIEW kpi_src_raw AS
                    SELECT {', '.join(KPI_COLUMNS)}, grade FROM drive_samples{where}""")
    missing = [r[0] for r in con.execute(
        "SELECT DISTINCT drive_id FROM kpi_src_raw WHERE p_batt IS NULL OR a IS NULL ORDER BY 1").fetchall()]
    if missing:
        _fill_missing(con, missing)
        con.execute("""CREATE OR REPLACE TEMP TABLE kpi_src AS
            SELECT r.drive_id, r.idx, r.t, r.s, r.v, r.segment, r.speed_limit, coalesce(r.a, f.a) AS a,
                   coalesce(r.p_batt, f.p_batt) AS p_batt, r.tl_id, r.tl_state, r.d_tl
            FROM kpi_src_raw r LEFT JOIN kpi_fill f USING (drive_id, idx) ORDER BY r.drive_id, r.idx""")
    else:
        con.execute("CREATE OR REPLACE TEMP TABLE kpi_src AS SELECT * EXCLUDE (grade) FROM kpi_src_raw "
                    "ORDER BY drive_id, idx")
    k = kpis_from_relation(con, "kpi_src", params)
    drives = con.execute("SELECT drive_id, participant_id, condition FROM drives").df()
    return drives.merge(k, on="drive_id", how="inner")[["participant_id", "condition", *KPI_FIELDS]]


def _fill_missing(con, drive_ids) -> None:
    """``a`` and ``p_batt`` for the drives whose log lacks them, into TEMP TABLE kpi_fill(drive_id, idx, a,
    p_batt): a by :func:`fill_acceleration`, p_batt by the vehicle power model (``pedas.power.fill_drive_columns``
    on t, v, grade and a — the model of ``kpi energy``). Vectorised per drive, not per row."""
    from pedas.power import fill_drive_columns

    frames = []
    for drive_id in drive_ids:
        d = con.execute("SELECT idx, t, v, a, grade, p_batt FROM kpi_src_raw WHERE drive_id = $d ORDER BY idx",
                        {"d": drive_id}).df()
        a = d["a"].astype(float).fillna(pd.Series(fill_acceleration(d["t"], d["v"]), index=d.index))
        p = d["p_batt"].astype(float)
        if p.isna().any():
            model = fill_drive_columns(d[["t", "v", "grade"]].assign(a=a.to_numpy()))
            p = p.fillna(pd.Series(model["p_batt"].to_numpy(float), index=d.index))
        frames.append(pd.DataFrame({"drive_id": drive_id, "idx": d["idx"].to_numpy(), "a": a.to_numpy(),
                                    "p_batt": p.to_numpy()}))
    fill = pd.concat(frames, ignore_index=True)
    con.register("kpi_fill_df", fill)
    con.execute("CREATE OR REPLACE TEMP TABLE kpi_fill AS SELECT * FROM kpi_fill_df")
    con.unregister("kpi_fill_df")


"""Objective KPIs of drive logs, per drive and per segment (urban, highway, overall), in DuckDB SQL.

One window pass over ``drive_samples`` (neighbours of each sample in drive and idx order) turns each sample into the
interval to the next sample and flags the few change points (violation on/off, stop/moving, traffic-light change,
red-light stand-still). The intervals are summed per drive and segment; the change points ride along in the same
group-by as short lists and are resolved by small windows over them. No Python loop per row.

Definitions (units SI unless the column name says otherwise; see docs/kpis.md for the reasoning):

* interval ``i`` = samples ``i -> i+1`` of a drive, attributed to the segment of sample ``i`` (left point). The
  segments are the labels the drive log carries (declared by the study's route); rows come per segment in order of
  first appearance in the drive, then ``overall`` (the sum over the segments).
* ``energy_wh``: battery energy, trapezoid of ``p_batt`` (W) over ``t`` (s), / 3600. Positive = drawn from the
  battery; recuperation counts negative.
* ``distance_m`` = sum of ``s[i+1] - s[i]``; ``trip_time_s`` = sum of ``t[i+1] - t[i]``; ``mean_speed_mps`` =
  distance / time.
* speed-limit violation at sample ``i``: ``v > speed_limit + tol`` with ``tol = max(tol_abs, tol_rel * speed_limit)``
  (the study declares the rule, study.folder.kpi_spec; the defaults here, 3 km/h and 3 %, are the German enforcement
  deduction the paper's study declares). ``violation_distance_m`` = distance of intervals whose
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
* user KPIs (:class:`study.folder.kpi_spec.SqlKpi`): a DuckDB aggregate over the samples, computed in the same
  GROUP BY (grouping sets: per segment and per whole drive), so a non-additive statistic such as a standard
  deviation is exact for the whole drive too.
* query KPIs (``SqlKpi`` with ``query``): a read-only query over the relation ``samples``, run once per drive (and
  per segment) against a temporary view that holds that drive's (segment's) rows in idx order (:func:`query_kpis`).
* event KPIs (:class:`study.folder.kpi_spec.EventKpi`): the time from a rising edge of one condition to the next sample
  where another holds, all drives in one window pass and an ASOF join (:func:`event_kpis`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from study.folder.kpi_fields import KPI_COLUMNS, KPI_FIELDS, SAMPLE_COLUMNS, KpiParams  # noqa: F401
from study.folder.kpi_spec import EventKpi, MeasureKpi, study_spec
from analysis.drives.user_kpis import event_kpis, is_aggregate, place, query_kpis
from pedas.vocabulary import SEGMENTS as ROUTE_SEGMENTS

# the simulator's route segments and the whole drive: the row order of the pandas peer (analysis.survey.testing), which
# the SQL's order of first appearance reproduces on the simulator's routes (urban first)
SEGMENTS = (*ROUTE_SEGMENTS, "overall")

# The KPI query. `p0` reads each sample with its neighbours; in "stream" mode the neighbours come from an
# un-partitioned window over the relation's own order (checked first by `in_drive_order`), in "sorted" mode from
# PARTITION BY drive_id ORDER BY idx. Neighbours from another drive are masked in both modes. The change points
# (a few % of the rows) are collected as lists in the same group-by (one scan; a second filtered scan cost ~20 %
# more CPU) and resolved by small windows after unnesting.
_KPI_SQL = """
WITH p0 AS NOT MATERIALIZED (
    SELECT drive_id, idx, t, s, v, segment, speed_limit, a, p_batt, tl_id, tl_state, d_tl{extra0},
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
    SELECT drive_id, idx, t, v, segment, tl_id, tl_state, d_tl, a{extra},
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
    SELECT drive_id, segment, {gset} AS gset,
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
           min(idx)                                                 AS idx_first,{user_aggs}
           -- the change points (a few % of the rows) ride along in the same scan
           list(struct_pack(idx := idx, t := t, viol := viol, tl_state := tl_state, viol_chg := viol_chg,
                            st := st, st_chg := st_chg, tl_cross := tl_cross, red_cand := red_cand))
             FILTER (WHERE viol_chg OR st_chg OR tl_cross OR red_cand) AS pts
    FROM p2
    GROUP BY {group_by}
),
pts AS MATERIALIZED (  -- change points only, ordered within each drive by the windows below
    SELECT drive_id, segment, unnest(pts, recursive := true) FROM groups WHERE gset = 0
),
drive_end AS (
    SELECT drive_id, max(t_last) AS t_end FROM groups WHERE gset = 0 GROUP BY drive_id
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
           g.jerk2_dt, g.jerk_time, g.abs_a_dt, g.a_time, g.idx_first{user_seg}
    FROM groups g
    LEFT JOIN viol_ev v USING (drive_id, segment)
    LEFT JOIN cross_ev c USING (drive_id, segment)
    LEFT JOIN red_ev r USING (drive_id, segment)
    LEFT JOIN stop_ev s USING (drive_id, segment)
    LEFT JOIN green_pass gp USING (drive_id, segment)
    WHERE g.gset = 0 AND g.segment IS NOT NULL
),
rolled AS (
    SELECT * FROM seg
    UNION ALL
    SELECT drive_id, 'overall', sum(n_intervals), sum(energy_wh), sum(distance_m), sum(trip_time_s),
           sum(violation_distance_m), sum(violation_events), sum(tl_crossed), sum(tl_crossed_green),
           sum(tl_crossed_yellow), sum(tl_crossed_red), sum(tl_green_passes), sum(red_stops), sum(stops),
           sum(jerk2_dt),
           sum(jerk_time), sum(abs_a_dt), sum(a_time), NULL{user_all}
    FROM seg {user_join} GROUP BY drive_id
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
       abs_a_dt / nullif(a_time, 0)                               AS mean_abs_a{user_out}
FROM rolled
ORDER BY drive_id, idx_first NULLS LAST
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


def kpi_sql(src: str = "drive_samples", mode: str = "sorted", chunk: bool = False, sql_kpis=(),
            columns=None) -> str:
    """The KPI query over the relation ``src`` (a table or view with :data:`KPI_COLUMNS` and every column the
    ``sql_kpis`` read); parameters are the fields of :class:`KpiParams` (``$tol_abs`` ...). ``mode="sorted"``
    windows ``PARTITION BY drive_id ORDER BY idx`` (any row order); ``mode="stream"`` reads neighbours in the
    relation's own order, which must be grouped by drive and ascending in idx (:func:`in_drive_order`). ``chunk``:
    only the drives with ``$lo <= drive_id < $hi`` (a filter keeps the rows' order, so a chunk of a relation in
    drive order is in drive order). ``sql_kpis``: user KPIs that are aggregate expressions
    (:class:`study.folder.kpi_spec.SqlKpi` without ``query``, checked by :func:`study.folder.kpi_spec.check_sql`), one more column
    each after :data:`KPI_FIELDS`; ``columns``: the columns of ``src`` (default: the standard drive-log columns), so
    that the columns they read are carried."""
    if mode == "sorted":
        w, window = "w", "WINDOW w AS (PARTITION BY drive_id ORDER BY idx)"
    elif mode == "stream":
        w, window = "()", ""
    else:
        raise ValueError(f"mode must be sorted or stream, not {mode!r}")
    parts = dict(extra="", extra0="", gset="0", user_aggs="", group_by="drive_id, segment", user_seg="", user_all="",
                 user_join="", user_out="")
    if sql_kpis:
        # the per-drive value of a user KPI cannot be rolled up from its segments (a standard deviation is not a
        # sum): one GROUP BY with two grouping sets computes both from the same scan
        extra = sql_columns(sql_kpis, columns)
        parts.update(
            extra="".join(f", {c}" for c in extra),
            extra0="".join(f", {c}" for c in extra if c not in KPI_COLUMNS),
            gset="grouping(segment)",
            user_aggs="".join(f"\n           ({k.sql})::DOUBLE AS u_{k.name}," for k in sql_kpis),
            group_by="GROUPING SETS ((drive_id, segment), (drive_id))",
            user_seg="".join(f", {'g.u_' + k.name if k.per_segment else 'NULL::DOUBLE'} AS u_{k.name}"
                             for k in sql_kpis),
            user_all="".join(f", any_value(u.u_{k.name})" for k in sql_kpis),
            user_join="LEFT JOIN (SELECT drive_id, " + ", ".join(f"u_{k.name}" for k in sql_kpis)
                      + " FROM groups WHERE gset = 1) u USING (drive_id)",
            user_out="".join(f",\n       u_{k.name} AS {k.name}" for k in sql_kpis))
    return _KPI_SQL.format(src=_check_name(src), w=w, window=window, where=_RANGE if chunk else "", **parts)


#: columns the KPI query passes from p0 to p2 anyway (a user KPI reading another column gets it passed on)
_P2_COLUMNS = {"drive_id", "idx", "t", "v", "segment", "tl_id", "tl_state", "d_tl", "a"}


def sql_columns(sql_kpis, columns=None) -> list[str]:
    """Columns of the source (``columns``, default the standard drive-log columns) that the user KPIs read and the
    KPI query does not carry to its group-by by itself, in the source's order."""
    import re

    words = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", " ".join(k.sql for k in sql_kpis)))
    return [c for c in (columns or SAMPLE_COLUMNS) if c not in _P2_COLUMNS and c in words]


def in_drive_order(con, src: str, lo_hi: tuple[int, int] | None = None) -> bool:
    """Whether ``src`` (or its drives ``lo <= drive_id < hi``) scans in drive order: each drive's rows contiguous
    and idx strictly ascending."""
    if not con.execute("SELECT current_setting('preserve_insertion_order')").fetchone()[0]:
        return False  # scans may reorder rows: un-partitioned windows would see an arbitrary order
    sql = _ORDER_CHECK_SQL.format(src=_check_name(src), where=_RANGE if lo_hi else "")
    backwards, runs, drives = con.execute(sql, dict(zip(("lo", "hi"), lo_hi or ()))).fetchone()
    return backwards == 0 and runs == drives


def kpis_from_relation(con, src: str, params: KpiParams | None = None, mode: str = "auto",
                       workers: int = 1, sql_kpis=()) -> pd.DataFrame:
    """KPIs (one row per drive and segment, columns :data:`KPI_FIELDS` and then one per user KPI of ``sql_kpis``)
    of the samples in relation ``src`` on the DuckDB connection ``con``. NULL ``p_batt`` -> NULL energy, NULL ``a``
    -> no jerk/|a| contribution; a user KPI not declared per segment is NULL in the segment rows.
    ``mode="auto"`` streams when the relation is already in drive order (one cheap check scan), else sorts.
    ``sql_kpis`` may mix aggregate expressions (computed in the built-ins' pass), query KPIs (:func:`query_kpis`)
    and event KPIs (:func:`event_kpis`); the latter two read every column of ``src``.

    ``workers`` > 1 splits the drives into that many chunks of about equal rows and runs them at once, each on its
    own cursor: the streaming window is one thread per query, so this is what puts more cores to work. The
    relation must then be visible to other cursors (a table or view, not a TEMP one). Same result as one chunk.
    """
    from concurrent.futures import ThreadPoolExecutor

    params = params or KpiParams()
    user = tuple(sql_kpis)
    sql_kpis = tuple(k for k in user if is_aggregate(k))
    chunks = _drive_chunks(con, src, workers) if workers > 1 else [None]
    columns = [d[0] for d in con.execute(f"SELECT * FROM {_check_name(src)} LIMIT 0").description] if sql_kpis \
        else None

    def run(lo_hi):
        c = con.cursor() if lo_hi else con
        try:
            m = mode if mode != "auto" else ("stream" if in_drive_order(c, src, lo_hi) else "sorted")
            values = {**params.sql_params(), **dict(zip(("lo", "hi"), lo_hi or ()))}
            return c.execute(kpi_sql(src, m, chunk=lo_hi is not None, sql_kpis=sql_kpis, columns=columns),
                             values).df()
        finally:
            if lo_hi:
                c.close()

    if len(chunks) == 1:
        parts = [run(chunks[0])]
    else:
        with ThreadPoolExecutor(len(chunks)) as pool:
            parts = list(pool.map(run, chunks))
    out = pd.concat(parts, ignore_index=True)
    events = [k for k in user if isinstance(k, EventKpi)]
    measures = [k for k in user if isinstance(k, MeasureKpi)]
    queries = [k for k in user if not is_aggregate(k) and not isinstance(k, (EventKpi, MeasureKpi))]
    if measures:
        from analysis.drives.measures import measure_kpis

        ordered = in_drive_order(con, src)
        out = place(out, measure_kpis(con, src, measures, ordered=ordered)[0], measures)
    if events:
        out = place(out, event_kpis(con, src, events), events)
    if queries:
        out = place(out, query_kpis(con, src, out[["drive_id", "segment"]], queries), queries)
    return out[[*KPI_FIELDS, *(k.name for k in user)]]


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


def kpis_from_frame(samples: pd.DataFrame, params: KpiParams | None = None, con=None, sql_kpis=()) -> pd.DataFrame:
    """KPIs of a drive-log DataFrame (columns as drive_samples; ``drive_id`` defaults to 1, ``idx`` to row order,
    missing optional columns to NULL; other columns, e.g. extra channels, are kept for the user KPIs ``sql_kpis``).
    Uses an in-memory DuckDB unless ``con`` is given."""
    import duckdb

    df = _complete_columns(samples)
    if sql_kpis:
        df = pd.concat([df, samples[[c for c in samples.columns if c not in df.columns]].loc[df.index]], axis=1)
    own = con is None
    con = con or duckdb.connect()
    try:
        con.register("kpi_input_df", df)
        con.execute("CREATE OR REPLACE TEMP VIEW kpi_input AS SELECT * FROM kpi_input_df")
        return kpis_from_relation(con, "kpi_input", params, sql_kpis=sql_kpis)
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
MEASURED = "measured"
UNAVAILABLE = "unavailable"


def store_kpis(st, drive_ids=None, params: KpiParams | None = None, spec=None) -> pd.DataFrame:
    """KPIs of the drives in the store ``st`` (a :class:`study.store.store.Store`), optionally only ``drive_ids``, as the
    study declares them (``spec``: :class:`study.folder.kpi_spec.KpiSpec`, default the store's study's; ``params``
    overrides its thresholds). Columns participant_id, condition, phase (the drive phase of a drive outside the
    conditions, e.g. familiarisation; empty for a condition's drive), drive_id, segment, n_intervals, then the declared
    KPI columns (:attr:`KpiSpec.columns`). :func:`store_kpis_with_sources` also says where each energy comes from."""
    return store_kpis_with_sources(st, drive_ids, params, spec)[0]


def store_kpis_with_sources(st, drive_ids=None, params: KpiParams | None = None, spec=None
                            ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(:func:`store_kpis`, energy sources): the second frame has drive_id, energy_source — ``measured`` (the log
    has battery power; the import's ``energy_source`` in drives.meta when it recorded one), the vehicle model's
    label (``modelled (Nissan Leaf parameters)``) where the study declares ``[energy] model`` and the log has no
    power, or ``unavailable`` (no power, no model: the energy is NULL, never a substitute). Empty without energy.

    A drive with (partly) NULL ``a`` gets it by central differences, and with NULL ``p_batt`` its power from the
    model when declared, in a temporary table; the store is not changed. The samples are copied into a temporary
    table in drive order so that the KPI query can stream.
    """
    if spec is None:
        from study.store.studies import definition

        spec = study_spec(definition(st))
    params = params or spec.params
    out_cols = ["participant_id", "condition", "phase", "drive_id", "segment", "n_intervals", *spec.columns]
    con = st.con
    where = ""
    if drive_ids is not None:
        ids = list(drive_ids)
        if not ids:
            return pd.DataFrame(columns=out_cols), pd.DataFrame(columns=["drive_id", "energy_source"])
        con.execute("CREATE OR REPLACE TEMP TABLE kpi_drive_sel AS SELECT unnest($ids) AS drive_id", {"ids": ids})
        where = " WHERE drive_id IN (SELECT drive_id FROM kpi_drive_sel)"
    have = [d[0] for d in con.execute("SELECT * FROM drive_samples LIMIT 0").description]
    user = spec.user_kpis
    if all(is_aggregate(k) for k in user):
        extra = sql_columns(spec.sql, have)
    else:   # a query or event KPI reads `samples` as the study declares it: every column and declared channel
        extra = [c for c in have if c in spec.channels or c in spec.measure_channels
                 or (c in SAMPLE_COLUMNS and c not in ("drive_id", "idx"))]
    missing_channels = sorted({c for c in spec.channels if c not in have}
                              & {w for k in user for w in _words(_kpi_text(k))}
                              | {c for c in spec.measure_channels if c not in have})
    if missing_channels:
        from study.common.errors import UserError

        raise UserError(f"the study's KPIs and measures read channel(s) {', '.join(missing_channels)}, which no drive "
                        f"in the store has; import drive logs that map them (docs/drive_logs.md)")
    extra = [c for c in extra if c not in KPI_COLUMNS]           # the others are carried anyway
    carried = "".join(f", {c}" for c in extra if c != "grade")
    con.execute(f"""CREATE OR REPLACE TEMP VIEW kpi_src_raw AS
                    SELECT {', '.join(KPI_COLUMNS)}, grade{carried} FROM drive_samples{where}""")
    energy = "energy" in spec.builtins
    model = spec.energy_source_model
    no_power = [r[0] for r in con.execute(
        "SELECT DISTINCT drive_id FROM kpi_src_raw WHERE p_batt IS NULL ORDER BY 1").fetchall()] if energy else []
    sources = _energy_sources(st, con, no_power, model) if energy else \
        pd.DataFrame(columns=["drive_id", "energy_source"])
    unavailable = [] if model else no_power
    fill_p = no_power if model else []
    missing_a = [r[0] for r in con.execute(
        "SELECT DISTINCT drive_id FROM kpi_src_raw WHERE a IS NULL ORDER BY 1").fetchall()]
    # without a model a drive lacking power gets none at all: a partial sum would pass for the drive's energy
    p_expr = "coalesce(r.p_batt, f.p_batt)" if fill_p or missing_a else "r.p_batt"
    if unavailable:
        con.execute("CREATE OR REPLACE TEMP TABLE kpi_no_power AS SELECT unnest($ids) AS drive_id",
                    {"ids": unavailable})
        p_expr = f"CASE WHEN r.drive_id IN (SELECT drive_id FROM kpi_no_power) THEN NULL ELSE {p_expr} END"
    fill_ids = sorted(set(fill_p) | set(missing_a))
    if fill_ids:
        _fill_missing(con, fill_ids, power=set(fill_p))
        join = "LEFT JOIN kpi_fill f USING (drive_id, idx)"
        a_expr = "coalesce(r.a, f.a)"
    else:
        join, a_expr = "", "r.a"
    rest = "".join(f", r.{c}" for c in extra)
    con.execute(f"""CREATE OR REPLACE TEMP TABLE kpi_src AS
        SELECT r.drive_id, r.idx, r.t, r.s, r.v, r.segment, r.speed_limit, {a_expr} AS a,
               {p_expr} AS p_batt, r.tl_id, r.tl_state, r.d_tl{rest}
        FROM kpi_src_raw r {join} ORDER BY r.drive_id, r.idx""")
    k = kpis_from_relation(con, "kpi_src", params, sql_kpis=user)
    drives = con.execute("SELECT drive_id, participant_id, condition, phase FROM drives").df()
    return drives.merge(k, on="drive_id", how="inner")[out_cols], sources


def _kpi_text(kpi) -> str:
    """The SQL a user KPI runs (its conditions for an event KPI)."""
    if isinstance(kpi, MeasureKpi):
        return " ".join(kpi.channels)
    return f"{kpi.start} {kpi.end}" if isinstance(kpi, EventKpi) else kpi.sql


def _words(sql: str) -> set[str]:
    import re

    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", sql))


def _energy_sources(st, con, no_power: list, model: str | None) -> pd.DataFrame:
    """drive_id, energy_source of the selected drives (module docstring of :func:`store_kpis_with_sources`)."""
    import json

    d = con.execute("SELECT drive_id, meta FROM drives WHERE drive_id IN (SELECT DISTINCT drive_id FROM kpi_src_raw)"
                    " ORDER BY drive_id").df()
    lacking = set(no_power)

    def source(row) -> str:
        if row.drive_id in lacking:
            return model or UNAVAILABLE
        try:
            meta = json.loads(row.meta) if isinstance(row.meta, str) and row.meta else {}
        except ValueError:
            meta = {}
        recorded = meta.get("energy_source") if isinstance(meta, dict) else None
        return str(recorded) if recorded else MEASURED

    return pd.DataFrame({"drive_id": d["drive_id"], "energy_source": [source(r) for r in d.itertuples()]})


def energy_note(sources: pd.DataFrame) -> str:
    """One line: how many drives' energy is measured, modelled or unavailable ('' without energy KPIs)."""
    if sources is None or sources.empty:
        return ""
    counts = sources["energy_source"].value_counts()
    parts = [f"{n} drive{'s' if n != 1 else ''} {src}" for src, n in sorted(counts.items(), key=lambda x: x[0])
             if src != UNAVAILABLE]
    if UNAVAILABLE in counts:
        n = int(counts[UNAVAILABLE])
        parts.append(f"{n} drive{'s' if n != 1 else ''} unavailable (no battery power logged and the study "
                     f"declares no vehicle model: energy left empty)")
    return "energy: " + ", ".join(parts)


def _fill_missing(con, drive_ids, power=frozenset()) -> None:
    """``a`` (all ``drive_ids``) and ``p_batt`` (the drives in ``power``) where the log lacks them, into TEMP TABLE
    kpi_fill(drive_id, idx, a, p_batt): a by :func:`fill_acceleration`, p_batt by the vehicle power model
    (``pedas.power.fill_drive_columns`` on t, v, grade and a — the model of ``kpi energy``). Vectorised per drive,
    not per row."""
    from pedas.power import fill_drive_columns

    frames = []
    for drive_id in drive_ids:
        d = con.execute("SELECT idx, t, v, a, grade, p_batt FROM kpi_src_raw WHERE drive_id = $d ORDER BY idx",
                        {"d": drive_id}).df()
        a = d["a"].astype(float).fillna(pd.Series(fill_acceleration(d["t"], d["v"]), index=d.index))
        p = d["p_batt"].astype(float)
        if drive_id in power and p.isna().any():
            model = fill_drive_columns(d[["t", "v", "grade"]].assign(a=a.to_numpy()))
            p = p.fillna(pd.Series(model["p_batt"].to_numpy(float), index=d.index))
        frames.append(pd.DataFrame({"drive_id": drive_id, "idx": d["idx"].to_numpy(), "a": a.to_numpy(),
                                    "p_batt": p.to_numpy()}))
    fill = pd.concat(frames, ignore_index=True)
    con.register("kpi_fill_df", fill)
    con.execute("CREATE OR REPLACE TEMP TABLE kpi_fill AS SELECT * FROM kpi_fill_df")
    con.unregister("kpi_fill_df")

"""A study's own KPIs that are not one aggregate expression (docs/kpis.md): event KPIs and query KPIs, computed in
DuckDB beside the built-ins' grouped pass (:func:`analysis.drives.kpis.kpis_from_relation` calls them).

* :func:`event_kpis`: time (s) from a rising edge of a condition ``from`` to the first sample at or after it where
  ``to`` holds, for every drive at once: one window pass marks the edges of ``from`` and the samples where ``to``
  starts to hold (a few rows), an ASOF join pairs each edge with the nearest such sample at or after it, and one
  GROUP BY with two grouping sets reduces the events per segment (the segment of the edge) and per drive. The
  ``count`` statistic counts the edges in the same grouped pass over every sample (0 where ``from`` is logged but
  never rises, NULL where it is not logged).
* :func:`query_kpis`: a full read-only query over ``samples``, run once per drive (and per segment of it) against a
  temporary view ``samples`` that selects that drive's (segment's) rows in idx order; the drive and segment are
  session variables, which DuckDB folds into the scan's filter (a drive's rows are read, not the table's).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from study.common.errors import UserError
from study.folder.kpi_fields import SAMPLE_COLUMNS
from study.folder.kpi_query import check_condition, check_query, condition_sql
from study.folder.kpi_spec import SqlKpi

#: how the events of one drive (or segment) become its value; ``dt`` = response time of one event (NULL: none);
#: ``count`` has its own query (it needs every sample, not only the events)
STATISTIC_SQL = {"first": "list(dt ORDER BY idx)[1]", "mean": "avg(dt)", "max": "max(dt)"}

_FLAGS = """
WITH flags AS NOT MATERIALIZED (
    SELECT drive_id, idx, t, segment, f_logged, coalesce(f_logged, false) AS f, g,
           lag(coalesce(f_logged, false)) OVER w AS f_prev, lag(g) OVER w AS g_prev
    FROM (SELECT drive_id, idx, t, segment, CAST(({start}) AS BOOLEAN) AS f_logged, {end} AS g FROM {src})
    WINDOW w AS (PARTITION BY drive_id ORDER BY idx)
)"""

# the events and their response times dt, reduced per segment (of the edge) and per drive
_EVENT_SQL = _FLAGS + """,
marks AS MATERIALIZED (  -- the few samples that matter: edges of `from`, and where `to` starts to hold
    SELECT drive_id, idx, t, segment, f AND NOT f_prev AS edge, g
    FROM flags
    WHERE (f AND NOT f_prev) OR (g AND g_prev IS DISTINCT FROM true)
),
events AS (  -- the first sample at or after an edge where `to` holds is the edge itself or the next start of `to`
    SELECT e.drive_id, e.segment, e.idx, h.t - e.t AS dt
    FROM (SELECT * FROM marks WHERE edge) e
    ASOF LEFT JOIN (SELECT drive_id, idx, t FROM marks WHERE g) h ON e.drive_id = h.drive_id AND h.idx >= e.idx
)
SELECT drive_id, CASE WHEN grouping(segment) = 1 THEN 'overall' ELSE segment END AS segment,
       ({stat})::DOUBLE AS value
FROM events
GROUP BY GROUPING SETS ((drive_id, segment), (drive_id))
"""

# the number of events: 0 where `from` is logged and never rises, NULL where it is not logged at all
_COUNT_SQL = _FLAGS + """
SELECT drive_id, CASE WHEN grouping(segment) = 1 THEN 'overall' ELSE segment END AS segment,
       CASE WHEN count(f_logged) > 0 THEN count(*) FILTER (WHERE f AND NOT f_prev) END::DOUBLE AS value
FROM flags
GROUP BY GROUPING SETS ((drive_id, segment), (drive_id))
"""

_DRIVE = "pedas_kpi_drive"      # session variables of the `samples` view
_SEGMENT = "pedas_kpi_segment"


def is_aggregate(kpi) -> bool:
    """Whether a user KPI is an aggregate expression (computed in the built-ins' grouped pass)."""
    return isinstance(kpi, SqlKpi) and not kpi.query


def _relation(con, src: str) -> list[tuple[str, str]]:
    """(column, type) of the relation ``src`` (a table or view name)."""
    if not src.replace("_", "").replace(".", "").isalnum():
        raise ValueError(f"not a relation name: {src!r}")
    return [(r[0], str(r[1])) for r in con.execute(f"DESCRIBE SELECT * FROM {src}").fetchall()]


def _channels(columns: list[tuple[str, str]]) -> tuple[str, ...]:
    return tuple(c for c, _ in columns if c not in SAMPLE_COLUMNS)


def _samples_select(columns: list[tuple[str, str]]) -> str:
    """The select list of ``samples`` over a source with ``columns``: every column of drive_samples (NULL of its
    type where the source has none, as on the trial connection of the check), then the source's other columns."""
    have = dict(columns)
    select = [f'"{c}"' if c in have else f'NULL::{t} AS "{c}"' for c, t in SAMPLE_COLUMNS.items()]
    return ", ".join(select + [f'"{c}"' for c in _channels(columns)])


def event_kpis(con, src: str, kpis) -> pd.DataFrame:
    """Event KPIs (:class:`study.folder.kpi_spec.EventKpi`) of every drive in ``src``: drive_id, segment (a segment or
    ``overall``), one column per KPI (a time KPI has rows only where a drive or segment has an event). The
    conditions are checked again (:func:`study.folder.kpi_query.check_condition`) before they run."""
    columns = _relation(con, src)
    channels = _channels(columns)
    src = f"(SELECT {_samples_select(columns)} FROM {src})"
    frames = []
    for k in kpis:
        for cond in (k.start, k.end):
            problem = check_condition(cond, channels)
            if problem:
                raise UserError(f"KPI {k.name}: {problem}")
        if k.statistic == "count":
            sql = _COUNT_SQL.format(src=src, start=k.start, end=condition_sql(k.end))
        else:
            sql = _EVENT_SQL.format(src=src, start=k.start, end=condition_sql(k.end), stat=STATISTIC_SQL[k.statistic])
        frames.append(con.execute(sql).df().rename(columns={"value": k.name}).set_index(["drive_id", "segment"]))
    return pd.concat(frames, axis=1).reset_index()


def query_kpis(con, src: str, rows: pd.DataFrame, kpis) -> pd.DataFrame:
    """Query KPIs (:class:`study.folder.kpi_spec.SqlKpi` with ``query``) for the (drive_id, segment) ``rows`` (segment
    ``overall`` = the whole drive): drive_id, segment, one column per KPI (NULL: not per segment, or the query gave
    NULL or no row). ``samples`` holds the columns of drive_samples (NULL where ``src`` lacks one) and ``src``'s
    other columns. Each query is checked again (:func:`study.folder.kpi_query.check_query`) before it runs; more than one
    row for a drive is refused (UserError). A temporary view ``samples`` and two session variables exist on ``con``
    while this runs."""
    columns = _relation(con, src)
    if src.lower() in ("samples", "temp.samples"):
        raise ValueError("the relation of the samples cannot itself be named samples")
    channels = _channels(columns)
    for k in kpis:
        problem = check_query(k.sql, channels)
        if problem:
            raise UserError(f"KPI {k.name}: {problem}")
    values = {k.name: [] for k in kpis}
    try:
        con.execute(f"SET VARIABLE {_DRIVE} = NULL")
        con.execute(f"SET VARIABLE {_SEGMENT} = NULL")
        con.execute(f"""CREATE OR REPLACE TEMP VIEW samples AS
            SELECT {_samples_select(columns)} FROM {src}
            WHERE drive_id = getvariable('{_DRIVE}')
              AND (getvariable('{_SEGMENT}') IS NULL OR segment = getvariable('{_SEGMENT}'))
            ORDER BY idx""")
        current = None
        for drive_id, segment in rows[["drive_id", "segment"]].itertuples(index=False):
            if drive_id != current:
                con.execute(f"SET VARIABLE {_DRIVE} = $d", {"d": int(drive_id)})
                current = drive_id
            whole = segment == "overall"
            con.execute(f"SET VARIABLE {_SEGMENT} = $s", {"s": None if whole else str(segment)})
            for k in kpis:
                values[k.name].append(_one_value(con, k, drive_id, segment) if whole or k.per_segment else np.nan)
    finally:
        con.execute("DROP VIEW IF EXISTS temp.samples")
        con.execute(f"RESET VARIABLE {_DRIVE}")
        con.execute(f"RESET VARIABLE {_SEGMENT}")
    return pd.DataFrame({"drive_id": rows["drive_id"].to_numpy(), "segment": rows["segment"].to_numpy(),
                         **{name: np.asarray(v, dtype="float64") for name, v in values.items()}})


def _one_value(con, kpi, drive_id, segment) -> float:
    import duckdb

    where = f"drive {drive_id}" + ("" if segment == "overall" else f", segment {segment}")
    try:
        rows = con.execute(kpi.sql).fetchall()
    except duckdb.Error as exc:
        raise UserError(f"KPI {kpi.name} ({where}): {' '.join(str(exc).split())[:200]}") from None
    if len(rows) > 1:
        raise UserError(f"KPI {kpi.name} ({where}): its query returned {len(rows)} rows; a KPI query returns one "
                        f"row (an aggregate, or ORDER BY ... LIMIT 1)")
    value = rows[0][0] if rows else None
    return np.nan if value is None else float(value)


def place(frame: pd.DataFrame, values: pd.DataFrame, kpis) -> pd.DataFrame:
    """``frame`` (the KPI rows, drive_id and segment) with the columns of ``kpis`` from ``values`` (drive_id,
    segment, one column per KPI; NULL where it has no row): a KPI not per segment is NULL in the segment rows."""
    values = values.astype({"drive_id": frame["drive_id"].dtype, "segment": object})   # also when it has no row
    out = frame.merge(values, on=["drive_id", "segment"], how="left")
    seg = out["segment"] != "overall"
    for k in kpis:
        out[k.name] = out[k.name].astype("float64").where(~seg | k.per_segment)
    return out

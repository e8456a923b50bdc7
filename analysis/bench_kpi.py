"""`bench kpi`: the drive KPIs in DuckDB over a synthetic ``drive_samples`` table (default 100 M rows = 10 000 drives
x 10 000 samples) against the same KPIs in pandas on a tenth of it, in one process.

The synthetic table is generated inside DuckDB (``range()`` and the seeded ``hash()``), written to a temporary
DuckDB file and deleted afterwards. Each sample: ``t = idx * 0.1`` s; ``v = A (1 + sin(w t + phi)) + noise`` so that
every drive stops, speeds and crosses lights; ``s`` the exact integral of the noise-free speed; urban first half
(50 km/h), highway second half (100 km/h); a light every 500 samples with a 90 s cycle; a simple road-load battery
power. The pandas peer (:func:`kpis_pandas`) implements the same definitions as :mod:`analysis.kpis` with
vectorised group shifts; it is also the cross-check of the SQL in the tests.
"""
from __future__ import annotations

import os
import re
import statistics
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.kpis import KPI_FIELDS, KpiParams, kpis_from_relation

FULL_ROWS = 100_000_000
SAMPLES_PER_DRIVE = 10_000
PEER_SHARE = 10  # pandas gets 1/PEER_SHARE of the rows


def synthetic_sql(n_rows: int, samples_per_drive: int = SAMPLES_PER_DRIVE, seed: int = 1) -> str:
    """SELECT producing ``n_rows`` synthetic drive samples (see module docstring); deterministic in ``seed``."""
    n_per = int(samples_per_drive)
    seed = int(seed)

    def u(expr: str, salt: int) -> str:  # uniform in [0, 1) from the seeded hash
        return f"((hash({expr}, {seed}, {salt}) % 1000003)::DOUBLE / 1000003.0::DOUBLE)"

    return f"""
    WITH base AS (
        SELECT i // {n_per} AS drive_id, (i % {n_per})::INTEGER AS idx, i,
               (i % {n_per})::DOUBLE * 0.1::DOUBLE AS t,
               6.0 + 6.0 * {u(f'i // {n_per}', 1)} AS amp,
               6.283185307 * {u(f'i // {n_per}', 2)} AS phi
        FROM range({int(n_rows)}) r(i)
    ), kin AS (
        SELECT *, 0.05 AS w,
               greatest(0.0, amp * (1 + sin(0.05 * t + phi)) + 0.3 * ({u('i', 3)} - 0.5)) AS v,
               amp * t - amp / 0.05 * (cos(0.05 * t + phi) - cos(phi)) AS s,
               amp * 0.05 * cos(0.05 * t + phi) AS a
        FROM base
    )
    SELECT drive_id, idx, t::DOUBLE AS t, s::DOUBLE AS s, v::DOUBLE AS v,
           CASE WHEN idx < {n_per // 2} THEN 'urban' ELSE 'highway' END AS segment,
           (CASE WHEN idx < {n_per // 2} THEN 50 / 3.6 ELSE 100 / 3.6 END)::DOUBLE AS speed_limit,
           a::DOUBLE AS a,
           (v * (1600.0 * a + 0.5 * 1.2 * 0.7 * v * v + 1600.0 * 9.81 * 0.01) + 300.0)::DOUBLE AS p_batt,
           CASE WHEN idx % 500 < 400 THEN 'TL' || (idx // 500)::VARCHAR END AS tl_id,
           CASE WHEN (idx + drive_id * 37) % 900 < 400 THEN 'green'
                WHEN (idx + drive_id * 37) % 900 < 430 THEN 'yellow' ELSE 'red' END AS tl_state,
           (CASE WHEN idx % 500 < 400 THEN (400 - idx % 500) * 0.5 END)::DOUBLE AS d_tl
    FROM kin
    """


# ------------------------------------------------------------------------------------------ pandas peer
def kpis_pandas(samples: pd.DataFrame, params: KpiParams | None = None) -> pd.DataFrame:
    """The KPIs of :mod:`analysis.kpis` computed with pandas (vectorised; same definitions, same output columns).
    ``samples`` has the :data:`analysis.kpis.KPI_COLUMNS`."""
    p = params or KpiParams()
    df = samples.sort_values(["drive_id", "idx"], kind="stable").reset_index(drop=True)
    g = df.groupby("drive_id", sort=False)
    t, v, s, lim = df["t"], df["v"], df["s"], df["speed_limit"]
    dt = g["t"].shift(-1) - t
    ds = g["s"].shift(-1) - s
    p_mid = (df["p_batt"] + g["p_batt"].shift(-1)) / 2.0
    a0 = df["a"].astype(float)  # the caller fills a missing `a` (analysis.kpis.fill_acceleration)
    a1 = g["a"].shift(-1).astype(float)
    viol = (v > lim + np.maximum(p.tol_abs, p.tol_rel * lim))
    first = ~df["drive_id"].duplicated()
    viol_chg = first | (viol != viol.shift(1))
    st = pd.Series(np.where(v < p.v_stop, "S", np.where(v > p.v_moving, "M", None)), index=df.index)
    st_prev = st.shift(1).where(~first, None)
    st_chg = st.notna() & ((st != st_prev) | st_prev.isna())
    tl_prev = g["tl_id"].shift(1)
    tl_chg = ~((df["tl_id"] == tl_prev) | (df["tl_id"].isna() & tl_prev.isna()))
    red_cand = (v < p.v_stop) & (df["tl_state"] == "red") & (df["d_tl"] < p.red_stop_dist) & df["tl_id"].notna()

    has = dt.notna()
    jerk_ok = has & a0.notna() & a1.notna() & (dt > 0)
    jerk2 = (((a1 - a0) / dt) ** 2 * dt).where(jerk_ok, 0.0)
    work = pd.DataFrame({
        "drive_id": df["drive_id"], "segment": df["segment"], "n_intervals": has.astype(int),
        "energy_wh": (p_mid * dt) / 3600.0, "distance_m": ds, "trip_time_s": dt,
        "violation_distance_m": ds.where(viol, 0.0), "jerk2_dt": jerk2, "jerk_time": dt.where(jerk_ok, 0.0),
        "abs_a_dt": (a0.abs() * dt), "a_time": dt.where(a0.notna()),
    })
    keys = ["drive_id", "segment"]
    seg = work.groupby(keys, sort=False).sum(min_count=1).reset_index()

    # violation episodes: from a change point to the next change point of the drive (or the drive's end)
    t_end = g["t"].transform("max")
    vc = df.loc[viol_chg, ["drive_id", "segment", "t"]].assign(viol=viol[viol_chg], t_end=t_end[viol_chg])
    nxt = vc.groupby("drive_id", sort=False)["t"].shift(-1).fillna(vc["t_end"])
    ev = vc[vc["viol"] & ((nxt - vc["t"]) >= p.min_event_s)]
    viol_ev = ev.groupby(keys, sort=False).size().rename("violation_events")
    # stops (hysteresis): an S change point whose previous change point is M
    sc = df.loc[st_chg, ["drive_id", "segment"]].assign(st=st[st_chg])
    before = sc.groupby("drive_id", sort=False)["st"].shift(1)
    stops = sc[(sc["st"] == "S") & (before == "M")].groupby(keys, sort=False).size().rename("stops")
    # crossings: tl_id changes away from a light; state and segment of the sample before
    cr_mask = tl_chg & tl_prev.notna()
    appr = tl_chg.astype(int).groupby(df["drive_id"], sort=False).cumsum()   # approach number per sample
    appr_before = appr.groupby(df["drive_id"], sort=False).shift(1)     # a crossing belongs to the approach it ends
    cr = pd.DataFrame({"drive_id": df["drive_id"][cr_mask], "segment": g["segment"].shift(1)[cr_mask],
                       "state": g["tl_state"].shift(1)[cr_mask], "appr": appr_before[cr_mask].astype("int64")})
    cross = cr.groupby(keys, sort=False)["state"].agg(
        tl_crossed="size", tl_crossed_green=lambda x: (x == "green").sum(),
        tl_crossed_yellow=lambda x: (x == "yellow").sum(), tl_crossed_red=lambda x: (x == "red").sum())
    # red stops: once per approach (run of one tl_id)
    rc = pd.DataFrame({"drive_id": df["drive_id"], "appr": appr, "segment": df["segment"]})[red_cand]
    red = rc.groupby(["drive_id", "appr"], sort=False)["segment"].first().reset_index()
    red_ev = red.groupby(keys, sort=False).size().rename("red_stops")
    # green passes: crossings in green whose approach had no red stop
    stopped = pd.MultiIndex.from_frame(red[["drive_id", "appr"]])
    gp = cr[(cr["state"] == "green") & ~pd.MultiIndex.from_frame(cr[["drive_id", "appr"]]).isin(stopped)]
    green_ev = gp.groupby(keys, sort=False).size().rename("tl_green_passes")

    for part in (viol_ev, stops, cross, red_ev, green_ev):
        seg = seg.merge(part.reset_index(), on=keys, how="left")
    counts = ["violation_events", "stops", "tl_crossed", "tl_crossed_green", "tl_crossed_yellow",
              "tl_crossed_red", "red_stops", "tl_green_passes"]
    seg[counts] = seg[counts].fillna(0).astype("int64")
    seg = seg[seg["segment"].isin(["urban", "highway"])]
    overall = seg.drop(columns="segment").groupby("drive_id", sort=False).sum(min_count=1).reset_index()
    overall["segment"] = "overall"
    out = pd.concat([seg, overall], ignore_index=True)
    out["mean_speed_mps"] = out["distance_m"] / out["trip_time_s"].replace(0, np.nan)
    out["wh_per_km"] = out["energy_wh"] / (out["distance_m"] / 1000.0).replace(0, np.nan)
    out["violation_share"] = out["violation_distance_m"] / out["distance_m"].replace(0, np.nan)
    out["rms_jerk"] = np.sqrt(out["jerk2_dt"] / out["jerk_time"].replace(0, np.nan))
    out["mean_abs_a"] = out["abs_a_dt"] / out["a_time"].replace(0, np.nan)
    order = {"urban": 0, "highway": 1, "overall": 2}
    out = out.sort_values(["drive_id", "segment"], key=lambda c: c.map(order) if c.name == "segment" else c)
    return out[list(KPI_FIELDS)].reset_index(drop=True)


# ------------------------------------------------------------------------------------------ the bench
@dataclass
class KpiBench:
    """Result of :func:`run_bench`; times are medians over ``repeat`` runs."""
    rows: int
    drives: int
    peer_rows: int
    repeat: int
    threads: int
    memory_limit: str
    generate_s: float
    duckdb_s: float
    pandas_s: float
    duckdb_rows_per_s: float
    pandas_rows_per_s: float
    per_row_speedup: float          # (pandas s/row) / (duckdb s/row)
    max_abs_diff: float             # max |duckdb - pandas| / max(|pandas|, 1) on the peer's drives
    duckdb_runs: list = field(default_factory=list)
    pandas_runs: list = field(default_factory=list)
    goal_s: float = 30.0
    goal_speedup: float = 3.0

    @property
    def duckdb_s_per_100m(self) -> float:
        return self.duckdb_s * FULL_ROWS / self.rows

    def as_dict(self) -> dict:
        d = asdict(self)
        d["duckdb_s_per_100m"] = self.duckdb_s_per_100m
        d["meets_time_goal"] = self.duckdb_s_per_100m <= self.goal_s if self.rows >= FULL_ROWS else None
        d["meets_speedup_goal"] = self.per_row_speedup >= self.goal_speedup
        return d

    def text(self) -> str:
        lines = [
            f"bench kpi: {self.rows:,} samples ({self.drives:,} drives), pandas peer on {self.peer_rows:,}; "
            f"median of {self.repeat}; DuckDB threads={self.threads} memory_limit={self.memory_limit}",
            f"  generate (DuckDB, not timed in the goal): {self.generate_s:.1f} s",
            f"  DuckDB KPIs : {self.duckdb_s:8.2f} s  {self.duckdb_rows_per_s / 1e6:8.2f} M rows/s",
            f"  pandas KPIs : {self.pandas_s:8.2f} s  {self.pandas_rows_per_s / 1e6:8.2f} M rows/s",
            f"  per-row speed-up DuckDB vs pandas: {self.per_row_speedup:.2f}x (goal >= {self.goal_speedup:g}x)",
            f"  DuckDB time scaled to 100 M rows: {self.duckdb_s_per_100m:.1f} s (goal <= {self.goal_s:g} s)",
            f"  agreement on the peer's drives: max relative difference DuckDB vs pandas = {self.max_abs_diff:.3g}",
        ]
        return "\n".join(lines)


def run_bench(rows: int = FULL_ROWS, repeat: int = 1, seed: int = 1, samples_per_drive: int = SAMPLES_PER_DRIVE,
              memory_limit: str = "6GB", threads: int | None = None, tmp_dir: str | os.PathLike | None = None
              ) -> KpiBench:
    """Generate the synthetic table, time the KPIs in DuckDB on all rows and in pandas on the first tenth of the
    drives (median of ``repeat`` runs each), and compare both results on the shared drives."""
    import duckdb

    if rows < 2:
        raise ValueError("--rows must be at least 2")
    if not re.fullmatch(r"\d+(\.\d+)?\s*[KMGT]i?B", memory_limit):
        raise ValueError(f"memory limit must look like 6GB, not {memory_limit!r}")
    n_per = min(int(samples_per_drive), int(rows))
    n_drives = max(1, rows // n_per)
    rows = n_drives * n_per
    peer_drives = max(1, n_drives // PEER_SHARE)
    with tempfile.TemporaryDirectory(prefix="kpi-bench-", dir=tmp_dir) as tmp:
        path = Path(tmp) / "bench.duckdb"
        con = duckdb.connect(str(path))
        try:
            con.execute(f"SET memory_limit = '{memory_limit}'")
            con.execute("SET enable_progress_bar = false")
            con.execute(f"SET temp_directory = '{Path(tmp) / 'spill'}'")
            if threads:
                con.execute(f"SET threads = {int(threads)}")
            nthreads = con.execute("SELECT current_setting('threads')").fetchone()[0]
            t0 = time.perf_counter()
            con.execute("CREATE TABLE drive_samples AS " + synthetic_sql(rows, n_per, seed))
            con.execute("CHECKPOINT")
            gen_s = time.perf_counter() - t0

            duck_runs, result = [], None
            for _ in range(max(1, repeat)):
                t0 = time.perf_counter()
                result = kpis_from_relation(con, "drive_samples", workers=int(nthreads))
                duck_runs.append(time.perf_counter() - t0)

            peer = con.execute(f"SELECT * FROM drive_samples WHERE drive_id < {peer_drives} "
                               "ORDER BY drive_id, idx").df()
        finally:
            con.close()
    peer_rows = len(peer)
    pandas_runs, peer_res = [], None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        peer_res = kpis_pandas(peer)
        pandas_runs.append(time.perf_counter() - t0)
    del peer

    mine = result[result["drive_id"] < peer_drives].reset_index(drop=True)
    num = [c for c in KPI_FIELDS if c not in ("drive_id", "segment")]
    a_, b_ = mine[num].astype(float).to_numpy(), peer_res[num].astype(float).to_numpy()
    diff = np.abs(a_ - b_) / np.maximum(np.abs(b_), 1.0)  # relative above 1, absolute below
    max_diff = float(np.nanmax(diff)) if diff.size else 0.0
    duck_s, pandas_s = statistics.median(duck_runs), statistics.median(pandas_runs)
    duck_rps, pandas_rps = rows / duck_s, peer_rows / pandas_s
    return KpiBench(rows=rows, drives=n_drives, peer_rows=peer_rows, repeat=max(1, repeat), threads=int(nthreads),
                    memory_limit=memory_limit, generate_s=gen_s, duckdb_s=duck_s, pandas_s=pandas_s,
                    duckdb_rows_per_s=duck_rps, pandas_rows_per_s=pandas_rps,
                    per_row_speedup=duck_rps / pandas_rps, max_abs_diff=max_diff,
                    duckdb_runs=duck_runs, pandas_runs=pandas_runs)

"""Time of the drive KPIs (`pedas-study bench kpi`): in DuckDB over a synthetic ``drive_samples`` table (default
100 M rows = 10 000 drives x 10 000 samples) against the same KPIs in pandas on a tenth of it, in one process.

The synthetic table is generated inside DuckDB (``range()`` and the seeded ``hash()``), written to a temporary
DuckDB file and deleted afterwards. Each sample: ``t = idx * 0.1`` s; ``v = A (1 + sin(w t + phi)) + noise`` so that
every drive stops, speeds and crosses lights; ``s`` the exact integral of the noise-free speed; urban first half
(50 km/h), highway second half (100 km/h); a light every 500 samples with a 90 s cycle; a simple road-load battery
power; an extra channel ``lat_pos`` (lateral position in the lane, m: a slow sway plus noise). Besides the built-in
KPIs one user KPI is timed, the SDLP ``stddev_samp(lat_pos)`` per segment and drive (:data:`BENCH_SQL_KPIS`).
The pandas peer is :func:`analysis.drives.testing.kpis_pandas`, the independent implementation of the same definitions
that the tests check the SQL against, plus the SDLP by a pandas group-by (:func:`sdlp_pandas`).
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

from study.folder.kpi_spec import SqlKpi
from analysis.drives.kpis import KPI_FIELDS, kpis_from_relation
from analysis.drives.testing import kpis_pandas

FULL_ROWS = 100_000_000
SAMPLES_PER_DRIVE = 10_000
PEER_SHARE = 10  # pandas gets 1/PEER_SHARE of the rows
#: the user KPI of the bench: standard deviation of the lateral position, per segment and drive
BENCH_SQL_KPIS = (SqlKpi("sdlp", "stddev_samp(lat_pos)", per_segment=True, unit="m", label="SDLP"),)


def sdlp_pandas(samples: pd.DataFrame, kpis: pd.DataFrame) -> pd.DataFrame:
    """``kpis`` (rows drive_id, segment as :func:`analysis.drives.testing.kpis_pandas` returns them) with the column
    sdlp: the sample standard deviation of ``lat_pos`` per drive and segment, and per drive for ``overall``."""
    per_seg = samples.groupby(["drive_id", "segment"], sort=False)["lat_pos"].std(ddof=1)
    per_drive = samples.groupby("drive_id", sort=False)["lat_pos"].std(ddof=1)
    seg_vals = per_seg.reindex(pd.MultiIndex.from_frame(kpis[["drive_id", "segment"]])).to_numpy()
    drive_vals = per_drive.reindex(kpis["drive_id"]).to_numpy()
    return kpis.assign(sdlp=np.where(kpis["segment"] == "overall", drive_vals, seg_vals))


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
           (CASE WHEN idx % 500 < 400 THEN (400 - idx % 500) * 0.5 END)::DOUBLE AS d_tl,
           (0.3 * sin(0.013 * t + phi) + 0.2 * ({u('i', 4)} - 0.5))::DOUBLE AS lat_pos
    FROM kin
    """


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
            f"  KPIs: the built-ins and the user KPI {', '.join(f'{k.name} = {k.sql}' for k in BENCH_SQL_KPIS)}",
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
                result = kpis_from_relation(con, "drive_samples", workers=int(nthreads), sql_kpis=BENCH_SQL_KPIS)
                duck_runs.append(time.perf_counter() - t0)

            peer = con.execute(f"SELECT * FROM drive_samples WHERE drive_id < {peer_drives} "
                               "ORDER BY drive_id, idx").df()
        finally:
            con.close()
    peer_rows = len(peer)
    pandas_runs, peer_res = [], None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        peer_res = sdlp_pandas(peer, kpis_pandas(peer))
        pandas_runs.append(time.perf_counter() - t0)
    del peer

    mine = result[result["drive_id"] < peer_drives].reset_index(drop=True)
    num = [c for c in (*KPI_FIELDS, *(k.name for k in BENCH_SQL_KPIS)) if c not in ("drive_id", "segment")]
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

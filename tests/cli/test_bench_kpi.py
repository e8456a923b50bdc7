"""`bench kpi` on a tiny size: functional only (no timing assertions)."""
from __future__ import annotations

import json

import duckdb
import pandas as pd
import pytest

from pedas_study.bench.kpi import run_bench, synthetic_sql


def test_synthetic_table_is_seeded_and_plausible():
    with duckdb.connect() as con:
        a = con.execute(synthetic_sql(4000, 1000, seed=5) + " ORDER BY drive_id, idx").df()
        b = con.execute(synthetic_sql(4000, 1000, seed=5) + " ORDER BY drive_id, idx").df()
        c = con.execute(synthetic_sql(4000, 1000, seed=6) + " ORDER BY drive_id, idx").df()
    assert a.equals(b) and not a["v"].equals(c["v"])
    assert a["drive_id"].nunique() == 4 and (a["v"] >= 0).all()
    assert (a.groupby("drive_id")["s"].diff().dropna() >= -1e-9).all()     # s never runs backwards
    assert set(a["segment"]) == {"urban", "highway"} and set(a["tl_state"]) == {"green", "yellow", "red"}


def test_run_bench_small_agrees_with_pandas():
    r = run_bench(rows=40_000, repeat=2, samples_per_drive=2_000, memory_limit="1GB")
    assert r.rows == 40_000 and r.drives == 20 and r.peer_rows == 4_000
    assert len(r.duckdb_runs) == 2 and len(r.pandas_runs) == 2
    assert r.max_abs_diff < 1e-9
    assert r.duckdb_rows_per_s > 0 and r.per_row_speedup > 0
    assert "M rows/s" in r.text()


def test_bench_kpi_cli_json(cli):
    res = cli("bench", "kpi", "--rows", "20000", "--repeat", "1", "--json", db=None)
    assert res.code == 0, res.err
    d = json.loads(res.out)
    assert d["rows"] == 20_000 and d["max_abs_diff"] < 1e-9
    assert d["meets_time_goal"] is None                        # only judged at the full 100 M rows
    assert isinstance(d["meets_speedup_goal"], bool)


@pytest.mark.parametrize("args,msg", [(("--rows", "1"), "at least 2"), (("--repeat", "0"), "at least 1"),
                                      (("--rows", "100", "--memory-limit", "6GB; DROP"), "memory limit")])
def test_bench_kpi_cli_bad_input(cli, args, msg):
    res = cli("bench", "kpi", *args, db=None)
    assert res.code == 2 and msg in res.err


@pytest.mark.parametrize("workers", [2, 3, 7])
def test_chunked_kpis_equal_one_chunk(tmp_path, workers):
    """Drive-id chunks run on their own cursors give exactly the one-query result, whatever the chunking."""
    from analysis.drives.kpis import _drive_chunks, kpis_from_relation

    con = duckdb.connect(str(tmp_path / "k.duckdb"))
    con.execute("CREATE TABLE drive_samples AS " + synthetic_sql(60_000, 2_000, 3))
    one = kpis_from_relation(con, "drive_samples")
    chunks = _drive_chunks(con, "drive_samples", workers)
    assert len(chunks) == min(workers, 30) and chunks[0][0] == 0 and chunks[-1][1] == 30
    assert all(a[1] == b[0] for a, b in zip(chunks, chunks[1:]))           # contiguous, no drive twice
    pd.testing.assert_frame_equal(kpis_from_relation(con, "drive_samples", workers=workers), one)
    con.close()

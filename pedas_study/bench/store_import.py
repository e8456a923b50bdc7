"""Throughput of drive-log import (`pedas-study bench import`): rows/s of the full path (read, validate, fill
computed columns, one transaction) against a peer in the same process: DuckDB reading the same Parquet file
straight into drive_samples (no validation, no computed columns) — the floor the import can approach."""
from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class ImportBench:
    rows: int
    repeats: int
    import_s_median: float
    import_rows_per_s: float
    peer_s_median: float
    peer_rows_per_s: float
    ratio: float            # import time / peer time

    def as_dict(self) -> dict:
        return asdict(self)


def synthetic_log(n: int, seed: int = 0) -> pd.DataFrame:
    """A plausible drive log of n samples at 10 Hz (urban first half, highway second half)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    v = np.clip(15 + np.cumsum(rng.normal(0, 0.05, n)), 0, 40)
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1)])
    seg = np.where(np.arange(n) < n // 2, "urban", "highway")
    return pd.DataFrame({"t": t, "s": s, "v": v, "segment": seg,
                         "speed_limit": np.where(seg == "urban", 13.89, 33.33),
                         "tl_state": np.where(rng.random(n) < 0.5, "green", "red"), "controller": "rt",
                         "hud_arrow": rng.integers(-1, 2, n), "warning": rng.random(n) < 0.01})


def bench_import(rows: int = 1_000_000, repeats: int = 3, seed: int = 0) -> ImportBench:
    from pedas_study.bench.store_export import fresh_import_store
    from study.logs.importing import import_drive_file
    from study.store.store import Store
    from study.store.studies import definition

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        log = tmp / "log.parquet"
        synthetic_log(rows, seed).to_parquet(log)
        ours, peer = [], []
        for i in range(repeats):
            fresh_import_store(tmp / f"a{i}.duckdb")  # the paper's study: a drive needs a participant of a study
            with Store.open(tmp / f"a{i}.duckdb", actor="bench") as st:
                definition(st)  # parsed before the clock starts, as import_drive_file's own clock does
                t0 = time.perf_counter()
                import_drive_file(st, "P001", "baseline", log)
                ours.append(time.perf_counter() - t0)
            with Store.open(tmp / f"b{i}.duckdb", actor="bench") as st:
                t0 = time.perf_counter()
                st.con.begin()
                st.con.execute("INSERT INTO drive_samples (drive_id, idx, t, s, v, segment, speed_limit, tl_state, "
                               "controller, hud_arrow, warning) SELECT 1, row_number() OVER () - 1, t, s, v, segment, "
                               "speed_limit, tl_state, controller, hud_arrow, warning FROM read_parquet(?)", [str(log)])
                st.con.commit()
                peer.append(time.perf_counter() - t0)
    mo, mp = statistics.median(ours), statistics.median(peer)
    return ImportBench(rows, repeats, mo, rows / mo, mp, rows / mp, mo / mp)

"""Exports stream from the store (DuckDB's COPY): what they write is the store's rows, in the store's types and in
(drive, sample) order, and CSV bytes are those of the DataFrame-based writer they replace; de-identified times are
computed in SQL and equal the hand-worked seconds."""
from __future__ import annotations

import json
from datetime import datetime

import pandas as pd
import pyarrow.parquet as pq
import pytest

from study.logs.importing import import_drive_frame
from study.export.writer import EXPORT_MEMORY, collect, export, samples_in_order, table_sql
from study.store.store import Store
from tests.study.test_export import db, small_drive  # noqa: F401  (the fixture: three participants, notes, a drive)


def _shown(st, table: str) -> list[tuple[str, str]]:
    """(column, type) of `table` as exported: the columns that carry nothing for this store are left out
    (study.export.writer.hidden_columns: the occasion of a study with one occasion, drives.phase without such drives)."""
    from study.export.writer import _study_of, hidden_columns

    hide = hidden_columns(st, _study_of(st)).get(table, set())
    cols = st.con.execute("SELECT column_name, data_type FROM duckdb_columns() WHERE table_name = ? "
                          "AND schema_name = 'main' ORDER BY column_index", [table]).fetchall()
    return [(c, t) for c, t in cols if c not in hide]


def _store_rows(st, table: str) -> list[tuple]:
    order = " ORDER BY drive_id, idx" if table == "drive_samples" else ""
    cols = ", ".join(f'"{c}"' for c, _ in _shown(st, table))
    return st.con.execute(f'SELECT {cols} FROM "{table}"{order}').fetchall()


def _csv_rows(st, table: str, path) -> list[tuple]:
    """The CSV read back by DuckDB with the table's column types (doubles are written in their shortest exact form,
    so they read back bit for bit)."""
    cols = _shown(st, table)
    spec = "{" + ", ".join(f"'{c}': '{t}'" for c, t in cols) + "}"
    return st.con.execute(f"SELECT * FROM read_csv('{path}', header = true, columns = {spec})").fetchall()


@pytest.fixture
def drives_db(db):  # noqa: F811
    """The export fixture with two more drives: one without HUD columns (missing hud_arrow and warning), one
    logged as two live sessions at once would store it: samples of two drives interleaved in the table."""
    with Store.open(db, actor="ra_mueller") as st:
        import_drive_frame(st, "P002", "baseline", small_drive(80).drop(columns=["hud_arrow", "warning"]))
        a = import_drive_frame(st, "P002", "pedas", small_drive(40))
        b = import_drive_frame(st, "P003", "baseline", small_drive(30))
        # move their samples to the end of the table, interleaved 10 rows at a time
        rows = st.df("SELECT * FROM drive_samples WHERE drive_id IN (?, ?) ORDER BY idx, drive_id",
                     [a.drive_id, b.drive_id])
        with st.transaction():
            st.con.execute("DELETE FROM drive_samples WHERE drive_id IN (?, ?)", [a.drive_id, b.drive_id])
            for k in range(0, 40, 10):
                st.insert_df("drive_samples", rows[(rows["idx"] >= k) & (rows["idx"] < k + 10)]
                             .sort_values(["drive_id", "idx"], ascending=[k % 20 == 0, True]))
    return db


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_files_read_back_are_the_stores_rows(cli, drives_db, tmp_path, fmt):
    """End to end: `export csv|parquet` of a store with drives; every table's file read back (CSV by DuckDB with the
    table's types, Parquet by pyarrow) is the table's rows, value for value; drive samples in (drive, sample) order
    although the store holds two drives interleaved."""
    r = cli("export", fmt, tmp_path / "out", db=drives_db)
    assert r.code == 0, r.err
    with Store.open(drives_db) as st:
        assert not samples_in_order(st)
        tables = [t for t in st.tables() if t != "participants"]  # participants: with the attributes (below)
        for t in tables:
            path = tmp_path / "out" / f"{t}.{fmt}"
            back = _csv_rows(st, t, path) if fmt == "csv" else [tuple(r.values()) for r in
                                                                pq.read_table(path).to_pylist()]
            assert back == _store_rows(st, t), t
        people = st.con.execute("SELECT participant_id, protocol, study_version, created_at FROM participants "
                                "ORDER BY participant_id").fetchall()
        n_samples = st.one("SELECT count(*) FROM drive_samples")
    if fmt == "parquet":
        back = pq.read_table(tmp_path / "out" / "participants.parquet")
        assert [tuple(r[c] for c in ("participant_id", "protocol", "study_version", "created_at"))
                for r in back.to_pylist()] == people
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert manifest["files"][f"drive_samples.{fmt}"] == n_samples == 50 + 80 + 40 + 30


def test_samples_in_order_after_imports(db):  # noqa: F811
    """Drives imported one after the other are stored in (drive, sample) order: the export streams them unsorted."""
    with Store.open(db) as st:
        import_drive_frame(st, "P002", "baseline", small_drive(70))
        assert samples_in_order(st)
        assert "ORDER BY" not in table_sql(st, "drive_samples")


def test_drive_samples_are_never_a_dataframe(drives_db):
    """The export's plan: drive_samples (and every table but the per-participant ones) is a SELECT that DuckDB
    writes as it reads it, plain and de-identified; only participants, the wide survey files and (de-identified)
    drives, whose meta is rewritten in Python, are built as DataFrames."""
    with Store.open(drives_db) as st:
        for deidentify in (False, True):
            parts, _ = collect(st, deidentify)
            framed = sorted(p.name for p in parts if p.frame is not None)
            assert framed == sorted(["participants", "survey_wide_pedas_acceptance_v1"]
                                    + (["drives"] if deidentify else []))
            samples = next(p for p in parts if p.name == "drive_samples")
            assert samples.frame is None and samples.sql.startswith("SELECT ")


def test_csv_bytes_are_those_of_the_dataframe_writer(drives_db, tmp_path):
    """CSV as before the export streamed: each table fetched as a DataFrame and written by the same DuckDB CSV
    writer gives the same bytes as the streamed COPY (types, number and time formatting, missing values)."""
    import duckdb

    with Store.open(drives_db) as st:
        export(st, "csv", tmp_path / "new")
        parts, _ = collect(st)
        con = duckdb.connect()
        con.execute("SET TimeZone = 'UTC'")
        for part in parts:
            frame = part.frame if part.frame is not None else st.df(part.sql)
            con.register("frame", frame)
            con.execute(f"COPY frame TO '{tmp_path / 'old.csv'}' (FORMAT csv, HEADER true)")
            con.unregister("frame")
            assert (tmp_path / "new" / f"{part.name}.csv").read_bytes() == (tmp_path / "old.csv").read_bytes(), \
                part.name
        con.close()


def test_parquet_keeps_the_store_types(drives_db, tmp_path):
    """Parquet written by DuckDB has the store's types: a TINYINT with missing values stays int8, a BOOLEAN bool,
    a column without any value keeps its text type, times are microsecond timestamps."""
    with Store.open(drives_db) as st:
        export(st, "parquet", tmp_path)
    samples = pq.read_schema(tmp_path / "drive_samples.parquet")
    assert (str(samples.field("hud_arrow").type), str(samples.field("warning").type),
            str(samples.field("idx").type), str(samples.field("t").type)) == ("int8", "bool", "int32", "double")
    assert str(samples.field("tl_id").type) == "string"             # no drive has a traffic-light id
    assert str(pq.read_schema(tmp_path / "drives.parquet").field("created_at").type) == "timestamp[us]"
    back = pd.read_parquet(tmp_path / "drive_samples.parquet", dtype_backend="numpy_nullable")
    assert str(back["hud_arrow"].dtype) == "Int8" and back["hud_arrow"].isna().sum() == 80


def test_relative_seconds_hand_worked(paper_db, tmp_path):
    """Registered 2026-05-04 09:00:00.000001; phase started 09:30:15.250001 and ended the next day 10:00:00.5:
    1815.25 s and 25 h + 0.499999 s = 90000.499999 s after the first event, exactly as pandas' total_seconds."""
    with Store.open(paper_db, actor="lab") as st:
        st.insert("participants", {"participant_id": "P010", "protocol": "paper_v1",
                                   "created_at": datetime(2026, 5, 4, 9, 0, 0, 1)})
        st.insert("phase_events", {"participant_id": "P010", "phase": "familiarisation", "seq": 1,
                                   "started_at": datetime(2026, 5, 4, 9, 30, 15, 250001),
                                   "ended_at": datetime(2026, 5, 5, 10, 0, 0, 500000), "outcome": "completed"})
        export(st, "csv", tmp_path, deidentify=True)
        start = st.df("SELECT started_at FROM phase_events")["started_at"] - pd.Timestamp("2026-05-04 09:00:00.000001")
    text = (tmp_path / "phase_events.csv").read_text().splitlines()
    assert text[0] == "participant_id,phase,seq,started_at_s,ended_at_s,outcome"
    assert text[1] == "P010,familiarisation,1,1815.25,90000.499999,completed"
    assert float(text[1].split(",")[3]) == start.dt.total_seconds().iloc[0]
    assert (tmp_path / "participants.csv").read_text().splitlines()[1].split(",")[-1] == "0.0"


def test_export_leaves_duckdb_settings_as_they_were(drives_db, tmp_path):
    """The export bounds DuckDB's memory (EXPORT_MEMORY) while it runs and restores the store's settings."""
    from study.common.duck_memory import size_bytes

    with Store.open(drives_db) as st:
        before = st.con.execute("SELECT value FROM duckdb_settings() WHERE name = 'memory_limit'").fetchone()[0]
        assert size_bytes(before) > size_bytes(EXPORT_MEMORY)
        export(st, "parquet", tmp_path)
        after = st.con.execute("SELECT value FROM duckdb_settings() WHERE name = 'memory_limit'").fetchone()[0]
        assert after == before
        st.con.execute("SET memory_limit = '300MB'")  # a lower limit already set is kept
        lower = st.con.execute("SELECT value FROM duckdb_settings() WHERE name = 'memory_limit'").fetchone()[0]
        export(st, "csv", tmp_path / "csv")
        assert st.con.execute("SELECT value FROM duckdb_settings() WHERE name = 'memory_limit'").fetchone()[0] \
            == lower


def test_size_bytes():
    from study.common.duck_memory import size_bytes

    assert (size_bytes("400MB"), size_bytes("18.5 GiB"), size_bytes("128 bytes")) == (4e8, 18.5 * 2 ** 30, 128)
    assert size_bytes("lots") is None and size_bytes("") is None


@pytest.mark.slow
def test_bench_export_on_a_small_store(cli):
    """`bench export` end to end on a tiny store: every operation ran in its own process and counted its rows (the
    export's files: the samples plus the other tables' rows; the import: the log's rows); no timing is asserted."""
    r = cli("bench", "export", "--samples", "3000", "--log-rows", "500", "--no-peers", "--json", db=None)
    assert r.code == 0, r.err
    res = json.loads(r.out)
    assert sorted(res["runs"]) == ["drive import csv", "export csv", "export csv --deidentify", "export parquet"]
    assert res["runs"]["drive import csv"]["rows"] == 500
    assert res["runs"]["export parquet"]["rows"] == res["runs"]["export csv"]["rows"] > 3000
    assert all(run["peak_mb"] > 0 and run["growth_mb"] >= 0 for run in res["runs"].values())

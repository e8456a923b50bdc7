"""The DuckDB store: migrations, transactions, audit trail, constraints."""
import json
import shutil

import duckdb
import pandas as pd
import pytest

from study import migrate
from study.errors import UserError
from study.store import Store


def test_open_creates_and_migrates(tmp_db):
    with Store.open(tmp_db, actor="alice") as st:
        assert st.schema_version == migrate.code_version()
        assert {"participants", "phase_events", "exclusions", "drives", "drive_samples", "instruments", "items",
                "responses", "audit_log", "schema_version"} <= set(st.tables())
        # the shipped codebook is loaded as reference data, not audited
        assert st.one("SELECT count(*) FROM items WHERE instrument = 'pedas_acceptance_v1'") == 33
        assert st.one("SELECT count(*) FROM audit_log") == 0


def test_reopen_is_idempotent(tmp_db):
    Store.open(tmp_db).close()
    with Store.open(tmp_db) as st:
        versions = st.df("SELECT version FROM schema_version ORDER BY version")["version"].tolist()
    assert versions == [m.version for m in migrate.discover()]


def test_older_store_is_upgraded(tmp_db, tmp_path):
    only_core = tmp_path / "mig"
    only_core.mkdir()
    shutil.copy(migrate.MIGRATIONS_DIR / "0001_core.sql", only_core)
    con = duckdb.connect(str(tmp_db))
    assert [m.version for m in migrate.migrate(con, only_core)] == [1]
    con.execute("INSERT INTO participants (participant_id, age) VALUES ('P001', 40)")
    con.close()
    with Store.open(tmp_db) as st:
        assert st.schema_version == migrate.code_version()
        assert st.one("SELECT age FROM participants WHERE participant_id = 'P001'") == 40


def test_newer_store_is_refused(tmp_db):
    Store.open(tmp_db).close()
    con = duckdb.connect(str(tmp_db))
    con.execute("INSERT INTO schema_version VALUES (9999, 'future', now()::timestamp)")
    con.close()
    with pytest.raises(UserError, match=r"store schema v9999 is newer than this pedas-study \(v\d+\)"):
        Store.open(tmp_db)
    with pytest.raises(UserError, match="newer"):
        Store.open(tmp_db, read_only=True)


def test_failed_migration_applies_nothing(tmp_db, tmp_path):
    d = tmp_path / "mig"
    d.mkdir()
    shutil.copy(migrate.MIGRATIONS_DIR / "0001_core.sql", d)
    (d / "0002_broken.sql").write_text("CREATE TABLE ok_table (x INTEGER); CREATE TABLE broken (;")
    con = duckdb.connect(str(tmp_db))
    with pytest.raises(UserError, match="0002_broken.sql"):
        migrate.migrate(con, d)
    assert migrate.current_version(con) == 0
    assert con.execute("SELECT count(*) FROM duckdb_tables()").fetchone()[0] == 0
    con.close()


def test_duplicate_migration_numbers_refused(tmp_path):
    (tmp_path / "0001_a.sql").write_text("SELECT 1;")
    (tmp_path / "0001_b.sql").write_text("SELECT 1;")
    with pytest.raises(UserError, match="two migrations with number 0001"):
        migrate.discover(tmp_path)


def test_audit_insert_update_delete(tmp_db):
    with Store.open(tmp_db, actor="alice") as st:
        st.insert("participants", {"participant_id": "P001", "age": 30})
        st.update("participants", {"participant_id": "P001"}, {"age": 31, "style": "normal"})
        assert st.delete("participants", {"participant_id": "P001"}) == 1
        log = st.df('SELECT "at", actor, action, table_name, row_key, old, new FROM audit_log ORDER BY audit_id')
    assert log["action"].tolist() == ["insert", "update", "delete"]
    assert set(log["actor"]) == {"alice"}
    assert set(log["table_name"]) == {"participants"}
    assert all(json.loads(k) == {"participant_id": "P001"} for k in log["row_key"])
    assert json.loads(log.loc[0, "new"])["age"] == 30 and pd.isna(log.loc[0, "old"])
    assert json.loads(log.loc[1, "old"]) == {"age": 30, "style": None}
    assert json.loads(log.loc[1, "new"]) == {"age": 31, "style": "normal"}
    assert json.loads(log.loc[2, "old"])["age"] == 31 and pd.isna(log.loc[2, "new"])
    assert log["at"].notna().all()


def test_actor_from_environment(tmp_db, monkeypatch):
    monkeypatch.setenv("PEDAS_STUDY_ACTOR", "bob")
    with Store.open(tmp_db) as st:
        assert st.actor == "bob"
    with Store.open(tmp_db, actor="carol") as st:
        assert st.actor == "carol"


def test_transaction_rolls_back_data_and_audit(tmp_db):
    with Store.open(tmp_db) as st:
        with pytest.raises(RuntimeError):
            with st.transaction():
                st.insert("participants", {"participant_id": "P001"})
                with st.transaction():  # nested joins the outer one
                    st.insert("participants", {"participant_id": "P002"})
                raise RuntimeError("boom")
        assert st.one("SELECT count(*) FROM participants") == 0
        assert st.one("SELECT count(*) FROM audit_log") == 0
        with st.transaction():
            st.insert("participants", {"participant_id": "P003"})
        assert st.one("SELECT count(*) FROM participants") == 1


def test_constraint_violation_is_user_error_and_changes_nothing(tmp_db):
    with Store.open(tmp_db) as st:
        st.insert("participants", {"participant_id": "P001"})
        before = st.counts()
        for row in ({"participant_id": "P001"}, {"participant_id": "X1"}, {"participant_id": "P002", "age": 5},
                    {"participant_id": "P002", "gender": "robot"}, {"participant_id": "P002", "eco_familiarity": 6},
                    {"participant_id": "P002", "age": 20, "license_years": 10}):
            with pytest.raises(UserError, match="participants"):
                st.insert("participants", row)
        assert st.counts() == before


def test_unknown_table_and_column(tmp_db):
    with Store.open(tmp_db) as st:
        with pytest.raises(UserError, match="no table"):
            st.insert("nope", {"a": 1})
        with pytest.raises(UserError, match="no column 'shoe_size'"):
            st.insert("participants", {"participant_id": "P001", "shoe_size": 44})
        with pytest.raises(UserError, match="no participants row"):
            st.update("participants", {"participant_id": "P404"}, {"age": 30})
        assert st.delete("participants", {"participant_id": "P404"}) == 0


def test_insert_df_is_bulk_and_not_audited(tmp_db):
    with Store.open(tmp_db) as st:
        st.insert("participants", {"participant_id": "P001"})
        df = pd.DataFrame({"drive_id": [1, 1], "idx": [0, 1], "t": [0.0, 0.1], "s": [0.0, 1.0], "v": [10.0, 10.0],
                           "segment": ["urban", "urban"], "speed_limit": [13.9, 13.9]})
        assert st.insert_df("drive_samples", df) == 2
        assert st.one("SELECT count(*) FROM drive_samples") == 2
        assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'drive_samples'") == 0
        bad = df.assign(v=[10.0, 99.0])
        with pytest.raises(UserError, match="drive_samples"):
            st.insert_df("drive_samples", bad)
        assert st.one("SELECT count(*) FROM drive_samples") == 2


def test_read_only(tmp_db):
    with pytest.raises(UserError, match="does not exist"):
        Store.open(tmp_db, read_only=True)
    Store.open(tmp_db).close()
    with Store.open(tmp_db, read_only=True) as st:
        with pytest.raises(UserError, match="read-only"):
            st.insert("participants", {"participant_id": "P001"})


def test_timestamps_are_utc(tmp_db):
    from study.audit_trail import utcnow

    with Store.open(tmp_db) as st:
        row = st.insert("participants", {"participant_id": "P001"})
    assert abs((row["created_at"] - utcnow()).total_seconds()) < 3600  # UTC, not a local-zone offset


def test_store_held_by_another_process(tmp_db):
    import subprocess
    import sys

    Store.open(tmp_db).close()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from study.store import Store; s = Store.open(sys.argv[1]); "
                               "print('ready', flush=True); sys.stdin.readline()", str(tmp_db)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "ready"
        with pytest.raises(UserError, match="in use by another process"):
            Store.open(tmp_db, lock_timeout=0.3)
    finally:
        holder.communicate("\n", timeout=30)
    with Store.open(tmp_db, lock_timeout=5) as st:  # released when the holder ends
        assert st.schema_version == migrate.code_version()


def test_cli_init_reports_upgrade(cli, tmp_db, tmp_path):
    d = tmp_path / "mig"
    d.mkdir()
    shutil.copy(migrate.MIGRATIONS_DIR / "0001_core.sql", d)
    con = duckdb.connect(str(tmp_db))
    migrate.migrate(con, d)
    con.close()
    r = cli("init")
    expect = "upgraded" if migrate.code_version() > 1 else "up to date"
    assert r.code == 0 and expect in r.out
    assert "up to date" in cli("init").out


def test_codebook_items_added_later_are_loaded(tmp_db, tmp_path, monkeypatch):
    from study.instrument import INSTRUMENT_DIR, load_instrument

    src = (INSTRUMENT_DIR / "pedas_acceptance_v1.csv").read_text()
    d = tmp_path / "instruments"
    d.mkdir()
    lines = src.splitlines()
    (d / "lab_v1.csv").write_text("\n".join(lines[:5]) + "\n")
    monkeypatch.setattr("study.store.INSTRUMENT_DIR", d)
    monkeypatch.setattr("study.instrument.INSTRUMENT_DIR", d)
    load_instrument.cache_clear()
    try:
        with Store.open(tmp_db) as st:
            assert st.one("SELECT count(*) FROM items WHERE instrument = 'lab_v1'") == 4
        (d / "lab_v1.csv").write_text("\n".join(lines[:8]) + "\n")
        load_instrument.cache_clear()
        with Store.open(tmp_db) as st:
            assert st.one("SELECT count(*) FROM items WHERE instrument = 'lab_v1'") == 7
            assert st.one("SELECT n_items FROM instruments WHERE instrument = 'lab_v1'") == 7
            assert st.df("SELECT position FROM items ORDER BY position")["position"].tolist() == list(range(1, 8))
    finally:
        load_instrument.cache_clear()

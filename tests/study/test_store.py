"""The DuckDB store: migrations, transactions, audit trail, constraints."""
import json
import shutil
from pathlib import Path

import duckdb
import pandas as pd
import pytest

from study.store import migrate
from study.common.errors import UserError
from study.store.store import Store

STUDIES = Path(__file__).resolve().parents[2] / "studies"
PAPER, LK = STUDIES / "pedas_paper", STUDIES / "lane_keeping"


def test_open_creates_and_migrates(tmp_db):
    with Store.open(tmp_db, actor="alice") as st:
        assert st.schema_version == migrate.code_version()
        assert {"participants", "participant_attributes", "study_definitions", "phase_events", "exclusions",
                "drives", "drive_samples", "instruments", "items", "responses", "audit_log",
                "schema_version"} <= set(st.tables())
        # no study is built in: opening loads no codebook
        assert st.one("SELECT count(*) FROM items") == 0 and st.one("SELECT count(*) FROM study_definitions") == 0


def test_the_study_brings_its_codebook(paper_db):
    with Store.open(paper_db) as st:
        # the study's codebook is loaded as reference data, not audited
        assert st.one("SELECT count(*) FROM items WHERE instrument = 'pedas_acceptance_v1'") == 33
        assert st.df("SELECT position FROM items ORDER BY position")["position"].tolist() == list(range(1, 34))
        assert st.one("SELECT count(*) FROM audit_log WHERE table_name IN ('items', 'instruments')") == 0


def test_reopen_is_idempotent(tmp_db):
    Store.open(tmp_db).close()
    with Store.open(tmp_db) as st:
        versions = st.df("SELECT version FROM schema_version ORDER BY version")["version"].tolist()
    assert versions == [m.version for m in migrate.discover()]


def _old_store(db, tmp_path, upto: int = 20):
    """A store created by the schema before studies were data (migrations 0001..`upto`), holding the data the
    paper's study gathered then: participants with their fixed demographics, a drive, a phase, an exclusion."""
    old = tmp_path / "old_migrations"
    old.mkdir()
    for m in migrate.discover():
        if m.version <= upto:
            shutil.copy(m.path, old)
    con = duckdb.connect(str(db))
    assert [m.version for m in migrate.migrate(con, old)][-1] == upto
    con.execute("INSERT INTO participants (participant_id, age, gender, license_years, style, eco_familiarity) "
                "VALUES ('P001', 40, 'female', 20, 'sporty', 3), ('P002', NULL, NULL, NULL, 'normal', NULL)")
    con.execute("INSERT INTO drives (participant_id, condition, source, checksum, n_samples, duration_s) "
                "VALUES ('P001', 'baseline', 'import', ?, 3, 12.5)", ["a" * 64])
    con.execute("INSERT INTO drive_samples (drive_id, idx, t, s, v, segment, speed_limit) SELECT drive_id, i, i, "
                "10.0 * i, 10.0, 'urban', 13.9 FROM drives, range(3) r(i)")
    con.execute("INSERT INTO phase_events (participant_id, phase, seq, started_at) "
                "VALUES ('P001', 'familiarisation', 1, TIMESTAMP '2026-01-05 09:00:00')")
    con.execute("INSERT INTO exclusions (participant_id, scope, reason) VALUES ('P002', 'all', 'withdrawn')")
    con.close()


def test_older_store_is_upgraded_and_keeps_its_data(tmp_db, tmp_path):
    """A store of the old schema opened by this code keeps every row; the demographics become attribute rows,
    which the paper's study then types as before."""
    from study.people.participants import participant_attributes
    from study.store.studies import register

    _old_store(tmp_db, tmp_path)
    with Store.open(tmp_db) as st:
        assert st.schema_version == migrate.code_version()
        assert st.df("SELECT participant_id, protocol FROM participants ORDER BY 1").values.tolist() == [
            ["P001", "paper_v1"], ["P002", "paper_v1"]]
        assert st.df("SELECT participant_id, attribute, value FROM participant_attributes ORDER BY 1, 2"
                     ).values.tolist() == [["P001", "age", "40"], ["P001", "eco_familiarity", "3"],
                                           ["P001", "gender", "female"], ["P001", "license_years", "20"],
                                           ["P001", "style", "sporty"], ["P002", "style", "normal"]]
        assert st.df("SELECT participant_id, condition, n_samples, duration_s FROM drives").values.tolist() == [
            ["P001", "baseline", 3, 12.5]]
        assert st.one("SELECT count(*) FROM drive_samples") == 3
        assert st.one("SELECT count(*) FROM phase_events") == 1 and st.one("SELECT count(*) FROM exclusions") == 1
        # the store gets its study afterwards; it holds data, so the study must fit it (it does)
        assert register(st, PAPER) == ("stored", 1)
        wide = participant_attributes(st).set_index("participant_id")
        assert wide.loc["P001", ["age", "gender", "license_years", "style", "eco_familiarity"]].tolist() == [
            40, "female", 20, "sporty", 3]
        assert pd.isna(wide.loc["P002", "age"]) and wide.loc["P002", "style"] == "normal"


def test_an_upgraded_store_refuses_a_study_its_data_do_not_fit(tmp_db, tmp_path):
    from study.store.studies import register

    _old_store(tmp_db, tmp_path)
    with Store.open(tmp_db) as st:
        before = st.counts()
        with pytest.raises(UserError, match="re-interpret stored data: participant P001: bad participant id"):
            register(st, LK)
        assert st.counts() == before


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
        st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})
        st.update("participants", {"participant_id": "P001"}, {"protocol": "b_v1", "study_version": 2})
        assert st.delete("participants", {"participant_id": "P001"}) == 1
        log = st.df('SELECT "at", actor, action, table_name, row_key, old, new FROM audit_log ORDER BY audit_id')
    assert log["action"].tolist() == ["insert", "update", "delete"]
    assert set(log["actor"]) == {"alice"}
    assert set(log["table_name"]) == {"participants"}
    assert all(json.loads(k) == {"participant_id": "P001"} for k in log["row_key"])
    assert json.loads(log.loc[0, "new"])["protocol"] == "a_v1" and pd.isna(log.loc[0, "old"])
    assert json.loads(log.loc[1, "old"]) == {"protocol": "a_v1", "study_version": None}
    assert json.loads(log.loc[1, "new"]) == {"protocol": "b_v1", "study_version": 2}
    assert json.loads(log.loc[2, "old"])["protocol"] == "b_v1" and pd.isna(log.loc[2, "new"])
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
                st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})
                with st.transaction():  # nested joins the outer one
                    st.insert("participants", {"participant_id": "P002", "protocol": "a_v1"})
                raise RuntimeError("boom")
        assert st.one("SELECT count(*) FROM participants") == 0
        assert st.one("SELECT count(*) FROM audit_log") == 0
        with st.transaction():
            st.insert("participants", {"participant_id": "P003", "protocol": "a_v1"})
        assert st.one("SELECT count(*) FROM participants") == 1


def test_constraint_violation_is_user_error_and_changes_nothing(tmp_db):
    """The schema keeps what holds for every study (a key, no whitespace, at most 64 characters, a protocol);
    a study's own rules are the Python layer's (tests/study/test_participants.py)."""
    with Store.open(tmp_db) as st:
        st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})
        before = st.counts()
        for row in ({"participant_id": "P001", "protocol": "a_v1"}, {"participant_id": "P 2", "protocol": "a_v1"},
                    {"participant_id": "", "protocol": "a_v1"}, {"participant_id": "P" * 65, "protocol": "a_v1"},
                    {"participant_id": "P002"}):
            with pytest.raises(UserError, match="participants"):
                st.insert("participants", row)
        with pytest.raises(UserError, match="participant_attributes"):
            st.insert("participant_attributes", {"participant_id": "P404", "attribute": "age", "value": "30"})
        assert st.counts() == before


def test_unknown_table_and_column(tmp_db):
    with Store.open(tmp_db) as st:
        with pytest.raises(UserError, match="no table"):
            st.insert("nope", {"a": 1})
        with pytest.raises(UserError, match="no column 'shoe_size'"):
            st.insert("participants", {"participant_id": "P001", "protocol": "a_v1", "shoe_size": 44})
        with pytest.raises(UserError, match="no participants row"):
            st.update("participants", {"participant_id": "P404"}, {"protocol": "b_v1"})
        assert st.delete("participants", {"participant_id": "P404"}) == 0


def test_insert_df_is_bulk_and_not_audited(tmp_db):
    with Store.open(tmp_db) as st:
        st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})
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
            st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})


def test_timestamps_are_utc(tmp_db):
    from study.store.audit_trail import utcnow

    with Store.open(tmp_db) as st:
        row = st.insert("participants", {"participant_id": "P001", "protocol": "a_v1"})
    assert abs((row["created_at"] - utcnow()).total_seconds()) < 3600  # UTC, not a local-zone offset


def test_store_held_by_another_process(tmp_db):
    import subprocess
    import sys

    Store.open(tmp_db).close()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from study.store.store import Store; s = Store.open(sys.argv[1]); "
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
    assert r.code == 0 and expect in r.out and "the store has no study yet" in r.out
    r = cli("init", "--study", PAPER)
    assert r.code == 0 and "up to date" in r.out and "study pedas_paper version 1 stored" in r.out


def test_cli_init_of_a_new_store_needs_a_study(cli, tmp_db, tmp_path):
    r = cli("init")
    assert r.code == 2 and "a new store needs its study" in r.err and not tmp_db.exists()
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "study.toml").write_text("[study]\nid = 'x'\n")
    r = cli("init", "--study", tmp_path / "broken")
    assert r.code == 2 and "study.toml" in r.err and len(r.err.strip().splitlines()) == 1
    assert not tmp_db.exists()  # a refused study creates no store


def test_a_waiting_opener_queues_and_gets_the_store_when_released(tmp_db):
    """While another process holds the store, an opener retries with back-off and announces that it waits
    (`others_waiting`, which a server checks before it reopens the store); it gets the store once released."""
    import subprocess
    import sys
    import threading
    import time

    from study.store.store import others_waiting

    Store.open(tmp_db).close()
    assert not others_waiting(tmp_db)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys; from study.store.store import Store; s = Store.open(sys.argv[1]); "
                               "print('ready', flush=True); sys.stdin.readline()", str(tmp_db)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    got = {}
    try:
        assert holder.stdout.readline().strip() == "ready"
        opener = threading.Thread(target=lambda: got.setdefault("st", Store.open(tmp_db, lock_timeout=60)))
        opener.start()
        deadline = time.monotonic() + 30
        while not others_waiting(tmp_db) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert others_waiting(tmp_db) and opener.is_alive()
    finally:
        holder.communicate("\n", timeout=30)
    opener.join(timeout=60)
    st = got["st"]
    assert st.lock_wait.retries > 0 and st.lock_wait.seconds > 0
    assert not others_waiting(tmp_db)           # the queue is left on success
    st.close()

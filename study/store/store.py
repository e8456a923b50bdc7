"""The study store: one embedded DuckDB file holding participants, protocol events, exclusions, drive logs,
survey answers and the audit trail.

    from study.store.store import Store
    with Store.open("data/study.duckdb", actor="alice") as st:
        with st.transaction():                       # all or nothing
            st.insert("participants", {"participant_id": "P001", "protocol": "paper_v1"})
            st.update("participants", {"participant_id": "P001"}, {"protocol": "counterbalanced_v1"})
        st.df("SELECT * FROM participants")

Every :meth:`Store.insert`, :meth:`Store.update` and :meth:`Store.delete` writes an ``audit_log`` row in the same
transaction. :meth:`Store.insert_df` is the bulk path for drive samples and is not audited per row (the parent
``drives`` row is). Opening a store creates the file if needed and applies pending migrations; a store with a
newer schema than this code is refused.
"""
from __future__ import annotations

import logging
import os
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import duckdb

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

from study.common.errors import UserError
from study.store import audit_trail, migrate

log = logging.getLogger(__name__)

#: how long opening waits for another process to release the store (s): longer than a command holds it
LOCK_TIMEOUT = 30.0
#: opening a store another process holds is retried after 5 ms, 7.5 ms, ... at most 100 ms apart
LOCK_BACKOFF_FIRST = 0.005
LOCK_BACKOFF_FACTOR = 1.5
LOCK_BACKOFF_MAX = 0.1
#: the migration that keys answers by occasion; the rows it migrates get their occasion from the stored study
OCCASIONS_MIGRATION = 50


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


class StoreBusy(UserError):
    """Another process held the store for longer than the opener was willing to wait."""


@dataclass
class LockWait:
    """How long :meth:`Store.open` waited for another process to release the file."""

    retries: int = 0
    seconds: float = 0.0


class _Queue:
    """Openers waiting for the store announce it with a shared ``flock`` on ``<store>.waiting`` (released on
    success, failure or the process's death); an opener that finds it held lets the waiting ones go first.
    Without ``fcntl`` (Windows) or a writable folder there is no queue, only the retries."""

    def __init__(self, path: Path) -> None:
        self.file = path.with_name(path.name + ".waiting")
        self.fd: int | None = None

    @property
    def joined(self) -> bool:
        return self.fd is not None

    def _open(self) -> int | None:
        try:
            return os.open(self.file, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            return None

    def others_waiting(self) -> bool:
        if fcntl is None or not self.file.exists():
            return False
        fd = self._open()
        if fd is None:
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return False
        except OSError:
            return True
        finally:
            os.close(fd)  # closing drops the probe's lock

    def join(self) -> None:
        if self.fd is None and fcntl is not None:
            self.fd = self._open()
            if self.fd is not None:
                fcntl.flock(self.fd, fcntl.LOCK_SH)

    def leave(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def others_waiting(path: str | Path) -> bool:
    """True while another opener (any process) waits for the store at `path` to be released."""
    return _Queue(Path(path)).others_waiting()


class Store:
    """An open study store. Create with :meth:`Store.open`; use as a context manager to close it."""

    def __init__(self, con: duckdb.DuckDBPyConnection, path: Path, actor: str, read_only: bool) -> None:
        self.con = con
        self.path = path
        self.actor = actor
        self.read_only = read_only
        self._depth = 0           # transaction nesting: only the outermost level talks to DuckDB
        self._columns: dict[str, list[str]] = {}
        self._keys: dict[str, list[str]] = {}
        self.applied: list[int] = []
        self.lock_wait = LockWait()

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path: str | Path, actor: str | None = None, read_only: bool = False,
             lock_timeout: float | None = None) -> "Store":
        """Open (creating and migrating if needed) the store at `path`.

        `actor` is recorded in the audit log (default $PEDAS_STUDY_ACTOR, else the OS user). `read_only=True`
        neither creates nor migrates. DuckDB allows one writing process per file: while another process holds
        the file, opening is retried with back-off for `lock_timeout` seconds (default :data:`LOCK_TIMEOUT`),
        then refused with a one-line reason (:class:`StoreBusy`). How long it waited is :attr:`lock_wait`.
        """
        path = Path(path)
        if read_only and not path.exists():
            raise UserError(f"store {path} does not exist (run `pedas-study init`)")
        if not read_only:
            path.parent.mkdir(parents=True, exist_ok=True)
        con, wait = cls._connect(path, read_only, LOCK_TIMEOUT if lock_timeout is None else lock_timeout)
        if wait.retries:
            log.info("waited %.3f s (%d retries) for store %s", wait.seconds, wait.retries, path)
        try:
            con.execute("SET TimeZone = 'UTC'")
            applied = [] if read_only else migrate.migrate(con)
            if read_only:
                migrate.check_not_newer(con)
            st = cls(con, path, audit_trail.resolve_actor(actor), read_only)
            st.applied = [m.version for m in applied]  # migrations applied by this open (for `init`)
            if OCCASIONS_MIGRATION in st.applied:  # answers stored before occasions get their study's occasion
                from study.folder.occasions import fill_migrated
                from study.store.studies import definition

                try:
                    study = definition(st)
                except UserError:  # no study stored yet: `init --study` fills them
                    study = None
                if study is not None:
                    fill_migrated(st, study)
            st.lock_wait = wait
        except BaseException:
            con.close()
            raise
        return st

    @staticmethod
    def _connect(path: Path, read_only: bool, lock_timeout: float) -> tuple[duckdb.DuckDBPyConnection, LockWait]:
        """A connection to `path`, retried with back-off while another process holds the file (see
        :class:`LockWait`); busy after `lock_timeout` seconds -> :class:`StoreBusy`."""
        wait = LockWait()
        start = time.monotonic()
        queue = _Queue(path)
        try:
            while True:
                # an opener that arrives while others wait lets them in first (fairness: a server that reopens
                # the store for every request would otherwise always win the race against a waiting command)
                polite = not queue.joined and queue.others_waiting()
                if not polite:
                    try:
                        con = duckdb.connect(str(path), read_only=read_only)
                        wait.seconds = time.monotonic() - start
                        return con, wait
                    except duckdb.IOException as exc:
                        if "lock" not in str(exc).lower():
                            raise UserError(f"cannot open store {path}: {_one_line(exc)}") from exc
                        busy = exc
                    except duckdb.Error as exc:
                        raise UserError(f"cannot open store {path}: {_one_line(exc)}") from exc
                    queue.join()
                if time.monotonic() - start >= lock_timeout:
                    raise StoreBusy(f"store {path} is in use by another process; try again later") from (
                        None if polite else busy)
                time.sleep(min(LOCK_BACKOFF_MAX, LOCK_BACKOFF_FIRST * LOCK_BACKOFF_FACTOR ** wait.retries))
                wait.retries += 1
        finally:
            queue.leave()

    def close(self) -> None:
        self.con.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        return migrate.current_version(self.con)

    # ------------------------------------------------------------------ transactions
    @contextmanager
    def transaction(self) -> Iterator["Store"]:
        """BEGIN ... COMMIT; ROLLBACK on any exception. Nested uses join the outer transaction.

        A statement that fails inside a transaction (e.g. a constraint violation) aborts the whole DuckDB
        transaction: let the exception propagate rather than catching it and writing on.
        """
        if self._depth:
            self._depth += 1
            try:
                yield self
            finally:
                self._depth -= 1
            return
        self.con.begin()
        self._depth = 1
        try:
            yield self
        except BaseException:
            self._depth = 0
            self.con.rollback()
            raise
        self._depth = 0
        try:
            self.con.commit()
        except duckdb.Error as exc:  # a constraint checked at commit
            try:
                self.con.rollback()
            except duckdb.Error:
                pass
            raise UserError(f"commit failed: {_one_line(exc)}") from exc

    # ------------------------------------------------------------------ schema helpers
    def columns(self, table: str) -> list[str]:
        """Column names of `table` in order; unknown table -> UserError."""
        if table not in self._columns:
            # the result's description, not duckdb_columns(): a catalog scan cost ~3 ms per table per command
            name = table.replace('"', '""')
            try:
                cur = self.con.execute(f'SELECT * FROM main."{name}" LIMIT 0')
            except duckdb.CatalogException:
                raise UserError(f"no table {table!r} in the store") from None
            self._columns[table] = [d[0] for d in cur.description]
        return self._columns[table]

    def key_columns(self, table: str) -> list[str]:
        """The primary key of `table` (else its first UNIQUE constraint, else [] = whole row)."""
        if table not in self._keys:
            self.columns(table)
            rows = self.con.execute(
                "SELECT constraint_type, constraint_column_names FROM duckdb_constraints() "
                "WHERE table_name = ? AND schema_name = 'main' AND constraint_type IN ('PRIMARY KEY', 'UNIQUE') "
                "ORDER BY constraint_type = 'PRIMARY KEY' DESC, constraint_index", [table]).fetchall()
            self._keys[table] = list(rows[0][1]) if rows else []
        return self._keys[table]

    def tables(self) -> list[str]:
        """Base tables of the store (alphabetical)."""
        return [r[0] for r in self.con.execute(
            "SELECT table_name FROM duckdb_tables() WHERE schema_name = 'main' ORDER BY table_name").fetchall()]

    def counts(self) -> dict[str, int]:
        """Row count of every table (used to show that a refused operation changed nothing)."""
        tables = self.tables()
        # one statement for all tables: the tests take this before and after each of thousands of requests
        sql = " UNION ALL ".join(f"SELECT {k} AS k, count(*) AS n FROM \"{t}\"" for k, t in enumerate(tables))
        n = dict(self.con.execute(sql).fetchall()) if tables else {}
        return {t: int(n[k]) for k, t in enumerate(tables)}

    def _check_columns(self, table: str, names: Sequence[str]) -> None:
        known = self.columns(table)
        for n in names:
            if n not in known:
                raise UserError(f"table {table} has no column {n!r}")

    def _key_of(self, table: str, row: Mapping[str, Any]) -> dict[str, Any]:
        cols = self.key_columns(table)
        return {c: row[c] for c in cols} if cols else dict(row)

    @staticmethod
    def _where(key: Mapping[str, Any]) -> tuple[str, list[Any]]:
        if not key:
            raise UserError("an empty key would match every row")
        parts, params = [], []
        for c, v in key.items():
            if v is None:
                parts.append(f'"{c}" IS NULL')
            else:
                parts.append(f'"{c}" = ?')
                params.append(v)
        return " AND ".join(parts), params

    def _fetch(self, table: str, key: Mapping[str, Any]) -> list[dict[str, Any]]:
        where, params = self._where(key)
        return self.dicts(f'SELECT * FROM "{table}" WHERE {where}', params)

    def _write(self, sql: str, params: list[Any], table: str):
        try:
            return self.con.execute(sql, params)
        except duckdb.ConstraintException as exc:  # said as the field's rule when the constraint's shape is known
            from study.store.constraint_text import constraint_rule

            raise UserError(f"{table}: {constraint_rule(str(exc)) or _one_line(exc)}") from exc
        except (duckdb.ConversionException, duckdb.InvalidInputException) as exc:
            raise UserError(f"{table}: {_one_line(exc)}") from exc

    # ------------------------------------------------------------------ audited writes
    def insert(self, table: str, row: Mapping[str, Any]) -> dict[str, Any]:
        """Insert one row (audited); returns the row as stored, defaults included."""
        self._writable()
        row = dict(row)
        self._check_columns(table, list(row))
        cols = ", ".join(f'"{c}"' for c in row)
        marks = ", ".join("?" for _ in row)
        with self.transaction():
            cur = self._write(f'INSERT INTO "{table}" ({cols}) VALUES ({marks}) RETURNING *', list(row.values()), table)
            names = [d[0] for d in cur.description]
            stored = dict(zip(names, cur.fetchone()))
            audit_trail.record(self.con, self.actor, "insert", table, self._key_of(table, stored), None, stored)
        return stored

    def update(self, table: str, key: Mapping[str, Any], values: Mapping[str, Any]) -> dict[str, Any]:
        """Update the row(s) matching `key` with `values` (audited old -> new of the changed columns).

        Returns the new row (the first when several match). No matching row -> UserError.
        """
        self._writable()
        key, values = dict(key), dict(values)
        self._check_columns(table, list(key) + list(values))
        if not values:
            raise UserError("update without values")
        with self.transaction():
            old_rows = self._fetch(table, key)
            if not old_rows:
                raise UserError(f"no {table} row with {audit_trail.to_json(key)}")
            sets = ", ".join(f'"{c}" = ?' for c in values)
            where, params = self._where(key)
            cur = self._write(f'UPDATE "{table}" SET {sets} WHERE {where} RETURNING *',
                              list(values.values()) + params, table)
            names = [d[0] for d in cur.description]
            new_rows = [dict(zip(names, r)) for r in cur.fetchall()]
            by_key = {audit_trail.to_json(self._key_of(table, r)): r for r in old_rows}
            for new in new_rows:
                k = self._key_of(table, new)
                old = by_key.get(audit_trail.to_json(k), old_rows[0])
                changed = [c for c in values if old.get(c) != new.get(c)]
                audit_trail.record(self.con, self.actor, "update", table, k,
                             {c: old.get(c) for c in changed}, {c: new.get(c) for c in changed})
        return new_rows[0]

    def delete(self, table: str, key: Mapping[str, Any]) -> int:
        """Delete the row(s) matching `key` (each audited with its old values); returns how many."""
        self._writable()
        key = dict(key)
        self._check_columns(table, list(key))
        with self.transaction():
            old_rows = self._fetch(table, key)
            if not old_rows:
                return 0
            where, params = self._where(key)
            self._write(f'DELETE FROM "{table}" WHERE {where}', params, table)
            for old in old_rows:
                audit_trail.record(self.con, self.actor, "delete", table, self._key_of(table, old), old, None)
        return len(old_rows)

    # ------------------------------------------------------------------ bulk
    def insert_df(self, table: str, df) -> int:
        """Bulk insert a pandas DataFrame (or Arrow table) whose columns are a subset of `table`'s, by name.

        Not audited per row: the caller audits the parent row (e.g. ``drives``) in the same transaction.
        """
        self._writable()
        names = list(df.column_names if hasattr(df, "column_names") else df.columns)
        self._check_columns(table, names)
        view = f"_insert_df_{id(df)}"
        cols = ", ".join(f'"{c}"' for c in names)
        with self.transaction():
            self.con.register(view, df)
            try:
                self._write(f'INSERT INTO "{table}" ({cols}) SELECT {cols} FROM "{view}"', [], table)
            finally:
                try:
                    self.con.unregister(view)
                except duckdb.Error:  # an aborted transaction refuses it; the name is replaced on next use
                    pass
        return len(df) if hasattr(df, "__len__") else df.num_rows

    # ------------------------------------------------------------------ reads
    def df(self, sql: str, params: Sequence[Any] | Mapping[str, Any] | None = None):
        """Run a query and return a pandas DataFrame."""
        return self.con.execute(sql, params).df() if params is not None else self.con.execute(sql).df()

    def dicts(self, sql: str, params: Sequence[Any] | None = None) -> list[dict[str, Any]]:
        """Run a query and return its rows as dicts of Python values (no pandas: for the commands that load none)."""
        cur = self.con.execute(sql, params or [])
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r)) for r in cur.fetchall()]

    def one(self, sql: str, params: Sequence[Any] | None = None) -> Any:
        """First column of the first row (None when no row)."""
        row = self.con.execute(sql, params or []).fetchone()
        return None if row is None else row[0]

    # ------------------------------------------------------------------ internals
    def _writable(self) -> None:
        if self.read_only:
            raise UserError(f"store {self.path} is open read-only")


class StoreHolder:
    """A long-running process's store (the survey server, the live server), open only while requests use it, so
    that CLI commands can use the same file between requests (DuckDB allows one writing process per file).

    Use it like a re-entrant lock (``with holder:``, ``acquire()``/``release()``): the outermost acquire opens the
    store (waiting, with back-off, for a command that holds it: :meth:`Store.open`), the matching release closes
    it — unless another request is already waiting for the lock and no other process waits for the file: then
    the next request gets the open store (a burst of requests opens the file once). Everything a request does
    under one acquire sees one connection, so a check and the write it guards stay together. One thread at a
    time: a DuckDB connection must not be shared by two threads. After :meth:`shut` acquiring no longer opens
    the store (:attr:`store` is None).
    """

    def __init__(self, path: str | Path, actor: str, lock_timeout: float | None = None) -> None:
        self.path, self.actor, self.lock_timeout = Path(path), actor, lock_timeout
        self.store: Store | None = None
        self.closed = False
        self._lock = threading.RLock()
        self._depth = 0
        self._queued = 0                # threads waiting for the lock
        self._count = threading.Lock()

    def acquire(self) -> bool:
        with self._count:
            self._queued += 1
        self._lock.acquire()
        with self._count:
            self._queued -= 1
        if self._depth == 0 and self.store is None and not self.closed:
            try:
                self.store = Store.open(self.path, actor=self.actor, lock_timeout=self.lock_timeout)
            except BaseException:
                self._lock.release()
                raise
        self._depth += 1
        return True

    def release(self) -> None:
        self._depth -= 1
        try:
            if self._depth == 0 and self.store is not None:
                with self._count:
                    handover = self._queued > 0
                if not handover or others_waiting(self.path):
                    st, self.store = self.store, None
                    st.close()
        finally:
            self._lock.release()

    def __enter__(self) -> "StoreHolder":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def shut(self) -> None:
        """Wait until no request holds the store, close it, and never open it again."""
        with self._lock:
            self.closed = True
            if self.store is not None:
                st, self.store = self.store, None
                st.close()

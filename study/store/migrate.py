"""Forward-only schema migrations of the study store.

Migrations are SQL files ``study/store/migrations/NNNN_name.sql`` applied in number order, each exactly once; the
applied ones are listed in the ``schema_version`` table. Number ranges per part: 0001-0009 core store,
0010-0019 survey, 0020-0029 scheduling. A store whose schema is newer than the newest file this code knows is
refused (an older program must not write into a newer layout).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from study.common.errors import UserError

MIGRATIONS_DIR = Path(__file__).with_name("migrations")
_NAME = re.compile(r"^(\d{4})_([A-Za-z0-9_]+)\.sql$")


@dataclass(frozen=True)
class Migration:
    version: int
    name: str
    path: Path

    @property
    def sql(self) -> str:
        return self.path.read_text(encoding="utf-8")


def discover(directory: Path = MIGRATIONS_DIR) -> list[Migration]:
    """All migration files in number order; two files with the same number are an error."""
    found: dict[int, Migration] = {}
    for path in sorted(directory.glob("*.sql")):
        m = _NAME.match(path.name)
        if not m:
            raise UserError(f"migration file name {path.name!r} does not match NNNN_name.sql")
        version = int(m.group(1))
        if version in found:
            raise UserError(f"two migrations with number {version:04d}: {found[version].path.name}, {path.name}")
        found[version] = Migration(version, m.group(2), path)
    return [found[v] for v in sorted(found)]


def code_version(directory: Path = MIGRATIONS_DIR) -> int:
    """The newest schema version this code can build."""
    migrations = discover(directory)
    return migrations[-1].version if migrations else 0


def applied_versions(con) -> set[int]:
    """The schema versions applied to an open store (empty for a file without ``schema_version``: a new store). One
    plain query: asking DuckDB's catalog first (``duckdb_tables()``) cost ~7 ms of every store opening."""
    import duckdb

    try:
        rows = con.execute("SELECT version FROM schema_version").fetchall()
    except duckdb.CatalogException:
        return set()
    return {int(r[0]) for r in rows}


def current_version(con) -> int:
    """Schema version of an open store (0 for an empty file)."""
    return max(applied_versions(con), default=0)


def check_not_newer(con, directory: Path = MIGRATIONS_DIR, applied: set[int] | None = None) -> int:
    """The store's schema version (`applied`: :func:`applied_versions`, if already read); UserError when it is newer
    than the newest migration of `directory`."""
    have = max(applied_versions(con) if applied is None else applied, default=0)
    know = code_version(directory)
    if have > know:
        raise UserError(f"store schema v{have} is newer than this pedas-study (v{know}); upgrade pedas-study")
    return have


def migrate(con, directory: Path = MIGRATIONS_DIR) -> list[Migration]:
    """Apply all pending migrations in ONE transaction (all or nothing); returns those applied."""
    applied = applied_versions(con)
    check_not_newer(con, directory, applied)
    todo = [m for m in discover(directory) if m.version not in applied]
    if not todo:
        return []
    con.begin()
    try:
        con.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER PRIMARY KEY, name VARCHAR NOT NULL, "
                    "applied_at TIMESTAMP NOT NULL)")
        for m in todo:
            try:
                con.execute(m.sql)
            except Exception as exc:
                raise UserError(f"migration {m.path.name} failed: {' '.join(str(exc).split())}") from exc
            con.execute("INSERT INTO schema_version VALUES (?, ?, ?)",
                        [m.version, m.name, datetime.now(timezone.utc).replace(tzinfo=None)])
        con.commit()
    except BaseException:
        con.rollback()
        raise
    return todo

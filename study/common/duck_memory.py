"""DuckDB's memory held to a bound while a statement streams millions of rows (an export, a large drive import).

DuckDB buffers and caches up to its memory limit, by default 80 % of the machine's memory, so a statement that
streams a whole table grows the process by gigabytes although it runs in a few hundred megabytes (measured by
``pedas-study bench export``, docs/store.md). Beyond the bound DuckDB writes to its temporary directory next to the
store. The limit belongs to the database, which every connection to the file in this process shares, so the block
restores the previous value afterwards; the survey server opens the store for one request at a time under its lock,
so two blocks never overlap.
"""
from __future__ import annotations

import re
from contextlib import contextmanager
from typing import Iterator

_UNITS = {"": 1, "b": 1, "byte": 1, "bytes": 1, "kb": 10 ** 3, "mb": 10 ** 6, "gb": 10 ** 9, "tb": 10 ** 12,
          "kib": 2 ** 10, "mib": 2 ** 20, "gib": 2 ** 30, "tib": 2 ** 40}


def size_bytes(text: str) -> float | None:
    """Bytes of a DuckDB size such as ``"400MB"`` or ``"18.7 GiB"``; None when it is not one."""
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([A-Za-z]*)\s*", str(text))
    if not m or m.group(2).lower() not in _UNITS:
        return None
    return float(m.group(1)) * _UNITS[m.group(2).lower()]


@contextmanager
def bounded(con, limit: str | None) -> Iterator[None]:
    """The block with `con`'s database held to `limit` of memory (a DuckDB size, e.g. ``"400MB"``; None or a lower
    limit already set: unchanged) and without DuckDB's progress bar on the terminal; both settings restored
    afterwards."""
    old = dict(con.execute("SELECT name, value FROM duckdb_settings() "
                           "WHERE name IN ('memory_limit', 'enable_progress_bar')").fetchall())
    want = None if limit is None else size_bytes(limit)
    if limit is not None and want is None:
        raise ValueError(f"not a DuckDB memory size: {limit!r}")
    have = size_bytes(old.get("memory_limit", ""))
    lowered = want is not None and (have is None or want < have)
    if lowered:
        con.execute(f"SET memory_limit = '{limit}'")
    con.execute("SET enable_progress_bar = false")
    try:
        yield
    finally:
        con.execute(f"SET enable_progress_bar = {old.get('enable_progress_bar', 'true')}")
        if lowered:
            # the shown value is rounded ("18.7 GiB"): the default is restored exactly by RESET, another value as shown
            con.execute("RESET memory_limit")
            if _setting(con, "memory_limit") != old["memory_limit"]:
                con.execute(f"SET memory_limit = '{old['memory_limit']}'")


def _setting(con, name: str) -> str:
    return con.execute("SELECT value FROM duckdb_settings() WHERE name = ?", [name]).fetchone()[0]

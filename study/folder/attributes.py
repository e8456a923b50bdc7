"""Participant attribute values against the study's declaration: each value typed and range-checked, the required
ones present, and the study's ``[[checks]]`` over several attributes evaluated (docs/study_folder.md)."""
from __future__ import annotations

import re
import threading
from typing import Any, Mapping

from study.common.errors import UserError

_SQL_TYPES = {"integer": "BIGINT", "number": "DOUBLE", "choice": "VARCHAR", "text": "VARCHAR"}
_CHECKS_LOCK = threading.Lock()
_CHECKS_DB: list = []   # the in-memory DuckDB database the checks run in, opened on first use


def _check_connection():
    """A new connection (cursor) to a private in-memory DuckDB database opened once per process. Why not
    ``duckdb.connect()`` per call: opening a database costs ~25 ms, a connection to an open one about 1 ms, and a
    roster checks every row. Why not the store's database: an error inside the store's transaction would abort
    that transaction, and the store's settings (its time zone, UTC) would be the checks' too, which they never
    were. One cursor per call, so threads (the web app) never share one."""
    import duckdb

    with _CHECKS_LOCK:
        if not _CHECKS_DB:
            _CHECKS_DB.append(duckdb.connect())
        return _CHECKS_DB[0].cursor()


def typed_attributes(study, attributes: Mapping[str, Any] | None) -> dict[str, Any]:
    """{name: typed value} of every declared attribute (None when not given) after checking each value, the
    required attributes and the study's checks; any problem -> UserError (one line)."""
    given = dict(attributes or {})
    values: dict[str, Any] = {a.name: None for a in study.attributes}
    for name, raw in given.items():
        values[study.attribute(name).name] = study.attribute(name).parse(raw)
    missing = [a.name for a in study.attributes if a.required and values[a.name] is None]
    if missing:
        raise UserError(f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} required "
                        f"(study {study.study_id})")
    run_checks(study, values)
    return values


def run_checks(study, values: dict[str, Any]) -> None:
    """Evaluate the study's [[checks]] with DuckDB over one row of typed values. A check that is false refuses
    the values with its message; NULL (a value it needs is missing) passes, as in a SQL CHECK constraint."""
    if not study.checks:
        return
    import duckdb

    attrs = study.attributes
    cols = ", ".join(f'CAST(? AS {_SQL_TYPES[a.type]}) AS "{a.name}"' for a in attrs) or "NULL AS _none"
    params = [values.get(a.name) for a in attrs]
    con = _check_connection()
    try:
        for c in study.checks:
            try:
                ok = con.execute(f"SELECT CAST(({c.sql}) AS BOOLEAN) FROM (SELECT {cols}) AS p", params).fetchone()[0]
            except duckdb.Error as exc:
                raise UserError(f"check {c.sql!r} of study {study.study_id} failed: {' '.join(str(exc).split())}") \
                    from None
            if ok is False:
                used = [a.name for a in attrs if re.search(rf"\b{re.escape(a.name)}\b", c.sql)]
                shown = ", ".join(f"{n} {values[n]}" for n in used if values.get(n) is not None)
                raise UserError(f"{c.message}" + (f" ({shown})" if shown else ""))
    finally:
        con.close()

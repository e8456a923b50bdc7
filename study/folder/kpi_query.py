"""The checks of a study's own SQL in its KPI file beyond one aggregate (docs/kpis.md): a full query over one drive's
samples (``[sql] name = {query = "..."}``) and a condition per sample (``[events] from = ... , to = ...``).

Both are tried on a trial DuckDB connection that holds nothing but an empty ``samples`` table (the columns of
``drive_samples`` and the declared channels) and has file access switched off, so that a query naming another table
fails to bind and one reading a file fails to run; the parse tree (``json_serialize_sql``) is also walked, because
DuckDB's catalog views (``duckdb_tables``, ``information_schema``) exist even on that connection. Every refusal is
one line.
"""
from __future__ import annotations

import json
import re

from study.folder.kpi_fields import SAMPLE_COLUMNS

#: table functions a KPI query may call: they make rows from their arguments and read nothing
TABLE_FUNCTIONS = ("range", "generate_series", "unnest")
#: functions whose value changes from run to run: a KPI must give the same bytes for the same drive
VOLATILE = ("random", "setseed", "uuid", "gen_random_uuid", "uuidv4", "uuidv7", "now", "current_timestamp",
            "get_current_timestamp", "transaction_timestamp", "current_date", "current_time", "today",
            "get_current_time", "current_localtimestamp", "current_localtime", "nextval", "currval")
#: result types of a KPI (one number per drive)
_NUMERIC = re.compile(r"^(TINYINT|SMALLINT|INTEGER|BIGINT|HUGEINT|UTINYINT|USMALLINT|UINTEGER|UBIGINT|UHUGEINT|FLOAT|"
                      r"DOUBLE|DECIMAL\(\d+,\s*\d+\))$")
# a condition is one expression per sample: no sub-query, window, second statement or comment
_NOT_IN_CONDITION = re.compile(r";|--|/\*|\b(select|from|over|window|qualify)\b", re.IGNORECASE)
# reference types of a query tree that read rows (a table, a table function) or only combine them
_REF_TYPES = ("BASE_TABLE", "TABLE_FUNCTION", "SUBQUERY", "JOIN", "EMPTY", "EXPRESSION_LIST", "PIVOT")


def trial_connection(channels: tuple[str, ...] = ()):
    """An in-memory DuckDB connection with file access off and one empty table ``samples``: the columns of
    ``drive_samples`` (:data:`study.folder.kpi_fields.SAMPLE_COLUMNS`, typed) and the ``channels`` (DOUBLE)."""
    import duckdb

    con = duckdb.connect(config={"enable_external_access": False})
    cols = {**SAMPLE_COLUMNS, **{c: "DOUBLE" for c in channels}}
    con.execute("CREATE TABLE samples (" + ", ".join(f'"{c}" {t}' for c, t in cols.items()) + ")")
    return con


def check_query(query: str, channels: tuple[str, ...] = ()) -> str | None:
    """None when ``query`` is one read-only SELECT (or WITH ... SELECT) that reads only ``samples`` (the columns of
    ``drive_samples`` and ``channels``) and returns one numeric column; else a one-line reason."""
    import duckdb

    if not isinstance(query, str) or not query.strip():
        return "needs a query, e.g. \"SELECT stddev_samp(lat_pos) FROM samples\""
    q = query.strip()
    con = trial_connection(channels)
    try:
        try:
            statements = con.extract_statements(q)
        except duckdb.Error as exc:
            return f"is not valid SQL: {_one_line(exc)}"
        if len(statements) != 1:
            return f"must be one statement (a SELECT or WITH query), found {len(statements)}"
        kind = statements[0].type
        if kind != duckdb.StatementType.SELECT:
            word = q.split()[0].upper()   # the statement as written (DuckDB files INSTALL under LOAD)
            return f"must be a read-only SELECT or WITH query, not {word if word.isalpha() else kind.name}"
        tree = json.loads(con.execute("SELECT json_serialize_sql($q)", {"q": q}).fetchall()[0][0])
        if tree.get("error"):
            return f"must be a read-only SELECT or WITH query ({tree.get('error_message', '')})"
        problem = _tree_problem(tree, query=True)
        if problem:
            return problem
        try:
            rel = con.sql(q)        # binds it against `samples` alone and runs it on the empty table
            names, types = rel.columns, [str(t) for t in rel.types]
            rel.fetchall()
        except duckdb.Error as exc:
            return _bind_problem(exc)
    finally:
        con.close()
    if len(names) != 1:
        return f"must return one column (the KPI), found {len(names)}: {', '.join(names)}"
    if not _NUMERIC.match(types[0]):
        return f"must return a number, not {types[0]} (cast it, e.g. ::DOUBLE)"
    return None


def check_condition(expr: str, channels: tuple[str, ...] = ()) -> str | None:
    """None when ``expr`` is a condition per sample: a boolean or numeric expression (non-zero = true) over the
    columns of ``drive_samples`` and ``channels``, no aggregate, window or sub-query; else a one-line reason."""
    import duckdb

    if not isinstance(expr, str) or not expr.strip():
        return "needs a condition, e.g. \"takeover_request\" or \"v < 0.5\""
    if _NOT_IN_CONDITION.search(expr):
        return "must be one condition per sample (no ;, comments, SELECT, FROM or window functions)"
    con = trial_connection(channels)
    try:
        sql = f"SELECT idx, ({expr}) AS x FROM samples"
        try:
            tree = json.loads(con.execute("SELECT json_serialize_sql($q)", {"q": sql}).fetchall()[0][0])
            problem = "must be one condition per sample" if tree.get("error") or len(tree["statements"]) != 1 \
                else _tree_problem(tree, query=False)
            if problem:
                return problem
            rel = con.sql(sql)      # beside a plain column: an aggregate fails to bind here
            kind = str(rel.types[1])
            rel.fetchall()
        except duckdb.Error as exc:
            msg = _one_line(exc)
            if "must appear in the GROUP BY" in msg or "aggregate" in msg.lower():
                return f"{expr!r} is an aggregate; a condition is true or false at each sample (e.g. v < 0.5)"
            return _bind_problem(exc)
    finally:
        con.close()
    if kind != "BOOLEAN" and not _NUMERIC.match(kind):
        return f"{expr!r} is {kind}; a condition is true/false or a number (non-zero = true)"
    return None


def condition_sql(expr: str) -> str:
    """The checked condition as a BOOLEAN that is never NULL: a number is true when non-zero, NULL is false."""
    return f"coalesce(CAST(({expr}) AS BOOLEAN), false)"


def _tree_problem(tree: dict, query: bool) -> str | None:
    """The first thing in a parse tree that reads outside ``samples``, samples rows or varies between runs; None if
    none. ``query``: a whole KPI query, which must read ``samples``."""
    ctes: set[str] = set()
    refs: list[dict] = []
    funcs: list[str] = []
    sampled = False

    def walk(node) -> None:
        nonlocal sampled
        if isinstance(node, dict):
            sampled = sampled or bool(node.get("sample"))   # USING SAMPLE on a query, TABLESAMPLE on a table
            cte_map = node.get("cte_map")
            if isinstance(cte_map, dict):
                ctes.update(e.get("key", "") for e in cte_map.get("map", []))
            if node.get("class") in ("FUNCTION", "WINDOW") and isinstance(node.get("function_name"), str):
                funcs.append(node["function_name"].lower())
            if "class" not in node and "sample" in node and "alias" in node and "type" in node:
                refs.append(node)   # a table reference (every kind serialises type, alias and sample)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(tree)
    if sampled:
        return "must not sample rows (TABLESAMPLE / USING SAMPLE): a KPI is computed from every sample"
    reads_samples = False
    for ref in refs:
        kind = ref["type"]
        if kind == "SHOW_REF":
            return "must compute a value (DESCRIBE, SUMMARIZE and SHOW describe a table)"
        if kind not in _REF_TYPES:
            return f"reads {kind.lower()}: a KPI query reads only samples"
        if kind == "TABLE_FUNCTION":
            name = str((ref.get("function") or {}).get("function_name", "")).lower()
            if name not in TABLE_FUNCTIONS:
                return (f"calls {name}(): a KPI query reads only samples (table functions allowed: "
                        f"{', '.join(TABLE_FUNCTIONS)})")
        if kind == "BASE_TABLE":
            name = ref.get("table_name", "")
            if ref.get("schema_name") or ref.get("catalog_name"):
                qualified = ".".join(p for p in (ref.get("catalog_name"), ref.get("schema_name"), name) if p)
                return f"reads table {qualified}: a KPI query reads only samples (the drive's samples)"
            if name == "samples":
                reads_samples = True
            elif name not in ctes:   # a CTE of another scope fails to bind on the trial connection
                return f"reads table {name}: a KPI query reads only samples (the drive's samples)"
    for name in funcs:
        if name in VOLATILE:
            return f"calls {name}(), which changes from run to run: a KPI gives the same value for the same drive"
    if query and not reads_samples:
        return "does not read samples: a KPI query computes its value from the drive's samples"
    return None


def _bind_problem(exc) -> str:
    """One line for an error of binding or running a KPI's SQL on the trial connection."""
    msg = _one_line(exc)
    low = msg.lower()
    if "table with name" in low and "does not exist" in low:
        name = re.search(r"Table with name (\S+) does not exist", msg)
        return (f"reads table {name.group(1) if name else '?'}: a KPI query reads only samples "
                f"(the drive's samples)")
    if "permission error" in low or "file system operations are disabled" in low:
        return "reads a file: a KPI query reads only samples (the drive's samples)"
    if "not found" in low and "column" in low:
        return f"reads an unknown column ({msg[:160]}); an extra channel must be listed in channels = [...]"
    return msg[:200]


def _one_line(exc) -> str:
    return " ".join(str(exc).split())

"""DuckDB's constraint errors said as the rule of the field they guard.

A write the store refuses (a CHECK, NOT NULL or key constraint of the schema, study/store/migrations/) must reach the
person as the field's rule — "simulator: 1 to 40 characters" — not as DuckDB's text ("Constraint Error: CHECK
constraint failed on table ... with expression CHECK((length(simulator) BETWEEN 1 AND 40))"). The common shapes
of the schema's constraints are translated; any other constraint keeps DuckDB's text on one line.
"""
from __future__ import annotations

import re

_CHECK = re.compile(r'CHECK constraint failed on table "?(?P<table>[^" ]+)"? with expression CHECK\((?P<expr>.*)\)$')
_NOT_NULL = re.compile(r"NOT NULL constraint failed: (?P<table>[^.\s]+)\.(?P<col>\S+)")
_DUPLICATE = re.compile(r'Duplicate key "(?P<col>[^:"]+): (?P<value>.*)" violates (primary key|unique) constraint')

_COL = r"(?P<col>[A-Za-z_][A-Za-z0-9_]*)"
_NUM = r"-?\d+(?:\.\d+)?"
_QUOTED = r"'([^']*)'"
_RULES = [  # (expression of a CHECK, without outer parentheses) -> the rule in words
    (re.compile(rf"length\({_COL}\) BETWEEN (?P<lo>\d+) AND (?P<hi>\d+)"),
     lambda m: f"{m['col']}: {m['lo']} to {m['hi']} characters"),
    (re.compile(rf"{_COL} BETWEEN (?P<lo>{_NUM}) AND (?P<hi>{_NUM})"),
     lambda m: f"{m['col']}: a value from {m['lo']} to {m['hi']}"),
    (re.compile(rf"{_COL} IN \((?P<values>'[^)]*')\)"),
     lambda m: f"{m['col']}: one of {', '.join(re.findall(_QUOTED, m['values']))}"),
    (re.compile(rf"{_COL} IN \((?P<values>{_NUM}(?:, {_NUM})*)\)"),
     lambda m: f"{m['col']}: one of {m['values']}"),
    (re.compile(rf"regexp_full_match\({_COL}, '(?P<pattern>.*)'\)"),
     lambda m: f"{m['col']}: must match {m['pattern']}"),
    (re.compile(rf"{_COL} (?P<op>>=|>|<=|<) (?P<bound>{_NUM})"),
     lambda m: f"{m['col']}: a value {m['op']} {m['bound']}"),
]


def _strip(expr: str) -> str:
    """`expr` without the parentheses DuckDB wraps around a whole expression."""
    expr = expr.strip()
    while expr.startswith("(") and expr.endswith(")") and _balanced(expr[1:-1]):
        expr = expr[1:-1].strip()
    return expr


def _balanced(text: str) -> bool:
    depth = 0
    for ch in text:
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if depth < 0:
            return False
    return depth == 0


def constraint_rule(message: str) -> str | None:
    """The field's rule a DuckDB constraint error `message` stands for (e.g. "simulator: 1 to 40 characters"), or
    None when its shape is not one of the translated ones."""
    text = " ".join(str(message).split())
    m = _NOT_NULL.search(text)
    if m:
        return f"{m['col']}: a value is required"
    m = _DUPLICATE.search(text)
    if m:
        return f"{m['col']} {m['value']} exists already"
    m = _CHECK.search(text)
    if m:
        expr = _strip(m["expr"])
        for pattern, say in _RULES:
            r = pattern.fullmatch(expr)
            if r:
                return say(r)
    return None

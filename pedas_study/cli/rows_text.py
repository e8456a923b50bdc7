"""Rows as text without pandas: what :func:`pedas_study.cli.common.format_frame` prints for the DataFrame of the
same values, character for character, for a listing that should not load pandas (``participant list``).

The values of a cell are None (missing), str, int, float or datetime — what DuckDB returns and what a DataFrame
holds as object, Int64, float64 and datetime64 columns. Each format follows the pandas writer it stands in for:

- table: missing as "-", floats with one decimal, times to the second; a column that is all integers is numeric
  for pandas, so its header gets a leading space; strings show tab, CR and LF escaped, and are never cut;
  cells right-aligned, columns one space apart (``DataFrame.to_string(index=False)``); no rows: "(none)".
- csv: the csv module's minimal quoting, missing as empty, floats as ``repr``, times at the finest precision any
  time of the column needs (date only, seconds, milliseconds or microseconds) (``DataFrame.to_csv``).
- json: records with one space of indent per level and no space after ":" or ",", ASCII with ``\\uXXXX``
  escapes and "/" escaped, floats to 10 decimals as pandas' ujson writes them, times as ISO 8601 to the
  millisecond (``DataFrame.to_json(orient="records", date_format="iso", indent=1)``).
"""
from __future__ import annotations

import csv
import io
import math
from datetime import datetime
from typing import Any, Sequence

from study.common.times import when

#: ujson's double precision in DataFrame.to_json (decimals after the point)
JSON_DECIMALS = 10


def format_rows(columns: Sequence[str], rows: Sequence[Sequence[Any]], fmt: str = "table") -> str:
    """`rows` (tuples in the order of `columns`) as text in `fmt` (table, csv or json), as format_frame prints
    the DataFrame of these values."""
    if fmt == "csv":
        return _csv(columns, rows)
    if fmt == "json":
        return _json(columns, rows)
    if not rows:
        return "(none)"
    return _table(columns, rows)


def _missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


# ---------------------------------------------------------------------------------------------- table
def _shown(v: Any) -> Any:
    """The cell as format_frame prepares it for to_string."""
    if _missing(v):
        return "-"
    if isinstance(v, datetime):
        return when(v, seconds=True)
    if isinstance(v, float):
        return f"{v:.1f}"
    return v


def _escaped(v: Any) -> str:
    return str(v).replace("\t", r"\t").replace("\n", r"\n").replace("\r", r"\r")


def _table_column(name: str, values: list[Any]) -> list[str]:
    """Header and cells of one column, each as wide as the column."""
    shown = [_shown(v) for v in values]
    if all(_is_int(x) for x in shown):   # pandas infers int64: a numeric column
        header, cells = " " + name, [f"{x:d}" for x in shown]
    else:
        header, cells = name, [_escaped(x) for x in shown]
    width = max(len(header), *(len(c) for c in cells))
    return [header.rjust(width)] + [c.rjust(width) for c in cells]


def _table(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    cols = [_table_column(name, [r[j] for r in rows]) for j, name in enumerate(columns)]
    # columns one space apart, each padded on the right to its widest cell (the last one without the space)
    widths = [max(len(c) for c in col) + 1 for col in cols[:-1]] + [max(len(c) for c in cols[-1])]
    return "\n".join("".join(col[i].ljust(w) for col, w in zip(cols, widths)) for i in range(len(rows) + 1))


# ---------------------------------------------------------------------------------------------- csv
def _time_format(values: list[Any]) -> str:
    """The strftime format of a column's times: the finest precision any of them needs."""
    times = [v for v in values if isinstance(v, datetime)]
    if all(t.hour == t.minute == t.second == t.microsecond == 0 for t in times):
        return "%Y-%m-%d"
    if all(t.microsecond == 0 for t in times):
        return "%Y-%m-%d %H:%M:%S"
    if all(t.microsecond % 1000 == 0 for t in times):
        return "ms"
    return "%Y-%m-%d %H:%M:%S.%f"


def _csv_cell(v: Any, time_format: str) -> str:
    if _missing(v):
        return ""
    if isinstance(v, datetime):
        if time_format == "ms":
            return f"{when(v, seconds=True)}.{v.microsecond // 1000:03d}"
        return v.strftime(time_format.replace("%Y", f"{v.year:04d}"))  # C strftime does not pad the year
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _csv(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(columns)
    formats = [_time_format([r[j] for r in rows]) for j in range(len(columns))]
    for r in rows:
        writer.writerow([_csv_cell(v, f) for v, f in zip(r, formats)])
    return out.getvalue().rstrip("\n")


# ---------------------------------------------------------------------------------------------- json
_JSON_ESCAPES = {'"': '\\"', "\\": "\\\\", "/": "\\/", "\b": "\\b", "\f": "\\f", "\n": "\\n", "\r": "\\r",
                 "\t": "\\t"}


def _json_text(s: str) -> str:
    """A JSON string as pandas' ujson writes it: ASCII only, lower-case hex escapes, "/" escaped."""
    out = []
    for ch in s:
        o = ord(ch)
        if ch in _JSON_ESCAPES:
            out.append(_JSON_ESCAPES[ch])
        elif o < 0x20 or 0x80 <= o < 0x10000:
            out.append(f"\\u{o:04x}")
        elif o >= 0x10000:  # a UTF-16 surrogate pair
            o -= 0x10000
            out.append(f"\\u{0xd800 + (o >> 10):04x}\\u{0xdc00 + (o & 0x3ff):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _json_float(value: float) -> str:
    """A finite float as ujson writes it with 10 decimals: fixed point rounded to 10 decimals (a tie rounds up
    when the last kept digit is odd or zero), trailing zeros dropped but one; beyond [1e-15, 1e16) C's %.10g."""
    neg = value < 0
    x = -value if neg else value
    if x > 1e16 - 1 or (x != 0.0 and x < 1e-15):
        return "%.10g" % value
    scale = 10.0 ** JSON_DECIMALS
    whole = int(x)
    tmp = (x - whole) * scale
    frac = int(tmp)
    diff = tmp - frac
    if diff > 0.5 or (diff == 0.5 and (frac == 0 or frac & 1)):
        frac += 1
    if frac >= scale:
        frac, whole = 0, whole + 1
    if frac:
        digits = JSON_DECIMALS
        while frac % 10 == 0:
            digits -= 1
            frac //= 10
        text = f"{whole}.{str(frac).zfill(digits)}"
    else:
        text = f"{whole}.0"
    return "-" + text if neg else text


def _json_value(v: Any) -> str:
    if _missing(v) or (isinstance(v, float) and math.isinf(v)):
        return "null"
    if isinstance(v, str):
        return _json_text(v)
    if isinstance(v, datetime):
        return f'"{v.year:04d}-{v:%m-%dT%H:%M:%S}.{v.microsecond // 1000:03d}"'
    if isinstance(v, float):
        return _json_float(v)
    if _is_int(v):
        return str(v)
    return _json_text(str(v))


def _json(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    keys = [_json_text(c) for c in columns]
    records = [" {\n" + ",\n".join(f"  {k}:{_json_value(v)}" for k, v in zip(keys, r)) + "\n }" for r in rows]
    return "[\n" + ",\n".join(records) + "\n]"

"""Where a key or a table stands in a TOML text (1-based line numbers), so that a problem can name its line; a TOML
text read with its problems as (line, field, message), and the first of them said as the user's one-line error."""
from __future__ import annotations

import re
import tomllib
from typing import Any

from study.common.errors import UserError


def line_of(text: str, key: str, section: str | None = None, nth: int = 0) -> int | None:
    """1-based line of `key = ...` (after the header of `section`, its nth occurrence), else of the header."""
    lines = text.splitlines()
    start = 0
    if section:
        hdr = re.compile(rf"^\s*\[\[?\s*{re.escape(section)}\s*\]\]?\s*(#.*)?$")
        hits = [i for i, ln in enumerate(lines) if hdr.match(ln)]
        if not hits:
            return None
        start = hits[min(nth, len(hits) - 1)]
        if not key:
            return start + 1
    pat = re.compile(rf"^\s*{re.escape(key)}\s*=")
    for i in range(start, len(lines)):
        if i > start and section and re.match(r"^\s*\[", lines[i]):
            break
        if pat.match(lines[i]):
            return i + 1
    return start + 1 if section else None


def read_toml(text: str) -> tuple[dict[str, Any] | None, list[tuple[int | None, str, str]]]:
    """(the tables of `text`, no problems), or (None, [(line or None, "", "not valid TOML: ...")]) when `text` is not
    valid TOML."""
    try:
        return tomllib.loads(text), []
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        return None, [(int(m.group(1)) if m else None, "", f"not valid TOML: {exc}")]


def raise_first_problem(name: str, problems: list[tuple[int | None, str, str]]) -> None:
    """When there are `problems` (line, field, message) of the file `name`: UserError ``name:line: field: message``
    of the first, saying how many more there are."""
    if problems:
        line, fld, msg = problems[0]
        where = f"{name}:{line}" if line else name
        more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
        raise UserError(f"{where}: {fld + ': ' if fld else ''}{msg}{more}")

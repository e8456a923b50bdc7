"""Where a key or a table stands in a TOML text (1-based line numbers), so that a problem can name its line."""
from __future__ import annotations

import re


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

"""The size limit of an input file that a command reads whole (a roster, a survey CSV, an analysis's responses):
checked from the file system before a byte is read, so a huge file is refused at once instead of filling memory."""
from __future__ import annotations

from pathlib import Path

from study.common.errors import UserError

MAX_INPUT_BYTES = 64 * 1024 * 1024  # a survey of 10,000 participants x 100 items with comments is ~10 MB


def check_size(path: str | Path, what: str = "CSV file", limit: int = MAX_INPUT_BYTES) -> None:
    """Refuse (UserError, one line) the file `path` when it is larger than `limit` bytes; nothing when it is not a
    file (the reader says so)."""
    path = Path(path)
    size = path.stat().st_size if path.is_file() else 0
    if size > limit:
        raise UserError(f"{path.name} is {size:,} bytes; a {what} may be at most {limit:,} bytes "
                        f"({limit / 2 ** 20:g} MiB: it is read whole)")

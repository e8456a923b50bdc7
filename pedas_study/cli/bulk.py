"""Bulk files on the command line (`participant import`, `session advance --from`): a refused file is reported as the
usual error line, ``pedas-study: error: FILE: N bad row(s)``, followed by one line per bad row on stderr."""
from __future__ import annotations

import sys


def refused(exc) -> int:
    """Print a :class:`study.common.bulk_rows.BadRows` refusal on stderr; the exit code of bad input (2)."""
    from pedas_study.cli import error_line

    print(error_line(exc), file=sys.stderr)
    for line in exc.lines():
        print(line, file=sys.stderr)
    return 2


def apply_file(args, name: str, apply, report) -> int | None:
    """Read the bulk file ``args.<name>`` (study.common.bulk_rows.read_table: its rows as text, no pandas), hand them to
    ``apply(st, rows, source=)`` inside the store, then print ``report(result)``; a refused file is printed by
    :func:`refused` (its exit code)."""
    from pathlib import Path

    from pedas_study.cli.common import open_store
    from study.common.bulk_rows import BadRows, read_table
    from study.common.errors import shown, split_names

    path = Path(getattr(args, name))
    try:
        rows = read_table(path, split_names(getattr(args, "ignore_columns", None)))
        with open_store(args) as st:
            result = apply(st, rows, source=shown(path))
    except BadRows as exc:
        return refused(exc)
    print(report(result))  # after closing: the store is held only while used
    return None


def add_ignore_option(p) -> None:
    """``--ignore-columns a,b`` of a command that reads a bulk file."""
    p.add_argument("--ignore-columns", dest="ignore_columns", default=None, metavar="A,B",
                   help="columns of the file to leave out (a lab's own bookkeeping), comma-separated")

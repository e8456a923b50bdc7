"""Bulk files on the command line (`participant import`, `session advance --from`): a refused file is reported as the
usual error line, ``pedas-study: error: FILE: N bad row(s)``, followed by one line per bad row on stderr."""
from __future__ import annotations

import sys


def refused(exc) -> int:
    """Print a :class:`study.bulk_rows.BadRows` refusal on stderr; the exit code of bad input (2)."""
    from pedas_study.cli import error_line

    print(error_line(exc), file=sys.stderr)
    for line in exc.lines():
        print(line, file=sys.stderr)
    return 2

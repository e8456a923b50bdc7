"""A time as messages print it: ISO 8601 with the year padded to four digits (C strftime's ``%Y``, which Python's
``f"{t:%Y}"`` uses, prints year 1 as "1")."""
from __future__ import annotations


def when(t, seconds: bool = False) -> str:
    """`t` (a datetime or pandas Timestamp) as ``YYYY-MM-DD HH:MM`` (``:SS`` with `seconds`).

    >>> from datetime import datetime
    >>> when(datetime(1, 1, 1)), when(datetime(2026, 5, 4, 9, 30, 7), seconds=True)
    ('0001-01-01 00:00', '2026-05-04 09:30:07')
    """
    text = f"{t.year:04d}-{t.month:02d}-{t.day:02d} {t.hour:02d}:{t.minute:02d}"
    return f"{text}:{t.second:02d}" if seconds else text

"""The audit trail: who changed which row of research data, when, and from what to what.

Rows are written by :class:`study.store.store.Store` in the same transaction as the change itself, so a change and
its audit record exist together or not at all. Keys and values are JSON text (sorted keys) so that the log is
readable in any SQL client and in exports.
"""
from __future__ import annotations

import getpass
import json
import math
import os
from datetime import date, datetime, time, timedelta, timezone
from decimal import Decimal
from typing import Any

from study.common.errors import UserError
from study.common.times import when

ACTOR_ENV = "PEDAS_STUDY_ACTOR"


def resolve_actor(actor: str | None = None) -> str:
    """The acting person: the explicit value, else $PEDAS_STUDY_ACTOR, else the OS user."""
    if actor:
        return actor
    env = os.environ.get(ACTOR_ENV)
    if env:
        return env
    try:
        return getpass.getuser()
    except Exception:  # no user database entry (some containers)
        return "unknown"


#: how far ahead of this computer's clock a given time may be (clocks of lab machines differ a little)
CLOCK_SKEW = timedelta(minutes=5)


def utcnow() -> datetime:
    """Current UTC time as a naive datetime (the store keeps UTC without zone)."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


def not_in_future(at: datetime) -> datetime:
    """`at` (naive UTC) unless it is later than now + :data:`CLOCK_SKEW` -> UserError."""
    now = utcnow()
    if at > now + CLOCK_SKEW:
        raise UserError(f"time {when(at, seconds=True)} is in the future (now {when(now, seconds=True)} UTC; at most "
                        f"{CLOCK_SKEW.total_seconds() / 60:g} min ahead is accepted as clock difference)")
    return at


def _plain(value: Any) -> Any:
    if value is None:
        return None
    if isinstance(value, (datetime, date, time)):
        return value.isoformat()
    if isinstance(value, Decimal):
        return float(value)
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):  # numpy scalars
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else str(value)
    return value


def to_json(values: dict[str, Any] | None) -> str | None:
    """Canonical JSON of a row fragment (sorted keys, dates ISO 8601, NaN as null)."""
    if values is None:
        return None
    return json.dumps({k: _plain(v) for k, v in values.items()}, sort_keys=True, default=str)


def record(con, actor: str, action: str, table: str, key: dict, old: dict | None, new: dict | None) -> None:
    """Append one audit_log row (the caller owns the transaction)."""
    con.execute('INSERT INTO audit_log ("at", actor, action, table_name, row_key, old, new) VALUES (?, ?, ?, ?, ?, ?, ?)',
                [utcnow(), actor, action, table, to_json(key), to_json(old), to_json(new)])

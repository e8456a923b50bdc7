"""What every request of the survey app shares: the one store connection, its lock, the instrument."""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Iterator

from flask import abort, current_app, render_template

from study import survey as sv


def state() -> dict:
    """The app's survey state: {"store", "lock", "instrument", "password"}."""
    return current_app.extensions["survey"]


def new_state(st, instrument, password: str) -> dict:
    # DuckDB allows one writing process per file and a connection must not be used by two threads at once:
    # the server owns one connection and every request uses it under this (re-entrant) lock
    return {"store": st, "lock": threading.RLock(), "instrument": instrument, "password": password}


@contextmanager
def store(actor: str | None = None) -> Iterator:
    """The store under the app's lock; `actor` (if given) is recorded in the audit log for the writes."""
    s = state()
    with s["lock"]:
        if s.get("closed"):
            abort(503, "The survey server is shutting down.")
        if actor is None:
            yield s["store"]
        else:
            with sv.acting_as(s["store"], actor):
                yield s["store"]


def message(title: str, text: str, status: int):
    """A plain page with one message (errors, refusals)."""
    return render_template("message.html", title=title, text=text), status


def close(app) -> None:
    """Wait until no request uses the store, then refuse every further use (503): after this the caller may
    close the store. A stopped server can still have a request in progress in one of its threads."""
    s = app.extensions.get("survey")
    if s is not None:
        with s["lock"]:
            s["closed"] = True

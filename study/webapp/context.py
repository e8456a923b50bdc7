"""What every request of the survey app shares: the store (opened only while a request uses it), its lock, the
instrument."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from flask import abort, current_app, render_template

from study.store.store import Store, StoreBusy, StoreHolder
from study.survey import answers as sv

BUSY = "The study store is busy (a command is using it). Please try again in a moment."


def state() -> dict:
    """The app's survey state: {"lock" (the :class:`StoreHolder`), "instrument", "study" (the store's study when
    the app was made)}; the researcher password lives (hashed) in the sign-in extension
    (:mod:`study.webapp.signin`)."""
    return current_app.extensions["survey"]


def new_state(st, instrument, study=None) -> dict:
    # the server keeps no connection between requests: each request opens the store under the holder's lock
    return {"lock": StoreHolder(st.path, st.actor), "instrument": instrument, "study": study}


def install(app) -> None:
    """Answer a request that could not get the store in time with 503 and a page saying so."""
    app.register_error_handler(StoreBusy, lambda exc: message("Busy", BUSY, 503))


@contextmanager
def store(actor: str | None = None) -> Iterator[Store]:
    """The store under the app's lock; `actor` (if given) is recorded in the audit log for the writes."""
    with state()["lock"] as h:
        if h.closed:
            abort(503, "The survey server is shutting down.")
        if actor is None:
            yield h.store
        else:
            with sv.acting_as(h.store, actor):
                yield h.store


def message(title: str, text: str, status: int):
    """A plain page with one message (errors, refusals)."""
    return render_template("message.html", title=title, text=text), status


def close(app) -> None:
    """Wait until no request uses the store, then refuse every further use (503). A stopped server can still
    have a request in progress in one of its threads."""
    s = app.extensions.get("survey")
    if s is not None:
        s["lock"].shut()

"""What every request of the survey app shares: the store (opened only while a request uses it), its lock, the
instrument."""
from __future__ import annotations

import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from flask import abort, current_app, render_template

from study import survey as sv
from study.store import Store, StoreBusy, others_waiting

BUSY = "The study store is busy (a command is using it). Please try again in a moment."


class StoreHolder:
    """The app's store, open only while requests use it, so that CLI commands can use the same file between
    requests (DuckDB allows one writing process per file).

    Use it like a re-entrant lock (``with holder:``, ``acquire()``/``release()``): the outermost acquire opens the
    store (waiting, with back-off, for a command that holds it: :meth:`Store.open`), the matching release closes
    it — unless another request is already waiting for the lock and no other process waits for the file: then
    the next request gets the open store (a burst of requests opens the file once). Everything a request does
    under one acquire sees one connection, so a check and the write it guards stay together. One thread at a
    time: a DuckDB connection must not be shared by two threads. After :meth:`shut` acquiring no longer opens
    the store (:attr:`store` is None).
    """

    def __init__(self, path: str | Path, actor: str, lock_timeout: float | None = None) -> None:
        self.path, self.actor, self.lock_timeout = Path(path), actor, lock_timeout
        self.store: Store | None = None
        self.closed = False
        self._lock = threading.RLock()
        self._depth = 0
        self._queued = 0                # threads waiting for the lock
        self._count = threading.Lock()

    def acquire(self) -> bool:
        with self._count:
            self._queued += 1
        self._lock.acquire()
        with self._count:
            self._queued -= 1
        if self._depth == 0 and self.store is None and not self.closed:
            try:
                self.store = Store.open(self.path, actor=self.actor, lock_timeout=self.lock_timeout)
            except BaseException:
                self._lock.release()
                raise
        self._depth += 1
        return True

    def release(self) -> None:
        self._depth -= 1
        try:
            if self._depth == 0 and self.store is not None:
                with self._count:
                    handover = self._queued > 0
                if not handover or others_waiting(self.path):
                    st, self.store = self.store, None
                    st.close()
        finally:
            self._lock.release()

    def __enter__(self) -> "StoreHolder":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def shut(self) -> None:
        """Wait until no request holds the store, close it, and never open it again."""
        with self._lock:
            self.closed = True
            if self.store is not None:
                st, self.store = self.store, None
                st.close()


def state() -> dict:
    """The app's survey state: {"lock" (the :class:`StoreHolder`), "instrument", "password"}."""
    return current_app.extensions["survey"]


def new_state(st, instrument, password: str) -> dict:
    # the server keeps no connection between requests: each request opens the store under the holder's lock
    return {"lock": StoreHolder(st.path, st.actor), "instrument": instrument, "password": password}


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

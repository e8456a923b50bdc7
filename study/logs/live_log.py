"""The drive log of a live session (`pedas-study live serve`), written into the store while the participant drives.

Crash-safe by construction: every :meth:`LiveDriveLog.flush` (the server calls it about once a second) commits the
samples received since the last one in one transaction, together with the drive's row, whose ``meta`` says
``{"live": {"complete": false, ...}}``. A session that is killed keeps every committed sample, marked incomplete
(n_samples, duration and distance as of the last flush; its checksum is a placeholder, the sha256 of the session
id). :meth:`LiveDriveLog.close` (the simulator said bye) replaces the partial drive, in one transaction, with the
complete log stored like an imported one (:func:`study.logs.importing.import_drive_frame`: validation, plausibility,
energy columns, content checksum) and ``meta.live.complete = true``.

What the HUD showed: a row may also carry the seven HUD channels (:data:`pedas.hud_log.HUD_CHANNELS`, the values of
:func:`pedas.hud_log.channel_values` of the frame sent with the advice; all or none). A session whose first flushed
row has them stores them in every flush as the drive's extra channels (registered in ``drive_channels`` like an
import's, :mod:`study.logs.hud_channels`), and the complete log keeps them.
"""
from __future__ import annotations

import hashlib
import json
import threading
import uuid
from contextlib import contextmanager

import numpy as np
import pandas as pd

from study.common.errors import UserError
from study.store.audit_trail import utcnow
from study.store.store import StoreHolder

LIVE_COLUMNS = ("t", "s", "v", "segment", "speed_limit", "a", "grade", "tl_id", "tl_state", "d_tl", "leader_gap",
                "leader_v", "v_advice", "controller", "hud_arrow", "hud_in_band", "warning")


class LiveDriveLog:
    """Log of one live drive of `participant_id` in `condition` (rows with the keys of LIVE_COLUMNS, SI units, t
    from the first sample). Thread-safe: the server appends in its event loop and flushes in a worker thread.

    `st`: an open Store, or a :class:`study.store.store.StoreHolder` — then the store is open only while a flush writes
    (about once a second), so CLI commands can use the same file during a live session."""

    def __init__(self, st, participant_id: str, condition: str, route: str | None, replace: bool = False) -> None:
        from study.people.participants import require
        from study.store.studies import definition

        self._source = st
        with self._store() as st:
            definition(st).check_condition(condition)
            require(st, participant_id)
            have = st.one("SELECT drive_id FROM drives WHERE participant_id = ? AND condition = ?",
                          [participant_id, condition])
        if have is not None and not replace:
            raise UserError(f"{participant_id} already has a {condition} drive; start the session with replace")
        self.participant_id, self.condition, self.route = participant_id, condition, route
        self._replaces = have   # the one drive this log may replace: the one stored when it started (with replace)
        self.session = str(uuid.uuid4())
        self.started_at = utcnow()
        self.drive_id: int | None = None
        self.n = 0                      # samples committed
        self._pending: list[dict] = []
        self._first: dict | None = None
        self._hud: tuple[str, ...] | None = None   # the HUD channels' names once a flush saw them, else ()
        self._last: dict | None = None
        self._lock = threading.Lock()    # the queue (held for microseconds: append runs in the event loop)
        self._write = threading.Lock()   # the store (flush and close, in a worker thread)

    @contextmanager
    def _store(self):
        """The store; opened for the duration of the block when a holder was given."""
        if isinstance(self._source, StoreHolder):
            with self._source as holder:
                yield holder.store
        else:
            yield self._source

    def _meta(self, complete: bool, **extra) -> str:
        return json.dumps({"live": {"complete": complete, "session": self.session, "started_at": str(self.started_at),
                                    **extra}}, sort_keys=True)

    def append(self, row: dict) -> None:
        """Queue one sample (committed at the next flush)."""
        with self._lock:
            self._pending.append(row)

    def flush(self) -> int:
        """Commit the queued samples (one transaction with the drive's row); returns the samples committed so far.
        The drive's row appears once two samples with a positive duration exist (the store's constraints). A flush
        that fails keeps the samples queued for the next one. A drive of the participant and condition stored by
        another writer since this log started is never replaced: UserError, and nothing of this log is stored."""
        with self._write:
            with self._lock:
                rows = list(self._pending)
                if not rows or (self.drive_id is None and (len(rows) < 2 or rows[-1]["t"] <= rows[0]["t"])):
                    return self.n
            first = self._first or rows[0]
            if self._hud is None:   # the session's first flush decides: the rows carry the HUD channels or not
                from study.logs.hud_channels import hud_names

                self._hud = hud_names() if all(k in rows[0] for k in hud_names()) else ()
            frame = pd.DataFrame(rows, columns=list(LIVE_COLUMNS) + list(self._hud))
            last = rows[-1]
            with self._store() as st, st.transaction(), _hud_columns(st, bool(self._hud)):
                if self.drive_id is None:
                    old = st.one("SELECT drive_id FROM drives WHERE participant_id = ? AND condition = ?",
                                 [self.participant_id, self.condition])
                    if old is not None and old != self._replaces:
                        raise UserError(f"{self.participant_id}'s {self.condition} drive {old} was stored by another "
                                        f"writer after live session {self.session} started: this session's samples "
                                        "are not stored over it")
                    if old is not None:   # the drive stored at the start, which replace=True allowed to replace
                        st.con.execute("DELETE FROM drive_samples WHERE drive_id = ?", [old])
                        st.delete("drives", {"drive_id": int(old)})
                    row = st.insert("drives", {
                        "participant_id": self.participant_id, "condition": self.condition, "source": "import",
                        "route": self.route, "checksum": hashlib.sha256(self.session.encode()).hexdigest(),
                        "n_samples": len(rows), "file_name": f"live session {self.session}",
                        "duration_s": last["t"] - first["t"], "distance_m": max(last["s"] - first["s"], 0.0),
                        "meta": self._meta(False)})
                    self.drive_id = int(row["drive_id"])
                else:
                    st.update("drives", {"drive_id": self.drive_id},
                              {"n_samples": self.n + len(rows), "duration_s": last["t"] - first["t"],
                               "distance_m": max(last["s"] - first["s"], 0.0)})
                samples = _typed(frame)
                samples.insert(0, "idx", np.arange(self.n, self.n + len(rows), dtype=np.int32))
                samples.insert(0, "drive_id", np.full(len(rows), self.drive_id, dtype=np.int64))
                st.insert_df("drive_samples", samples)
            with self._lock:
                del self._pending[:len(rows)]
            self.n += len(rows)
            self._first = first
            return self.n

    def close(self):
        """Flush, then store the complete log in place of the partial one; the DriveImport, or None when fewer than
        two samples arrived. A log the import refuses stays stored as logged, its meta naming the reason."""
        from study.logs.importing import import_drive_frame
        from study.logs.stored import drive_samples

        self.flush()
        with self._write:
            if self.drive_id is None:
                return None
            with self._store() as st:
                frame = drive_samples(st, self.participant_id, self.condition,
                                      channels=list(self._hud or ()))[list(LIVE_COLUMNS) + list(self._hud or ())]
                try:
                    return import_drive_frame(st, self.participant_id, self.condition, frame, source="import",
                                              route=self.route, replace=True,
                                              file_name=f"live session {self.session}",
                                              meta=json.loads(self._meta(True, samples=len(frame))))
                except UserError as exc:
                    st.update("drives", {"drive_id": self.drive_id},
                              {"meta": self._meta(True, samples=len(frame), import_error=str(exc))})
                    return None


@contextmanager
def _hud_columns(st, wanted: bool):
    """Within a flush's transaction: the HUD channels registered and their columns in drive_samples (when
    `wanted`); the store's cached column list dropped afterwards (a rolled-back ALTER TABLE leaves it stale)."""
    if not wanted:
        yield
        return
    from study.logs.hud_channels import hud_channel_defs
    from study.logs.importing import _store_channels

    try:
        _store_channels(st, hud_channel_defs())
        yield
    finally:
        st._columns.pop("drive_samples", None)


def _typed(frame: pd.DataFrame) -> pd.DataFrame:
    """The sample columns in the store's types."""
    out = frame.copy()
    for c in ("segment", "tl_id", "tl_state", "controller"):
        out[c] = pd.array(out[c], dtype="string")
    out["hud_arrow"] = pd.array(out["hud_arrow"], dtype="Int8")
    out["hud_in_band"] = pd.array(out["hud_in_band"], dtype="boolean")
    out["warning"] = pd.array(out["warning"], dtype="boolean")
    for c in ("t", "s", "v", "speed_limit", "a", "grade", "d_tl", "leader_gap", "leader_v", "v_advice"):
        out[c] = out[c].astype(float)
    for c in frame.columns[len(LIVE_COLUMNS):]:   # the HUD channels (NaN: not shown)
        out[c] = pd.to_numeric(out[c]).astype(float)
    return out

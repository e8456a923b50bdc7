"""The stored drives: one drive's samples, the extra channels, the list of drives."""
from __future__ import annotations

import pandas as pd

from study.common.errors import UserError
from study.folder.drive_columns import COLUMNS


def drive_samples(st, participant_id: str, condition: str, channels: bool | list[str] = False) -> pd.DataFrame:
    """The samples of one drive in order (columns of the drive-log format, then the extra `channels`: True = all
    registered ones, or a list of names); unknown drive or channel -> UserError."""
    drive_id = st.one("SELECT drive_id FROM drives WHERE participant_id = ? AND coalesce(condition, phase) = ?",
                      [participant_id, condition])
    if drive_id is None:
        raise UserError(f"{participant_id} has no {condition} drive")
    known = list_channels(st)["channel"].tolist()
    if channels is True:
        extra = known
    elif channels:
        extra = list(channels)
        for name in extra:
            if name not in known:
                raise UserError(f"unknown drive channel {name!r} (stored: {', '.join(known) or 'none'})")
    else:
        extra = []
    cols = ", ".join(list(COLUMNS) + [f'"{c}"' for c in extra])
    return st.df(f"SELECT {cols} FROM drive_samples WHERE drive_id = ? ORDER BY idx", [drive_id])


def list_channels(st) -> pd.DataFrame:
    """The extra channels stored with drive samples: channel, unit, description, added_at."""
    return st.df("SELECT channel, unit, description, added_at FROM drive_channels ORDER BY channel")


def list_drives(st) -> pd.DataFrame:
    """Every stored drive; a ``phase`` column after ``condition`` only when a drive outside the conditions is
    stored (a familiarisation drive: condition empty, its phase named)."""
    phase = ", phase" if st.one("SELECT count(*) FROM drives WHERE phase IS NOT NULL") else ""
    return st.df(f"SELECT drive_id, participant_id, condition{phase}, source, route, n_samples, duration_s, "
                 f"distance_m, file_name, checksum, created_at FROM drives ORDER BY participant_id, condition, "
                 f"drive_id")

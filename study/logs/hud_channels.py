"""The HUD channels of a drive in the store: what the head-up display showed at each sample (docs/hud.md).

A canonical drive log (a simulated pEDAS drive, a live session's log, a DataFrame given to
:func:`study.logs.importing.import_drive_frame`) may carry the columns of :data:`pedas.hud_log.HUD_CHANNELS`. The import
keeps them as extra channels: DOUBLE columns of ``drive_samples`` registered in ``drive_channels`` with the
documented unit and description (:func:`hud_channel_defs`), NaN/NULL where the HUD showed nothing. Any other column
outside the drive-log format stays ignored, as before.

:func:`hud_extras` checks them (numbers; the codes and ranges of their documentation; the first problem is one line
naming column and 1-based row), :func:`with_channels` adds their values to a frame's content checksum: a log with
them is other content than the same log without them, while a log without them keeps its checksum.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pandas as pd

from study.common.errors import UserError
from study.common.numbers import column_floats

#: allowed values of the coded channels (NaN = not shown is allowed everywhere)
_CODES = {"hud_light": (1.0, 2.0, 3.0), "hud_icon": (0.0, 1.0, 2.0, 3.0, 4.0), "hud_tone": (0.0, 1.0),
          "hud_arrow_shown": (-2.0, -1.0, 0.0, 1.0)}
#: channels a log may leave out even when it has the others (added later: logs written before keep importing)
_OPTIONAL = ("hud_arrow_shown",)
#: closed ranges of the others: the digits in km/h (up to the drive log's 70 m/s bound), the arrow as a fraction,
#: the countdown in whole s
_RANGES = {"hud_speed": (0.0, 252.0), "hud_limit": (0.0, 252.0), "hud_arrow_len": (0.0, 1.0),
           "hud_countdown": (0.0, 9.0)}


def hud_channel_defs() -> tuple:
    """The HUD channels as :class:`study.folder.logmap.Channel` (name, unit, description of
    :data:`pedas.hud_log.HUD_CHANNELS`), in that order."""
    from pedas.hud_log import HUD_CHANNELS
    from study.folder.logmap import Channel

    return tuple(Channel(name, name, unit, description=desc) for name, unit, desc in HUD_CHANNELS)


def hud_names() -> tuple[str, ...]:
    """The HUD channels' names, in the order of :data:`pedas.hud_log.HUD_CHANNELS`."""
    return tuple(ch.name for ch in hud_channel_defs())


def _values(s: pd.Series, name: str) -> np.ndarray:
    """A column as float64 (NaN = empty); a non-number -> UserError naming column and row."""
    if pd.api.types.is_bool_dtype(s):
        raise UserError(f"column {name} must be numeric (dtype {s.dtype})")
    return column_floats(s, lambda i: f"column {name} row {i + 1}")


def hud_extras(df: pd.DataFrame) -> tuple[pd.DataFrame | None, tuple]:
    """(the HUD channels `df` carries as a float64 frame row for row with it, their Channels) — (None, ()) when it
    carries none. A log carrying some but not all of them (the optional ones aside), a value that is not a number, infinite, outside its
    channel's codes or range, or a countdown that is not whole -> UserError (one line, column and 1-based row)."""
    every = hud_channel_defs()
    have = [ch for ch in every if ch.name in df.columns]
    if not have:
        return None, ()
    missing = [ch.name for ch in every if ch.name not in df.columns and ch.name not in _OPTIONAL]
    if missing:
        required = [ch.name for ch in every if ch.name not in _OPTIONAL]
        raise UserError(f"the log has HUD channels but not {', '.join(missing)}: a log keeps all of "
                        f"{', '.join(required)} or none")
    defs = tuple(have)
    out = {}
    for ch in defs:
        x = _values(df[ch.name].reset_index(drop=True), ch.name)
        if ch.name in _CODES:
            bad = ~np.isnan(x) & ~np.isin(x, _CODES[ch.name])
            allowed = "|".join(f"{c:g}" for c in _CODES[ch.name])
            why = f"not one of {allowed}"
        else:
            lo, hi = _RANGES[ch.name]
            bad = np.isinf(x) | (~np.isnan(x) & ((x < lo) | (x > hi)))
            why = f"outside {lo:g}..{hi:g} {ch.unit}"
            if ch.name == "hud_countdown":
                bad |= ~np.isnan(x) & ~np.isinf(x) & (x != np.floor(x))
                why += " or not whole"
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise UserError(f"column {ch.name} row {i + 1}: {x[i]:g} is {why} ({ch.description})")
        out[ch.name] = x
    return pd.DataFrame(out), defs


def with_channels(checksum: str, extras: pd.DataFrame | None, channels: tuple) -> str:
    """A frame's content checksum (sha256 hex) with the values of its extra channels: `checksum` unchanged without
    channels, else sha256 of it followed by each channel's name and float64 little-endian bytes (NaN as stored)."""
    if not channels:
        return checksum
    h = hashlib.sha256(f"frame\x1d{checksum}".encode())
    for ch in channels:
        h.update(f"\x1e{ch.name}\x1d".encode())
        h.update(np.ascontiguousarray(extras[ch.name].to_numpy(dtype="<f8")).tobytes())
    return h.hexdigest()

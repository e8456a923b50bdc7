"""The live advice protocol (docs/hud.md): JSON messages between a driving simulator and `pedas-study live serve`.

One JSON object per WebSocket text message or UDP datagram. The simulator sends

* ``{"type": "hello", "participant": "P007", "condition": "pedas"}`` once (both optional: without a participant
  nothing is logged); the server answers ``{"type": "ready", "route": ..., "length_m": ..., "logging": bool,
  "pair": code}``, over UDP also ``"secret": 32 hex digits``, which every later datagram of the session carries;
* ``{"type": "state", "seq": 17, "t": 412.2, "s": 1830.4, "v": 12.9, "leader": {"gap": 35.0, "v": 11.2},
  "spat": {"id": "tl3", "state": "red", "remaining": 4.2}}`` at 5-50 Hz: t in s on the clock of the route's signal
  programs, s in m along the route, v in m/s, leader null or gap (m, bumper to bumper) and speed (m/s), spat
  optional (the next light's state as the simulator shows it); the server answers
  ``{"type": "advice", "seq": 17, "advice": {...}, "hud": {...}, "spat_ok": true|null}``: the controller's
  :class:`pedas.controller.Advisory` without its plan, and the :class:`pedas.hud_frame.HudFrame`;
* ``{"type": "bye"}`` at the end; the server answers ``{"type": "done", "samples": n, "drive_id": id|null}``.

A bad message gets ``{"type": "error", "seq": ..., "error": "one line"}`` and changes nothing: one that is not JSON,
larger than :data:`pedas.live_limits.MAX_MESSAGE_BYTES` or nested deeper than :data:`~pedas.live_limits.MAX_DEPTH`,
and a state outside the physical ranges of :mod:`pedas.live_limits` (speed, position on the route, time order).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

from pedas.live_limits import MAX_DEPTH, MAX_MESSAGE_BYTES, S_MARGIN, T_MAX, V_MAX
from pedas.route import STATES

ADVICE_FIELDS = ("v_advice", "controller", "mode", "ft", "fb", "hud_arrow", "arrow_len", "hud_in_band", "warning",
                 "tl_countdown", "icon", "solve_status", "fallback", "speed_limit")


class ProtocolError(ValueError):
    """A message that does not follow the protocol; its text is the one-line error sent back."""


@dataclass(frozen=True)
class State:
    """A parsed state message (units as in the module docstring)."""

    seq: int | None
    t: float
    s: float
    v: float
    leader: tuple[float, float] | None
    spat: tuple[str, str, float | None] | None   # (light id, state, remaining s or None)


def _number(msg: dict, key: str, lo: float = -math.inf, hi: float = math.inf, unit: str = "") -> float:
    """msg[key] as a float in [lo, hi]; ProtocolError with the bounds (and unit) otherwise."""
    x = msg.get(key)
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or not lo <= x <= hi:
        bound = ("" if lo == -math.inf else f" >= {lo:g}") + ("" if hi == math.inf else
                                                                (" and" if lo > -math.inf else "") + f" <= {hi:g}")
        raise ProtocolError(f"'{key}' must be a finite number{bound}{' ' + unit if unit and bound else ''}, "
                            f"got {x!r}")
    return float(x)


def _too_deep(text: str) -> bool:
    """Whether objects/arrays nest deeper than MAX_DEPTH outside strings (a linear scan, stopped at the first
    excess, so the JSON parser never recurses on a hostile message)."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:   # the usual message: no scan needed
        return False
    depth, in_str, esc = 0, False, False
    for ch in text:
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return True
        elif ch in "]}":
            depth -= 1
    return False


def decode(text: str | bytes) -> dict:
    """The message object of one text message / datagram; ProtocolError when it is larger than MAX_MESSAGE_BYTES,
    nested deeper than MAX_DEPTH, not JSON, or not an object with a known type."""
    size = len(text) if isinstance(text, (bytes, bytearray)) else len(text.encode())
    if size > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {size} bytes: at most {MAX_MESSAGE_BYTES} bytes")
    try:
        if isinstance(text, (bytes, bytearray)):
            text = bytes(text).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"not JSON: {exc}") from None
    if _too_deep(text):
        raise ProtocolError(f"JSON nested deeper than {MAX_DEPTH} levels")
    try:
        msg = json.loads(text)
    except ValueError as exc:
        raise ProtocolError(f"not JSON: {exc}") from None
    if not isinstance(msg, dict) or msg.get("type") not in ("hello", "state", "bye"):
        raise ProtocolError("expected a JSON object with type hello|state|bye")
    return msg


def parse_state(msg: dict, route_length: float | None = None) -> State:
    """The :class:`State` of a state message; ProtocolError names the first bad field. Speeds lie in [0, V_MAX]
    m/s, t in [-T_MAX, T_MAX] s and s in [0, route_length + S_MARGIN] m (s >= 0 only without a route length); the
    time order is the
    session's to check (:class:`pedas.live.LiveSession`)."""
    seq = msg.get("seq")
    if seq is not None and (isinstance(seq, bool) or not isinstance(seq, int)):
        raise ProtocolError(f"'seq' must be an integer, got {seq!r}")
    s_max = math.inf if route_length is None else float(route_length) + S_MARGIN
    t = _number(msg, "t", -T_MAX, T_MAX, "s")
    s, v = _number(msg, "s", 0.0, s_max, "m"), _number(msg, "v", 0.0, V_MAX, "m/s")
    lead = msg.get("leader")
    leader = None
    if lead is not None:
        if not isinstance(lead, dict):
            raise ProtocolError("'leader' must be null or {\"gap\": m, \"v\": m/s}")
        leader = (_number(lead, "gap", 0.0, unit="m"), _number(lead, "v", 0.0, V_MAX, "m/s"))
    sp = msg.get("spat")
    spat = None
    if sp is not None:
        if not isinstance(sp, dict) or not isinstance(sp.get("id"), str) or sp.get("state") not in STATES:
            raise ProtocolError(f"'spat' must be {{\"id\": str, \"state\": {'|'.join(STATES)}, \"remaining\": s}}")
        spat = (sp["id"], sp["state"], _number(sp, "remaining", 0.0) if sp.get("remaining") is not None else None)
    return State(seq, t, s, v, leader, spat)


def advice_message(seq, advisory, frame, spat_ok: bool | None) -> str:
    """The reply to a state message (JSON text; floats written exactly, so a client decodes the same numbers)."""
    adv = {k: getattr(advisory, k) for k in ADVICE_FIELDS}
    return json.dumps({"type": "advice", "seq": seq, "advice": adv, "hud": frame.as_dict(), "spat_ok": spat_ok},
                      separators=(",", ":"))


def error_message(seq, error: str) -> str:
    return json.dumps({"type": "error", "seq": seq, "error": " ".join(str(error).split())})

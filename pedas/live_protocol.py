"""The live advice protocol (docs/hud.md): JSON messages between a driving simulator and `pedas-study live serve`.

One JSON object per WebSocket text message or UDP datagram. The simulator sends

* ``{"type": "hello", "participant": "P007", "condition": "pedas"}`` once (both optional: without a participant
  nothing is logged); the server answers ``{"type": "ready", "route": ..., "length_m": ..., "logging": bool}``;
* ``{"type": "state", "seq": 17, "t": 412.2, "s": 1830.4, "v": 12.9, "leader": {"gap": 35.0, "v": 11.2},
  "spat": {"id": "tl3", "state": "red", "remaining": 4.2}}`` at 5-50 Hz: t in s on the clock of the route's signal
  programs, s in m along the route, v in m/s, leader null or gap (m, bumper to bumper) and speed (m/s), spat
  optional (the next light's state as the simulator shows it); the server answers
  ``{"type": "advice", "seq": 17, "advice": {...}, "hud": {...}, "spat_ok": true|null}``: the controller's
  :class:`pedas.controller.Advisory` without its plan, and the :class:`pedas.hud_frame.HudFrame`;
* ``{"type": "bye"}`` at the end; the server answers ``{"type": "done", "samples": n, "drive_id": id|null}``.

A bad message gets ``{"type": "error", "seq": ..., "error": "one line"}`` and changes nothing.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

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


def _number(msg: dict, key: str, lo: float = -math.inf) -> float:
    x = msg.get(key)
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x < lo:
        bound = "" if lo == -math.inf else f" >= {lo:g}"
        raise ProtocolError(f"'{key}' must be a finite number{bound}, got {x!r}")
    return float(x)


def decode(text: str | bytes) -> dict:
    """The message object of one text message / datagram; ProtocolError when it is not a JSON object with a
    known type."""
    try:
        msg = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"not JSON: {exc}") from None
    if not isinstance(msg, dict) or msg.get("type") not in ("hello", "state", "bye"):
        raise ProtocolError("expected a JSON object with type hello|state|bye")
    return msg


def parse_state(msg: dict) -> State:
    """The :class:`State` of a state message; ProtocolError names the first bad field."""
    seq = msg.get("seq")
    if seq is not None and (isinstance(seq, bool) or not isinstance(seq, int)):
        raise ProtocolError(f"'seq' must be an integer, got {seq!r}")
    t, s, v = _number(msg, "t"), _number(msg, "s"), _number(msg, "v", 0.0)
    lead = msg.get("leader")
    leader = None
    if lead is not None:
        if not isinstance(lead, dict):
            raise ProtocolError("'leader' must be null or {\"gap\": m, \"v\": m/s}")
        leader = (_number(lead, "gap", 0.0), _number(lead, "v", 0.0))
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

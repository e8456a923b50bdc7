"""The limits of the live server (`pedas-study live serve`), in one place: the physical ranges a state must lie in,
the size and nesting a message may have, and the per-client rate, idle time and session count the server grants;
with :class:`Throttle`, the token bucket that enforces the rate.

Each limit answers a failure seen on the server (docs/hud.md, "Limits"): a speed of 1e6 m/s was advised on and
shown as 3,600,000 km/h, 50,000-deep JSON closed the socket with a traceback, 5,000 messages in 1 s from one client
stalled another client's advice for 1.9 s, 500 UDP source ports kept a controller each for ever, 300 WebSocket
sessions held 443 MB.
"""
from __future__ import annotations

import time

# ---- physical ranges of a state message: outside them a value is a simulator bug or a forged message, and the
# controller would plan with it and the HUD show it
V_MAX = 100.0     # m/s (360 km/h), for the ego and the leader: above any car's top speed in a driving study, and the
                  # largest speed the HUD's three digits can show
S_MARGIN = 100.0  # m: s lies in [0, route length + S_MARGIN]; a simulator's car may run on a little past the route's
                  # end before it is removed (2 s at 50 m/s), never before its start
T_MAX = 1e7       # s (116 days): |t| on the clock of the route's signal programs; a lab's drive starts near 0 (or
                  # at a program's offset) and lasts an hour, and the controller's scans over phase starts must stay
                  # short: t = 1e18 once stalled every session for 9 s and grew the server by 3 GB
# time: a session's t never decreases (t >= the previous state's t; equal is allowed, a simulator may resend a
# frame): the controller plans the green wave on the route's signal clock, which only moves on; hello restarts it

# ---- size and nesting of one message: a state is about 250 bytes and 2 levels deep (the state, its leader/spat)
MAX_MESSAGE_BYTES = 16_384   # larger: an error answer; WebSocket frames above WS_MAX_FRAME close the connection
WS_MAX_FRAME = 65_536        # (close code 1009, the WebSocket library's answer) before the frame is even buffered
MAX_DEPTH = 8                # nested objects/arrays; deeper: an error answer before the JSON parser recurses

# ---- what one client gets
RATE = 200.0       # messages/s sustained per client: 4x the protocol's fastest simulator (50 Hz), so the reference
                   # client driving faster than real time is slowed, not refused, and a flooding client costs the
                   # server at most RATE controller steps a second
BURST = 100        # messages a client may send at once above RATE: half a second of RATE (a simulator catching up
                   # after a pause); `live serve --max-rate` keeps this ratio
UDP_IDLE = 30.0    # s without a datagram after which a UDP session ends (UDP has no close; a WebSocket session
                   # ends with its connection)
MAX_SESSIONS = 32  # simulator sessions at once, per transport: WebSocket connections, UDP peers (a lab runs one or
                   # a few simulators); each holds a controller (about 1.5 MB: 300 WebSocket sessions grew the server
                   # by 443 MB). Beyond it: a WebSocket connection gets an error line and is closed (1013), a UDP
                   # peer's hello an error line. `live serve --max-sessions`
MAX_PAGES = 8      # HUD pages (/display) at once per session: a projector, a monitor, the experimenter's screen


class Throttle:
    """A token bucket: `rate` messages/s on average, up to `burst` at once. :meth:`delay` (WebSocket: the sender
    waits, so TCP back-pressure slows it) and :meth:`take` (UDP: a message over the limit is dropped) spend one token
    per message."""

    def __init__(self, rate: float = RATE, burst: int = BURST, clock=time.monotonic) -> None:
        self.rate, self.burst, self.clock = float(rate), float(burst), clock
        self.tokens, self.last = float(burst), clock()

    def _refill(self) -> None:
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now

    def delay(self) -> float:
        """Spend a token, borrowing when none is left; the seconds (>= 0) to wait before handling the message, so
        that the messages handled never exceed rate * time + burst."""
        self._refill()
        self.tokens -= 1.0
        return 0.0 if self.tokens >= 0 else -self.tokens / self.rate

    def take(self) -> bool:
        """Spend a token if there is one (True), else spend nothing (False: drop the message)."""
        self._refill()
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True

"""Live advice for a lab's own simulator: :class:`PedasController` behind the protocol of :mod:`pedas.live_protocol`,
over WebSocket and UDP, with a full-screen HUD page for a second monitor or a head-up projector.

:class:`LiveSession` is the protocol without sockets (one per WebSocket connection or UDP peer): it answers each
message with exactly the in-process controller's advice for the same inputs, and hands a log row per state to an
optional drive log (:class:`study.logs.live_log.LiveDriveLog`, any object with append/flush/close). :class:`LiveServer` runs
the sockets: WebSocket and HTTP on ``port`` (``/?pair=CODE`` is the HUD page of one session, ``/display?pair=CODE``
its feed of HUD frames, any other path the simulator's channel) and UDP on the same port number; drive logs are
flushed about once a second in a worker thread so that the store never delays an answer. Each client is throttled
to :data:`pedas.live_limits.RATE` messages/s, sessions are capped at :data:`~pedas.live_limits.MAX_SESSIONS` per
transport and UDP sessions end after :data:`~pedas.live_limits.UDP_IDLE` s without a datagram (docs/hud.md,
"Limits"). A participant's drive has one writer: a second session's hello for it is refused. A UDP session is its
source address plus the secret its ready carried; a datagram without the secret is dropped.
"""
from __future__ import annotations

import asyncio
import gc
import hmac
import json
import math
import secrets
import time
from bisect import bisect_left
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pedas.hud_frame import hud_frame
from pedas.hud_log import channel_values
from pedas.live_display import hud_page, new_pair_code, pair_of
from pedas.live_limits import BURST, MAX_PAGES, MAX_SESSIONS, RATE, UDP_IDLE, WS_MAX_FRAME, Throttle
from pedas.live_protocol import ProtocolError, advice_message, decode, error_message, parse_state

FLUSH_EVERY = 1.0  # s of wall time between drive-log commits


@dataclass(frozen=True)
class LiveRoute:
    """What a session needs of a route: the route, its DP reference speeds and its name."""

    name: str
    route: object
    v_dp: np.ndarray

    @classmethod
    def load(cls, name: str = "study") -> "LiveRoute":
        """'study' (the study network, built once) or 'synthetic-mixed' (pedas.route.Route.synthetic_mixed)."""
        from pedas.dp import dp_reference

        if name == "study":
            from pedas.drive import study_route_and_reference

            return cls(name, *study_route_and_reference())
        if name == "synthetic-mixed":
            from pedas.route import Route

            route = Route.synthetic_mixed()
            return cls(name, route, dp_reference(route))
        raise ValueError(f"unknown route {name!r} (expected study|synthetic-mixed)")


LoggerFactory = Callable[[str, str], object]   # (participant, condition) -> drive log


class LiveSession:
    """One simulator's session: hello -> state* -> bye; :meth:`handle` maps each message text to its reply text.
    ``pair`` is the session's pairing code (its HUD page's key), fixed for the session's life and sent in ready."""

    tone_rule = "unfollowed"   # when its HUD sounds (pedas.hud_frame.TONE_RULES)

    def __init__(self, live: LiveRoute, logger_factory: LoggerFactory | None = None, settings=None,
                 writers: dict | None = None, peer: str = "") -> None:
        from pedas.params import CONTROLLER

        self.live, self.settings = live, settings or CONTROLLER
        self.logger_factory = logger_factory
        self.log = None
        # (participant, condition) -> the session logging that drive, shared by a server's sessions: one writer per
        # drive; `peer` names this session in another's refusal
        self.writers = {} if writers is None else writers
        self.peer = peer
        self.drive: tuple[str, str] | None = None   # (participant, condition) of the drive logged, since (UTC)
        self.since = ""
        self.samples = 0
        self.pair = new_pair_code()
        self._lights = tuple(live.route.lights)
        self._light_s = [tl.s for tl in self._lights]
        self.ctrl = None   # made by hello or the first state: a session that sends nothing valid costs no controller
        self._t0 = None
        self._prev = None
        self.throttle: Throttle | None = None   # the server's: this client's rate limit
        self.last_seen = 0.0                    # the server's: time.monotonic() of the client's last message
        self.flush_error: str | None = None     # the server's: why the last flush of the drive log failed
        self.secret: str | None = None          # the server's, UDP: what every datagram after the first hello carries
        self.forged = 0                         # the server's, UDP: datagrams from its address without the secret

    def _reset(self) -> None:
        from pedas.controller import PedasController

        self.ctrl = PedasController(self.live.route, v_dp=self.live.v_dp, settings=self.settings)
        self._t0 = None
        self._prev = None   # (t, v) of the last state: the logged acceleration, and the time order of states

    def handle(self, text: str | bytes | dict) -> str:
        """The reply to one message (text, or the object :func:`decode` made of it)."""
        seq = None
        try:
            msg = text if isinstance(text, dict) else decode(text)
            seq = msg.get("seq")
            kind = msg["type"]
            if kind == "state":
                return self._state(msg)
            if kind == "hello":
                return self._hello(msg)
            return self._bye()
        except ValueError as exc:   # a ProtocolError, or a refused log (unknown participant, drive exists, ...)
            return error_message(seq, str(exc))

    def _hello(self, msg: dict) -> str:
        participant, condition = msg.get("participant"), msg.get("condition", "pedas")
        if self.log is not None:
            raise ProtocolError("a session is running: send bye first")
        if participant is not None:
            if self.logger_factory is None:
                raise ProtocolError("this server logs no drives (start it with a store: --db)")
            drive = (str(participant), str(condition))
            other = self.writers.get(drive)
            if other is not None and other is not self:
                raise ProtocolError(f"{drive[0]}'s {drive[1]} drive is being logged by another session ({other.peer}, "
                                    f"since {other.since} UTC): one simulator per drive; that session must say bye "
                                    "or disconnect first")
            self.log = self.logger_factory(*drive)
            self.writers[drive], self.drive, self.since = self, drive, time.strftime("%H:%M:%S", time.gmtime())
        self._reset()
        self.samples = 0
        return json.dumps({"type": "ready", "route": self.live.name, "length_m": float(self.live.route.length),
                           "logging": self.log is not None, "pair": self.pair,
                           **({"secret": self.secret} if self.secret else {})})

    def _state(self, msg: dict) -> str:
        st = parse_state(msg, float(self.live.route.length))
        if self._prev is not None and st.t < self._prev[0]:
            raise ProtocolError(f"'t' went backwards: {st.t!r} s after {self._prev[0]!r} s (a session's time never "
                                "decreases; hello starts a new one)")
        if self.ctrl is None:
            self._reset()
        adv = self.ctrl.step(st.t, st.s, st.v, st.leader)
        frame = hud_frame(st.v, adv, st.leader, self.tone_rule)
        tl = self._next_light(st.s)
        spat_ok = None
        if st.spat is not None:
            spat_ok = tl is not None and st.spat[0] == tl.tl_id and st.spat[1] == tl.state_at(st.t)
        if self.log is not None:
            # what the driver was shown, per sample (pedas.hud_log): the replay shows exactly this
            self.log.append({**self._row(st, adv, tl), **channel_values(frame)})
        self._prev = (st.t, st.v)
        self.samples += 1
        return advice_message(st.seq, adv, frame, spat_ok)

    def _bye(self) -> str:
        drive_id = None
        if self.log is not None:
            result = self.log.close()
            drive_id = getattr(result, "drive_id", None) or getattr(self.log, "drive_id", None)
            self.release()
        return json.dumps({"type": "done", "samples": self.samples, "drive_id": drive_id})

    def release(self) -> None:
        """Forget the drive log (after bye, or when the session ends): its drive is free for another session."""
        if self.writers.get(self.drive) is self:
            del self.writers[self.drive]
        self.log = self.drive = None

    def _next_light(self, s: float):
        j = bisect_left(self._light_s, s)
        return self._lights[j] if j < len(self._lights) else None

    def _row(self, st, adv, tl) -> dict:
        """The drive-log row of a state (study.logs.live_log.LIVE_COLUMNS)."""
        r = self.live.route
        if self._t0 is None:
            self._t0 = st.t
        i = int(np.clip(np.searchsorted(r.s, st.s, side="right") - 1, 0, r.s.size - 1))
        a = 0.0 if self._prev is None or st.t <= self._prev[0] else (st.v - self._prev[1]) / (st.t - self._prev[0])
        state = (st.spat[1] if st.spat is not None else tl.state_at(st.t)) if tl is not None else None
        lead = st.leader
        return {"t": round(st.t - self._t0, 6), "s": st.s, "v": st.v, "segment": str(r.segment[i]),
                "speed_limit": float(r.speed_limit[i]), "a": a, "grade": float(r.grade[i]),
                "tl_id": tl.tl_id if tl is not None else None, "tl_state": state,
                "d_tl": tl.s - st.s if tl is not None else math.nan,
                "leader_gap": lead[0] if lead else math.nan, "leader_v": lead[1] if lead else math.nan,
                "v_advice": adv.v_advice, "controller": adv.controller, "hud_arrow": adv.hud_arrow,
                "hud_in_band": adv.hud_in_band, "warning": adv.warning}


# ---------------------------------------------------------------------------------------------- the server
Announce = Callable[[str], None]   # one console line: a session's pairing code and HUD page, a session's end


def _has_secret(msg, secret: str) -> bool:
    """Whether a decoded datagram carries the session's secret (compared in constant time)."""
    given = msg.get("secret") if isinstance(msg, dict) else None
    return isinstance(given, str) and hmac.compare_digest(given.encode(), secret.encode())


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _decode_error(text: str | bytes) -> str:
    """The error answer to a message that does not decode."""
    try:
        decode(text)
    except ProtocolError as exc:
        return error_message(None, str(exc))
    raise AssertionError("the message decodes")


class _Udp(asyncio.DatagramProtocol):
    def __init__(self, server: "LiveServer") -> None:
        self.server = server
        self.transport = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        server, key = self.server, ("udp",) + tuple(addr)
        session = server.sessions.get(key)
        msg, store = server.triage(data)
        if session is not None:
            # a source address is easily forged: only a datagram with the session's secret is the simulator's;
            # others are dropped unanswered (an answer would go to the forged address) and counted
            if not _has_secret(msg, session.secret):
                server.forged(session)
                return
            if not session.throttle.take():
                return   # over the client's rate: dropped unanswered (UDP has no back-pressure)
        else:
            # only a hello makes a session (its ready carries the secret); anything else, and a hello beyond the
            # session cap, is answered (within a server-wide budget) and forgotten, so stray datagrams from many
            # ports hold no memory
            if not isinstance(msg, dict) or msg["type"] != "hello" or server.count("udp") >= server.max_sessions:
                if server.strays.take():
                    why = (_decode_error(msg) if not isinstance(msg, dict) else
                           error_message(msg.get("seq"), "a UDP session starts with hello: its ready carries the "
                                                         "secret that every later datagram must carry")
                           if msg["type"] != "hello" else
                           error_message(msg.get("seq"), f"too many UDP sessions ({server.max_sessions} at "
                                                         f"once): try again after {server.udp_idle:g} s"))
                    self.transport.sendto(why.encode(), addr)
                return
            session = server.session_for(key)
            session.secret = secrets.token_hex(16)
        session.last_seen = time.monotonic()
        if store:
            asyncio.ensure_future(self._reply_later(session, msg, addr, key))
            return
        self._send(session, session.handle(msg), addr, key, msg)

    async def _reply_later(self, session: LiveSession, msg: dict, addr, key) -> None:
        self._send(session, await self.server.handle_in_store_thread(session, msg), addr, key, msg)

    def _send(self, session: LiveSession, reply: str, addr, key, msg) -> None:
        self.transport.sendto(reply.encode(), addr)
        self.server.answered(session, key, msg, reply)


class LiveServer:
    """The sockets around :class:`LiveSession`s; run with :meth:`run` (blocks) or ``asyncio.run(server.start())``.

    ``rate``/``burst``: each client's throttle (messages/s, messages at once); ``udp_idle``: s without a datagram
    after which a UDP session ends; ``max_sessions``: simulator sessions at once, per transport (WebSocket
    connections, UDP peers); ``announce``: called with a console
    line when a session says hello (its pairing code and HUD page) and when a session ends."""

    hud_theme = "light"        # the HUD page's theme (pedas.hud_theme), set by `live serve --theme`
    tone_rule = "unfollowed"   # when the HUD sounds (pedas.hud_frame.TONE_RULES), set by `live serve --tone`
    visual_warning = True      # the HUD page's warning triangle and blinking border, `live serve --visual-warning`

    def __init__(self, live: LiveRoute, host: str = "127.0.0.1", port: int = 8765,
                 logger_factory: LoggerFactory | None = None, on_ready: Callable[[int], None] | None = None,
                 announce: Announce | None = None, rate: float = RATE, burst: int = BURST,
                 udp_idle: float = UDP_IDLE, max_sessions: int = MAX_SESSIONS) -> None:
        self.live, self.host, self.port = live, host, port
        self.logger_factory = logger_factory
        self.on_ready = on_ready
        self.announce = announce or (lambda line: None)
        self.rate, self.burst, self.udp_idle, self.max_sessions = rate, burst, udp_idle, max_sessions
        self.sessions: dict[tuple, LiveSession] = {}
        self.writers: dict[tuple[str, str], LiveSession] = {}   # (participant, condition) -> the session logging it
        self.paired: dict[str, LiveSession] = {}    # pairing code -> its session
        self.displays: dict[str, set] = {}          # pairing code -> the HUD pages showing that session
        self.full = False                           # the WebSocket session cap was met (and said) since one ended
        self.strays = Throttle(rate, burst)         # answers to UDP datagrams that get no session, all peers together
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="drive-log")   # the store's one writer
        self.bound_port = port

    def triage(self, text: str | bytes) -> tuple[dict | str | bytes, bool]:
        """(the message decoded once, or the text itself when it does not decode: the session answers with the
        error; whether it touches the store: a hello or bye while drives are logged opens or completes a drive
        log)."""
        try:
            msg = decode(text)
        except ProtocolError:
            return text, False
        return msg, self.logger_factory is not None and msg["type"] in ("hello", "bye")

    async def in_store_thread(self, fn, *args):
        """Run fn in the one thread that uses the store (DuckDB's connection is not shared between threads)."""
        return await asyncio.get_running_loop().run_in_executor(self.pool, fn, *args)

    async def handle_in_store_thread(self, session: LiveSession, msg: dict) -> str:
        """The session's answer to a hello or bye that opens or completes a drive log; a failure the session does
        not answer itself (a store that cannot be opened) is one error line to the client and to the console."""
        try:
            return await self.in_store_thread(session.handle, msg)
        except Exception as exc:   # the server goes on: the client may say bye again
            why = _one_line(exc)
            self.announce(f"session {session.peer}: {msg['type']} failed: {why}")
            return error_message(msg.get("seq"), f"{msg['type']} failed: {why}")

    async def flush(self, session: LiveSession, then: str = "its samples stay queued for the next flush") -> None:
        """Commit a session's drive log in the store's thread. A failure is one console line (again only when its
        cause changes), never the end of the flushing: `then` says what becomes of the samples."""
        log = session.log
        if log is None:
            return
        try:
            await self.in_store_thread(log.flush)
            session.flush_error = None
        except Exception as exc:
            why = _one_line(exc)
            if why != session.flush_error:
                session.flush_error = why
                self.announce(f"session {session.peer} ({', '.join(session.drive or ())}): drive log not written: "
                              f"{why}; {then}")

    def session_for(self, key: tuple) -> LiveSession:
        if key not in self.sessions:
            session = LiveSession(self.live, self.logger_factory, writers=self.writers,
                                  peer=f"{key[0]} {key[1]}:{key[2]}")
            session.tone_rule = self.tone_rule
            session.throttle, session.last_seen = Throttle(self.rate, self.burst), time.monotonic()
            self.sessions[key] = session
            self.paired[session.pair] = session
        return self.sessions[key]

    def forged(self, session: LiveSession) -> None:
        """Count a datagram from a UDP session's address without its secret; the first is a console line."""
        session.forged += 1
        if session.forged == 1:
            self.announce(f"session {session.peer}: a datagram without the session's secret dropped (forged, or a "
                          "simulator that does not send the secret of its ready); further ones are counted")

    def count(self, transport: str) -> int:
        """Sessions of a transport ("ws" or "udp") at this moment."""
        return sum(1 for key in self.sessions if key[0] == transport)

    def answered(self, session: LiveSession, key: tuple, msg, reply: str) -> None:
        """After each answer: an advice goes to the session's HUD pages; a hello is announced (accepted: its pairing
        code; refused, with a participant: why)."""
        if reply.startswith('{"type":"advice"'):
            pages = self.displays.get(session.pair)
            if pages:
                from websockets.asyncio.server import broadcast

                broadcast(pages, reply)
        elif isinstance(msg, dict) and msg["type"] == "hello":
            who = ", ".join(str(msg[k]) for k in ("participant", "condition") if msg.get(k) is not None)
            if reply.startswith('{"type": "ready"'):
                self.announce(f"session {session.peer}{f' ({who})' if who else ''}: pairing code {session.pair}, "
                              f"HUD page http://{self.host}:{self.bound_port}/?pair={session.pair}")
            elif who:   # a refused hello of a participant: the researcher sees why no drive is logged
                self.announce(f"session {session.peer} ({who}): hello refused: {json.loads(reply)['error']}")

    async def end_session(self, key: tuple, why: str) -> None:
        """Forget a session: its log flushed (a drive without bye stays incomplete), its HUD pages closed."""
        session = self.sessions.pop(key, None)
        if session is None:
            return
        self.full = False
        self.paired.pop(session.pair, None)
        await self.flush(session, then="the samples since the last flush are lost")
        session.release()
        for page in list(self.displays.pop(session.pair, ())):   # not awaited: a slow page delays nothing
            asyncio.ensure_future(page.close(1000, "session ended"))
        if key[0] == "udp":
            forged = f" ({session.forged} datagrams without its secret dropped)" if session.forged else ""
            self.announce(f"session {session.peer} ended: {why}{forged}")

    def _http(self, connection, request):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = request.path.split("?")[0]
        if path in ("/", "/hud") and "upgrade" not in request.headers.get("Connection", "").lower():
            body = hud_page(theme=self.hud_theme, visual_warning=self.visual_warning).encode()
            return Response(200, "OK", Headers([("Content-Type", "text/html; charset=utf-8"),
                                                ("Content-Length", str(len(body))),
                                                ("Cache-Control", "no-store")]), body)
        return None

    async def _display(self, connection) -> None:
        """A HUD page: bound to the session of its pairing code, or told the code is unknown and closed."""
        from websockets.exceptions import ConnectionClosed

        code = pair_of(connection.request.path)
        if code not in self.paired:
            await self._refuse(connection, f"unknown pairing code {code!r}: open the HUD page address the console "
                                           "printed for the session (/?pair=CODE)", 1008, "unknown pairing code")
            return
        if len(self.displays.get(code, ())) >= MAX_PAGES:
            await self._refuse(connection, f"too many HUD pages for session {code} ({MAX_PAGES} at once)", 1008,
                               "too many pages")
            return
        self.displays.setdefault(code, set()).add(connection)
        throttle = Throttle(self.rate, self.burst)
        try:
            async for _ in connection:   # a page sends nothing today; whatever it sends is read, throttled, dropped
                if delay := throttle.delay():
                    await asyncio.sleep(delay)
        except ConnectionClosed:   # a page that went away abruptly: nothing to answer
            pass
        finally:
            pages = self.displays.get(code)
            if pages is not None:
                pages.discard(connection)
                if not pages:
                    self.displays.pop(code, None)

    async def _refuse(self, connection, why: str, code: int, reason: str) -> None:
        """One error line, then the connection closed with `code` and `reason`."""
        from websockets.exceptions import ConnectionClosed

        try:
            await connection.send(error_message(None, why))
            await connection.close(code, reason)
        except ConnectionClosed:   # it went away first
            pass

    async def _ws(self, connection) -> None:
        from websockets.exceptions import ConnectionClosed

        if connection.request.path.split("?")[0] == "/display":
            await self._display(connection)
            return
        if self.count("ws") >= self.max_sessions:
            if not self.full:   # said once until a session ends: a burst of connections is not a burst of lines
                self.full = True
                self.announce(f"{self.max_sessions} WebSocket sessions at once: new connections are refused")
            await self._refuse(connection, f"too many WebSocket sessions ({self.max_sessions} at once): try again "
                                           "when one has ended", 1013, "too many sessions")
            return
        key = ("ws",) + tuple(connection.remote_address[:2]) + (id(connection),)
        session = self.session_for(key)
        try:
            async for text in connection:
                if delay := session.throttle.delay():   # over the rate: wait, and TCP back-pressure slows the sender
                    await asyncio.sleep(delay)
                msg, store = self.triage(text)
                reply = await self.handle_in_store_thread(session, msg) if store else session.handle(msg)
                await connection.send(reply)
                self.answered(session, key, msg, reply)
                await asyncio.sleep(0)   # let the other clients' messages in between: one busy client cannot hog
        except ConnectionClosed:   # a client that went away abruptly (or sent a frame above WS_MAX_FRAME: 1009)
            pass
        finally:   # a simulator that went away without bye: keep what it sent, the drive stays incomplete
            await self.end_session(key, "disconnected")

    async def _housekeeper(self) -> None:
        """Flush the drive logs about every FLUSH_EVERY s; end UDP sessions idle for udp_idle s. Runs for the
        server's life: a failure is a console line, and the next round comes as usual."""
        tick = min(FLUSH_EVERY, self.udp_idle / 4)
        last_flush = time.monotonic()
        while True:
            await asyncio.sleep(tick)
            try:
                now = time.monotonic()
                idle = [k for k, s in self.sessions.items() if k[0] == "udp" and now - s.last_seen > self.udp_idle]
                for key in idle:
                    await self.end_session(key, f"{self.udp_idle:g} s without a datagram")
                if idle:
                    gc.collect()   # a controller holds reference cycles: give its memory back now, not later
                if now - last_flush >= FLUSH_EVERY:
                    last_flush = now
                    for session in list(self.sessions.values()):
                        await self.flush(session)
            except Exception as exc:
                self.announce(f"housekeeping failed: {_one_line(exc)}; it goes on")

    async def start(self) -> None:
        """Serve until cancelled."""
        from websockets.asyncio.server import serve

        loop = asyncio.get_running_loop()
        async with serve(self._ws, self.host, self.port, process_request=self._http, max_queue=64,
                         max_size=WS_MAX_FRAME) as ws:
            port = self.bound_port = ws.sockets[0].getsockname()[1]
            transport, _ = await loop.create_datagram_endpoint(lambda: _Udp(self), local_addr=(self.host, port))
            housekeeper = asyncio.create_task(self._housekeeper())
            if self.on_ready:
                self.on_ready(port)
            try:
                await asyncio.Future()
            finally:
                housekeeper.cancel()
                transport.close()

    def run(self) -> None:
        """Serve until Ctrl-C / SIGTERM."""
        try:
            asyncio.run(self.start())
        except KeyboardInterrupt:
            pass
        finally:
            self.pool.shutdown(wait=True)

"""Live advice for a lab's own simulator: :class:`PedasController` behind the protocol of :mod:`pedas.live_protocol`,
over WebSocket and UDP, with a full-screen HUD page for a second monitor or a head-up projector.

:class:`LiveSession` is the protocol without sockets (one per WebSocket connection or UDP peer): it answers each
message with exactly the in-process controller's advice for the same inputs, and hands a log row per state to an
optional drive log (:class:`study.logs.live_log.LiveDriveLog`, any object with append/flush/close). :class:`LiveServer` runs
the sockets: WebSocket and HTTP on ``port`` (``/?pair=CODE`` is the HUD page of one session, ``/display?pair=CODE``
its feed of HUD frames, any other path the simulator's channel) and UDP on the same port number; drive logs are
flushed about once a second in a worker thread so that the store never delays an answer. Each client is throttled
to :data:`pedas.live_limits.RATE` messages/s and UDP sessions end after :data:`~pedas.live_limits.UDP_IDLE` s
without a datagram (docs/hud.md, "Limits").
"""
from __future__ import annotations

import asyncio
import gc
import json
import math
import time
from bisect import bisect_left
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pedas.hud_frame import hud_frame
from pedas.hud_log import channel_values
from pedas.live_display import hud_page, new_pair_code, pair_of
from pedas.live_limits import BURST, MAX_UDP_SESSIONS, RATE, UDP_IDLE, WS_MAX_FRAME, Throttle
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

    def __init__(self, live: LiveRoute, logger_factory: LoggerFactory | None = None, settings=None) -> None:
        from pedas.params import CONTROLLER

        self.live, self.settings = live, settings or CONTROLLER
        self.logger_factory = logger_factory
        self.log = None
        self.samples = 0
        self.pair = new_pair_code()
        self._lights = tuple(live.route.lights)
        self._light_s = [tl.s for tl in self._lights]
        self.ctrl = None   # made by hello or the first state: a session that sends nothing valid costs no controller
        self._t0 = None
        self._prev = None
        self.throttle: Throttle | None = None   # the server's: this client's rate limit
        self.last_seen = 0.0                    # the server's: time.monotonic() of the client's last message

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
            self.log = self.logger_factory(str(participant), str(condition))
        self._reset()
        self.samples = 0
        return json.dumps({"type": "ready", "route": self.live.name, "length_m": float(self.live.route.length),
                           "logging": self.log is not None, "pair": self.pair})

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
            self.log = None
        return json.dumps({"type": "done", "samples": self.samples, "drive_id": drive_id})

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
        if session is not None and not session.throttle.take():
            return   # over the client's rate: dropped unanswered (UDP has no back-pressure; an answer would double it)
        msg, store = server.triage(data)
        if session is None:
            # no session for a message that does not decode, nor beyond the session cap: answered (within a
            # server-wide budget) and forgotten, so stray datagrams from many ports hold no memory
            if not isinstance(msg, dict) or server.udp_count() >= server.max_udp_sessions:
                if server.strays.take():
                    why = (_decode_error(msg) if not isinstance(msg, dict) else
                           error_message(msg.get("seq"), f"too many UDP sessions ({server.max_udp_sessions} at "
                                                         f"once): try again after {server.udp_idle:g} s"))
                    self.transport.sendto(why.encode(), addr)
                return
            session = server.session_for(key)
        session.last_seen = time.monotonic()
        if store:
            asyncio.ensure_future(self._reply_later(session, msg, addr, key))
            return
        self._send(session, session.handle(msg), addr, key, msg)

    async def _reply_later(self, session: LiveSession, msg: dict, addr, key) -> None:
        self._send(session, await self.server.in_store_thread(session.handle, msg), addr, key, msg)

    def _send(self, session: LiveSession, reply: str, addr, key, msg) -> None:
        self.transport.sendto(reply.encode(), addr)
        self.server.answered(session, key, msg, reply)


class LiveServer:
    """The sockets around :class:`LiveSession`s; run with :meth:`run` (blocks) or ``asyncio.run(server.start())``.

    ``rate``/``burst``: each client's throttle (messages/s, messages at once); ``udp_idle``: s without a datagram
    after which a UDP session ends; ``max_udp_sessions``: UDP sessions at once; ``announce``: called with a console
    line when a session says hello (its pairing code and HUD page) and when a session ends."""

    hud_theme = "light"        # the HUD page's theme (pedas.hud_theme), set by `live serve --theme`
    tone_rule = "unfollowed"   # when the HUD sounds (pedas.hud_frame.TONE_RULES), set by `live serve --tone`
    visual_warning = True      # the HUD page's warning triangle and blinking border, `live serve --visual-warning`

    def __init__(self, live: LiveRoute, host: str = "127.0.0.1", port: int = 8765,
                 logger_factory: LoggerFactory | None = None, on_ready: Callable[[int], None] | None = None,
                 announce: Announce | None = None, rate: float = RATE, burst: int = BURST,
                 udp_idle: float = UDP_IDLE, max_udp_sessions: int = MAX_UDP_SESSIONS) -> None:
        self.live, self.host, self.port = live, host, port
        self.logger_factory = logger_factory
        self.on_ready = on_ready
        self.announce = announce or (lambda line: None)
        self.rate, self.burst, self.udp_idle, self.max_udp_sessions = rate, burst, udp_idle, max_udp_sessions
        self.sessions: dict[tuple, LiveSession] = {}
        self.paired: dict[str, LiveSession] = {}    # pairing code -> its session
        self.displays: dict[str, set] = {}          # pairing code -> the HUD pages showing that session
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

    def session_for(self, key: tuple) -> LiveSession:
        if key not in self.sessions:
            session = LiveSession(self.live, self.logger_factory)
            session.tone_rule = self.tone_rule
            session.throttle, session.last_seen = Throttle(self.rate, self.burst), time.monotonic()
            self.sessions[key] = session
            self.paired[session.pair] = session
        return self.sessions[key]

    def udp_count(self) -> int:
        return sum(1 for key in self.sessions if key[0] == "udp")

    def answered(self, session: LiveSession, key: tuple, msg, reply: str) -> None:
        """After each answer: an advice goes to the session's HUD pages; a hello that was accepted is announced."""
        if reply.startswith('{"type":"advice"'):
            pages = self.displays.get(session.pair)
            if pages:
                from websockets.asyncio.server import broadcast

                broadcast(pages, reply)
        elif reply.startswith('{"type": "ready"') and isinstance(msg, dict):
            who = ", ".join(str(msg[k]) for k in ("participant", "condition") if msg.get(k) is not None)
            self.announce(f"session {key[0]} {':'.join(map(str, key[1:3]))}{f' ({who})' if who else ''}: pairing "
                          f"code {session.pair}, HUD page http://{self.host}:{self.bound_port}/?pair={session.pair}")

    async def end_session(self, key: tuple, why: str) -> None:
        """Forget a session: its log flushed (a drive without bye stays incomplete), its HUD pages closed."""
        session = self.sessions.pop(key, None)
        if session is None:
            return
        self.paired.pop(session.pair, None)
        if session.log is not None:
            await self.in_store_thread(session.log.flush)
        for page in list(self.displays.pop(session.pair, ())):   # not awaited: a slow page delays nothing
            asyncio.ensure_future(page.close(1000, "session ended"))
        if key[0] == "udp":
            self.announce(f"session udp {':'.join(map(str, key[1:3]))} ended: {why}")

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
            await connection.send(error_message(None, f"unknown pairing code {code!r}: open the HUD page address "
                                                      "the console printed for the session (/?pair=CODE)"))
            await connection.close(1008, "unknown pairing code")
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

    async def _ws(self, connection) -> None:
        from websockets.exceptions import ConnectionClosed

        if connection.request.path.split("?")[0] == "/display":
            await self._display(connection)
            return
        key = ("ws",) + tuple(connection.remote_address[:2]) + (id(connection),)
        session = self.session_for(key)
        try:
            async for text in connection:
                if delay := session.throttle.delay():   # over the rate: wait, and TCP back-pressure slows the sender
                    await asyncio.sleep(delay)
                msg, store = self.triage(text)
                reply = await self.in_store_thread(session.handle, msg) if store else session.handle(msg)
                await connection.send(reply)
                self.answered(session, key, msg, reply)
                await asyncio.sleep(0)   # let the other clients' messages in between: one busy client cannot hog
        except ConnectionClosed:   # a client that went away abruptly (or sent a frame above WS_MAX_FRAME: 1009)
            pass
        finally:   # a simulator that went away without bye: keep what it sent, the drive stays incomplete
            await self.end_session(key, "disconnected")

    async def _housekeeper(self) -> None:
        """Flush the drive logs about every FLUSH_EVERY s; end UDP sessions idle for udp_idle s."""
        tick = min(FLUSH_EVERY, self.udp_idle / 4)
        last_flush = time.monotonic()
        while True:
            await asyncio.sleep(tick)
            now = time.monotonic()
            idle = [k for k, s in self.sessions.items() if k[0] == "udp" and now - s.last_seen > self.udp_idle]
            for key in idle:
                await self.end_session(key, f"{self.udp_idle:g} s without a datagram")
            if idle:
                gc.collect()   # a controller holds reference cycles: give its memory back now, not some time later
            if now - last_flush >= FLUSH_EVERY:
                last_flush = now
                for session in list(self.sessions.values()):
                    if session.log is not None:
                        await self.in_store_thread(session.log.flush)

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

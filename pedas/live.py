"""Live advice for a lab's own simulator: :class:`PedasController` behind the protocol of :mod:`pedas.live_protocol`,
over WebSocket and UDP, with a full-screen HUD page for a second monitor or a head-up projector.

:class:`LiveSession` is the protocol without sockets (one per WebSocket connection or UDP peer): it answers each
message with exactly the in-process controller's advice for the same inputs, and hands a log row per state to an
optional drive log (:class:`study.live_log.LiveDriveLog`, any object with append/flush/close). :class:`LiveServer` runs
the sockets: WebSocket and HTTP on ``port`` (``/`` is the HUD page, ``/display`` its feed of HUD frames, any other
path the simulator's channel) and UDP on the same port number; drive logs are flushed about once a second in a
worker thread so that the store never delays an answer.
"""
from __future__ import annotations

import asyncio
import json
import math
from bisect import bisect_left
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pedas.hud_frame import hud_frame
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
    """One simulator's session: hello -> state* -> bye; :meth:`handle` maps each message text to its reply text."""

    def __init__(self, live: LiveRoute, logger_factory: LoggerFactory | None = None, settings=None) -> None:
        from pedas.params import CONTROLLER

        self.live, self.settings = live, settings or CONTROLLER
        self.logger_factory = logger_factory
        self.log = None
        self.samples = 0
        self._lights = tuple(live.route.lights)
        self._light_s = [tl.s for tl in self._lights]
        self._reset()

    def _reset(self) -> None:
        from pedas.controller import PedasController

        self.ctrl = PedasController(self.live.route, v_dp=self.live.v_dp, settings=self.settings)
        self._t0 = None
        self._prev = None   # (t, v) of the last state, for the logged acceleration

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
                           "logging": self.log is not None})

    def _state(self, msg: dict) -> str:
        st = parse_state(msg)
        adv = self.ctrl.step(st.t, st.s, st.v, st.leader)
        frame = hud_frame(st.v, adv)
        tl = self._next_light(st.s)
        spat_ok = None
        if st.spat is not None:
            spat_ok = tl is not None and st.spat[0] == tl.tl_id and st.spat[1] == tl.state_at(st.t)
        if self.log is not None:
            self.log.append(self._row(st, adv, tl))
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
        """The drive-log row of a state (study.live_log.LIVE_COLUMNS)."""
        r = self.live.route
        if self._t0 is None:
            self._t0 = st.t
        i = int(np.clip(np.searchsorted(r.s, st.s, side="right") - 1, 0, r.s.size - 1))
        a = 0.0 if self._prev is None or st.t <= self._prev[0] else (st.v - self._prev[1]) / (st.t - self._prev[0])
        self._prev = (st.t, st.v)
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
def hud_page(feed_path: str = "/display") -> str:
    """The full-screen HUD page: ``<pedas-hud sound>`` fed by the server's frames (a click enables the tone)."""
    from pedas.hud_png import hud_script

    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8"><title>pEDAS HUD</title>
<style>html,body{{margin:0;height:100%;background:#000}}pedas-hud{{width:100vw;max-height:100vh;margin:auto}}
#state{{position:fixed;bottom:4px;left:6px;color:#888;font:12px sans-serif}}</style>
<script>{hud_script()}</script></head><body><pedas-hud id="hud" sound></pedas-hud><div id="state">connecting</div>
<script>
const hud = document.getElementById("hud"), state = document.getElementById("state");
document.body.addEventListener("click", () => document.documentElement.requestFullscreen?.());
function connect() {{
  const ws = new WebSocket(`ws://${{location.host}}{feed_path}`);
  ws.onopen = () => {{ state.textContent = "live"; }};
  ws.onmessage = e => {{ const m = JSON.parse(e.data); hud.frame = m.hud; hud.dataset.seq = String(m.seq); }};
  ws.onclose = () => {{ state.textContent = "reconnecting"; setTimeout(connect, 1000); }};
}}
connect();
</script></body></html>"""


class _Udp(asyncio.DatagramProtocol):
    def __init__(self, server: "LiveServer") -> None:
        self.server = server
        self.transport = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        session = self.server.session_for(("udp",) + tuple(addr))
        msg, store = self.server.triage(data)
        if store:
            asyncio.ensure_future(self._reply_later(session, msg, addr))
            return
        self._send(session.handle(msg), addr)

    async def _reply_later(self, session: LiveSession, msg: dict, addr) -> None:
        self._send(await self.server.in_store_thread(session.handle, msg), addr)

    def _send(self, reply: str, addr) -> None:
        self.transport.sendto(reply.encode(), addr)
        self.server.broadcast(reply)


class LiveServer:
    """The sockets around :class:`LiveSession`s; run with :meth:`run` (blocks) or ``asyncio.run(server.start())``."""

    def __init__(self, live: LiveRoute, host: str = "127.0.0.1", port: int = 8765,
                 logger_factory: LoggerFactory | None = None, on_ready: Callable[[int], None] | None = None) -> None:
        self.live, self.host, self.port = live, host, port
        self.logger_factory = logger_factory
        self.on_ready = on_ready
        self.sessions: dict[tuple, LiveSession] = {}
        self.displays: set = set()
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="drive-log")   # the store's one writer

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
            self.sessions[key] = LiveSession(self.live, self.logger_factory)
        return self.sessions[key]

    def broadcast(self, reply: str) -> None:
        """Send an advice's HUD frame to every display page."""
        if not self.displays or not reply.startswith('{"type":"advice"'):
            return
        from websockets.asyncio.server import broadcast

        broadcast(self.displays, reply)

    def _http(self, connection, request):
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        if request.path in ("/", "/hud") and "upgrade" not in request.headers.get("Connection", "").lower():
            body = hud_page().encode()
            return Response(200, "OK", Headers([("Content-Type", "text/html; charset=utf-8"),
                                                ("Content-Length", str(len(body)))]), body)
        return None

    async def _ws(self, connection) -> None:
        if connection.request.path == "/display":
            self.displays.add(connection)
            try:
                await connection.wait_closed()
            finally:
                self.displays.discard(connection)
            return
        key = ("ws", id(connection))
        session = self.session_for(key)
        try:
            async for text in connection:
                msg, store = self.triage(text)
                reply = await self.in_store_thread(session.handle, msg) if store else session.handle(msg)
                await connection.send(reply)
                self.broadcast(reply)
        finally:   # a simulator that went away without bye: keep what it sent, the drive stays incomplete
            self.sessions.pop(key, None)
            if session.log is not None:
                await self.in_store_thread(session.log.flush)

    async def _flusher(self) -> None:
        while True:
            await asyncio.sleep(FLUSH_EVERY)
            for session in list(self.sessions.values()):
                if session.log is not None:
                    await self.in_store_thread(session.log.flush)

    async def start(self) -> None:
        """Serve until cancelled."""
        from websockets.asyncio.server import serve

        loop = asyncio.get_running_loop()
        async with serve(self._ws, self.host, self.port, process_request=self._http, max_queue=64) as ws:
            port = ws.sockets[0].getsockname()[1]
            transport, _ = await loop.create_datagram_endpoint(lambda: _Udp(self), local_addr=(self.host, port))
            flusher = asyncio.create_task(self._flusher())
            if self.on_ready:
                self.on_ready(port)
            try:
                await asyncio.Future()
            finally:
                flusher.cancel()
                transport.close()

    def run(self) -> None:
        """Serve until Ctrl-C / SIGTERM."""
        try:
            asyncio.run(self.start())
        except KeyboardInterrupt:
            pass
        finally:
            self.pool.shutdown(wait=True)

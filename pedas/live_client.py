"""The reference client of the live protocol: :class:`RemoteController` has the interface of
:class:`pedas.controller.PedasController` (``step(t, s, v, leader) -> Advisory``) but asks a running
`pedas-study live serve` over WebSocket, so :func:`pedas.drive.drive` drives a virtual participant in SUMO through
the socket and the protocol is exercised end to end."""
from __future__ import annotations

import json
import time

from pedas.controller import Advisory
from pedas.live_protocol import ADVICE_FIELDS


class LiveError(RuntimeError):
    """The server answered with an error message."""


class RemoteController:
    """A WebSocket client of the live server. hello on open (with participant/condition: the server logs the
    drive), one state per :meth:`step`, bye on :meth:`close`. ``latencies`` holds the round trip of every step (s,
    perf_counter)."""

    def __init__(self, url: str, participant: str | None = None, condition: str = "pedas",
                 timeout: float = 30.0) -> None:
        from websockets.sync.client import connect

        self.ws = connect(url, open_timeout=timeout, max_size=2**20)
        self.timeout = timeout
        self.stats: dict = {"steps": 0, "remote": url}
        self.latencies: list[float] = []
        hello = {"type": "hello", "condition": condition}
        if participant is not None:
            hello["participant"] = participant
        self.ready = self._ask(hello, "ready")
        self.done: dict | None = None

    def _ask(self, msg: dict, expect: str) -> dict:
        self.ws.send(json.dumps(msg))
        reply = json.loads(self.ws.recv(timeout=self.timeout))
        if reply.get("type") == "error":
            raise LiveError(reply["error"])
        if reply.get("type") != expect:
            raise LiveError(f"expected a {expect} message, got {reply.get('type')!r}")
        return reply

    def step(self, t: float, s: float, v: float, leader: tuple[float, float] | None = None) -> Advisory:
        seq = self.stats["steps"]
        msg = {"type": "state", "seq": seq, "t": t, "s": s, "v": v,
               "leader": None if leader is None else {"gap": leader[0], "v": leader[1]}}
        t0 = time.perf_counter()
        reply = self._ask(msg, "advice")
        self.latencies.append(time.perf_counter() - t0)
        if reply["seq"] != seq:
            raise LiveError(f"advice for message {reply['seq']} received for {seq}")
        self.stats["steps"] += 1
        adv = reply["advice"]
        return Advisory(**{k: adv[k] for k in ADVICE_FIELDS}, plan_v=())

    def close(self) -> dict:
        """Say bye; the server's done message (samples, drive_id)."""
        if self.done is None:
            self.done = self._ask({"type": "bye"}, "done")
            self.ws.close()
        return self.done

    def __enter__(self) -> "RemoteController":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.close()
        else:
            self.ws.close()

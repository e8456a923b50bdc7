"""The live server's limits (pedas.live_limits, pedas.live_display): a HUD page shows only the session it is paired
with, idle UDP sessions end, a flooding client is throttled while a good client gets every advice, a state outside
the physical ranges or a message too large or too deep is answered with a one-line error and the server goes on.
A real server (pedas.live.LiveServer) runs in a thread of the test with small limits; clients talk to it over
WebSocket and UDP on localhost."""
from __future__ import annotations

import asyncio
import json
import re
import socket
import threading
import time
from contextlib import ExitStack, contextmanager

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from pedas.live import LiveRoute, LiveServer, LiveSession
from pedas.live_display import PAIR_ALPHABET, pair_of
from pedas.live_limits import MAX_DEPTH, MAX_MESSAGE_BYTES, MAX_PAGES, S_MARGIN, T_MAX, V_MAX, WS_MAX_FRAME, Throttle
from pedas.live_protocol import ProtocolError, decode, parse_state


@pytest.fixture(scope="module")
def live():
    return LiveRoute.load("synthetic-mixed")   # 13,200 m, no traffic lights


@pytest.fixture(scope="module")
def study():
    return LiveRoute.load("study")   # the study network's route, with its signal programs


@contextmanager
def running(live, **limits):
    """A LiveServer on a free port in a thread of its own; (server, port, announced console lines)."""
    lines, box, ready = [], {}, threading.Event()
    server = LiveServer(live, port=0, on_ready=lambda port: (box.update(port=port), ready.set()),
                        announce=lines.append, **limits)

    def serve() -> None:
        loop = asyncio.new_event_loop()
        box["loop"], box["task"] = loop, loop.create_task(server.start())
        try:
            loop.run_until_complete(box["task"])
        except asyncio.CancelledError:
            pass
        finally:
            loop.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(60), "server did not start"
    try:
        yield server, box["port"], lines
    finally:
        box["loop"].call_soon_threadsafe(box["task"].cancel)
        thread.join(timeout=30)
        server.pool.shutdown(wait=True)


def state(k: int, v: float = 10.0, **kw) -> str:
    return json.dumps({"type": "state", "seq": k, "t": 0.2 * k, "s": 5.0 + 2.0 * k, "v": v, **kw})



def ask(ws, text: str) -> dict:
    ws.send(text)
    return json.loads(ws.recv(timeout=30))


# ---------------------------------------------------------------------------------------------- the arithmetic
def test_throttle_by_hand():
    """rate 10/s, burst 3, a hand-set clock: three at once, then one per 0.1 s; delay() borrows and says how long."""
    now = [0.0]
    th = Throttle(10.0, 3, clock=lambda: now[0])
    assert [th.take() for _ in range(4)] == [True, True, True, False]
    now[0] = 0.05
    assert th.take() is False            # half a token
    now[0] = 0.1
    assert th.take() is True and th.take() is False
    th = Throttle(10.0, 3, clock=lambda: now[0])
    assert [th.delay() for _ in range(3)] == [0.0, 0.0, 0.0]
    assert th.delay() == pytest.approx(0.1) and th.delay() == pytest.approx(0.2)   # the 4th, 5th message wait
    now[0] += 0.2                        # the debt paid: the next waits one period again
    assert th.delay() == pytest.approx(0.1)
    now[0] += 10.0                       # a long pause refills only up to the burst
    assert [th.delay() for _ in range(3)] == [0.0, 0.0, 0.0] and th.delay() > 0


def test_message_size_and_depth_limits():
    ok = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    with pytest.raises(ProtocolError, match="type hello"):           # deep enough to parse, then not an object
        decode(ok)
    for bad, says in [("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), f"nested deeper than {MAX_DEPTH} levels"),
                      ("[" * 16_000, f"nested deeper than {MAX_DEPTH} levels"),
                      ("[" * 50_000, f"message of 50000 bytes: at most {MAX_MESSAGE_BYTES} bytes"),
                      (b"\xff", "not JSON"),
                      ('{"type":"hello","participant":"' + "é" * 9000 + '"}', "message of 18033 bytes")]:
        with pytest.raises(ProtocolError, match=says):
            decode(bad)
    # brackets inside strings are text, not nesting
    assert decode('{"type":"hello","participant":"[[[[[[[[[[[[{{{{{{{{"}')["participant"] == "[[[[[[[[[[[[{{{{{{{{"


def test_physical_ranges(live):
    length = float(live.route.length)
    st = parse_state({"t": 0, "s": length + S_MARGIN, "v": V_MAX, "leader": {"gap": 0, "v": V_MAX}}, length)
    assert (st.s, st.v, st.leader) == (13_300.0, 100.0, (0.0, 100.0))
    for bad, says in [({"v": 1e6}, "'v' must be a finite number >= 0 and <= 100 m/s, got 1000000.0"),
                      ({"v": 100.001}, "'v' must be a finite number >= 0 and <= 100 m/s, got 100.001"),
                      ({"s": -0.5}, "'s' must be a finite number >= 0 and <= 13300 m, got -0.5"),
                      ({"s": 1e7}, "'s' must be a finite number >= 0 and <= 13300 m, got 10000000.0"),
                      ({"leader": {"gap": 5, "v": 101}}, "'v' must be a finite number >= 0 and <= 100 m/s"),
                      ({"t": 1e18}, "'t' must be a finite number >= -1e+07 and <= 1e+07 s, got 1e+18"),
                      ({"t": -1e300}, "'t' must be a finite number >= -1e+07 and <= 1e+07 s, got -1e+300"),
                      ({"t": T_MAX * (1 + 1e-15)}, "'t' must be a finite number >= -1e+07 and <= 1e+07 s")]:
        with pytest.raises(ProtocolError, match=re.escape(says)):
            parse_state({"t": 0, "s": 5.0, "v": 10.0, **bad}, length)


def test_a_time_far_off_is_refused_at_once_and_other_sessions_go_on(study):
    """On a route with signal programs, t = 1e18 (-1e300, 1e308, a jump of 1e9 s within a session) once stalled
    every session in an endless scan over phase starts: now each is a one-line error answered at once, the
    session's clock unchanged, and a good client on the same server gets each advice meanwhile."""
    with running(study) as (server, port, lines):
        with connect(f"ws://127.0.0.1:{port}/") as good, connect(f"ws://127.0.0.1:{port}/") as bad:
            ask(good, '{"type":"hello"}')
            ask(bad, '{"type":"hello"}')
            for k, t in enumerate((1e18, -1e300, 1e308)):
                err = ask(bad, json.dumps({"type": "state", "seq": k, "t": t, "s": 1000, "v": 10, "leader": None}))
                assert err == {"type": "error", "seq": k,
                               "error": f"'t' must be a finite number >= -1e+07 and <= 1e+07 s, got {t!r}"}
                assert ask(good, state(k))["type"] == "advice"
            assert ask(bad, state(25))["type"] == "advice"                         # t = 5 s
            err = ask(bad, state(26, t=5.0 + 1e9))
            assert err["error"] == "'t' must be a finite number >= -1e+07 and <= 1e+07 s, got 1000000005.0"
            assert ask(bad, state(27))["type"] == "advice"                         # its clock is still at 5 s
            assert ask(good, state(3))["type"] == "advice"


def test_time_never_goes_back_within_a_session(live):
    """A state earlier than the last one is refused with one line and changes nothing; the same t is accepted;
    hello starts a new clock."""
    session = LiveSession(live)
    session.handle('{"type":"hello"}')
    assert json.loads(session.handle(state(5)))["type"] == "advice"            # t = 1.0
    err = json.loads(session.handle(state(4)))                                  # t = 0.8
    assert err == {"type": "error", "seq": 4, "error": "'t' went backwards: 0.8 s after 1.0 s (a session's time "
                                                       "never decreases; hello starts a new one)"}
    assert session.samples == 1
    assert json.loads(session.handle(state(5)))["type"] == "advice" and session.samples == 2   # same t again
    session.handle('{"type":"hello"}')
    assert json.loads(session.handle(state(0)))["type"] == "advice"


def test_pairing_code_in_a_typed_address():
    assert pair_of("/display?pair=k7qm-2xfd") == "K7QM2XFD" and pair_of("/display") == ""
    assert set(PAIR_ALPHABET).isdisjoint("01IO") and len(PAIR_ALPHABET) == 32


# ---------------------------------------------------------------------------------------------- the server
def test_a_hud_page_shows_only_its_session(live):
    """Takeover refused: a second client's states (a bogus 1e6 m/s among them) never reach the page paired with the
    first; a page without a code, or with one no session has, gets a one-line error and is closed (1008)."""
    with running(live) as (server, port, lines):
        with connect(f"ws://127.0.0.1:{port}/") as good, connect(f"ws://127.0.0.1:{port}/") as other:
            code = ask(good, '{"type":"hello","condition":"pedas"}')["pair"]
            other_code = ask(other, '{"type":"hello"}')["pair"]
            assert code != other_code
            assert any(f"(pedas): pairing code {code}, HUD page http://127.0.0.1:{port}/?pair={code}" in line
                       for line in lines)
            with connect(f"ws://127.0.0.1:{port}/display?pair={code.lower()}") as page:
                assert ask(other, state(0, v=1e6))["error"].startswith("'v' must be a finite number")
                for k in range(3):
                    ask(other, state(100 + k, v=20.0))        # valid, but the other session's
                    assert ask(good, state(k))["seq"] == k
                shown = [json.loads(page.recv(timeout=30)) for _ in range(3)]
                assert [m["seq"] for m in shown] == [0, 1, 2] and {m["hud"]["speed"] for m in shown} == {36}
                with pytest.raises(TimeoutError):
                    page.recv(timeout=0.5)                    # nothing else came: not the other session's frames
            for path in ("/display", "/display?pair=AAAAAAAA"):
                with connect(f"ws://127.0.0.1:{port}{path}") as page:
                    err = json.loads(page.recv(timeout=30))
                    assert err["type"] == "error" and err["error"].startswith("unknown pairing code")
                    with pytest.raises(ConnectionClosed) as closed:
                        page.recv(timeout=30)
                    assert closed.value.rcvd.code == 1008


def test_idle_udp_sessions_end_and_strays_hold_nothing(live):
    """A UDP session ends after udp_idle s without a datagram (its page is closed, its code forgotten); datagrams
    that do not decode, or are not a hello, make no session; beyond max_sessions a new peer gets a one-line
    error."""
    with running(live, udp_idle=2.0, max_sessions=2) as (server, port, lines):
        peers = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(4)]
        for p in peers:
            p.settimeout(30)
        peers[0].sendto(b"[[[", ("127.0.0.1", port))
        assert json.loads(peers[0].recv(65536))["error"].startswith("not JSON")
        assert server.sessions == {}
        peers[0].sendto(state(0).encode(), ("127.0.0.1", port))               # not a hello: no session
        assert json.loads(peers[0].recv(65536))["error"].startswith("a UDP session starts with hello")
        assert server.sessions == {}
        peers[0].sendto(b'{"type":"hello"}', ("127.0.0.1", port))
        code = json.loads(peers[0].recv(65536))["pair"]
        peers[1].sendto(b'{"type":"hello"}', ("127.0.0.1", port))
        code1 = json.loads(peers[1].recv(65536))["pair"]
        peers[2].sendto(b'{"type":"hello","seq":1}', ("127.0.0.1", port))
        assert json.loads(peers[2].recv(65536)) == {
            "type": "error", "seq": 1, "error": "too many UDP sessions (2 at once): try again after 2 s"}
        assert len(server.sessions) == 2
        with connect(f"ws://127.0.0.1:{port}/display?pair={code}") as page0, \
                connect(f"ws://127.0.0.1:{port}/display?pair={code1}") as page1:
            for page in (page0, page1):
                with pytest.raises(ConnectionClosed) as closed:
                    page.recv(timeout=30)                      # the session idles out: its page is closed
                assert (closed.value.rcvd.code, closed.value.rcvd.reason) == (1000, "session ended")
        assert server.sessions == {} and server.paired == {}
        port0 = peers[0].getsockname()[1]
        assert f"session udp 127.0.0.1:{port0} ended: 2 s without a datagram" in lines
        with connect(f"ws://127.0.0.1:{port}/display?pair={code}") as page:
            assert json.loads(page.recv(timeout=30))["error"].startswith(f"unknown pairing code '{code}'")
        peers[3].sendto(b'{"type":"hello"}', ("127.0.0.1", port))   # room again
        assert json.loads(peers[3].recv(65536))["type"] == "ready"
        for p in peers:
            p.close()


def test_a_flooding_client_is_throttled_and_a_good_one_gets_every_advice(live):
    """One client sends 300 states without waiting; another, meanwhile, 20 states one by one: the good client gets
    each advice, in order; the flooder gets all 300 answers too, but never faster than the limit allows (the
    server's throttle, rate 100/s after a burst of 10, so the 300th answer comes >= 2.9 s after the first send)."""
    with running(live, rate=100.0, burst=10) as (server, port, lines):
        with connect(f"ws://127.0.0.1:{port}/") as good, connect(f"ws://127.0.0.1:{port}/") as flood:
            ask(good, '{"type":"hello"}')
            ask(flood, '{"type":"hello"}')
            answers: list[dict] = []

            def read_flood() -> None:
                for _ in range(300):
                    answers.append(json.loads(flood.recv(timeout=60)))

            t0 = time.monotonic()
            for k in range(300):
                flood.send(state(k))
            reader = threading.Thread(target=read_flood)
            reader.start()
            got = [ask(good, state(k)) for k in range(20)]
            reader.join(timeout=120)
            elapsed = time.monotonic() - t0
    assert [(m["type"], m["seq"]) for m in got] == [("advice", k) for k in range(20)]
    assert [(m["type"], m["seq"]) for m in answers] == [("advice", k) for k in range(300)]
    assert elapsed >= (300 - 10 - 1) / 100.0   # a lower bound: a slow machine only makes it later


def test_bad_input_is_answered_and_the_server_goes_on(live):
    """Deep JSON and oversize messages get an error frame on an open socket; a frame above the WebSocket limit is
    closed by the library with 1009 (no traceback, no 1011); out-of-range states are one-line errors; afterwards
    the same socket is advised and the server takes new clients."""
    with running(live) as (server, port, lines):
        with connect(f"ws://127.0.0.1:{port}/", max_size=None) as ws:
            ask(ws, '{"type":"hello"}')
            for text, says in [("[" * 16_000, "JSON nested deeper than 8 levels"),
                               ("[" * 50_000, "message of 50000 bytes: at most 16384 bytes"),
                               (state(1, v=1e6), "'v' must be a finite number >= 0 and <= 100 m/s, got 1000000.0"),
                               (state(2, s=-50.0), "'s' must be a finite number >= 0 and <= 13300 m, got -50.0"),
                               (state(3, s=1e7), "'s' must be a finite number >= 0 and <= 13300 m, got 10000000.0")]:
                err = ask(ws, text)
                assert err["type"] == "error" and err["error"] == says and "\n" not in err["error"]
            assert ask(ws, state(10))["type"] == "advice"
            err = ask(ws, state(9))
            assert err["error"].startswith("'t' went backwards: 1.8 s after 2.0 s")
        with connect(f"ws://127.0.0.1:{port}/", max_size=None) as ws:
            ws.send("[" * (WS_MAX_FRAME + 1))
            with pytest.raises(ConnectionClosed) as closed:
                ws.recv(timeout=30)
            assert closed.value.rcvd.code == 1009
        with connect(f"ws://127.0.0.1:{port}/") as ws:
            assert ask(ws, '{"type":"hello"}')["type"] == "ready"


def test_websocket_sessions_and_pages_are_capped(live):
    """Beyond max_sessions a WebSocket connection gets one error line and is closed (1013), the console says so
    once; when a session ends there is room again. A session's HUD pages are capped at MAX_PAGES."""
    with running(live, max_sessions=2) as (server, port, lines):
        with connect(f"ws://127.0.0.1:{port}/") as a, connect(f"ws://127.0.0.1:{port}/") as b:
            code = ask(a, '{"type":"hello"}')["pair"]
            ask(b, '{"type":"hello"}')
            for _ in range(2):
                with connect(f"ws://127.0.0.1:{port}/") as c:
                    assert json.loads(c.recv(timeout=30)) == {
                        "type": "error", "seq": None,
                        "error": "too many WebSocket sessions (2 at once): try again when one has ended"}
                    with pytest.raises(ConnectionClosed) as closed:
                        c.recv(timeout=30)
                    assert closed.value.rcvd.code == 1013
            assert lines.count("2 WebSocket sessions at once: new connections are refused") == 1
            with ExitStack() as stack:
                pages = [stack.enter_context(connect(f"ws://127.0.0.1:{port}/display?pair={code}"))
                         for _ in range(MAX_PAGES)]
                with connect(f"ws://127.0.0.1:{port}/display?pair={code}") as extra:
                    assert json.loads(extra.recv(timeout=30))["error"] == \
                        f"too many HUD pages for session {code} ({MAX_PAGES} at once)"
                assert ask(a, state(0))["type"] == "advice"
                assert all(json.loads(page.recv(timeout=30))["seq"] == 0 for page in pages)   # each page is fed
        deadline = time.monotonic() + 30
        while server.sessions and time.monotonic() < deadline:
            time.sleep(0.05)
        with connect(f"ws://127.0.0.1:{port}/") as c:
            assert ask(c, '{"type":"hello"}')["type"] == "ready"


def test_serve_refuses_bad_limits(cli):
    for flag in ("--udp-idle", "--max-rate", "--max-sessions"):
        r = cli("live", "serve", "--no-log", flag, "0", db=None)
        assert r.code == 2 and r.err.count("\n") == 1 and f"{flag} must be a positive number, got 0" in r.err
    for port in ("99999", "-1", "65536"):
        r = cli("live", "serve", "--no-log", "--port", port, db=None)
        assert r.code == 2 and r.err.count("\n") == 1 and \
            f"--port must be 1-65535 (or 0: any free port), got {port}" in r.err

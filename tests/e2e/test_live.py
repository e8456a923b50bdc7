"""Live advice (pedas.live, pedas.live_protocol, study.logs.live_log): the protocol with hand-made messages, the
advice equal to the in-process controller's for the same inputs, the drive log in a real store (complete after
bye, kept and marked incomplete when the server is killed), UDP, the HUD page in headless Chromium, and a virtual
participant driving in SUMO through the socket (slow)."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pedas.live import LiveRoute, LiveSession
from pedas.live_protocol import ProtocolError, decode, parse_state
from tests.conftest import OUTPUT, REPO, needs_chromium



@pytest.fixture(scope="module")
def live():
    return LiveRoute.load("synthetic-mixed")


def states(n: int, t0: float = 0.0, v: float = 10.0, dt: float = 0.2):
    """A car at constant speed v (m/s) from s = 5 m, one state every dt s; a leader 40 m ahead from the 10th on."""
    for k in range(n):
        yield {"type": "state", "seq": k, "t": t0 + k * dt, "s": 5.0 + v * k * dt, "v": v,
               "leader": {"gap": 40.0, "v": 9.0} if k >= 10 else None}


def test_protocol_messages():
    st = parse_state(decode('{"type":"state","seq":3,"t":1.5,"s":20,"v":12.5,"leader":{"gap":30,"v":11},'
                            '"spat":{"id":"tl1","state":"red","remaining":4}}'))
    assert (st.seq, st.t, st.s, st.v, st.leader, st.spat) == (3, 1.5, 20.0, 12.5, (30.0, 11.0), ("tl1", "red", 4.0))
    assert parse_state({"type": "state", "t": 0, "s": 0, "v": 0}).leader is None
    for bad, says in [("[1]", "type hello|state|bye"), ("{", "not JSON"), ('{"type":"go"}', "type"),
                      ('{"type":"state","t":1,"s":2,"v":-1}', "'v' must be a finite number >= 0"),
                      ('{"type":"state","t":1,"s":2}', "'v'"),
                      ('{"type":"state","t":1,"s":2,"v":1,"leader":{"gap":-2,"v":1}}', "'gap'"),
                      ('{"type":"state","t":1,"s":2,"v":1,"spat":{"id":"a","state":"blue"}}', "'spat'"),
                      ('{"type":"state","seq":"x","t":1,"s":2,"v":1}', "'seq'")]:
        with pytest.raises(ProtocolError, match=says.replace("|", r"\|").replace("(", r"\(")):
            parse_state(decode(bad))


def test_session_advice_equals_the_in_process_controller(live):
    """Every reply carries exactly the advice PedasController gives for the same inputs; a bad message in between
    is answered with an error and changes nothing."""
    from pedas.controller import PedasController
    from pedas.hud_frame import hud_frame
    from pedas.live_protocol import ADVICE_FIELDS

    session = LiveSession(live)
    ready = json.loads(session.handle('{"type":"hello"}'))
    assert ready == {"type": "ready", "route": "synthetic-mixed", "length_m": 13200.0, "logging": False,
                     "pair": session.pair}
    assert len(session.pair) == 8 and set(session.pair) <= set("23456789ABCDEFGHJKLMNPQRSTUVWXYZ")
    ref = PedasController(live.route, v_dp=live.v_dp)
    for k, msg in enumerate(states(150)):
        if k == 50:
            err = json.loads(session.handle('{"type":"state","seq":50,"t":"soon","s":1,"v":1}'))
            assert err == {"type": "error", "seq": 50,
                           "error": "'t' must be a finite number >= -1e+07 and <= 1e+07 s, got 'soon'"}
        reply = json.loads(session.handle(json.dumps(msg)))
        lead = (msg["leader"]["gap"], msg["leader"]["v"]) if msg["leader"] else None
        want = ref.step(msg["t"], msg["s"], msg["v"], lead)
        assert reply["seq"] == k and reply["advice"] == {f: getattr(want, f) for f in ADVICE_FIELDS}
        assert reply["hud"] == hud_frame(msg["v"], want).as_dict() and reply["spat_ok"] is None
    assert json.loads(session.handle('{"type":"bye"}')) == {"type": "done", "samples": 150, "drive_id": None}
    # hello restarts the controller: the same inputs give the first answers again
    session.handle('{"type":"hello"}')
    first = next(states(1))
    again = PedasController(live.route, v_dp=live.v_dp).step(first["t"], first["s"], first["v"], None)
    assert json.loads(session.handle(json.dumps(first)))["advice"]["v_advice"] == again.v_advice


def test_spat_checked_against_the_route_program(live):
    session = LiveSession(live)
    session.handle('{"type":"hello"}')
    assert not live.route.lights   # the synthetic route has no lights: any SPaT is inconsistent with it
    r = json.loads(session.handle('{"type":"state","t":0,"s":5,"v":10,"spat":{"id":"x","state":"red"}}'))
    assert r["spat_ok"] is False
    assert json.loads(session.handle('{"type":"hello","participant":"P1"}'))["error"].startswith("this server logs")


# ---------------------------------------------------------------------------------------------- the drive log
def test_drive_log_complete_after_bye(paper_db, live):
    from pedas.hud_frame import HudFrame
    from pedas.hud_log import channel_values
    from study.logs.stored import drive_samples
    from study.logs.importing import import_drive_frame
    from study.logs.live_log import LIVE_COLUMNS, LiveDriveLog
    from study.people.participants import add_participant
    from study.store.store import Store

    with Store.open(paper_db, actor="lab") as st:
        add_participant(st, "P001")
        with pytest.raises(ValueError, match="P404"):
            LiveDriveLog(st, "P404", "pedas", "synthetic-mixed")
        with pytest.raises(ValueError, match="condition"):
            LiveDriveLog(st, "P001", "nap", "synthetic-mixed")
        session = LiveSession(live, lambda p, c: LiveDriveLog(st, p, c, "synthetic-mixed"))
        assert json.loads(session.handle('{"type":"hello","participant":"P001","condition":"pedas"}'))["logging"]
        msgs = list(states(60))
        for msg in msgs[:30]:
            session.handle(json.dumps(msg))
        assert session.log.flush() == 30
        row = st.df("SELECT n_samples, duration_s, meta FROM drives WHERE participant_id = 'P001'").iloc[0]
        assert row["n_samples"] == 30 and row["duration_s"] == pytest.approx(29 * 0.2)
        assert json.loads(row["meta"])["live"]["complete"] is False
        replies = [json.loads(session.handle(json.dumps(msg))) for msg in msgs[30:]]
        done = json.loads(session.handle('{"type":"bye"}'))
        assert done["samples"] == 60 and done["drive_id"] is not None
        d = st.df("SELECT drive_id, n_samples, checksum, meta FROM drives WHERE participant_id = 'P001'").iloc[0]
        log = drive_samples(st, "P001", "pedas", channels=True)
        assert d["n_samples"] == 60 and json.loads(d["meta"])["live"]["complete"] is True
        session_id = json.loads(d["meta"])["live"]["session"]
        assert d["checksum"] != hashlib.sha256(session_id.encode()).hexdigest()   # the content's, not the placeholder
        # what the page was sent is what the log stores as the displayed HUD (pedas.hud_log)
        shown = pd.DataFrame([channel_values(HudFrame(**r["hud"])) for r in replies])
        pd.testing.assert_frame_equal(log[list(shown.columns)].iloc[30:].reset_index(drop=True), shown,
                                      check_dtype=False)
        again = import_drive_frame(st, "P001", "pedas", log[[*LIVE_COLUMNS, *shown.columns]], source="import")
        assert again.status == "unchanged"                                # the same content stored as an import
        assert log["t"].iloc[-1] == pytest.approx(59 * 0.2) and (log["v"] == 10.0).all()
        assert log["leader_gap"].isna().sum() == 10 and (log["controller"].iloc[10:] == "cf").all()
        # a second session for the same drive is refused unless replacing
        assert "already has a pedas drive" in json.loads(
            session.handle('{"type":"hello","participant":"P001","condition":"pedas"}'))["error"]
        assert set(LIVE_COLUMNS) <= set(log.columns)


# ---------------------------------------------------------------------------------------------- the server
def start_server(db: Path | None, *extra: str):
    """`live serve` on the synthetic route (unless `extra` names another) as a process; (process, port)."""
    from pedas_study.bench.live import start_live_server

    route = [] if "--route" in extra else ["--route", "synthetic-mixed"]
    return start_live_server(db, *route, *extra, cwd=REPO)


@pytest.mark.slow
def test_killed_session_keeps_what_was_logged(paper_db, cli_proc):
    from websockets.sync.client import connect

    from study.people.participants import add_participant
    from study.store.store import Store

    with Store.open(paper_db, actor="lab") as st:
        add_participant(st, "P002")
    proc, port = start_server(paper_db)
    try:
        with connect(f"ws://127.0.0.1:{port}/") as ws:
            ws.send(json.dumps({"type": "hello", "participant": "P002", "condition": "pedas"}))
            assert json.loads(ws.recv(timeout=30))["logging"] is True
            sent = 0
            t_end = time.monotonic() + 3.5                                   # about three flushes
            for msg in states(100_000, dt=0.02, v=12.0):
                ws.send(json.dumps(msg))
                assert json.loads(ws.recv(timeout=30))["type"] == "advice"
                sent += 1
                time.sleep(0.01)
                if time.monotonic() > t_end:
                    break
            # the session is still open: the server holds the store only while a flush writes
            r = cli_proc("participant", "list", db=paper_db, timeout=120)
            assert r.code == 0 and "P002" in r.out, r.err
            os.kill(proc.pid, signal.SIGKILL)                                # no bye, no clean shutdown
            proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    with Store.open(paper_db, actor="lab", read_only=True) as st:
        d = st.df("SELECT drive_id, n_samples, duration_s, meta FROM drives WHERE participant_id = 'P002'").iloc[0]
        n = st.one("SELECT count(*) FROM drive_samples WHERE drive_id = ?", [int(d["drive_id"])])
        t = st.df("SELECT t FROM drive_samples WHERE drive_id = ? ORDER BY idx", [int(d["drive_id"])])["t"]
    meta = json.loads(d["meta"])["live"]
    assert meta["complete"] is False
    assert 0 < n == d["n_samples"] <= sent and n >= sent - 3 * 100          # at most ~1 s (+ margin) lost
    assert np.allclose(np.diff(t.to_numpy()), 0.02) and d["duration_s"] == pytest.approx(t.iloc[-1])
    (OUTPUT / "live").mkdir(parents=True, exist_ok=True)
    (OUTPUT / "live" / "killed_session.json").write_text(json.dumps(
        {"sent": sent, "kept": int(n), "duration_s": float(d["duration_s"]), "meta": meta}, indent=1))


def doc_udp_client():
    """The class LiveUdp of docs/hud.md ("UDP: the session's secret"), from the code block as written there."""
    text = (REPO / "docs" / "hud.md").read_text()
    block = text.split("### UDP: the session's secret", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    space: dict = {}
    exec(compile(block, "docs/hud.md", "exec"), space)
    return space["LiveUdp"]


@pytest.mark.slow
def test_udp_and_the_hud_page_feed(cli_proc):
    """A simulator speaking UDP (the client of docs/hud.md) gets the advice; the feed of the HUD page paired with
    its session gets each frame. A datagram from the session's address without its secret, or with another, is
    dropped unanswered and never reaches the page (the console says so once, and counts); a state from an address
    without a session is told to say hello; a second server on the same port is a one-line error."""
    from websockets.sync.client import connect

    proc, port = start_server(None, "--udp-idle", "2")
    try:
        r = cli_proc("live", "serve", "--no-log", "--route", "synthetic-mixed", "--port", port, db=None, timeout=120)
        assert r.code == 2 and r.err.count("\n") == 1 and f"cannot listen on 127.0.0.1:{port}" in r.err
        stray = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        stray.settimeout(30)
        stray.sendto(json.dumps(next(states(1))).encode(), ("127.0.0.1", port))
        assert json.loads(stray.recv(65536))["error"] == ("a UDP session starts with hello: its ready carries the "
                                                          "secret that every later datagram must carry")
        sim = doc_udp_client()(port=port, timeout=30)
        assert sim.ready["type"] == "ready" and len(sim.secret) == 32 and int(sim.secret, 16) >= 0
        with connect(f"ws://127.0.0.1:{port}/display?pair={sim.ready['pair']}") as display:
            msgs = list(states(6))
            for msg in msgs[:5]:
                reply = sim.state(msg["seq"], msg["t"], msg["s"], msg["v"])
                assert reply["type"] == "advice" and reply["seq"] == msg["seq"]
                shown = json.loads(display.recv(timeout=30))
                assert shown["seq"] == msg["seq"] and shown["hud"] == reply["hud"]
            # what a forged datagram looks like to the server: the session's address, no (or another) secret
            for secret in ({}, {"secret": "0" * 32}, {"secret": sim.secret[:-1]}, {"secret": 7}):
                sim.sock.send(json.dumps({**msgs[5], "v": 99.0, **secret}).encode())
                sim.sock.send(b'{"type":"bye"}')
            with pytest.raises(TimeoutError):
                display.recv(timeout=1.0)                                  # nothing reached the page
            sim.sock.settimeout(0.5)
            with pytest.raises(TimeoutError):
                sim.sock.recv(65536)                                       # nor was anything answered
            sim.sock.settimeout(30)
            assert sim.state(5, msgs[5]["t"], msgs[5]["s"], 10.0)["hud"]["speed"] == 36   # the session goes on
            sim.sock.send(json.dumps({"type": "state", "secret": sim.secret}).encode())
            assert json.loads(sim.sock.recv(65536))["error"].startswith("'t' must be")
            assert sim.bye() == {"type": "done", "samples": 6, "drive_id": None}
        time.sleep(3.5)                                                    # the session idles out (2 s)
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    peer = f"session udp 127.0.0.1:{sim.sock.getsockname()[1]}"
    assert f"{peer}: a datagram without the session's secret dropped" in out
    assert f"{peer} ended: 2 s without a datagram (8 datagrams without its secret dropped)" in out


def test_udp_session_logs_a_complete_drive(paper_db):
    from study.people.participants import add_participant
    from study.store.store import Store

    with Store.open(paper_db, actor="lab") as st:
        add_participant(st, "P003")
    proc, port = start_server(paper_db)
    try:
        sim = doc_udp_client()(port=port, participant="P003", timeout=60)
        assert sim.ready["logging"] is True
        for msg in states(40):
            assert sim.state(msg["seq"], msg["t"], msg["s"], msg["v"])["seq"] == msg["seq"]
        done = sim.bye()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
    assert done["type"] == "done" and done["samples"] == 40
    with Store.open(paper_db, actor="lab", read_only=True) as st:
        d = st.df("SELECT drive_id, n_samples, meta FROM drives WHERE participant_id = 'P003'").iloc[0]
    assert int(d["drive_id"]) == done["drive_id"] and d["n_samples"] == 40
    assert json.loads(d["meta"])["live"]["complete"] is True


def _stored(holder, participant: str) -> tuple[int, int, dict] | None:
    """(drive_id, samples stored, meta.live) of the participant's pedas drive, read through the server's holder."""
    with holder:
        d = holder.store.df("SELECT drive_id, meta FROM drives WHERE participant_id = ? AND condition = 'pedas'",
                            [participant])
        if d.empty:
            return None
        drive_id = int(d["drive_id"].iloc[0])
        n = holder.store.one("SELECT count(*) FROM drive_samples WHERE drive_id = ?", [drive_id])
    return drive_id, n, json.loads(d["meta"].iloc[0])["live"]


def _until(what, timeout: float = 20.0):
    """Poll `what()` until it is truthy (a flush comes about once a second)."""
    t_end = time.monotonic() + timeout
    while not (got := what()) and time.monotonic() < t_end:
        time.sleep(0.1)
    return got


@pytest.mark.slow
def test_one_simulator_per_drive(paper_db, live):
    """A second hello for the drive a session logs is refused in one line (the console says so) and deletes
    nothing: the first session's partial drive grows in the store each second, the refused session is advised
    without a log, and the first's bye stores its every sample. A flush that fails (the drive removed behind the
    server's back) is a console line, and the other sessions are flushed on."""
    from websockets.sync.client import connect

    from study.logs.live_log import LiveDriveLog
    from study.people.participants import add_participant
    from study.store.store import Store, StoreHolder
    from tests.pedas.test_live_limits import ask, running

    with Store.open(paper_db, actor="lab") as st:
        add_participant(st, "P001")
        add_participant(st, "P002")
    holder = StoreHolder(paper_db, "lab")
    hello = '{"type":"hello","participant":"%s","condition":"pedas"}'
    with running(live, logger_factory=lambda p, c: LiveDriveLog(holder, p, c, "synthetic-mixed")) as (
            server, port, lines), connect(f"ws://127.0.0.1:{port}/") as first, \
            connect(f"ws://127.0.0.1:{port}/") as second:
        assert ask(first, hello % "P001")["logging"] is True
        peer = f"ws 127.0.0.1:{first.local_address[1]}"
        err = ask(second, hello % "P001")["error"]
        assert err.startswith(f"P001's pedas drive is being logged by another session ({peer}, since ") and \
            err.endswith("one simulator per drive; that session must say bye or disconnect first")
        assert _until(lambda: any(line.startswith("session ws 127.0.0.1:") and
                                  line.endswith(f"(P001, pedas): hello refused: {err}") for line in lines))
        msgs = [json.dumps(m) for m in states(60)]
        for m in msgs[:20]:
            assert ask(first, m)["type"] == "advice"
        for m in states(10, t0=100.0):
            assert ask(second, json.dumps(m))["type"] == "advice"          # advised, not logged
        drive_id, n, meta = _until(lambda: (got := _stored(holder, "P001")) and got[1] == 20 and got)
        assert meta["complete"] is False                                   # the partial drive, during the session
        for m in msgs[20:40]:
            ask(first, m)
        assert _until(lambda: _stored(holder, "P001")[1] == 40)            # flushed on: nothing deleted it
        # the drive removed behind the server's back: the first's flush fails, says so once, and flushing goes on
        assert ask(second, hello % "P002")["logging"] is True
        for m in msgs[:20]:
            ask(second, m)
        with holder:
            holder.store.con.execute("DELETE FROM drive_samples WHERE drive_id = ?", [drive_id])
            holder.store.con.execute("DELETE FROM drives WHERE drive_id = ?", [drive_id])
        for m in msgs[40:]:
            ask(first, m)
        failed = _until(lambda: [line for line in lines if "drive log not written" in line])
        assert failed[0].startswith(f"session {peer} (P001, pedas): drive log not written: ") and \
            failed[0].endswith("its samples stay queued for the next flush")
        for m in states(20, t0=4.0):
            ask(second, json.dumps(m))
        assert _until(lambda: (_stored(holder, "P002") or (0, 0))[1] == 40)   # the other session is flushed on
        time.sleep(2.5)
        assert len([line for line in lines if "drive log not written" in line]) == 1   # said once per cause
        assert ask(second, '{"type":"bye"}')["samples"] == 40
    holder.shut()
    with Store.open(paper_db, actor="lab", read_only=True) as st:
        d = st.df("SELECT participant_id, n_samples, meta FROM drives ORDER BY participant_id")
    assert d["participant_id"].tolist() == ["P002"] and d["n_samples"].tolist() == [40]
    assert json.loads(d["meta"].iloc[0])["live"]["complete"] is True


def test_a_drive_stored_by_another_writer_is_never_replaced(paper_db):
    """Two drive logs of one participant's drive (two servers on one store): the second's flush is refused and
    deletes nothing; the first's samples stay whole. A log with replace replaces only the drive it started over."""
    from study.logs.live_log import LiveDriveLog
    from study.people.participants import add_participant
    from study.store.store import Store

    rows = [{"t": 0.2 * k, "s": 5.0 + 2 * k, "v": 10.0, "segment": "urban", "speed_limit": 13.9, "a": 0.0,
             "grade": 0.0, "tl_id": None, "tl_state": None, "d_tl": float("nan"), "leader_gap": float("nan"),
             "leader_v": float("nan"), "v_advice": 10.0, "controller": "rt", "hud_arrow": 0, "hud_in_band": True,
             "warning": False} for k in range(30)]
    with Store.open(paper_db, actor="lab") as st:
        add_participant(st, "P001")
        a = LiveDriveLog(st, "P001", "pedas", "synthetic-mixed")
        b = LiveDriveLog(st, "P001", "pedas", "synthetic-mixed", replace=True)   # started before a stored any
        for row in rows[:20]:
            a.append(row)
            b.append(row)
        assert a.flush() == 20
        with pytest.raises(ValueError, match=f"P001's pedas drive {a.drive_id} was stored by another writer"):
            b.flush()
        for row in rows[20:]:
            a.append(row)
        assert a.flush() == 30 and a.close() is not None
        assert st.one("SELECT n_samples FROM drives WHERE participant_id = 'P001'") == 30
        assert st.one("SELECT count(*) FROM drive_samples") == 30
        c = LiveDriveLog(st, "P001", "pedas", "synthetic-mixed", replace=True)   # over the drive stored now
        for row in rows[:10]:
            c.append(row)
        assert c.flush() == 10 and st.one("SELECT count(*) FROM drive_samples") == 10


@pytest.mark.browser
@needs_chromium
@pytest.mark.parametrize("theme", ["light", "dark"])
def test_hud_page_in_chromium_follows_the_advice(theme):
    """The server's full-screen HUD page (/?pair=CODE, the code of the simulator's session) draws each frame the
    simulator's states produce, and says in a full-panel message, the HUD hidden, when it is not live: waiting
    (no code), paired (no frame yet), session ended, wrong code; no console error on the way (no favicon
    request). Screenshots tests/output/live/hud_page_<theme>_<state>.png."""
    from playwright.sync_api import expect, sync_playwright
    from websockets.sync.client import connect

    from pedas.hud_png import launch

    proc, port = start_server(None, "--theme", theme)
    out = OUTPUT / "live"
    out.mkdir(parents=True, exist_ok=True)
    errors, requests = [], []

    def shot(page, state):
        expect(page.locator("body")).to_have_attribute("data-state", state, timeout=30_000)
        assert page.locator("#hud").is_visible() == (state == "live")
        page.screenshot(path=str(out / f"hud_page_{theme}_{state}.png"))

    try:
        with sync_playwright() as p:
            b = launch(p)
            page = b.new_page(viewport={"width": 960, "height": 540})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("request", lambda r: requests.append(r.url))
            page.goto(f"http://127.0.0.1:{port}/")                       # no code: waiting, a field to type it
            shot(page, "waiting")
            expect(page.locator("#pair input[name=pair]")).to_be_visible()
            with connect(f"ws://127.0.0.1:{port}/") as ws:
                ws.send('{"type":"hello"}')
                code = json.loads(ws.recv(timeout=30))["pair"]
                page.goto(f"http://127.0.0.1:{port}/?pair={code}")
                shot(page, "paired")
                expect(page.locator("#detail")).to_contain_text(code)
                for msg in states(3, v=13.0):
                    ws.send(json.dumps(msg))
                    reply = json.loads(ws.recv(timeout=30))
                expect(page.locator("#hud")).to_have_attribute("data-seq", "2", timeout=30_000)
                assert page.locator("#hud").get_attribute("data-speed") == str(reply["hud"]["speed"]) == "47"
                assert page.locator("#hud").get_attribute("theme") == theme
                shot(page, "live")
                ws.send('{"type":"bye"}')
            shot(page, "ended")                                         # the last frame is no longer shown
            expect(page.locator("#state")).to_have_text("session ended")
            page.goto(f"http://127.0.0.1:{port}/?pair=AAAAAAAA")
            shot(page, "wrong-code")
            expect(page.locator("#detail")).to_contain_text("unknown pairing code 'AAAAAAAA'")
            expect(page.locator("#pair input[name=pair]")).to_be_visible()
            b.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    assert errors == [] and not [u for u in requests if "favicon" in u]


@pytest.mark.slow
@pytest.mark.sumo
def test_virtual_participant_drives_through_the_socket(cli_proc):
    """The reference client: a whole pEDAS drive in SUMO with every advice from the server, identical to the
    in-process drive with the same seeds."""
    proc, port = start_server(None, "--route", "study")
    try:
        r = cli_proc("live", "drive", "--url", f"ws://127.0.0.1:{port}/", "--seed", "3", "--compare", db=None)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    assert r.code == 0, r.err
    assert "identical log" in r.out and "round trip median" in r.out
    r = cli_proc("live", "drive", "--url", f"ws://127.0.0.1:{port}/", db=None)   # the server is gone
    assert r.code == 2 and r.err.count("\n") == 1 and "Connection refused" in r.err


@pytest.mark.slow
@pytest.mark.sumo
def test_bench_live_through_the_cli(cli_proc):
    """`bench live` on a few messages: latencies measured, the advice equal to the in-process controller's, every
    state logged (timing is reported, never asserted)."""
    r = cli_proc("bench", "live", "--messages", "60", "--rate", "100", "--json", db=None)
    assert r.code == 0, r.err
    res = json.loads(r.out)
    assert res["messages"] == 60 and res["mismatches"] == 0 and res["logged_samples"] == 60
    assert 0 < res["median_ms"] <= res["p99_ms"] <= res["max_ms"]
    r = cli_proc("bench", "live", "--messages", "0", db=None)
    assert r.code == 2 and "--messages" in r.err

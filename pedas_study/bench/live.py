"""Latency of live advice (`pedas-study bench live`): a simulator's state in -> the advice out, on localhost.

The server is `pedas-study live serve` in its own process, logging the drive into a temporary store (as in a
session with a participant). The states are those of a simulated pEDAS drive on the study route (SUMO time,
position, speed, leader), replayed as one session per drive length until `messages` states are sent, one every
1/rate s (a 50 Hz simulator); the latency of a message is the wall time from sending the state to receiving its
advice (WebSocket, JSON, controller step, HUD frame). Every advice is compared with a PedasController run
in-process on the same inputs (field by field, exact floats).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def drive_states(seed: int = 1, style: str = "normal") -> list[dict]:
    """The state messages of a simulated pEDAS drive (t on SUMO's clock)."""
    from pedas.drive import drive

    df = drive(seed, style, "pedas")
    t_ins = df.attrs["drive"]["t_insert"]
    out = []
    for k, (t, s, v, gap, lv) in enumerate(df[["t", "s", "v", "leader_gap", "leader_v"]].itertuples(index=False)):
        leader = None if gap != gap else {"gap": float(gap), "v": float(lv)}
        out.append({"type": "state", "seq": k, "t": float(t) + t_ins, "s": float(s), "v": float(v), "leader": leader})
    return out


def start_live_server(db: Path | None, *extra: str, cwd: Path | None = None) -> tuple[subprocess.Popen, int]:
    """`pedas-study live serve --port 0 EXTRA...` in its own process, logging into the store `db` (None: no log);
    (process, the port it listens on)."""
    argv = [sys.executable, "-m", "pedas_study.cli"] + ([f"--db={db}"] if db else []) + \
        ["live", "serve", "--port", "0", *extra] + ([] if db else ["--no-log"])
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)
    line = proc.stdout.readline()
    if "listening on ws://" not in line:
        raise RuntimeError(f"live server did not start: {line}{proc.stderr.read()}")
    return proc, int(line.split("ws://127.0.0.1:")[1].split("/")[0])


def bench_live(messages: int = 10_000, rate: float = 50.0, seed: int = 1) -> dict:
    """{'messages', 'rate_hz', 'sessions', 'median_ms', 'p99_ms', 'max_ms', 'mismatches', 'logged_samples'}."""
    from websockets.sync.client import connect

    from pedas.controller import PedasController
    from pedas.drive import study_route_and_reference
    from pedas.live_protocol import ADVICE_FIELDS
    from study.people.participants import add_participant
    from study.store.store import Store
    from study.store.studies import register

    from analysis.paper.published import PAPER_STUDY_DIR

    states = drive_states(seed)
    route, v_dp = study_route_and_reference()
    lat, mismatches, sessions = [], 0, 0
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "live.duckdb"
        with Store.open(db, actor="bench") as st:
            register(st, PAPER_STUDY_DIR)
            n_sessions = -(-messages // len(states))
            for k in range(n_sessions):
                add_participant(st, f"P{900 + k}")
        proc, port = start_live_server(db)
        try:
            with connect(f"ws://127.0.0.1:{port}/") as ws:
                sent = 0
                while sent < messages:
                    ws.send(json.dumps({"type": "hello", "participant": f"P{900 + sessions}", "condition": "pedas"}))
                    json.loads(ws.recv(timeout=60))
                    ref = PedasController(route, v_dp=v_dp)
                    period, t_next = 1.0 / rate, time.perf_counter()
                    for msg in states[:messages - sent]:
                        while (now := time.perf_counter()) < t_next:
                            time.sleep(min(t_next - now, 0.002))
                        t_next += period
                        t0 = time.perf_counter()
                        ws.send(json.dumps(msg))
                        reply = json.loads(ws.recv(timeout=60))
                        lat.append(time.perf_counter() - t0)
                        lead = None if msg["leader"] is None else (msg["leader"]["gap"], msg["leader"]["v"])
                        want = ref.step(msg["t"], msg["s"], msg["v"], lead)
                        if reply["advice"] != {f: getattr(want, f) for f in ADVICE_FIELDS}:
                            mismatches += 1
                        sent += 1
                    ws.send('{"type":"bye"}')
                    json.loads(ws.recv(timeout=120))
                    sessions += 1
        finally:
            proc.terminate()
            proc.wait(timeout=60)
        with Store.open(db, actor="bench", read_only=True) as st:
            logged = int(st.one("SELECT coalesce(sum(n_samples), 0) FROM drives"))
    ms = np.asarray(lat) * 1e3
    return {"messages": len(lat), "rate_hz": rate, "sessions": sessions, "median_ms": float(np.median(ms)),
            "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()), "mismatches": mismatches,
            "logged_samples": logged}

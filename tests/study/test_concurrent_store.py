"""The CLI and a running survey server on one store at the same time: `survey serve` as a real process, 20
participants answering and submitting over HTTP from 20 threads, interleaved with CLI processes importing drive
logs, registering participants and listing them. Nothing is lost, every command and request succeeds. The
figures (wall time, waits, retries) are printed (run with -s), never asserted: timing is measured, not tested."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from concurrent.futures import ThreadPoolExecutor

import pytest

from study.survey import answers as sv
from study.people.participants import add_participant
from study.store.store import Store
from tests.conftest import REPO
from tests.study.test_drive_import import make_drive
from tests.study.test_survey_web import ATTRIBUTE_ITEMS, free_port, seeded_answers

N_WEB = 20
N_DRIVES = 2
WAITED = re.compile(r"waited ([0-9.]+) s \((\d+) retries\)")


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *a, **kw):
        return None


OPENER = urllib.request.build_opener(_NoRedirect)  # a submission answers 303: count that, do not follow it


def _post(url: str, data: dict) -> tuple[int, float]:
    """(HTTP status, seconds) of one POST."""
    t0 = time.perf_counter()
    try:
        with OPENER.open(urllib.request.Request(url, data=urllib.parse.urlencode(data).encode()), timeout=120) as r:
            code = r.status
    except urllib.error.HTTPError as e:
        code = e.code
    return code, time.perf_counter() - t0


def _waits(text: str) -> list[tuple[float, int]]:
    return [(float(s), int(n)) for s, n in WAITED.findall(text)]


@pytest.mark.slow
def test_server_and_cli_share_the_store(paper_db, tmp_path):
    web = [f"P{100 + i}" for i in range(N_WEB)]
    drivers = [f"P{200 + i}" for i in range(N_DRIVES)]
    with Store.open(paper_db, actor="lab") as st:
        for p in web + drivers:
            add_participant(st, p)
        tokens = {p: sv.issue_link(st, p) for p in web}
    answers = {p: seeded_answers(i) for i, p in enumerate(web)}
    logs = []
    for i in range(N_DRIVES):
        f = tmp_path / f"drive{i}.csv"
        make_drive(n=3000, seed=i).to_csv(f, index=False)
        logs.append(f)

    env = {**os.environ, "PEDAS_SURVEY_PASSWORD": "pw", "PEDAS_STUDY_LOG": "info", "PYTHONPATH": str(REPO)}
    port = free_port()
    server_err = tmp_path / "server.err"
    with open(server_err, "w") as err:
        server = subprocess.Popen([sys.executable, "-m", "pedas_study.cli", f"--db={paper_db}", "survey", "serve",
                                   "--port", str(port)], stdout=subprocess.PIPE, stderr=err, text=True, env=env,
                                  cwd=REPO)
    base = f"http://127.0.0.1:{port}"
    try:
        assert server.stdout.readline().startswith("survey form on ")

        def participant(p: str) -> list[tuple[int, float]]:
            # three answers as the tablet saves them, then the whole form submitted
            out = [_post(f"{base}/s/{tokens[p]}/answer", {"item": item, "value": answers[p][item]})
                   for item in list(answers[p])[:3]]
            out.append(_post(f"{base}/s/{tokens[p]}", {**answers[p], "action": "submit"}))
            return out

        commands = []
        for i in range(N_DRIVES):
            commands += [["drive", "import", drivers[i], "baseline", str(logs[i])],
                         ["participant", "list", "--format", "csv"],
                         ["participant", "add", f"P{300 + i}"]]
        cli_results: list[tuple[list[str], int, str, float]] = []

        def run_commands(part: list[list[str]]) -> None:
            for args in part:
                t0 = time.perf_counter()
                p = subprocess.run([sys.executable, "-m", "pedas_study.cli", f"--db={paper_db}", *args],
                                   capture_output=True, text=True, env=env, cwd=REPO, timeout=300)
                cli_results.append((args, p.returncode, p.stderr, time.perf_counter() - t0))

        t0 = time.perf_counter()
        cli_thread = threading.Thread(target=run_commands, args=(commands,))
        cli_thread.start()
        with ThreadPoolExecutor(max_workers=N_WEB) as pool:
            web_results = [r for rs in pool.map(participant, web) for r in rs]
        web_wall = time.perf_counter() - t0
        cli_thread.join()
        wall = time.perf_counter() - t0
    finally:
        server.terminate()
        server.wait(timeout=30)
    server_log = server_err.read_text()

    cli_waits = [w for _, _, e, _ in cli_results for w in _waits(e)]
    server_waits = _waits(server_log)
    lat = sorted(s for _, s in web_results)
    print(f"\nconcurrency: wall {wall:.2f} s (web part {web_wall:.2f} s); {len(web_results)} HTTP requests, "
          f"latency median {lat[len(lat) // 2] * 1000:.0f} ms, p95 {lat[int(0.95 * (len(lat) - 1))] * 1000:.0f} ms, "
          f"max {lat[-1] * 1000:.0f} ms; "
          f"{len(cli_results)} CLI commands, each {min(r[3] for r in cli_results):.2f}-"
          f"{max(r[3] for r in cli_results):.2f} s; CLI opens that waited: {len(cli_waits)}, "
          f"max wait {max([s for s, _ in cli_waits], default=0):.3f} s, retries {sum(n for _, n in cli_waits)}; "
          f"server opens that waited: {len(server_waits)}, max wait {max([s for s, _ in server_waits], default=0):.3f} "
          f"s, retries {sum(n for _, n in server_waits)}")

    bad = [(a, code, e) for a, code, e, _ in cli_results if code != 0]
    assert bad == [] and len(cli_results) == len(commands)
    assert {c for c, _ in web_results} == {200, 303}, sorted({c for c, _ in web_results})
    with Store.open(paper_db, read_only=True) as st:
        n = st.df("SELECT participant_id, count(*) AS n FROM responses GROUP BY 1").set_index("participant_id")["n"]
        assert sorted(n.index) == web
        stored = set(st.df("SELECT item_id FROM responses")["item_id"])
        assert set(n) == {len(stored)}
        assert st.one("SELECT count(*) FROM survey_submissions") == N_WEB
        final = sv.final_responses(st).set_index("participant_id")
        drives = st.df("SELECT participant_id, n_samples FROM drives ORDER BY 1")
        assert list(drives["participant_id"]) == drivers and set(drives["n_samples"]) == {3000}
        assert st.one("SELECT count(*) FROM participants WHERE participant_id LIKE 'P3%'") == N_DRIVES
    for p in web:
        scale = {i: str(int(final.loc[p, i])) for i in answers[p] if i not in ATTRIBUTE_ITEMS and i != "Q1"}
        assert scale == {i: v for i, v in answers[p].items() if i in scale}
        assert final.loc[p, "Q1"] == answers[p]["Q1"]

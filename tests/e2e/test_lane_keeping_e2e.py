"""The second study (studies/lane_keeping) end to end through the CLI on a temporary store, as a lab would run it:
check the folder, create the store, register 24 participants with their age, book their slots (the counterbalanced
orders alternate), walk each through the protocol phases (one drops out in the first drive), one participant answers
the questionnaire in the web form in Chromium and the others' paper forms come in as a CSV, then the analysis, the
report document and the SPSS export. Every command and what it printed is written to
tests/output/lane_keeping_e2e.txt (and to the captured output)."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
from datetime import date, timedelta
from pathlib import Path

import pandas as pd
import pytest

from tests.conftest import LK_STUDY, OUTPUT, REPO, needs_chromium

LK_DATA = REPO / "tests" / "data" / "lane_keeping"
ITEMS = [f"{c}{k}" for c in ("PE", "EE", "SI", "BI") for k in (1, 2, 3)]
DROPOUT = "LK-24"          # motion sickness in the first drive: excluded from all analyses, no questionnaire
WEB = "LK-01"              # answers in the web form; everyone else on paper (CSV import)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.browser,
    needs_chromium,
]


class Transcript:
    """Runs `pedas-study --db DB ...` in-process and records each command with its output."""

    def __init__(self, db: Path, capsys):
        self.db, self.capsys, self.lines = db, capsys, []

    def record(self, argv: list[str], code: int, out: str, err: str) -> None:
        shown = " ".join(a if re.fullmatch(r"[\w@%+=:,./-]+", a) else repr(a) for a in argv)
        self.lines.append(f"$ pedas-study {shown}")
        text = (out + err).replace(str(self.db.parent) + "/", "")  # paths relative to the test's folder
        self.lines += [f"  {ln}" for ln in text.rstrip("\n").splitlines()]
        if code:
            self.lines.append(f"  (exit {code})")

    def __call__(self, *args, db: bool = True, quiet: bool = False) -> str:
        from pedas_study.cli import main

        argv = ([f"--db={self.db}"] if db else []) + [str(a) for a in args]
        self.capsys.readouterr()
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
        cap = self.capsys.readouterr()
        shown = [a.replace(str(self.db.parent) + "/", "").replace(str(REPO) + "/", "") for a in argv]
        if not quiet:
            self.record(shown, code, cap.out, cap.err)
        assert code == 0, f"`pedas-study {' '.join(shown)}` failed (exit {code}): {cap.err.strip()}"
        return cap.out

    def write(self) -> str:
        text = "\n".join(self.lines) + "\n"
        OUTPUT.mkdir(exist_ok=True)
        (OUTPUT / "lane_keeping_e2e.txt").write_text(text, encoding="utf-8")
        return text


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _fill_web_form(link: str, answers: dict, age: int) -> None:
    """Open the participant's link in Chromium, answer age and the 12 items by clicking, submit."""
    from playwright.sync_api import expect, sync_playwright

    from pedas.hud_png import launch

    with sync_playwright() as p:
        browser = launch(p)
        try:
            page = browser.new_page(viewport={"width": 1024, "height": 768})
            page.goto(link)
            assert "lane-keeping" in page.content()
            page.fill("#in-AGE", str(age))
            for item in ITEMS:
                page.click(f"#q-{item} label.point:nth-of-type({int(answers[item])})")
            expect(page.locator("#save-status")).to_have_attribute("data-pending", "0", timeout=30_000)
            page.click("#submit-btn")
            page.wait_for_selector("text=Thank you!")
        finally:
            browser.close()


def test_lane_keeping_study_end_to_end(tmp_path, capsys):
    db = tmp_path / "lk.duckdb"
    run = Transcript(db, capsys)
    survey = pd.read_csv(LK_DATA / "survey.csv", dtype={"participant_id": str})
    people = pd.read_csv(LK_DATA / "participants.csv", dtype={"participant_id": str})
    assert list(people["participant_id"]) == [f"LK-{k:02d}" for k in range(1, 25)]
    protocol = json.loads((LK_STUDY / "protocol.json").read_text())
    try:
        # the study folder, then a store that serves it
        assert run("study", "check", LK_STUDY, db=False).startswith("study lane_keeping OK: 3 attributes, "
                                                                     "conditions hud|no_hud")
        out = run("init", "--study", LK_STUDY)
        assert "study lane_keeping version 1 stored" in out

        # 24 participants with their age (required by the study)
        for r in people.itertuples():
            run("participant", "add", r.participant_id, "--attr", f"age={r.age}", quiet=r.Index > 1)
        listing = json.loads(run("participant", "list", "--format", "json", quiet=True))
        assert [p["age"] for p in listing] == people["age"].tolist()

        # slots on three days (from four weeks ahead: bookings must lie in the future), 8 per day; booking
        # assigns the counterbalanced order, which alternates
        first_day = date.today() + timedelta(days=28)
        orders = {}
        for k, pid in enumerate(people["participant_id"]):
            day, slot = divmod(k, 8)
            at = f"{first_day + timedelta(days=day)}T{8 + slot:02d}:00"
            run("session", "schedule", pid, "--at", at, quiet=k > 1)
            orders[pid] = run("session", "assign", pid, quiet=k > 1).strip().rsplit(" ", 1)[-1]
        assert [orders[p] for p in people["participant_id"]] == ["hud_first", "no_hud_first"] * 12
        assert "LK-08" in run("schedule", "day", str(first_day))

        # the protocol phases in each participant's order; the dropout aborts in the first drive
        for k, pid in enumerate(people["participant_id"]):
            phases = protocol["orders"][orders[pid]]
            if pid == DROPOUT:
                run("session", "advance", pid, phases[0])
                run("session", "advance", pid, phases[1])
                run("session", "abort", pid, "--reason", "motion sickness")
                run("exclude", pid, "--scope", "all", "--reason", "motion_sickness")
                continue
            for phase in phases:
                run("session", "advance", pid, phase, quiet=k > 0)
            run("session", "complete", pid, quiet=k > 0)
        status = json.loads(run("session", "status", "LK-02", "--format", "json"))
        assert [p["phase"] for p in status["phases"]] == protocol["orders"]["no_hud_first"]
        assert {p["outcome"] for p in status["phases"]} == {"completed"}

        # one participant in the web form (a real `survey serve` process), the others' paper forms as a CSV
        port = _free_port()
        link_out = run("survey", "link", WEB, "--base-url", f"http://127.0.0.1:{port}")
        link = re.search(r"http://\S+", link_out).group(0)
        server = subprocess.Popen([sys.executable, "-m", "pedas_study.cli", f"--db={db}", "survey", "serve",
                                   "--port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  cwd=REPO, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        try:
            first = server.stdout.readline()
            assert "survey form on" in first, first
            run.lines += [f"$ pedas-study --db={db.name} survey serve --port {port}   (in the background)",
                          f"  {first.strip()}"]
            web = survey.set_index("participant_id").loc[WEB]
            _fill_web_form(link, web.to_dict(), int(web["AGE"]))
            run.lines.append(f"  (Chromium: {WEB} answered the 12 items in the form and submitted)")
        finally:
            server.send_signal(signal.SIGTERM)
            server.wait(timeout=30)
        paper = tmp_path / "paper_forms.csv"
        survey[~survey["participant_id"].isin([WEB, DROPOUT])].to_csv(paper, index=False)
        run("survey", "import", paper)
        run("survey", "status", quiet=True)

        # analysis, report document, SPSS export
        out = run("analyze", "survey", "--out", tmp_path / "survey", "--bootstrap", "200")
        hyp = pd.read_csv(tmp_path / "survey" / "hypotheses.csv")
        assert list(hyp["hypothesis"]) == ["H1", "H2", "H3"] and set(hyp["path"]) == {"PE -> BI", "EE -> BI",
                                                                                     "SI -> BI"}
        assert int(hyp["n"].iloc[0]) == 23
        out = run("report", "--out", tmp_path / "reports", "--bootstrap", "200", "--cache-dir", tmp_path / "cache")
        assert "skipped drives: the store has no drives" in out
        doc = (tmp_path / "reports" / "index.html").read_text(encoding="utf-8")
        assert "<h1>Acceptance of a lane-keeping head-up display</h1>" in doc
        assert "UTAUT models" in doc and "model 1, BI: step 1: age; step 2: PE + EE + SI" in doc
        for h in ("H1", "H2", "H3"):
            assert re.search(rf"<tr><td>{h}</td><td>[A-Z]+ -&gt; BI</td><td>positive</td>.*?"
                             rf"<td>(supported|not supported)</td></tr>", doc), h
        assert "24 registered; 23 in the survey analysis</dd>" in doc   # no drives: no drive sample
        run("export", "sav", tmp_path / "sav")
    finally:
        print(run.write())

    import pyreadstat

    wide, meta = pyreadstat.read_sav(str(tmp_path / "sav" / "survey_wide_lk_acceptance_v1.sav"))
    wide = wide.set_index("participant_id").sort_index()
    assert list(wide.index) == [p for p in people["participant_id"] if p != DROPOUT]
    want = survey.set_index("participant_id").loc[wide.index, ITEMS]
    assert (wide[ITEMS].astype(int).to_numpy() == want.to_numpy()).all()
    assert meta.column_names_to_labels["PE1"] == "The lane-keeping display helps me keep my lane."

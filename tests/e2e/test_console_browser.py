"""The researcher console in Debian's headless Chromium driven by Playwright: one participant from registration to
the submitted survey (booking, phases by start/end buttons, drive uploads with progress, link with QR code, the
tablet's survey, completeness, export download), then two participants interleaved on two simulators (an aborted
drive and an exclusion, a refused implausible log, a revoked link). Every console page is saved as a screenshot in
tests/output/console/. The store is checked after the server has stopped, through a fresh read-only connection."""
from __future__ import annotations

import io
import re
import zipfile
from datetime import date, datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from study.store.store import Store
from study.webapp import SurveyServer, create_app
from tests.study.test_drive_import import make_drive
from tests.conftest import needs_chromium
from tests.e2e.test_webform_browser import SCALED, pick_by_click, wait_saved

SHOTS = Path(__file__).resolve().parents[1] / "output" / "console"
PASSWORD = "console pw for tests"
TODAY = date.today().isoformat()


def slot() -> str:
    """A bookable start (bookings in the past are refused): in ten minutes, local time, to the minute."""
    return f"{datetime.now() + timedelta(minutes=10):%Y-%m-%dT%H:%M}"

pytestmark = [
    pytest.mark.browser,
    needs_chromium,
]


@pytest.fixture
def served(paper_db):
    """(store path, running server); the server and its store are closed before the test reads the store."""
    st = Store.open(paper_db, actor="lab")
    srv = SurveyServer(create_app(st, PASSWORD), quiet=True).start()
    box = {"open": True}

    def stop():
        if box["open"]:
            srv.close()
            st.close()
            box["open"] = False
    yield paper_db, srv, stop
    stop()


def shot(page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"), full_page=True)


def flash(page, timeout: float = 30_000) -> str:
    """The page's message, once it has one: a click returns before the page its form leads to is complete."""
    shown = page.locator(".flash", has_text=re.compile(r"\S")).first
    shown.wait_for(timeout=timeout)                             # a selector's wait outlives a navigation
    return shown.inner_text()


def forget_flash(page) -> None:
    """Remove the shown message, so that waiting for one waits for the next page's."""
    page.evaluate("document.querySelectorAll('.flash').forEach(e => e.remove())")


def submit(page, selector: str) -> str:
    """Click `selector` and return the message of the page it leads to, never the one still shown."""
    forget_flash(page)
    page.click(selector)
    return flash(page)


def sign_in(browser, srv, name: str):
    page = browser.new_context(viewport={"width": 1280, "height": 900}, accept_downloads=True).new_page()
    page.goto(f"{srv.url}/r/today")
    page.fill("#name", name)
    page.fill("#password", PASSWORD)
    page.click("button[type=submit]")
    page.wait_for_selector(f"h1:has-text('Agenda of {TODAY}')")
    return page


def register(page, srv, pid: str, attrs: dict[str, str]) -> None:
    page.goto(f"{srv.url}/r/participants")
    page.fill("#participant_id", pid)
    for name, value in attrs.items():
        if page.locator(f"select#a-{name}").count():
            page.select_option(f"#a-{name}", value)
        else:
            page.fill(f"#a-{name}", value)
    assert submit(page, "#register-form button[type=submit]") == f"participant {pid} added"
    page.wait_for_selector(f"h1:has-text('Participant {pid}')")


def book(page, srv, pid: str, at: str, simulator: str) -> None:
    """Book on the agenda page; afterwards the page shows the agenda of the booked day."""
    page.goto(f"{srv.url}/r/today")
    page.select_option("#book-pid", pid)
    page.fill("#book-at", at)
    page.fill("#book-sim", simulator)
    assert submit(page, "#book-form button[type=submit]").startswith(f"{pid}: {simulator} booked {at.replace('T', ' ')}")


def start(page, srv, pid: str, phase: str) -> None:
    page.goto(f"{srv.url}/r/p/{pid}")
    msg = submit(page, "#start-btn")
    assert msg.startswith(f"{pid}: {phase} started"), msg
    assert page.get_attribute(f"tr[data-phase='{phase}']", "data-outcome") == "in_progress"


def upload(page, pid: str, condition: str, path: Path, force: str | None = None) -> str:
    page.select_option("#condition", condition)
    page.set_input_files("#file", str(path))
    if force:
        page.click("details summary")
        page.fill("#force", force)
    return submit(page, "#upload-form button[type=submit]")


def drive_file(tmp_path: Path, name: str, n: int, seed: int) -> Path:
    path = tmp_path / name
    make_drive(n, seed=seed).to_csv(path, index=False)
    return path


def fill_survey(browser, url: str, seed: int) -> None:
    """The participant's tablet: every question answered by clicks, then submitted."""
    page = browser.new_context(viewport={"width": 1024, "height": 768}).new_page()
    page.goto(url)
    page.fill("#in-AGE", str(30 + seed))
    page.get_by_label("Female", exact=True).check()
    page.fill("#in-LICENSE_YEARS", "10")
    page.get_by_label("Normal", exact=True).check()
    page.locator("#q-ECO_FAM input[value='3']").check()
    for k, item in enumerate(SCALED):
        pick_by_click(page, item, 1 + (k + seed) % 5)
    wait_saved(page)
    page.click("#submit-btn")
    page.wait_for_selector("text=Thank you!")
    page.context.close()


def issue_link(page, srv, pid: str, name: str | None = None) -> str:
    """Issue a link on the participant's page; the address shown, checked against what its QR code decodes to."""
    import zxingcpp
    from PIL import Image

    page.goto(f"{srv.url}/r/p/{pid}")
    page.click("#issue-link")
    page.wait_for_selector("#qr svg")
    if name:
        shot(page, name)
    url = page.inner_text("#survey-link").strip()
    codes = zxingcpp.read_barcodes(Image.open(io.BytesIO(page.locator("#qr").screenshot())))
    assert [c.text for c in codes] == [url]                  # the tablet's camera gets exactly this address
    return url


def read_store(db: Path, sql: str) -> pd.DataFrame:
    with Store.open(db, read_only=True) as st:
        return st.df(sql)


# ---------------------------------------------------------------------------------------------- one participant
def test_one_participant_from_registration_to_submitted_survey(browser, served, tmp_path):
    db, srv, stop = served
    page = sign_in(browser, srv, "Ann")
    shot(page, "01_today_empty")

    register(page, srv, "P001", {"age": "34", "gender": "female", "license_years": "12", "style": "normal",
                                  "eco_familiarity": "3"})
    page.goto(f"{srv.url}/r/participants")
    row = page.inner_text("tr[data-participant='P001']")
    assert "34" in row and "female" in row and "normal" in row
    shot(page, "02_participants")
    page.fill("#participant_id", "P001")                        # the same id again: refused, form kept
    assert submit(page, "#register-form button[type=submit]") == "participant P001 already exists"

    book(page, srv, "P001", slot(), "sim1")
    assert "booked" in page.inner_text("#agenda tr[data-participant='P001']")
    shot(page, "03_today_booked")

    logs = {"baseline": drive_file(tmp_path, "P001_baseline.csv", 60_000, 1),   # ~5 MB: progress is visible
            "pedas": drive_file(tmp_path, "P001_pedas.csv", 3_000, 2)}
    for phase in ("familiarisation", "baseline_drive"):
        start(page, srv, "P001", phase)
    shot(page, "04_participant_in_drive")
    # a slow network (1 MB/s up) so that the upload's progress bar can be seen and photographed
    cdp = page.context.new_cdp_session(page)
    cdp.send("Network.emulateNetworkConditions", {"offline": False, "latency": 20, "downloadThroughput": -1,
                                                  "uploadThroughput": 1_000_000})
    page.select_option("#condition", "baseline")
    page.set_input_files("#file", str(logs["baseline"]))
    forget_flash(page)
    page.click("#upload-form button[type=submit]")
    page.wait_for_selector(".upload-text:has-text('MB sent')")
    shot(page, "05_upload_progress")
    msg = flash(page, timeout=60_000)
    assert re.match(r"P001 baseline: imported drive \d+, 60000 samples", msg), msg
    cdp.send("Network.emulateNetworkConditions", {"offline": False, "latency": 0, "downloadThroughput": -1,
                                                  "uploadThroughput": -1})
    assert "60000 samples" in page.inner_text("li[data-condition='baseline']")
    assert "missing" in page.inner_text("li[data-condition='pedas']")
    for phase in ("pedas_intro", "practice", "pedas_drive"):
        start(page, srv, "P001", phase)
    assert upload(page, "P001", "pedas", logs["pedas"]).startswith("P001 pedas: imported drive")
    start(page, srv, "P001", "survey")
    shot(page, "06_participant_survey_phase")

    url = issue_link(page, srv, "P001", "07_link_qr")
    assert url.startswith(f"{srv.url}/s/")
    fill_survey(browser, url, seed=1)

    page.goto(f"{srv.url}/r/p/P001")
    assert page.get_attribute("#survey-basis", "data-basis") == "single"
    assert submit(page, "#end-btn") == "P001: survey completed"
    assert page.inner_text(".phase-buttons").strip() == "protocol finished"
    shot(page, "08_participant_finished")

    page.goto(f"{srv.url}/r/completeness")
    assert page.get_attribute("tr[data-participant='P001']", "data-complete") == "yes"
    shot(page, "09_completeness")
    page.goto(f"{srv.url}/r/")
    shot(page, "10_survey_status")
    page.goto(f"{srv.url}/r/discrepancies")
    shot(page, "11_discrepancies")

    page.goto(f"{srv.url}/r/export")
    shot(page, "12_export")
    page.check("input[name=format][value=csv]")
    with page.expect_download() as dl:
        page.click("#export-form button[type=submit]")
    download = dl.value
    assert re.fullmatch(rf"pedas_paper-csv-deidentified-{TODAY}\.zip", download.suggested_filename)
    with zipfile.ZipFile(io.BytesIO(Path(download.path()).read_bytes())) as z:
        names = set(z.namelist())
        participants = pd.read_csv(z.open("participants.csv"))
    assert {"manifest.json", "participants.csv", "drives.csv", "phase_events.csv"} <= names
    assert "audit_log.csv" not in names                               # de-identified: no audit log
    assert participants["participant_id"].tolist() == ["P001"]
    page.goto(f"{srv.url}/r/password")
    shot(page, "13_password")
    page.context.close()
    stop()

    events = read_store(db, "SELECT phase, started_at, ended_at, outcome FROM phase_events ORDER BY seq")
    assert events["phase"].tolist() == ["familiarisation", "baseline_drive", "pedas_intro", "practice",
                                        "pedas_drive", "survey"]
    assert (events["outcome"] == "completed").all()
    assert (events["ended_at"].iloc[:-1].to_numpy() == events["started_at"].iloc[1:].to_numpy()).all()
    drives = read_store(db, "SELECT condition, n_samples, file_name FROM drives ORDER BY condition")
    assert drives.values.tolist() == [["baseline", 60000, "P001_baseline.csv"], ["pedas", 3000, "P001_pedas.csv"]]
    actors = read_store(db, "SELECT DISTINCT actor FROM audit_log WHERE table_name IN "
                            "('participants', 'phase_events', 'drives', 'appointments')")["actor"].tolist()
    assert actors == ["Ann"]
    got = read_store(db, "SELECT item_id, value FROM responses WHERE participant_id = 'P001'").set_index("item_id")
    assert {i: int(got.loc[i, "value"]) for i in SCALED} == {i: 1 + (k + 1) % 5 for k, i in enumerate(SCALED)}


# ---------------------------------------------------------------------------------------------- two interleaved
def test_two_participants_interleaved(browser, served, tmp_path):
    db, srv, stop = served
    ann, ben = sign_in(browser, srv, "Ann"), sign_in(browser, srv, "Ben")   # two researchers, two simulators
    register(ann, srv, "P002", {"age": "41", "gender": "male"})
    register(ben, srv, "P003", {"age": "25", "style": "sporty"})
    at = slot()
    book(ann, srv, "P002", at, "sim1")
    book(ben, srv, "P003", at, "sim2")
    ann.goto(f"{srv.url}/r/today?date={at[:10]}")
    assert submit(ann, "#agenda tr[data-participant='P003'] button:has-text('Attended')") == \
        "P003: appointment attended"

    start(ann, srv, "P002", "familiarisation")
    start(ben, srv, "P003", "familiarisation")
    start(ann, srv, "P002", "baseline_drive")
    start(ben, srv, "P003", "baseline_drive")
    ann.goto(f"{srv.url}/r/today?date={at[:10]}")
    assert "baseline_drive" in ann.inner_text("#agenda tr[data-participant='P002']")
    shot(ann, "20_today_two_simulators")

    # P003: motion sickness in the baseline drive, aborted and excluded; the protocol is then closed
    ben.goto(f"{srv.url}/r/p/P003")
    ben.fill("#abort-reason", "motion sickness")
    assert submit(ben, "button:has-text('Abort baseline drive')") == "P003: baseline_drive aborted (motion sickness)"
    ben.select_option("#scope", "all")
    ben.select_option("#reason", "motion_sickness")
    ben.fill("#note", "stopped after 4 min")
    assert submit(ben, "#exclude-form button[type=submit]") == "P003: excluded (all, motion_sickness)"
    assert ben.locator("#start-btn").count() == 0               # the protocol is closed: no start button
    assert "protocol closed" in ben.inner_text(".phase-buttons")
    shot(ben, "21_participant_excluded")

    # P002: an implausible log (distance 10 times the integrated speed) is refused with the importer's message
    ann.goto(f"{srv.url}/r/p/P002")
    bad = make_drive(2_000, seed=3)
    bad["s"] = bad["s"] * 10
    bad_path = tmp_path / "P002_baseline_bad.csv"
    bad.to_csv(bad_path, index=False)
    msg = upload(ann, "P002", "baseline", bad_path)
    assert msg.startswith("P002_baseline_bad.csv:") and ann.locator(".flash.error").count() == 1
    shot(ann, "22_upload_refused")
    assert upload(ann, "P002", "baseline", drive_file(tmp_path, "P002_baseline.csv", 2_000, 4)).startswith(
        "P002 baseline: imported")
    for phase in ("pedas_intro", "practice", "pedas_drive"):
        start(ann, srv, "P002", phase)
    assert upload(ann, "P002", "pedas", drive_file(tmp_path, "P002_pedas.csv", 2_000, 5)).startswith(
        "P002 pedas: imported")
    start(ann, srv, "P002", "survey")

    # a link issued, revoked (the tablet then refuses it), issued again and used
    first = issue_link(ann, srv, "P002")
    ann.goto(f"{srv.url}/r/p/P002")
    assert submit(ann, "#revoke-link") == "P002: survey link revoked" and ann.inner_text("#link-status") == "revoked"
    tablet = browser.new_page()
    assert tablet.goto(first).status == 403
    tablet.close()
    fill_survey(browser, issue_link(ann, srv, "P002"), seed=2)
    ann.goto(f"{srv.url}/r/p/P002")
    ann.click("#end-btn")

    ben.goto(f"{srv.url}/r/completeness")
    assert ben.get_attribute("tr[data-participant='P002']", "data-complete") == "yes"
    p3 = ben.locator("tr[data-participant='P003']")
    assert p3.get_attribute("data-complete") == "yes" and "all" in p3.inner_text()   # excluded: nothing owed
    shot(ben, "23_completeness_two")
    ann.context.close()
    ben.context.close()
    stop()

    events = read_store(db, "SELECT participant_id, phase, outcome, started_at FROM phase_events ORDER BY started_at")
    order = [f"{r.participant_id}:{r.phase}" for r in events.itertuples()]
    assert order[:4] == ["P002:familiarisation", "P003:familiarisation", "P002:baseline_drive",
                         "P003:baseline_drive"]                   # interleaved, in the order the buttons were hit
    p3 = events[events["participant_id"] == "P003"].set_index("phase")["outcome"].to_dict()
    assert p3 == {"familiarisation": "completed", "baseline_drive": "aborted"}
    assert np.all(np.diff(events["started_at"].to_numpy()) > np.timedelta64(0))
    drives = read_store(db, "SELECT participant_id, condition, n_samples FROM drives ORDER BY condition")
    assert drives.values.tolist() == [["P002", "baseline", 2000], ["P002", "pedas", 2000]]
    excl = read_store(db, "SELECT participant_id, scope, reason, note FROM exclusions")
    assert excl.values.tolist() == [["P003", "all", "motion_sickness", "stopped after 4 min"]]
    appts = read_store(db, "SELECT participant_id, simulator, status FROM appointments ORDER BY participant_id")
    assert appts.values.tolist() == [["P002", "sim1", "booked"], ["P003", "sim2", "attended"]]
    who = read_store(db, "SELECT actor, count(*) AS n FROM audit_log WHERE table_name = 'exclusions' GROUP BY actor")
    assert who.values.tolist() == [["Ben", 1]]

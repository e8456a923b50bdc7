"""Questionnaire occasions in the web app, in Debian's headless Chromium through Playwright: the within-subjects
takeover study (studies/takeover, the same post-drive questionnaire after each condition drive). A participant is
registered in the console and walked through the protocol by the CLI; the console's participant page lists one row
per questionnaire phase with the condition it rates, issues the links of two occasions (each link page says which),
a new link of one occasion revokes only that occasion's earlier link; the tablet answers each occasion's form (Likert
items by clicks, the NASA-TLX sliders by keyboard), which is headed by the drive it rates. The store then holds each
occasion's answers under its own occasion, and answering the second left the first's rows as they were.

Screenshots in tests/output/: occasions_console_links.png (the participant page while occasion 1 is answered and
occasion 2's link is out), occasions_console.png (both answered), occasions_link.png (the link page of occasion 2),
occasions_form_2_top.png and occasions_form_2.png (occasion 2's form: its heading; a slider set)."""
from __future__ import annotations

import pandas as pd
import pytest

from study.store.store import Store
from study.webapp import SurveyServer, create_app
from tests.conftest import OUTPUT, REPO, needs_chromium
from tests.e2e.test_console_browser import flash, register, sign_in
from tests.e2e.test_webform_browser import wait_saved

STUDY = REPO / "studies" / "takeover"
PID = "TOR-A01"
PASSWORD = "console pw for tests"   # sign_in's
OCC1, OCC2 = "survey_after_none", "survey_after_visual"
SUS = [f"sus{k}" for k in range(1, 11)]
TLX = ["tlx_mental", "tlx_physical", "tlx_temporal", "tlx_performance", "tlx_effort", "tlx_frustration"]
TRUST = [f"trust{k}" for k in range(1, 7)]

pytestmark = [pytest.mark.browser, needs_chromium]


def answers(seed: int) -> dict[str, int]:
    """The answers given at one occasion: SUS 1..5, TLX 0..100 in steps of 5, trust 1..7 (different per seed)."""
    out = {item: 1 + (k + seed) % 5 for k, item in enumerate(SUS)}
    out |= {item: 5 * ((3 * k + 7 * seed) % 21) for k, item in enumerate(TLX)}
    out |= {item: 1 + (2 * k + seed) % 7 for k, item in enumerate(TRUST)}
    return out


def cli(db, *args) -> None:
    from pedas_study.cli import main

    assert main([f"--db={db}", *map(str, args)]) == 0, args


@pytest.fixture
def served(tmp_db):
    """(store path, running server over a fresh takeover store); the server is closed before the test reads."""
    cli(tmp_db, "init", "--study", STUDY)
    st = Store.open(tmp_db, actor="lab")
    srv = SurveyServer(create_app(st, PASSWORD), quiet=True).start()
    st.close()   # the app opens the store's file itself for each request
    box = {"open": True}

    def stop():
        if box["open"]:
            srv.close()
            box["open"] = False
    yield tmp_db, srv, stop
    stop()


def row(page, occasion: str):
    return page.locator(f"#occasion-table tr[data-occasion='{occasion}']")


def issue(page, srv, occasion: str) -> str:
    """Press the occasion's issue button on the participant page; the link page's URL."""
    page.goto(f"{srv.url}/r/p/{PID}")
    page.click(f"button[data-issue='{occasion}']")
    page.wait_for_selector("#survey-link")
    assert page.get_attribute("#link-occasion", "data-occasion") == occasion
    return page.inner_text("#survey-link").strip()


def set_slider(page, item: str, value: int) -> None:
    """The keyboard: Home = 0, then one ArrowRight per step of 5 (the codebook's step)."""
    page.focus(f"#range-{item}")
    page.keyboard.press("Home")
    for _ in range(value // 5):
        page.keyboard.press("ArrowRight")


def answer_form(page, want: dict[str, int]) -> None:
    for item in SUS + TRUST:
        page.click(f"#q-{item} label.point:nth-of-type({want[item]})")
    for item in TLX:
        set_slider(page, item, want[item])
    wait_saved(page)
    assert page.inner_text("#progress") == "22 of 22 questions answered."


def statuses(page, srv) -> dict[str, str]:
    """occasion -> the status its row on the participant page shows."""
    page.goto(f"{srv.url}/r/p/{PID}")
    rows = page.locator("#occasion-table tbody tr")
    return {rows.nth(k).get_attribute("data-occasion"): rows.nth(k).get_attribute("data-status")
            for k in range(rows.count())}


def occasion_rows(srv, occasion: str) -> tuple:
    """Every stored row of one occasion (responses, submissions, drafts, links), read under the app's lock."""
    with srv.app.extensions["survey"]["lock"] as h:
        return tuple(h.store.df(f"SELECT * FROM {t} WHERE occasion = ? ORDER BY ALL", [occasion]).to_dict("records")
                     for t in ("responses", "survey_submissions", "survey_drafts", "survey_tokens"))


def stored(db) -> pd.DataFrame:
    """Every stored answer with its submission (a fresh read-only connection, the server stopped)."""
    with Store.open(db, read_only=True) as st:
        return st.df("SELECT r.occasion, r.item_id, r.value, r.entry_round, r.entered_by, s.submitted_at "
                      "FROM responses r JOIN survey_submissions s USING (participant_id, instrument, occasion, "
                      "entry_round) WHERE r.participant_id = ? ORDER BY r.occasion, r.item_id", [PID])


def test_two_occasions_get_their_own_links_forms_and_answers(browser, served):
    db, srv, stop = served
    page = sign_in(browser, srv, "Ann")
    register(page, srv, PID, {"age": "31"})
    cli(db, "session", "assign", PID)                 # the first of the Latin square's orders: none, visual, audiovisual
    for phase in ("familiarisation", "drive_none", OCC1, "drive_visual", OCC2):
        cli(db, "session", "advance", PID, phase)

    # the participant page: the three questionnaire phases in the participant's order, each with its condition
    page.goto(f"{srv.url}/r/p/{PID}")
    rows = page.locator("#occasion-table tbody tr")
    assert [rows.nth(k).get_attribute("data-occasion") for k in range(rows.count())] == [
        OCC1, OCC2, "survey_after_audiovisual"]
    assert row(page, OCC1).locator("td").nth(0).inner_text() == "No takeover warning (the automation only switches off)"
    assert row(page, OCC2).locator("td").nth(0).inner_text() == "Visual takeover warning"
    assert "now" in row(page, OCC2).locator("th").inner_text()        # the phase the participant is in
    assert all(rows.nth(k).get_attribute("data-status") == "not started" for k in range(3))

    first = issue(page, srv, OCC1)
    assert "rating the drive with No takeover warning" in page.inner_text("#link-occasion")
    second = issue(page, srv, OCC2)
    assert "rating the drive with Visual takeover warning" in page.inner_text("#link-occasion")
    OUTPUT.mkdir(exist_ok=True)
    page.screenshot(path=str(OUTPUT / "occasions_link.png"), full_page=True)
    assert first != second

    tablet = browser.new_context(viewport={"width": 1024, "height": 768}).new_page()
    tablet.goto(first)                                 # occasion 2's link did not revoke occasion 1's
    assert tablet.inner_text("#occasion-heading") == ("After the drive with: No takeover warning (the automation "
                                                      "only switches off)")
    again = issue(page, srv, OCC1)                     # a new link of occasion 1 revokes only occasion 1's
    assert tablet.goto(first).status == 403
    assert "withdrawn" not in tablet.content() and "replaced by a newer one" in tablet.content()
    assert tablet.goto(second).status == 200

    # occasion 1 answered and submitted on its (new) link
    one = answers(1)
    tablet.goto(again)
    answer_form(tablet, one)
    assert statuses(page, srv) == {OCC1: "draft", OCC2: "link issued", "survey_after_audiovisual": "not started"}
    assert "22 answers saved" in row(page, OCC1).inner_text()
    page.screenshot(path=str(OUTPUT / "occasions_console_links.png"), full_page=True)
    tablet.click("#submit-btn")
    tablet.wait_for_selector("text=Thank you!")
    assert "No takeover warning" in tablet.inner_text("#occasion-done")
    assert statuses(page, srv) == {OCC1: "final", OCC2: "link issued", "survey_after_audiovisual": "not started"}
    snapshot = occasion_rows(srv, OCC1)
    assert len(snapshot[0]) == 22 and len(snapshot[1]) == 1 and not snapshot[2]

    # occasion 2: its own heading, an empty form (occasion 1's answers are not shown), a slider set by keyboard
    two = answers(2)
    tablet.goto(second)
    assert tablet.inner_text("#occasion-heading") == "After the drive with: Visual takeover warning"
    assert tablet.input_value("#in-tlx_mental") == "" and tablet.locator("input[type=radio]:checked").count() == 0
    answer_form(tablet, {**two, "tlx_mental": 0})      # first 0 ...
    set_slider(tablet, "tlx_mental", two["tlx_mental"])   # ... then moved: the last value counts
    wait_saved(tablet)
    assert tablet.input_value("#in-tlx_mental") == str(two["tlx_mental"])
    tablet.locator("#q-tlx_mental").scroll_into_view_if_needed()
    tablet.evaluate("window.scrollTo(0, 0)")
    tablet.screenshot(path=str(OUTPUT / "occasions_form_2_top.png"))
    tablet.evaluate("window.scrollTo(0, document.getElementById('q-tlx_mental').offsetTop - 260)")
    tablet.screenshot(path=str(OUTPUT / "occasions_form_2.png"))
    tablet.click("#submit-btn")
    tablet.wait_for_selector("text=Thank you!")
    assert "Visual takeover warning" in tablet.inner_text("#occasion-done")

    assert occasion_rows(srv, OCC1) == snapshot           # answering occasion 2 left occasion 1 as it was
    assert statuses(page, srv) == {OCC1: "final", OCC2: "final", "survey_after_audiovisual": "not started"}
    assert row(page, OCC1).locator("button").count() == 0            # answered: no new link for that occasion
    assert row(page, "survey_after_audiovisual").locator("button[data-issue]").count() == 1
    page.screenshot(path=str(OUTPUT / "occasions_console.png"), full_page=True)
    tablet.context.close()
    page.context.close()
    stop()

    got = stored(db)
    assert set(got["occasion"]) == {OCC1, OCC2}
    assert (got["entry_round"] == 1).all() and (got["entered_by"] == "participant").all()
    for occasion, want in ((OCC1, one), (OCC2, two)):
        mine = got[got["occasion"] == occasion].set_index("item_id")["value"]
        assert mine.astype(int).to_dict() == want, occasion
    # occasion 1's rows were written once, at its submission, before occasion 2 was submitted
    times = got.groupby("occasion")["submitted_at"].agg(["min", "max"])
    assert times.loc[OCC1, "min"] == times.loc[OCC1, "max"] < times.loc[OCC2, "min"]

"""The survey form in Debian's headless Chromium driven by Playwright (never a downloaded browser): a participant
fills the whole form by mouse and keyboard, reloads midway, submits; a second link cannot see the first
participant's answers; paper forms typed in twice with one deliberate discrepancy, detected and resolved; the
lane-keeping study's 7-point form filled and submitted."""
from __future__ import annotations


import pytest

from study.survey import answers as sv
from study.folder.definition import load
from study.people.participants import add_participant, participant_attributes
from study.store.store import Store
from study.webapp import SurveyServer, create_app
from tests.conftest import LK_STUDY, OUTPUT, PAPER_STUDY, needs_chromium

INS = load(PAPER_STUDY).instrument()
SCALED = INS.scaled_items
PASSWORD = "pw for tests"

pytestmark = [
    pytest.mark.browser,
    needs_chromium,
]


def serve(db, participants: dict[str, dict]):
    """(store, running server, the app's store lock) of the study store `db` with `participants` added."""
    st = Store.open(db, actor="lab")
    for pid, attributes in participants.items():
        add_participant(st, pid, attributes=attributes)
    srv = SurveyServer(create_app(st, PASSWORD), quiet=True).start()
    return st, srv, srv.app.extensions["survey"]["lock"]


@pytest.fixture
def served(paper_db):
    st, srv, lock = serve(paper_db, {"P001": {}, "P002": {}, "P003": {}})
    yield st, srv, lock
    srv.close()
    st.close()


@pytest.fixture
def served_lk(lk_db):
    st, srv, lock = serve(lk_db, {"LK-07": {"age": 52, "gender": "female"}})
    yield st, srv, lock
    srv.close()
    st.close()


def wait_saved(page) -> None:
    """Wait until every answer POST of the page has come back and was accepted."""
    from playwright.sync_api import expect

    # a selector wait, not wait_for_function: the app's Content-Security-Policy forbids eval
    expect(page.locator("#save-status")).to_have_attribute("data-pending", "0", timeout=30_000)
    assert "Not saved" not in page.inner_text("#save-msg")


def target(seed: int) -> dict[str, int]:
    return {item: 1 + (k * 3 + seed) % 5 for k, item in enumerate(SCALED)}


def pick_by_click(page, item: str, value: int) -> None:
    page.click(f"#q-{item} label.point:nth-of-type({value})")


def pick_by_keyboard(page, item: str, value: int) -> None:
    """Focus the group's first radio and move with the arrow keys (native radio group behaviour)."""
    page.focus(f"#q-{item} input[value='1']")
    page.keyboard.press("Space")
    for _ in range(value - 1):
        page.keyboard.press("ArrowRight")


def checked_values(page) -> dict[str, int]:
    return page.evaluate("""() => Object.fromEntries([...document.querySelectorAll('input[type=radio]:checked')]
                            .map(e => [e.name, Number(e.value)]))""")


def test_participant_fills_reloads_and_submits(browser, served):
    st, srv, lock = served
    with lock:
        token = sv.issue_link(st, "P001")
    want = target(1)
    ctx = browser.new_context(viewport={"width": 1024, "height": 768})
    page = ctx.new_page()
    page.goto(f"{srv.url}/s/{token}")
    assert page.title().startswith("Questionnaire")

    page.fill("#in-AGE", "34")
    page.get_by_label("Male", exact=True).check()
    page.fill("#in-LICENSE_YEARS", "12")
    page.get_by_label("Normal", exact=True).check()
    page.get_by_label(INS.choices("ECO_FAM")[2]).check()
    half = SCALED[:12]
    for k, item in enumerate(half):
        (pick_by_keyboard if k % 2 else pick_by_click)(page, item, want[item])
    wait_saved(page)
    page.locator("#sec-2").scroll_into_view_if_needed()
    OUTPUT.mkdir(exist_ok=True)
    page.evaluate("window.scrollTo(0, document.getElementById('sec-2').offsetTop - 8)")
    page.screenshot(path=str(OUTPUT / "survey_form_1024x768.png"))

    page.reload()                                                   # a reload resumes where it was
    assert checked_values(page) == {**{i: want[i] for i in half}, "GENDER": 2, "STYLE": 2, "ECO_FAM": 2}
    assert page.input_value("#in-AGE") == "34" and page.input_value("#in-LICENSE_YEARS") == "12"
    other = browser.new_context(viewport={"width": 768, "height": 1024}).new_page()   # a fresh tablet, same link
    other.goto(f"{srv.url}/s/{token}")
    assert checked_values(other) == checked_values(page)
    other.screenshot(path=str(OUTPUT / "survey_form_768x1024.png"))
    other.context.close()

    for k, item in enumerate(SCALED[12:]):
        (pick_by_keyboard if k % 2 else pick_by_click)(page, item, want[item])
    page.fill("#in-Q1", "The arrow is easy to see.")
    page.locator("#in-Q3").press_sequentially("Navigation hints, please.")
    wait_saved(page)
    assert page.inner_text("#progress") == "30 of 30 questions answered."
    page.click("#submit-btn")
    page.wait_for_selector("text=Thank you!")
    page.reload()
    assert page.locator("input").count() == 0                         # read-only after submission
    ctx.close()

    with lock:
        got = st.df("SELECT item_id, value, text, entry_round FROM responses WHERE participant_id = 'P001'")
        part = participant_attributes(st, ["P001"]).iloc[0].tolist()[1:]
    got = got.set_index("item_id")
    assert {i: int(got.loc[i, "value"]) for i in SCALED} == want     # the store holds exactly what was clicked
    assert got.loc["Q1", "text"] == "The arrow is easy to see." and got.loc["Q3", "text"] == "Navigation hints, please."
    assert got["text"].isna()["Q2"] and set(got["entry_round"]) == {1}
    assert part == [34, "male", 12, "normal", 2]


def test_second_link_cannot_see_first_participants_page(browser, served):
    st, srv, lock = served
    with lock:
        t1, t2 = sv.issue_link(st, "P001"), sv.issue_link(st, "P002")
    page = browser.new_page()
    page.goto(f"{srv.url}/s/{t1}")
    pick_by_click(page, "PU1", 5)
    page.fill("#in-AGE", "50")
    page.fill("#in-Q1", "private remark")
    page.locator("#in-Q1").blur()
    wait_saved(page)
    page.goto(f"{srv.url}/s/{t2}")
    assert checked_values(page) == {} and page.input_value("#in-AGE") == "" and page.input_value("#in-Q1") == ""
    assert "private remark" not in page.content()
    tampered = t1[:-3] + ("abc" if t1[-3:] != "abc" else "abd")
    with lock:
        before = st.counts()
    resp = page.goto(f"{srv.url}/s/{tampered}")
    assert resp.status == 404 and "This survey link is not valid" in page.inner_text("main")
    with lock:
        assert st.counts() == before
    page.close()


def test_fast_changes_to_one_item_are_stored_in_the_order_given(browser, served):
    """Arrow keys fire one change per step; the server must end up with the last one even when an earlier
    request is slow (here: the answer "2" is held back 0.6 s, so it would arrive after "3" and "4")."""
    import time

    from flask import request

    st, srv, lock = served

    @srv.app.before_request
    def hold_back_two():
        if request.path.endswith("/answer") and request.form.get("value") == "2":
            time.sleep(0.6)

    with lock:
        token = sv.issue_link(st, "P002")
    page = browser.new_page(viewport={"width": 1024, "height": 768})
    page.goto(f"{srv.url}/s/{token}")
    pick_by_keyboard(page, "PU1", 4)                                  # 1, 2, 3, 4 in quick succession
    wait_saved(page)
    with lock:
        assert sv.draft(st, "P002")["PU1"].value == 4
    page.reload()
    assert checked_values(page)["PU1"] == 4
    page.close()


def test_keyboard_focus_is_visible(browser, served):
    st, srv, lock = served
    with lock:
        token = sv.issue_link(st, "P003")
    page = browser.new_page(viewport={"width": 1024, "height": 768})
    page.goto(f"{srv.url}/s/{token}")
    page.keyboard.press("Tab")                                        # skip link first
    assert page.evaluate("document.activeElement.className") == "skip-link"
    page.keyboard.press("Tab")
    assert page.evaluate("document.activeElement.id") == "in-AGE"
    page.keyboard.press("Tab")                                        # into the gender radio group
    page.keyboard.press("ArrowDown")
    name = page.evaluate("document.activeElement.name + '=' + document.activeElement.value")
    assert name == "GENDER=2"
    outline = page.evaluate("getComputedStyle(document.activeElement.closest('label')).outlineStyle")
    assert outline == "solid"
    page.close()


def type_entry(page, values: dict[str, str]) -> None:
    for item, v in values.items():
        page.fill(f"#e-{item}", v)


def test_double_entry_discrepancy_detected_and_resolved(browser, served):
    st, srv, lock = served
    paper = {i: str(v) for i, v in target(4).items()}
    paper["Q2"] = "too late warnings"

    def signed_in(name):
        page = browser.new_context().new_page()
        page.goto(f"{srv.url}/r/")
        page.fill("#name", name)
        page.fill("#password", PASSWORD)
        page.click("button[type=submit]")
        page.wait_for_selector("h1:has-text('Survey status')")
        return page

    ann = signed_in("Ann")
    ann.click("#row-P003 a:has-text('Paper entry 1')")
    type_entry(ann, paper)
    ann.click("button:has-text('Save entry 1')")
    ann.wait_for_selector("#row-P003")

    ben = signed_in("Ben")
    ben.click("#row-P003 a:has-text('Paper entry 2')")
    assert ben.input_value("#e-PU1") == ""                           # blind second entry
    typo = dict(paper, ATT4=str(paper["ATT4"] == "1" and 2 or 1))     # the deliberate discrepancy
    type_entry(ben, typo)
    ben.click("button:has-text('Save entry 2')")
    ben.wait_for_selector("#row-P003")
    assert "unresolved" in ben.inner_text("#row-P003")

    ann.goto(f"{srv.url}/r/discrepancies")
    rows = ann.locator("#discrepancies tbody tr[data-item]")
    assert rows.count() == 1 and rows.first.get_attribute("data-item") == "ATT4"
    rows.first.locator("input[name=value]").fill(paper["ATT4"])
    rows.first.locator("input[name=note]").fill("checked the paper form")
    rows.first.locator("button").click()
    ann.wait_for_selector("#discrepancies .badge.ok")
    ann.goto(f"{srv.url}/r/")
    assert "final" in ann.inner_text("#row-P003")
    with lock:
        final = sv.final_responses(st).set_index("participant_id")
        actors = st.df("SELECT DISTINCT actor FROM audit_log WHERE table_name = 'responses'")["actor"].tolist()
    assert {i: str(int(final.loc["P003", i])) for i in SCALED} == {i: paper[i] for i in SCALED}
    assert final.loc["P003", "Q2"] == "too late warnings"
    assert sorted(actors) == ["Ann", "Ben"]
    ann.context.close()
    ben.context.close()


def test_seven_point_form_of_another_study(browser, served_lk):
    """studies/lane_keeping: 12 items on 7-point scales (EE3 reverse-coded, stored as ticked), age and gender as
    attribute items; filled by mouse and keyboard in Chromium, submitted, and the store holds what was ticked."""
    st, srv, lock = served_lk
    study = load(LK_STUDY)
    ins = study.instrument()
    with lock:
        token = sv.issue_link(st, "LK-07")
    want = {item: 1 + (k * 5 + 2) % 7 for k, item in enumerate(ins.scaled_items)}
    assert set(want.values()) == set(range(1, 8))                      # every point of the scale is used
    page = browser.new_page(viewport={"width": 1024, "height": 768})
    page.goto(f"{srv.url}/s/{token}")
    assert page.inner_text("h1") == study.title
    for item in ins.scaled_items:
        assert page.locator(f"#q-{item} input[type=radio]").count() == 7
    page.fill("#in-AGE", "53")                                          # replaces the recorded 52
    page.get_by_label("Diverse", exact=True).check()
    for k, item in enumerate(ins.scaled_items):
        (pick_by_keyboard if k % 2 else pick_by_click)(page, item, want[item])
    page.fill("#in-REMARKS", "The lane bar is easy to read.")
    wait_saved(page)
    OUTPUT.mkdir(exist_ok=True)
    page.screenshot(path=str(OUTPUT / "survey_form_lane_keeping_1024x768.png"))
    assert page.inner_text("#progress") == "13 of 13 questions answered."
    page.click("#submit-btn")
    page.wait_for_selector("text=Thank you!")
    page.close()
    with lock:
        got = st.df("SELECT item_id, value, text FROM responses WHERE participant_id = 'LK-07'").set_index("item_id")
        attrs = participant_attributes(st, ["LK-07"]).iloc[0]
        final = sv.final_responses(st).set_index("participant_id")
    assert {i: int(got.loc[i, "value"]) for i in ins.scaled_items} == want
    assert got.loc["REMARKS", "text"] == "The lane bar is easy to read."
    assert (attrs["age"], attrs["gender"]) == (53, "diverse")
    assert final.loc["LK-07", "EE3"] == want["EE3"]                    # raw, not reversed
    assert final.loc["LK-07", ["AGE", "GENDER"]].tolist() == [53, 3]

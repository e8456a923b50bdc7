"""The slider (visual analogue scale) of the survey form in Debian's headless Chromium through Playwright: set by
keyboard and by mouse, an untouched slider is not answered, a reload shows the saved values, the submission stores
exactly them. Screenshots: tests/output/survey_slider_*.png."""
from __future__ import annotations

import pytest

from pedas_study.cli import main
from study.survey import answers as sv
from study.people.participants import add_participant
from study.store.store import Store
from study.webapp import SurveyServer, create_app
from tests.conftest import OUTPUT, needs_chromium
from tests.study.test_slider import slider_study

pytestmark = [pytest.mark.browser, needs_chromium]
LIKERT = ["PU1", "PU2", "PU3", "EOU1", "EOU2", "EOU3", "BI1", "BI2", "BI3"]


@pytest.fixture
def served(tmp_path):
    db = tmp_path / "s.duckdb"
    assert main([f"--db={db}", "init", "--study", str(slider_study(tmp_path / "sliders"))]) == 0
    st = Store.open(db, actor="lab")
    add_participant(st, "P001", {"age": 30, "gender": "female", "license_years": 5})
    srv = SurveyServer(create_app(st, "pw for tests"), quiet=True).start()
    yield st, srv, srv.app.extensions["survey"]["lock"]
    srv.close()
    st.close()


def form_page(browser, served, width: int, height: int):
    """A new page of a `width` x `height` browser window showing the form of a new survey link of P001."""
    st, srv, lock = served
    with lock:
        token = sv.issue_link(st, "P001")
    page = browser.new_context(viewport={"width": width, "height": height}).new_page()
    page.goto(f"{srv.url}/s/{token}")
    return page


def wait_saved(page) -> None:
    from playwright.sync_api import expect

    expect(page.locator("#save-status")).to_have_attribute("data-pending", "0", timeout=30_000)
    assert "Not saved" not in page.inner_text("#save-msg")


def test_slider_by_keyboard_and_mouse_is_stored(browser, served):
    st, _, lock = served
    page = form_page(browser, served, 1024, 768)
    OUTPUT.mkdir(exist_ok=True)
    section = page.locator("#q-TLX_MD").locator("xpath=ancestor::section")
    assert page.is_visible("#range-TLX_MD") and page.input_value("#in-TLX_MD") == ""   # untouched: not answered
    assert page.locator("#q-TLX_MD .slider").get_attribute("class") == "slider unset"
    section.screenshot(path=str(OUTPUT / "survey_slider_unset.png"))

    page.focus("#range-TLX_MD")                       # keyboard: Home = 0, then 7 steps of 5 to the right
    page.keyboard.press("Home")
    for _ in range(7):
        page.keyboard.press("ArrowRight")
    wait_saved(page)
    assert page.input_value("#in-TLX_MD") == "35"

    box = page.locator("#range-VAS").bounding_box()   # mouse: a click at three quarters of the track
    page.mouse.click(box["x"] + 0.75 * box["width"], box["y"] + box["height"] / 2)
    wait_saved(page)
    vas = int(page.input_value("#in-VAS"))
    assert 70 <= vas <= 80                            # where the thumb lands depends on the thumb's width

    for k, item in enumerate(LIKERT):
        page.click(f"#q-{item} label.point:nth-of-type({1 + k % 5})")
    wait_saved(page)
    page.focus("#range-TLX_MD")
    section.screenshot(path=str(OUTPUT / "survey_slider_set.png"))

    page.reload()                                     # the saved values come back
    assert page.input_value("#in-TLX_MD") == "35" and page.input_value("#range-TLX_MD") == "35"
    assert page.input_value("#in-VAS") == str(vas)
    page.click("#submit-btn")
    page.wait_for_selector("text=Thank you!")
    page.context.close()
    with lock:
        got = st.df("SELECT item_id, value FROM responses WHERE participant_id = 'P001'").set_index("item_id")
    assert int(got.loc["TLX_MD", "value"]) == 35 and int(got.loc["VAS", "value"]) == vas
    assert [int(got.loc[i, "value"]) for i in LIKERT] == [1 + k % 5 for k in range(len(LIKERT))]


def test_an_untouched_required_slider_blocks_submission(browser, served):
    st, _, lock = served
    page = form_page(browser, served, 768, 1024)
    for k, item in enumerate(LIKERT):
        page.click(f"#q-{item} label.point:nth-of-type({1 + k % 5})")
    wait_saved(page)
    page.click("#submit-btn")
    page.wait_for_selector("#error-summary")
    assert "How mentally demanding was the drive?" in page.inner_text("#error-summary")
    assert page.locator("#q-TLX_MD.invalid").count() == 1
    page.locator("#q-TLX_MD").scroll_into_view_if_needed()
    page.locator("#q-TLX_MD").locator("xpath=ancestor::section").screenshot(
        path=str(OUTPUT / "survey_slider_required_768x1024.png"))
    page.context.close()
    with lock:
        assert st.df("SELECT count(*) AS n FROM responses")["n"].item() == 0

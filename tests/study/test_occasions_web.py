"""Questionnaire occasions in the web app over HTTP (Flask's test client on a real store of studies/takeover, the
same post-drive questionnaire after each of three condition drives): the console's participant page has one row
per questionnaire phase with its rated condition and status; a link is issued per occasion and a new one revokes
only its own occasion's earlier link; a bad occasion is refused in one line with the store unchanged; paper double
entry, the discrepancy report and its resolution carry the occasion; the form is headed by the drive it rates. The
paper's study (one occasion) keeps its pages: no occasion table, no heading, the same link page."""
from __future__ import annotations

import html as html_text
import re

import pytest

from study.survey import answers as sv
from study.people.participants import add_participant
from study.people.orders import assign_order
from study.people.protocol import advance
from study.store.store import Store
from study.webapp import create_app
from tests.conftest import REPO
from tests.study.test_console import flashed, snapshot
from tests.study.test_survey_web import login

PASSWORD = "correct horse"
STUDY = REPO / "studies" / "takeover"
OCC = ["survey_after_none", "survey_after_visual", "survey_after_audiovisual"]
ITEMS = [*(f"sus{k}" for k in range(1, 11)), "tlx_mental", "tlx_physical", "tlx_temporal", "tlx_performance",
         "tlx_effort", "tlx_frustration", *(f"trust{k}" for k in range(1, 7))]


@pytest.fixture
def tor(tmp_db):
    from pedas_study.cli import main

    assert main([f"--db={tmp_db}", "init", "--study", str(STUDY)]) == 0
    st = Store.open(tmp_db, actor="lab")
    for pid in ("TOR-A01", "TOR-A02"):
        add_participant(st, pid, attributes={"age": 30})
        assign_order(st, pid)
    for phase in ("familiarisation", "drive_none", "survey_after_none"):   # TOR-A01 answers the first questionnaire
        advance(st, "TOR-A01", phase)
    yield st
    st.close()


@pytest.fixture
def console_store(tor):
    """The store the console client (tests/conftest.py) signs in to: the takeover study's, not the paper's."""
    return tor


@pytest.fixture
def client(console_client):
    return console_client


def rows(html: str) -> list[tuple[str, str]]:
    """(occasion, status) of each row of the participant page's questionnaire table."""
    return re.findall(r'<tr id="occ-[^"]+" data-occasion="([^"]+)" data-status="([^"]+)"', html)


def issue(client, pid: str, occasion: str | None) -> str:
    r = client.post("/r/link", data={"participant_id": pid, "csrf": client.csrf,
                                      **({"occasion": occasion} if occasion else {})})
    assert r.status_code == 200, r.get_data(as_text=True)
    return re.search(r'<code class="link" id="survey-link">http://[^/]+(/s/[^<]+)</code>', r.get_data(as_text=True))[1]


def test_the_participant_page_lists_each_occasion_with_its_condition_and_status(client):
    html = client.get("/r/p/TOR-A01").get_data(as_text=True)
    assert rows(html) == [(o, "not started") for o in OCC]
    assert 'id="link-status"' not in html                       # the one-occasion card is not shown
    table = html[html.index('id="occasion-table"'):]
    assert "No takeover warning (the automation only switches off)" in table and "Visual takeover warning" in table
    assert re.search(r'data-occasion="survey_after_none"[^>]*class="current"', html)   # the phase in progress
    issue(client, "TOR-A01", "survey_after_visual")
    assert rows(client.get("/r/p/TOR-A01").get_data(as_text=True))[1] == ("survey_after_visual", "link issued")


def test_one_link_per_occasion_a_new_one_revokes_only_its_own(tor, client):
    first = issue(client, "TOR-A01", None)                      # no occasion: the questionnaire phase TOR-A01 is in
    r = client.post("/r/link", data={"participant_id": "TOR-A01", "occasion": "survey_after_visual",
                                     "csrf": client.csrf})
    page = r.get_data(as_text=True)
    assert 'data-occasion="survey_after_visual"' in page and "rating the drive with <strong>Visual takeover" in page
    second = re.search(r'id="survey-link">http://[^/]+(/s/[^<]+)<', page)[1]
    assert client.get(first).status_code == 200 and client.get(second).status_code == 200
    again = issue(client, "TOR-A01", "survey_after_none")
    assert client.get(first).status_code == 403 and client.get(second).status_code == 200
    assert client.get(again).status_code == 200
    links = tor.df("SELECT occasion, revoked_at IS NULL AS active FROM survey_tokens ORDER BY issued_at")
    assert links.values.tolist() == [["survey_after_none", False], ["survey_after_visual", True],
                                     ["survey_after_none", True]]
    # the form names the drive it rates; the paper study's form has no such heading (other test)
    assert ("After the drive with: No takeover warning (the automation only switches off)"
            in html_text.unescape(client.get(again).get_data(as_text=True)))
    assert "After the drive with: Visual takeover warning" in client.get(second).get_data(as_text=True)
    client.post("/r/p/TOR-A01/link/revoke", data={"occasion": "survey_after_visual", "csrf": client.csrf})
    assert flashed(client) == ["TOR-A01: survey link of survey_after_visual revoked"]
    assert client.get(second).status_code == 403 and client.get(again).status_code == 200


BAD = [  # (path, form or query, status, the one line shown)
    ("/r/link", {"participant_id": "TOR-A02"}, 400,
     "instrument post_drive_v1 is answered on 3 occasions (survey_after_none, survey_after_visual, "
     "survey_after_audiovisual): name one with --occasion"),
    ("/r/link", {"participant_id": "TOR-A01", "occasion": "drive_none"}, 400,
     "unknown questionnaire phase 'drive_none' (the study's: survey_after_none, survey_after_visual, "
     "survey_after_audiovisual)"),
    ("/r/link", {"participant_id": "TOR-A01", "occasion": "x" * 70_000}, 400,
     "unknown questionnaire phase (the study's: survey_after_none, survey_after_visual, survey_after_audiovisual)"),
    ("/r/link", {"participant_id": "TOR-A01", "occasion": "survey\r\nX: 1"}, 400, "unknown questionnaire phase (the"),
    ("/r/resolve", {"participant_id": "TOR-A01", "item_id": "sus1", "value": "3", "occasion": "nope"}, 400,
     "unknown questionnaire phase 'nope'"),
    ("/r/resolve", {"participant_id": "TOR-A01", "item_id": "sus1", "value": "3", "occasion": "survey_after_none"},
     400, "TOR-A01 sus1: no discrepancy between the two entries to resolve at survey_after_none"),
]


@pytest.mark.parametrize("path, form, status, text", BAD, ids=[f"{p} {t[:28]}" for p, _, _, t in BAD])
def test_a_bad_occasion_is_refused_in_one_line_and_stores_nothing(tor, client, path, form, status, text):
    before = snapshot(tor)
    r = client.post(path, data={**form, "csrf": client.csrf})
    page = html_text.unescape(r.get_data(as_text=True))
    assert r.status_code == status
    shown = re.search(r"<p>([^<]*)</p>", page[page.index("<main"):])[1]
    assert text in shown and "\n" not in shown and len(shown) < 300, shown
    assert snapshot(tor) == before


@pytest.mark.parametrize("method, path, form", [
    ("post", "/r/p/TOR-A01/link/revoke", {"occasion": "nope"}),
    ("post", "/r/p/TOR-A01/link/revoke", {"occasion": "survey_after_visual"}),
])
def test_a_refused_revoke_flashes_one_line(tor, client, method, path, form):
    before = snapshot(tor)
    assert client.post(path, data={**form, "csrf": client.csrf}).status_code == 303
    shown = flashed(client)
    assert len(shown) == 1 and ("unknown questionnaire phase 'nope'" in shown[0]
                                or shown[0] == "TOR-A01 has no active survey link at survey_after_visual"), shown
    assert snapshot(tor) == before


def test_a_bad_occasion_of_a_paper_entry_page_is_400_in_one_line(tor, client):
    before = snapshot(tor)
    for q in ("?occasion=nope", "?occasion=" + "y" * 5000):
        r = client.get("/r/entry/TOR-A01/1" + q)
        assert r.status_code == 400 and "unknown questionnaire phase" in r.get_data(as_text=True)
        assert "y" * 100 not in r.get_data(as_text=True)
    assert client.get("/r/entry/TOR-A01/1").status_code == 400    # several occasions: one must be named
    assert snapshot(tor) == before


def test_paper_double_entry_and_resolution_per_occasion(tor, client):
    one = {item: "3" if not item.startswith("tlx") else "50" for item in ITEMS}
    two = {**one, "sus4": "2"}                                    # a typing difference at survey_after_visual only
    for rnd, values in ((1, one), (2, two)):
        page = client.get(f"/r/entry/TOR-A01/{rnd}?occasion=survey_after_visual").get_data(as_text=True)
        assert 'data-occasion="survey_after_visual"' in page and "Visual takeover warning" in page
        r = client.post(f"/r/entry/TOR-A01/{rnd}?occasion=survey_after_visual", data={**values, "csrf": client.csrf})
        assert r.status_code == 303 and r.headers["Location"].endswith("#row-TOR-A01-survey_after_visual")
    status = client.get("/r/").get_data(as_text=True)
    assert 'id="row-TOR-A01-survey_after_visual" data-occasion="survey_after_visual"' in status
    assert "occasion=survey_after_visual" in status                      # its paper-entry buttons name it
    d = client.get("/r/discrepancies").get_data(as_text=True)
    assert re.search(r'data-item="sus4" data-occasion="survey_after_visual"', d)
    assert '<input type="hidden" name="occasion" value="survey_after_visual">' in d
    assert rows(client.get("/r/p/TOR-A01").get_data(as_text=True)) == [
        ("survey_after_none", "not started"), ("survey_after_visual", "submitted"),
        ("survey_after_audiovisual", "not started")]
    r = client.post("/r/resolve", data={"participant_id": "TOR-A01", "item_id": "sus4", "value": "3",
                                        "occasion": "survey_after_visual", "csrf": client.csrf})
    assert r.status_code == 303
    assert rows(client.get("/r/p/TOR-A01").get_data(as_text=True))[1] == ("survey_after_visual", "final")
    final = sv.final_responses(tor, occasion="survey_after_visual")
    assert final.loc[final["participant_id"] == "TOR-A01", "sus4"].item() == 3
    assert tor.one("SELECT count(*) FROM responses WHERE occasion <> 'survey_after_visual'") == 0


def test_the_paper_study_keeps_its_one_occasion_pages(paper_db):
    st = Store.open(paper_db, actor="lab")
    try:
        add_participant(st, "P001")
        c = create_app(st, PASSWORD).test_client()
        c.csrf = login(c)
        html = c.get("/r/p/P001").get_data(as_text=True)
        assert 'id="link-status"' in html and 'id="issue-link"' in html and "occasion-table" not in html
        r = c.post("/r/link", data={"participant_id": "P001", "csrf": c.csrf})
        page = r.get_data(as_text=True)
        assert r.status_code == 200 and "link-occasion" not in page and "earlier links\n    of P001 no longer work" in page
        token = re.search(r'id="survey-link">http://[^/]+(/s/[^<]+)<', page)[1]
        assert "occasion-heading" not in c.get(token).get_data(as_text=True)
        assert "data-occasion" not in c.get("/r/").get_data(as_text=True)
    finally:
        st.close()


def test_one_server_serves_every_instrument_of_the_study(tmp_path, tmp_db):
    """A study with two instruments (post_drive after each drive, final at the end): the console issues the link of
    each occasion and the one server shows each link's own questionnaire and stores it under its own instrument."""
    from pedas_study.cli import main
    from tests.study.test_occasions import write_study

    assert main([f"--db={tmp_db}", "init", "--study", str(write_study(tmp_path / "two"))]) == 0
    st = Store.open(tmp_db, actor="lab")
    try:
        add_participant(st, "TOR-A01")
        assign_order(st, "TOR-A01")
        c = create_app(st, PASSWORD).test_client()          # the researcher pages: the first instrument, post_drive
        c.csrf = login(c)
        html = c.get("/r/p/TOR-A01").get_data(as_text=True)
        assert [o for o, _ in rows(html)] == [*OCC, "final"]
        final_row = html[html.index('data-occasion="final"'):]
        final_row = final_row[:final_row.index("</tr>")]
        assert "final_v1" in final_row and "Paper 1" not in final_row   # paper entry: the app's instrument only
        post, final = issue(c, "TOR-A01", "survey_after_none"), issue(c, "TOR-A01", "final")
        page = c.get(final).get_data(as_text=True)
        assert 'name="PREF"' in page and 'name="sus1"' not in page and "occasion-heading" not in page
        assert 'name="sus1"' in c.get(post).get_data(as_text=True)
        r = c.post(final, data={"PREF": "2", "action": "submit"})
        assert r.status_code == 303 and "Thank you!" in c.get(final).get_data(as_text=True)
        assert c.post(post + "/answer", json={"item": "PREF", "value": "2"}).status_code == 400   # not its item
        got = st.df("SELECT instrument, occasion, item_id, value FROM responses").values.tolist()
        assert got == [["final_v1", "final", "PREF", 2.0]]
        assert rows(c.get("/r/p/TOR-A01").get_data(as_text=True))[-1] == ("final", "final")
    finally:
        st.close()

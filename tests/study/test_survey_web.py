"""The survey web app over HTTP: participant links, isolation, bad input, researcher double entry, concurrent
submissions against the running server, and `survey serve` as a process."""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.parse
import urllib.request
from concurrent.futures import ThreadPoolExecutor

import pytest

from study.survey import answers as sv
from study.folder.definition import load
from study.people.participants import add_participant, participant_attributes
from study.store.store import Store
from study.webapp import SurveyServer, create_app
from tests.conftest import LK_STUDY, PAPER_STUDY

PAPER = load(PAPER_STUDY)
INS = PAPER.instrument()
SCALED = INS.scaled_items
ATTRIBUTE_ITEMS = list(sv.attribute_items(INS))
PASSWORD = "correct horse"


def seeded_answers(seed: int) -> dict[str, str]:
    ans = {item: str(1 + (k * 7 + seed) % 5) for k, item in enumerate(SCALED)}
    ans.update(AGE=str(25 + seed % 30), GENDER=str(1 + seed % 4), LICENSE_YEARS=str(seed % 9), STYLE=str(1 + seed % 3),
               ECO_FAM=str(1 + seed % 5), Q1=f"answer {seed}: ok & <fine>")
    return ans


@pytest.fixture
def store(paper_db):
    st = Store.open(paper_db, actor="lab")
    for i in range(1, 4):
        add_participant(st, f"P00{i}")
    yield st
    st.close()


@pytest.fixture
def app(store):
    return create_app(store, PASSWORD)


@pytest.fixture
def client(app):
    return app.test_client()


def form_token(html: str) -> str:
    """The CSRF token of the first form of a page."""
    return re.search(r'name="csrf" value="([^"]+)"', html).group(1)


def login(client, name="Ann", password=PASSWORD):
    """Sign in through the form; the session's CSRF token for the researcher pages."""
    r = client.post("/r/login", data={"name": name, "password": password,
                                      "csrf": form_token(client.get("/r/login").get_data(as_text=True))})
    assert r.status_code == 303
    return form_token(client.get("/r/").get_data(as_text=True))


def checked(html: str) -> dict[str, str]:
    """{item: value} of the checked radios and filled number inputs of a rendered form."""
    out = {m.group(1): m.group(2) for m in re.finditer(r'name="([A-Za-z0-9_]+)" value="(\d+)" checked', html)}
    out.update({m.group(1): m.group(2) for m in re.finditer(
        r'name="([A-Z_]+)" inputmode="numeric" step="1"\s+min="\d+" max="\d+" value="(\d+)"', html)})
    return out


def test_participant_page_shows_the_instrument(store, client):
    token = sv.issue_link(store, "P001")
    r = client.get(f"/s/{token}")
    html = r.get_data(as_text=True)
    assert r.status_code == 200
    assert r.headers["Referrer-Policy"] == "no-referrer" and r.headers["Cache-Control"] == "no-store"
    for item in SCALED:
        assert html.count(f'name="{item}" value=') == 5            # a 5-point radio group per item
        assert INS.items.loc[item, "anchor_low"] in html and INS.items.loc[item, "anchor_high"] in html
    for item in INS.text_items:
        assert f'<textarea id="in-{item}" name="{item}"' in html
    assert html.count("Strongly disagree") >= 16 and "Not at all annoying" in html
    assert "I find the pEDAS when I am driving to be:" in html
    # the texts come from studies/pedas_paper/study.toml, the section titles from its codebook
    assert f"<h1>{PAPER.title}</h1>" in html and PAPER.description.split(".")[0] in html
    assert f"<title>Questionnaire – {PAPER.title}</title>" in html
    assert [f'<h2 id="sec-{k}">{title}</h2>' in html for k, (title, _) in enumerate(INS.sections, start=1)] == \
        [True] * len(INS.sections)
    assert '<p class="hint">1 = strongly disagree, 5 = strongly agree</p>' in html
    for label in INS.choices("ECO_FAM").values():
        assert label in html
    assert "https://" not in html and "http://" not in html     # nothing from a CDN


def test_answers_resume_and_stay_private(store, client):
    t1, t2 = sv.issue_link(store, "P001"), sv.issue_link(store, "P002")
    for item, value in (("PU1", "4"), ("ATT9", "2"), ("AGE", "41"), ("ECO_FAM", "3")):
        r = client.post(f"/s/{t1}/answer", data={"item": item, "value": value})
        assert r.status_code == 200 and r.json["ok"]
    assert checked(client.get(f"/s/{t1}").get_data(as_text=True)) == {"PU1": "4", "ATT9": "2", "AGE": "41",
                                                                     "ECO_FAM": "3"}
    page2 = client.get(f"/s/{t2}").get_data(as_text=True)
    assert checked(page2) == {} and "Participant P002" in page2 and "P001" not in page2   # none of P001's data
    client.post(f"/s/{t2}/answer", data={"item": "PU1", "value": "1"})
    assert sv.draft(store, "P001")["PU1"].value == 4 and sv.draft(store, "P002")["PU1"].value == 1


def test_bad_tokens_and_bad_answers_store_nothing(store, client):
    token = sv.issue_link(store, "P001")
    tampered = token[:10] + ("x" if token[10] != "x" else "y") + token[11:]
    before = store.counts()
    for bad in (tampered, "not-a-token", token + "A"):
        r = client.get(f"/s/{bad}")
        assert r.status_code == 404 and "This survey link is not valid" in r.get_data(as_text=True)
        r = client.post(f"/s/{bad}/answer", data={"item": "PU1", "value": "3"})
        assert r.status_code == 404 and "not valid" in r.json["error"]
        assert client.post(f"/s/{bad}", data={"PU1": "3", "action": "submit"}).status_code == 404
    r = client.post(f"/s/{token}/answer", data={"item": "PU1", "value": "6"})
    assert r.status_code == 400 and r.json["error"] == "PU1: value 6 outside 1-5"
    r = client.post(f"/s/{token}/answer", data={"item": "PU7", "value": "3"})
    assert r.status_code == 400 and "unknown item 'PU7'" in r.json["error"]
    r = client.post(f"/s/{token}", data={"PU1": "3", "EVIL": "1", "action": "save"})
    assert r.status_code == 400 and "unknown item" in r.get_data(as_text=True)
    r = client.post(f"/s/{token}/answer", data={"item": "AGE", "value": "7"})
    assert r.status_code == 400 and "outside 18-99" in r.json["error"]
    assert store.counts() == before
    sv.issue_link(store, "P001")                                   # a newer link replaces this one
    r = client.get(f"/s/{token}")
    assert r.status_code == 403 and "replaced by a newer one" in r.get_data(as_text=True)


def test_submit_without_js_validates_then_is_read_only(store, client):
    token = sv.issue_link(store, "P003")
    ans = seeded_answers(5)
    partial = {k: v for k, v in ans.items() if k not in ("PU2", "BI1")}
    r = client.post(f"/s/{token}", data={**partial, "action": "submit"})
    html = r.get_data(as_text=True)
    assert r.status_code == 400 and "2 still open" in html and 'href="#q-PU2"' in html and 'href="#q-BI1"' in html
    assert store.one("SELECT count(*) FROM responses") == 0
    assert len(sv.draft(store, "P003")) == len(partial)            # what was given is kept
    r = client.post(f"/s/{token}", data={"PU2": ans["PU2"], "action": "save"}, follow_redirects=True)
    assert r.status_code == 200 and "Your answers are saved" in r.get_data(as_text=True)
    r = client.post(f"/s/{token}", data={"PU2": ans["PU2"], "BI1": ans["BI1"], "action": "submit"})
    assert r.status_code == 303
    got = store.df("SELECT item_id, value, text FROM responses WHERE participant_id = 'P003'").set_index("item_id")
    assert {i: str(int(got.loc[i, "value"])) for i in SCALED} == {i: ans[i] for i in SCALED}
    assert got.loc["Q1", "text"] == ans["Q1"]
    page = client.get(f"/s/{token}")
    assert page.status_code == 200 and "can no longer be changed" in page.get_data(as_text=True)
    assert 'type="radio"' not in page.get_data(as_text=True)
    assert client.post(f"/s/{token}/answer", data={"item": "PU1", "value": "1"}).status_code == 409
    assert client.post(f"/s/{token}", data={"PU1": "1", "action": "submit"}).status_code == 409
    assert store.one("SELECT count(*) FROM responses WHERE participant_id = 'P003'") == 28


def test_researcher_mode_requires_password_and_csrf(store, client):
    assert client.get("/r/").status_code == 302
    r = client.post("/r/login", data={"name": "Ann", "password": "wrong",
                                      "csrf": form_token(client.get("/r/login").get_data(as_text=True))})
    assert r.status_code == 401 and "Wrong password" in r.get_data(as_text=True)
    csrf = login(client)
    assert client.get("/r/").status_code == 200
    before = store.counts()
    r = client.post("/r/entry/P001/1", data={"PU1": "3"})            # no CSRF token
    assert r.status_code == 400 and store.counts() == before
    r = client.post("/r/link", data={"participant_id": "P002", "csrf": csrf})
    url = re.search(r'id="survey-link">([^<]+)<', r.get_data(as_text=True)).group(1)
    assert url.startswith("http://localhost/s/") and sv.resolve_token(store, url.rsplit("/", 1)[1]).participant_id == "P002"


def test_researcher_double_entry_discrepancy_resolution(store, app):
    a, b = app.test_client(), app.test_client()
    ca, cb = login(a, "Ann"), login(b, "Ben")
    paper = {k: v for k, v in seeded_answers(2).items() if k not in ATTRIBUTE_ITEMS}
    assert a.post("/r/entry/P002/1", data={**paper, "csrf": ca}).status_code == 303
    form2 = b.get("/r/entry/P002/2").get_data(as_text=True)
    assert 'value="' + paper["PU1"] + '" aria-label="PU1' not in form2     # blind: round 1 not shown
    typo = dict(paper, PBC2="5" if paper["PBC2"] != "5" else "4")
    assert b.post("/r/entry/P002/2", data={**typo, "csrf": cb}).status_code == 303
    page = a.get("/r/discrepancies").get_data(as_text=True)
    assert page.count('data-participant="P002"') == 1 and 'data-item="PBC2"' in page
    d = sv.discrepancies(store)
    assert d[["item_id", "entered_by_1", "entered_by_2"]].values.tolist() == [["PBC2", "Ann", "Ben"]]
    assert sv.final_responses(store).empty
    r = a.post("/r/resolve", data={"participant_id": "P002", "item_id": "PBC2", "value": "8", "csrf": ca})
    assert r.status_code == 400 and "outside 1-5" in r.get_data(as_text=True)
    r = a.post("/r/resolve", data={"participant_id": "P002", "item_id": "PBC2", "value": paper["PBC2"],
                                   "note": "form checked", "csrf": ca})
    assert r.status_code == 303
    final = sv.final_responses(store).set_index("participant_id")
    assert {i: str(int(final.loc["P002", i])) for i in SCALED} == {i: paper[i] for i in SCALED}
    assert store.one("SELECT actor FROM audit_log WHERE table_name = 'survey_resolutions'") == "Ann"
    r = a.post("/r/entry/P002/1", data={**paper, "PU1": "9", "csrf": ca})
    assert r.status_code == 400 and "outside 1-5" in r.get_data(as_text=True)


# ---------------------------------------------------------------------------------------------- any study
LK_ITEMS = ["PE1", "PE2", "PE3", "EE1", "EE2", "EE3", "SI1", "SI2", "SI3", "BI1", "BI2", "BI3"]


@pytest.fixture
def lk_store(lk_db):
    st = Store.open(lk_db, actor="lab")
    add_participant(st, "LK-01", attributes={"age": 30})
    yield st
    st.close()


def test_seven_point_form_and_server_side_validation(lk_store):
    """The lane-keeping study's form: its own title, 7 radios per item, attribute items; POSTs are checked against
    the codebook (range, required, the attribute's declaration) and a refused POST changes nothing."""
    study = load(LK_STUDY)
    client = create_app(lk_store, PASSWORD).test_client()
    token = sv.issue_link(lk_store, "LK-01")
    html = client.get(f"/s/{token}").get_data(as_text=True)
    assert f"<h1>{study.title}</h1>" in html and "pEDAS" not in html
    for item in LK_ITEMS:
        assert html.count(f'name="{item}" value=') == 7
        assert f'name="{item}" value="8"' not in html
    assert html.count('<p class="hint">1 = strongly disagree, 7 = strongly agree</p>') == 4
    assert html.count('name="GENDER" value=') == 4 and 'id="in-AGE"' in html
    before = lk_store.counts()
    for item, value, msg in (("PE1", "8", "PE1: value 8 outside 1-7"), ("EE3", "0", "EE3: value 0 outside 1-7"),
                             ("AGE", "17", "AGE: value 17 outside 18-90"), ("GENDER", "5", "outside 1-4")):
        r = client.post(f"/s/{token}/answer", data={"item": item, "value": value})
        assert r.status_code == 400 and msg in r.json["error"]
    r = client.post(f"/s/{token}", data={**{i: "4" for i in LK_ITEMS}, "PE2": "9", "action": "submit"})
    assert r.status_code == 400 and "PE2: value 9 outside 1-7" in r.get_data(as_text=True)
    assert lk_store.counts() == before                                  # nothing stored, not even a draft
    r = client.post(f"/s/{token}", data={**{i: "4" for i in LK_ITEMS[1:]}, "AGE": "44", "action": "submit"})
    assert r.status_code == 400 and 'href="#q-PE1"' in r.get_data(as_text=True)   # required PE1 unanswered
    assert lk_store.one("SELECT count(*) FROM responses") == 0
    r = client.post(f"/s/{token}", data={"PE1": "7", "GENDER": "2", "action": "submit"})
    assert r.status_code == 303
    got = lk_store.df("SELECT item_id, value FROM responses WHERE participant_id = 'LK-01'").set_index("item_id")
    assert got.loc["PE1", "value"] == 7 and got.loc["EE3", "value"] == 4 and len(got) == 13   # 12 + REMARKS
    attrs = participant_attributes(lk_store, ["LK-01"]).iloc[0]
    assert (attrs["age"], attrs["gender"]) == (44, "male")


def test_a_question_the_form_cannot_show_is_an_error(store):
    """A response type without a widget is refused when the app is made, never shown as a question without
    inputs."""
    from study.common.errors import UserError
    from study.folder.instrument import Instrument
    from study.webapp import check_renderable, widget

    assert [widget(k) for k in ("likert7", "semantic11", "likert", "choice", "number", "text")] == \
        ["scale", "scale", "scale", "choice", "number", "text"]
    items = INS.items.copy()
    items.loc["PU2", "response_type"] = "matrix"
    with pytest.raises(UserError, match="instrument pedas_acceptance_v1, item PU2: the web form cannot show "
                                        "response type 'matrix'"):
        check_renderable(Instrument(INS.name, items))
    check_renderable(INS)


def test_fully_labelled_points_are_shown(store):
    """A Likert item whose codebook labels every point shows each label with its radio (no anchors)."""
    from flask import render_template_string

    items = INS.items.copy()
    items.loc["PU1", "choices"] = "1=never|2=rarely|3=sometimes|4=often|5=always"
    from study.folder.instrument import Instrument

    ins = Instrument(INS.name, items)
    app = create_app(store, PASSWORD)
    with app.test_request_context():
        html = render_template_string('{% from "_widgets.html" import scale_item %}'
                                      '{{ scale_item("PU1", row, none, labels) }}',
                                      row=ins.items.loc["PU1"], labels=ins.choices("PU1"))
    assert html.count('type="radio"') == 5 and "anchor" not in html
    assert [w in html for w in ("never", "rarely", "sometimes", "often", "always")] == [True] * 5
    assert 'class="item scale-item likert labelled wide"' in html


# ---------------------------------------------------------------------------------------------- running server
def http(url: str, data: dict | None = None, timeout: float = 60) -> tuple[int, str]:
    body = None if data is None else urllib.parse.urlencode(data).encode()
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data=body), timeout=timeout) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


@pytest.mark.slow
def test_twenty_concurrent_submissions(paper_db):
    n = 20
    st = Store.open(paper_db, actor="lab")
    pids = [f"P{100 + i}" for i in range(n)]
    for p in pids:
        add_participant(st, p)
    tokens = {p: sv.issue_link(st, p) for p in pids}
    answers = {p: seeded_answers(i) for i, p in enumerate(pids)}
    with SurveyServer(create_app(st, PASSWORD), quiet=True) as srv:
        def one_answer(job):
            p, item = job
            return http(f"{srv.url}/s/{tokens[p]}/answer", {"item": item, "value": answers[p][item]})[0]

        def submit(p):
            return http(f"{srv.url}/s/{tokens[p]}", {"action": "submit"})[0]

        with ThreadPoolExecutor(max_workers=n) as pool:
            jobs = [(p, item) for item in answers[pids[0]] for p in pids]   # interleaved across participants
            assert set(pool.map(one_answer, jobs)) == {200}
            # every participant submits twice at the same time: one is stored, the other is refused
            codes = list(pool.map(submit, pids + pids))
        with srv.app.extensions["survey"]["lock"]:
            assert sorted(codes) == [200] * n + [409] * n
            counts = st.df("SELECT participant_id, count(*) AS n FROM responses GROUP BY participant_id")
            assert sorted(counts["participant_id"]) == pids and set(counts["n"]) == {28}
            assert st.one("SELECT count(*) FROM survey_submissions") == n
            assert st.one("SELECT count(*) FROM survey_drafts") == 0
            final = sv.final_responses(st).set_index("participant_id")
    st.close()
    for p in pids:
        assert {i: str(int(final.loc[p, i])) for i in SCALED} == {i: answers[p][i] for i in SCALED}
        assert final.loc[p, "Q1"] == answers[p]["Q1"]


def test_close_waits_for_the_request_using_the_store_then_refuses(store, app):
    """Stopping the server leaves a request in progress in its thread: close() waits until it has finished with
    the store (so the store can be closed next), and any later use is refused with 503, nothing stored."""
    import threading

    token = sv.issue_link(store, "P001")
    srv = SurveyServer(app, quiet=True).start()
    lock = app.extensions["survey"]["lock"]
    lock.acquire()                                  # a request is using the store
    closer = threading.Thread(target=srv.close)
    closer.start()
    closer.join(timeout=1.0)
    assert closer.is_alive()                        # close() waits for it
    lock.release()
    closer.join(timeout=10)
    assert not closer.is_alive()
    r = app.test_client().post(f"/s/{token}/answer", data={"item": "PU1", "value": "3"})
    assert r.status_code == 503
    assert store.one("SELECT count(*) FROM survey_drafts") == 0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_survey_serve_process(paper_db):
    tmp_db = paper_db
    port = free_port()
    env = {**os.environ, "PEDAS_SURVEY_PASSWORD": ""}
    proc = subprocess.Popen([sys.executable, "-m", "pedas_study.cli", f"--db={tmp_db}", "survey", "serve",
                             "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        assert lines[0].startswith(f"survey form on http://127.0.0.1:{port}/")
        password = lines[1].rsplit(": ", 1)[1].strip()
        assert len(password) >= 16
        code, html = http(f"http://127.0.0.1:{port}/", timeout=30)
        assert code == 200 and "Researcher sign-in" in html
        assert http(f"http://127.0.0.1:{port}/s/{'A' * 43}", timeout=30)[0] == 404
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "survey server stopped" in out and "/s/AAAA" not in err   # tokens never in the access log

"""Bad requests the web app once answered with HTTP 500, each now a 4xx (or a refused redirect) with one line and the
store unchanged; and the lesser faults of the same hardening: the password change throttled like sign-in, a
constraint said as the field's rule, a withdrawn link said so, no request data echoed into a redirect, no token in
the error log, no export date in a de-identified .sav header. Flask's test client on a real store; the booking at
9999-12-31 also through the CLI."""
from __future__ import annotations

import io
import logging
import re
import zipfile

import pytest

from study.survey import answers as sv
from study.store.constraint_text import constraint_rule
from study.webapp import create_app
from study.webapp.signin import SignInSettings
from tests.study.test_console import flashed, snapshot
from tests.study.test_survey_web import form_token

PASSWORD = "correct horse"


@pytest.fixture
def store(console_store):
    return console_store


@pytest.fixture
def console_app(store):
    """The console's app (the signed-in `client`'s too), its sign-in guarded as these tests count on."""
    return create_app(store, PASSWORD, signin=SignInSettings(max_failures=5, lockout_s=30))


@pytest.fixture
def app(console_app):
    return console_app


@pytest.fixture
def client(console_client):
    return console_client


# ---------------------------------------------------------------------------------------------- the five 500s
def test_a_non_ascii_csrf_token_is_refused_not_a_crash(store, app, client):
    anon = app.test_client()
    anon.get("/r/login")
    r = anon.post("/r/login", data={"name": "Ann", "password": PASSWORD, "csrf": "é"})
    assert r.status_code == 400 and "The sign-in form expired" in r.get_data(as_text=True)
    before = snapshot(store)
    r = client.post("/r/participants", data={"participant_id": "P003", "csrf": "é" + client.csrf[1:]})
    assert r.status_code == 400 and "Form expired" in r.get_data(as_text=True)
    assert snapshot(store) == before


@pytest.mark.parametrize("body", ['["item", "value"]', '"PU1"', "3", "null", "true", '{"item": 3, "value": "3"}',
                                  '{"item": ["PU1"]}', '{"item": "PU1", "value": [3]}', '{"item": "PU1", "value": {}}',
                                  '{"item": "PU1", "value": true}'])
def test_an_answer_that_is_not_a_json_object_is_refused_and_no_token_is_logged(store, client, caplog, body):
    token = sv.issue_link(store, "P001")
    before = snapshot(store), sv.draft(store, "P001")
    with caplog.at_level(logging.INFO):
        r = client.post(f"/s/{token}/answer", data=body, content_type="application/json")
    assert r.status_code == 400 and r.json["error"] in ("expected item and value",
                                                        "the value must be text, a number or null")
    assert (snapshot(store), sv.draft(store, "P001")) == before
    assert token not in caplog.text


def test_the_error_log_never_shows_a_link_token(store, app, caplog, monkeypatch):
    """A fault inside a participant's request (made here on purpose) is logged with the path redacted."""
    token = sv.issue_link(store, "P001")

    def broken(*a, **kw):
        raise RuntimeError("a fault")

    monkeypatch.setattr(sv, "save_draft", broken)
    with caplog.at_level(logging.ERROR):
        r = app.test_client().post(f"/s/{token}/answer", json={"item": "PU1", "value": "3"})
    assert r.status_code == 500
    assert "Exception on /s/<token>/answer [POST]" in caplog.text and "RuntimeError: a fault" in caplog.text
    assert token not in caplog.text


def test_a_refused_registration_with_url_for_keywords_goes_back_to_the_form(store, client):
    before = snapshot(store)
    form = {"participant_id": "bad id", "age": "30", "_method": "PUT", "_external": "1", "_anchor": "x",
            "csrf": client.csrf}
    r = client.post("/r/participants", data=form)
    assert r.status_code == 303 and r.headers["Location"] == "/r/participants"
    assert snapshot(store) == before
    page = client.get("/r/participants").get_data(as_text=True)   # the form comes back filled in, once
    assert 'value="bad id"' in page and re.search(r'name="age"[^>]*value="30"', page, re.S)
    assert "bad participant id" in page
    assert 'value="bad id"' not in client.get("/r/participants").get_data(as_text=True)


def test_sign_in_with_cr_lf_in_next_goes_to_the_console_with_a_cookie(app):
    c = app.test_client()
    token = form_token(c.get("/r/login").get_data(as_text=True))
    r = c.post("/r/login?next=/r/%0d%0aSet-Cookie:%20x=1", data={"name": "Ann", "password": PASSWORD, "csrf": token})
    assert r.status_code == 303 and r.headers["Location"] == "/r/today"
    assert r.headers["Set-Cookie"].startswith("session=") and c.get("/r/today").status_code == 200
    for nxt, to in [("/r/p/P001", "/r/p/P001"), ("//evil.example/r/", "/r/today"), ("/r/../s/x", "/r/today"),
                    ("/r/" + "a" * 300, "/r/today"), ("https://evil.example/r/", "/r/today")]:
        c = app.test_client()
        token = form_token(c.get("/r/login").get_data(as_text=True))
        r = c.post("/r/login", query_string={"next": nxt}, data={"name": "Ann", "password": PASSWORD, "csrf": token})
        assert r.status_code == 303 and r.headers["Location"] == to, nxt


def test_booking_at_the_end_of_time_is_refused(store, client):
    before = snapshot(store)
    r = client.post("/r/book", data={"participant_id": "P001", "at": "9999-12-31T23:59", "csrf": client.csrf})
    assert r.status_code == 303 and r.headers["Location"] == "/r/today?date=9999-12-31"
    assert flashed(client) == ["a slot starting 9999-12-31 23:59 would end after 9999-12-31 (the latest date there "
                               "is); book an earlier slot"]
    assert snapshot(store) == before


def test_cli_booking_at_the_end_of_time_is_one_line_exit_2(cli, paper_db):
    assert cli("participant", "add", "P001", db=paper_db).code == 0
    r = cli("session", "schedule", "P001", "--at", "9999-12-31T23:59", db=paper_db)
    assert r.code == 2 and r.err.strip().splitlines() == [
        "pedas-study: error: a slot starting 9999-12-31 23:59 would end after 9999-12-31 (the latest date there is); "
        "book an earlier slot"]
    r = cli("session", "schedule", "P001", "--at", "2099-01-05T09:00", "--buffer", "inf", db=paper_db)
    assert r.code == 2 and "a slot of inf minutes is longer than any calendar" in r.err


# ---------------------------------------------------------------------------------------------- the lesser ones
def test_wrong_current_passwords_are_throttled_like_sign_in(app, client):
    for _ in range(5):
        r = client.post("/r/password", data={"current": "guess", "new": "x" * 12, "confirm": "x" * 12,
                                             "csrf": client.csrf})
        assert r.status_code == 400 and "The current password is wrong" in r.get_data(as_text=True)
    r = client.post("/r/password", data={"current": PASSWORD, "new": "y" * 12, "confirm": "y" * 12,
                                         "csrf": client.csrf})                     # locked: not even checked
    assert r.status_code == 429 and r.headers["Retry-After"] == "30"
    assert "Too many wrong passwords" in r.get_data(as_text=True)
    anon = app.test_client()                                                    # the same name is locked for sign-in
    token = form_token(anon.get("/r/login").get_data(as_text=True))
    assert anon.post("/r/login", data={"name": "Ann", "password": PASSWORD, "csrf": token}).status_code == 429


def test_a_long_simulator_name_is_refused_with_the_rule(store, client):
    before = snapshot(store)
    client.post("/r/book", data={"participant_id": "P001", "at": "2099-01-05T09:00", "simulator": "S" * 41,
                                 "csrf": client.csrf})
    assert flashed(client) == ["a simulator name has at most 40 characters, not 41"]
    assert snapshot(store) == before


@pytest.mark.parametrize("raw, rule", [
    ('Constraint Error: CHECK constraint failed on table "appointments" with expression '
     'CHECK((length(simulator) BETWEEN 1 AND 40))', "simulator: 1 to 40 characters"),
    ('Constraint Error: CHECK constraint failed on table "t" with expression CHECK((age BETWEEN 16 AND 110))',
     "age: a value from 16 to 110"),
    ("Constraint Error: CHECK constraint failed on table \"t\" with expression CHECK((status IN ('booked', "
     "'cancelled')))", "status: one of booked, cancelled"),
    ('Constraint Error: CHECK constraint failed on table "t" with expression CHECK((hud_arrow IN (-1, 0, 1)))',
     "hud_arrow: one of -1, 0, 1"),
    ("Constraint Error: CHECK constraint failed on table \"t\" with expression CHECK(regexp_full_match(id, "
     "'^P[0-9]{3,}$'))", "id: must match ^P[0-9]{3,}$"),
    ('Constraint Error: CHECK constraint failed on table "t" with expression CHECK((n_samples >= 2))',
     "n_samples: a value >= 2"),
    ("Constraint Error: NOT NULL constraint failed: appointments.simulator", "simulator: a value is required"),
    ('Constraint Error: Duplicate key "participant_id: P001" violates primary key constraint.',
     "participant_id P001 exists already"),
    ('Constraint Error: CHECK constraint failed on table "t" with expression CHECK(((a IS NULL) OR (b <= a)))', None),
])
def test_constraint_errors_are_said_as_the_fields_rule(raw, rule):
    assert constraint_rule(raw) == rule


def test_the_store_says_a_broken_check_as_the_rule(store):
    from study.common.errors import UserError

    with pytest.raises(UserError) as err:
        store.insert("appointments", {"participant_id": "P001", "simulator": "S" * 41, "starts_at": "2099-01-05 09:00",
                                      "ends_at": "2099-01-05 10:00", "status": "booked", "protocol": "paper_v1"})
    assert str(err.value) == "appointments: simulator: 1 to 40 characters"


def test_a_withdrawn_link_is_not_said_to_be_replaced(store, client):
    token = sv.issue_link(store, "P001")
    sv.revoke_links(store, "P001")
    r = client.get(f"/s/{token}")
    assert r.status_code == 403 and "withdrawn by the researcher" in r.get_data(as_text=True)
    r = client.post(f"/s/{token}/answer", json={"item": "PU1", "value": "3"})
    assert r.status_code == 403 and "withdrawn" in r.json["error"]
    newer = sv.issue_link(store, "P001")
    sv.issue_link(store, "P001")                                   # `newer` is now replaced, not withdrawn
    assert "replaced by a newer one" in client.get(f"/s/{newer}").get_data(as_text=True)


def test_a_70_kb_field_is_never_echoed_into_a_redirect_or_the_cookie(store, client):
    before = snapshot(store)
    r = client.post("/r/participants", data={"participant_id": "P003", "age": "1" * 70_000, "gender": "female",
                                             "csrf": client.csrf})
    assert r.status_code == 303 and r.headers["Location"] == "/r/participants"
    assert len(r.headers.get("Set-Cookie", "")) < 1000
    page = client.get("/r/participants").get_data(as_text=True)
    assert "1" * 1000 not in page and '<option selected>female</option>' in page   # the short fields come back
    assert snapshot(store) == before
    r = client.post("/r/appointment", data={"participant_id": "P001", "status": "x" * 70_000, "date": "y" * 70_000,
                                            "csrf": client.csrf})
    assert r.status_code == 303 and r.headers["Location"] == "/r/today" and len(r.headers["Set-Cookie"]) < 1000


def test_http_errors_are_one_line_pages(store, client):
    r = client.put("/r/today")
    assert r.status_code == 405 and "GET" in r.headers["Allow"]
    assert re.search(r'<section class="card message" role="alert">\s*<h1>Method Not Allowed</h1>\s*<p>[^\n<]+</p>',
                     r.get_data(as_text=True))
    token = sv.issue_link(store, "P001")
    r = client.post(f"/s/{token}/answer", data={"item": "x" * (300 * 1024)})
    assert r.status_code == 413 and "\n" not in r.json["error"]


def test_the_deidentified_sav_export_has_no_export_time(store, client, tmp_path):
    import pyreadstat

    from study.export.writer import export

    export(store, "sav", tmp_path, deidentify=True)
    header = (tmp_path / "participants.sav").read_bytes()[92:109]
    assert header == b"01 Jan 7000:00:00"
    _, meta = pyreadstat.read_sav(str(tmp_path / "participants.sav"), metadataonly=True)
    assert str(meta.creation_time) == "1970-01-01 00:00:00"
    r = client.post("/r/export", data={"format": "sav", "deidentify": "1", "csrf": client.csrf})
    assert r.status_code == 200
    with zipfile.ZipFile(io.BytesIO(r.data)) as z:
        assert {i.date_time for i in z.infolist()} == {(1980, 1, 1, 0, 0, 0)}
        assert z.read("participants.sav")[92:109] == b"01 Jan 7000:00:00"

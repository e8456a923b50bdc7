"""Researcher sign-in hardened: lockout with back-off per account and per client address, server-side sessions ended
by logout and by a password change, CSRF on the sign-in form and every researcher form, Secure cookies."""
from __future__ import annotations

import pytest

from study.people.participants import add_participant
from study.store.store import Store
from study.webapp import create_app
from study.webapp.signin import SignInSettings, Throttle, check_password, hash_password
from tests.study.test_survey_web import form_token, login

PASSWORD = "correct horse"


class Clock:
    """A hand-moved clock (seconds) for lockout times."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def store(paper_db):
    st = Store.open(paper_db, actor="lab")
    add_participant(st, "P001")
    yield st
    st.close()


def make_app(store, clock: Clock | None = None, **settings):
    app = create_app(store, PASSWORD, signin=SignInSettings(**settings))
    if clock is not None:
        app.extensions["signin"].throttle.clock = clock
    return app


def attempt(client, name: str, password: str, addr: str = "127.0.0.1"):
    token = form_token(client.get("/r/login", environ_base={"REMOTE_ADDR": addr}).get_data(as_text=True))
    return client.post("/r/login", data={"name": name, "password": password, "csrf": token},
                       environ_base={"REMOTE_ADDR": addr})


# ---------------------------------------------------------------------------------------------- units
def test_password_hash_round_trip():
    h = hash_password("s3cret pass")
    assert h.startswith("scrypt$") and "s3cret" not in h
    assert check_password("s3cret pass", h) and not check_password("s3cret pasS", h)
    assert hash_password("x", bytes(16)) == hash_password("x", bytes(16)) != hash_password("x")


def test_throttle_backs_off_doubling_up_to_the_cap():
    clock = Clock()
    t = Throttle(SignInSettings(max_failures=3, lockout_s=30, max_lockout_s=100), clock)
    keys = ["account:ann"]
    waits = []
    for _ in range(4):                       # four lockouts in a row: 30, 60, 100 (capped), 100 s
        t.failed(keys)
        t.failed(keys)
        assert t.locked_for(keys) == 0       # two failures: not yet
        t.failed(keys)
        waits.append(t.locked_for(keys))
        clock.now += waits[-1]
        assert t.locked_for(keys) == 0
    assert waits == [30, 60, 100, 100]
    t.succeeded(keys)
    for _ in range(3):
        t.failed(keys)
    assert t.locked_for(keys) == 30          # a success starts the back-off afresh


# ---------------------------------------------------------------------------------------------- lockout
def test_lockout_after_n_wrong_passwords_for_one_account(store):
    clock = Clock()
    app = make_app(store, clock, max_failures=5, lockout_s=60)
    c = app.test_client()
    codes = [attempt(c, "Ann", f"guess {i}").status_code for i in range(5)]
    assert codes == [401] * 5
    r = attempt(c, "Ann", PASSWORD)                            # locked: even the right password is refused
    assert r.status_code == 429 and r.headers["Retry-After"] == "60"
    assert "Too many failed sign-ins" in r.get_data(as_text=True)
    assert attempt(c, "ann ", PASSWORD).status_code == 429     # the same account, however typed
    assert attempt(c, "Ben", PASSWORD).status_code == 303      # another account from the same address is not
    clock.now += 59
    assert attempt(c, "Ann", PASSWORD).status_code == 429
    clock.now += 1.5
    assert attempt(c, "Ann", PASSWORD).status_code == 303      # after the lockout
    for i in range(5):
        attempt(c, "Ann", f"again {i}")
    assert attempt(c, "Ann", PASSWORD).headers["Retry-After"] == "60"   # a success reset the back-off


def test_lockout_per_client_address_across_account_names(store):
    app = make_app(store, Clock(), max_failures=5, max_failures_per_address=8, lockout_s=60)
    c = app.test_client()
    assert [attempt(c, f"name{i}", "wrong", "10.0.0.7").status_code for i in range(8)] == [401] * 8
    assert attempt(c, "Ann", PASSWORD, "10.0.0.7").status_code == 429   # a fresh name from the same address
    assert attempt(c, "Ann", PASSWORD, "10.0.0.8").status_code == 303   # another address


def test_the_address_behind_a_trusted_proxy_is_the_forwarded_one(store):
    app = make_app(store, Clock(), max_failures=50, max_failures_per_address=3, trust_proxy=1)
    c = app.test_client()

    def via_proxy(name, password, client_ip):
        token = form_token(c.get("/r/login").get_data(as_text=True))
        return c.post("/r/login", data={"name": name, "password": password, "csrf": token},
                      headers={"X-Forwarded-For": client_ip})
    assert [via_proxy(f"n{i}", "wrong", "203.0.113.5").status_code for i in range(3)] == [401] * 3
    assert via_proxy("Ann", PASSWORD, "203.0.113.5").status_code == 429
    assert via_proxy("Ann", PASSWORD, "203.0.113.6").status_code == 303  # the proxy's own address is not locked


# ---------------------------------------------------------------------------------------------- sessions
def test_logout_invalidates_the_old_cookie(store):
    app = make_app(store)
    c = app.test_client()
    csrf = login(c)
    old = c.get_cookie("session").value
    assert c.get("/r/").status_code == 200
    assert c.post("/r/logout", data={"csrf": csrf}).status_code == 303
    replay = app.test_client()
    replay.set_cookie("session", old)                          # the cookie as it was before logout
    r = replay.get("/r/")
    assert r.status_code == 302 and "/r/login" in r.headers["Location"]
    assert replay.post("/r/link", data={"csrf": csrf, "participant_id": "P001"}).status_code == 302
    assert store.one("SELECT count(*) FROM survey_tokens") == 0


def test_password_change_ends_every_session(store):
    app = make_app(store)
    a, b = app.test_client(), app.test_client()
    ca, _ = login(a, "Ann"), login(b, "Ben")
    a_old = a.get_cookie("session").value
    r = a.post("/r/password", data={"csrf": ca, "current": "wrong", "new": "a new long one",
                                    "confirm": "a new long one"})
    assert r.status_code == 400 and "current password is wrong" in r.get_data(as_text=True)
    assert b.get("/r/").status_code == 200                # a refused change ends nothing
    r = a.post("/r/password", data={"csrf": ca, "current": PASSWORD, "new": "short", "confirm": "short"})
    assert r.status_code == 400 and "at least 10" in r.get_data(as_text=True)
    r = a.post("/r/password", data={"csrf": ca, "current": PASSWORD, "new": "a new long one",
                                    "confirm": "a new long one"})
    assert r.status_code == 303
    assert a.get("/r/").status_code == 200                # the one who changed it goes on, in a new session
    assert b.get("/r/").status_code == 302                # everyone else is signed out
    replay = app.test_client()
    replay.set_cookie("session", a_old)
    assert replay.get("/r/").status_code == 302           # so is the changer's old cookie
    assert attempt(app.test_client(), "Ben", PASSWORD).status_code == 401
    assert attempt(app.test_client(), "Ben", "a new long one").status_code == 303


def test_idle_session_ends(store):
    clock = Clock()
    app = make_app(store, session_idle_s=600)
    app.extensions["signin"].sessions.clock = clock
    c = app.test_client()
    login(c)
    clock.now += 599
    assert c.get("/r/").status_code == 200
    clock.now += 601
    assert c.get("/r/").status_code == 302


# ---------------------------------------------------------------------------------------------- CSRF
POSTS = [  # a form of each kind: each must be refused without the session's token
    ("/r/link", {"participant_id": "P001"}),
    ("/r/entry/P001/1", {"PU1": "3"}),
    ("/r/resolve", {"participant_id": "P001", "item_id": "PU1", "value": "3"}),
    ("/r/password", {"current": PASSWORD, "new": "a new long one", "confirm": "a new long one"}),
    ("/r/logout", {}),
    # the console
    ("/r/participants", {"participant_id": "P002"}),
    ("/r/book", {"participant_id": "P001", "at": "2030-01-07T09:00"}),
    ("/r/p/P001/start", {"phase": "familiarisation"}),
    ("/r/p/P001/exclude", {"scope": "all", "reason": "withdrawn"}),
    ("/r/p/P001/link/revoke", {}),
    ("/r/export", {"format": "csv"}),
]


def test_posts_without_or_with_a_wrong_csrf_token_are_refused(store):
    app = make_app(store)
    c = app.test_client()
    r = c.post("/r/login", data={"name": "Ann", "password": PASSWORD})          # the sign-in form too
    assert r.status_code == 400 and c.get("/r/").status_code == 302
    c.get("/r/login")
    r = c.post("/r/login", data={"name": "Ann", "password": PASSWORD, "csrf": "forged"})
    assert r.status_code == 400 and c.get("/r/").status_code == 302
    csrf = login(c)
    before = store.counts()
    for path, data in POSTS:
        assert c.post(path, data=data).status_code == 400, path
        assert c.post(path, data={**data, "csrf": csrf[::-1]}).status_code == 400, path
    assert store.counts() == before
    assert attempt(app.test_client(), "Ann", PASSWORD).status_code == 303      # the password did not change


# ---------------------------------------------------------------------------------------------- cookies
def set_cookie_after_login(app, **request_kw) -> str:
    c = app.test_client()
    token = form_token(c.get("/r/login", **request_kw).get_data(as_text=True))
    r = c.post("/r/login", data={"name": "Ann", "password": PASSWORD, "csrf": token}, **request_kw)
    assert r.status_code == 303
    return r.headers["Set-Cookie"]


def flags(cookie: str) -> set[str]:
    return {part.strip().split("=")[0].lower() for part in cookie.split(";")[1:]}


def test_cookie_is_secure_when_configured_or_over_https(store):
    assert "secure" not in flags(set_cookie_after_login(make_app(store)))          # plain HTTP, default
    assert {"secure", "httponly", "samesite"} <= flags(set_cookie_after_login(make_app(store, secure_cookies="always")))
    https = {"base_url": "https://localhost"}
    assert "secure" in flags(set_cookie_after_login(make_app(store), **https))
    proxied = {"headers": {"X-Forwarded-Proto": "https"}}
    assert "secure" in flags(set_cookie_after_login(make_app(store, trust_proxy=1), **proxied))
    # without trust_proxy anyone could send the header: it is ignored
    assert "secure" not in flags(set_cookie_after_login(make_app(store), **proxied))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="secure_cookies"):
        SignInSettings(secure_cookies="sometimes")
    with pytest.raises(ValueError, match=">= 1"):
        SignInSettings(max_failures=0)

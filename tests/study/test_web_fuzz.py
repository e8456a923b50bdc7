"""Property-based fuzzing of the survey web app through the real server (werkzeug, threaded, over a TCP socket).

Every route of the app's URL map, signed in and not, gets requests drawn by hypothesis: any method, path
parameters (valid, unknown and garbage tokens and participant ids), query strings, urlencoded forms with the
app's own field names and random ones, JSON of any shape and JSON nested thousands deep, multipart uploads (file
names of 300 bytes and more), raw bodies under any content type, odd headers, Host headers that name no host, and
paths percent-encoded in other spellings. The properties:

* no answer is 5xx;
* a refusal (4xx, or a redirect carrying an error message) leaves the store exactly as it was (row counts of every
  table, the audit log, the unsaved survey drafts);
* a one-message page says its message on one line.

The requests go over a socket written by hand (not http.client, which refuses CR/LF and non-ASCII in a request)
so that what reaches the server is exactly what was drawn, and the server's own request parsing, cookie handling
and redirects are part of what is tested. The draws are derandomized (a fixed seed): CI runs the same
:data:`PER_ROUTE` requests for each route every time. The status histogram is printed (``pytest -s``).
"""
from __future__ import annotations

import collections
import json
import re
import socket
import urllib.parse

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from study.survey import answers as sv
from study.people.participants import add_participant
from study.store.store import Store
from study.webapp import SurveyServer, create_app
from study.webapp.signin import SignInSettings

PASSWORD = "correct horse"
PER_ROUTE = 40  # requests per route: 30 routes -> 1,200 requests, ~2 min on one core (printed histogram)
METHODS = ["GET", "POST", "HEAD", "PUT", "DELETE", "PATCH", "OPTIONS", "TRACE", "BREW"]
FIELDS = ["csrf", "name", "password", "participant_id", "at", "simulator", "status", "date", "note", "phase", "reason",
          "scope", "condition", "format", "deidentify", "replace", "force", "vehicle", "protocol", "age", "gender",
          "license_years", "style", "eco_familiarity", "item", "value", "action", "current", "new", "confirm",
          "item_id", "next", "_method", "_external", "_anchor", "_scheme", "PU1", "AGE", "Q1"]

GOOD = {"name": "Ann", "password": PASSWORD, "participant_id": "P001", "at": "2099-01-05T09:00", "simulator": "sim1",
        "status": "attended", "date": "2099-01-05", "phase": "familiarisation", "reason": "motion_sickness",
        "scope": "all", "condition": "baseline", "format": "csv", "protocol": "paper_v1", "age": "30",
        "gender": "female", "item": "PU1", "value": "3", "action": "submit", "current": PASSWORD,
        "new": "a new password 1", "confirm": "a new password 1", "item_id": "PU1", "PU1": "3", "AGE": "30"}
text = st.text(st.characters(codec="utf-8"), max_size=40)
nasty = st.sampled_from(["", " ", "é", "\r\n", "\x00", "%0d%0a", "../../etc", "//evil.example", "/r/today",
                         "/r/\r\nX: 1", "9999-12-31T23:59", "0001-01-01T00:00", "2099-01-01T09:00", "1e309", "NaN",
                         "-1", "3", "P001", "P002", "P999", "sim1", "S" * 41, "x" * 5000, PASSWORD, "submit",
                         "attended", "no_show", "all", "csv", "sav", "baseline", "familiarisation", "{}", "[]"])
value = st.one_of(nasty, text)
BAD_HOSTS = ["a..b", "x" * 64 + ".example", "é.example", "", " ", "[::1", "-a.example", "a_b.example",
             "127.0.0.1:99999999", "localhost:", "xn--.example", "a" * 300, "ex ample.org"]
ids = st.one_of(st.sampled_from(["P001", "P002", "P999", "", " ", "P001/..", "é", "\r\n", "x" * 300]), text)


@pytest.fixture
def served(paper_db):
    """(store, app, server, {"token", "revoked"}): the paper's study, P001..P003, a live and a revoked link."""
    store = Store.open(paper_db, actor="lab")
    for pid in ("P001", "P002", "P003"):
        add_participant(store, pid)
    revoked = sv.issue_link(store, "P003")
    sv.revoke_links(store, "P003")
    links = {"token": sv.issue_link(store, "P002"), "revoked": revoked}
    # no lockout: the fuzzer's wrong passwords must not lock its own later sign-ins (tests/study/test_signin.py does)
    app = create_app(store, PASSWORD, signin=SignInSettings(max_failures=10 ** 9, max_failures_per_address=10 ** 9))
    server = SurveyServer(app, quiet=True).start()
    yield store, app, server, links
    server.close()
    store.close()


def fingerprint(store) -> tuple:
    """What a refused request must not change: every table's row count, the audit log, the unsaved drafts."""
    drafts = store.one("SELECT md5(coalesce(string_agg(concat_ws('|', participant_id, instrument, item_id, value, "
                       "text), ',' ORDER BY participant_id, instrument, item_id), '')) FROM survey_drafts")
    return store.counts(), store.one("SELECT max(audit_id) FROM audit_log"), drafts


class Client:
    """Raw HTTP/1.1 over a socket, one connection per request; the session cookie made with the app's own key."""

    def __init__(self, app, server) -> None:
        self.app, self.server = app, server
        self.serializer = app.session_interface.get_signing_serializer(app)
        self.signin = app.extensions["signin"]
        self.sid: str | None = None

    def cookie(self, signed_in: bool) -> tuple[str, str]:
        """(cookie header value, CSRF token of the forms): a live researcher session or a sign-in form's session."""
        if not signed_in:
            return "session=" + self.serializer.dumps({"login_csrf": "login-token"}), "login-token"
        who = self.signin.sessions.get(self.sid)
        if who is None:  # the last request signed out or changed the password: a new session
            self.sid = self.signin.sessions.create("Fuzz")
            who = self.signin.sessions.get(self.sid)
        return "session=" + self.serializer.dumps({"sid": self.sid, "login_csrf": "login-token"}), who.csrf

    def send(self, method: str, target: str, headers: list[tuple[str, str]], body: bytes,
             host: str | None = None) -> tuple[int, dict, bytes]:
        host = f"{self.server.host}:{self.server.port}" if host is None else host
        head = [f"{method} {target} HTTP/1.1", f"Host: {host}", "Connection: close",
                f"Content-Length: {len(body)}"] + [f"{k}: {v}" for k, v in headers]
        raw = ("\r\n".join(head) + "\r\n\r\n").encode("utf-8") + body
        with socket.create_connection((self.server.host, self.server.port), timeout=60) as s:
            s.sendall(raw)
            data = b""
            while b"\r\n\r\n" not in data:
                chunk = s.recv(65536)
                if not chunk:
                    break
                data += chunk
            top, _, payload = data.partition(b"\r\n\r\n")
            lines = top.decode("latin-1").split("\r\n")
            status = int(lines[0].split()[1])
            heads: dict[str, list[str]] = collections.defaultdict(list)
            for line in lines[1:]:
                k, _, v = line.partition(":")
                heads[k.strip().lower()].append(v.strip())
            # read the body by its length: the server may keep the socket open while it drains an unread request body
            length = 0 if method == "HEAD" else int(heads.get("content-length", ["-1"])[0])
            while length < 0 or len(payload) < length:
                chunk = s.recv(65536)
                if not chunk:
                    break
                payload += chunk
        return status, heads, payload

    def flashes(self, heads: dict) -> list[tuple[str, str]]:
        """The messages the response's session cookie carries (category, text)."""
        for c in heads.get("set-cookie", []):
            if c.startswith("session="):
                value = c.split(";")[0][len("session="):]
                if value:
                    return [tuple(f) for f in self.serializer.loads(value).get("_flashes", [])]
        return []


def routes(app) -> list[tuple[str, list[str], set[str]]]:
    """(rule, its argument names, its methods) of every route of the app."""
    return [(r.rule, sorted(r.arguments), set(r.methods)) for r in app.url_map.iter_rules()]


@st.composite
def requests(draw, route, links):
    """One request to `route`. Hypothesis leans to the simplest draw (0, False, the first element), so the simplest
    request is the plausible one (signed in, allowed method, good CSRF token, good field values) and the odd ones
    are the deviations from it."""
    rule, args, methods = route
    values = {}
    for a in args:
        if a == "token":
            values[a] = draw(st.sampled_from([links["token"], links["token"], links["revoked"],
                                              links["token"][:-1] + "A", "not-a-token", draw(text)]))
        elif a == "pid":
            values[a] = draw(ids)
        elif a == "entry_round":
            values[a] = str(draw(st.integers(-3, 2 ** 70)))
        else:  # the static files
            values[a] = draw(st.sampled_from(["survey.css", "console.js", "nope.js", "../__init__.py", "é"]))
    path = rule
    for a, v in values.items():
        path = re.sub(rf"<(?:[a-z]+:)?{a}>", urllib.parse.quote(v, safe=""), path)
    spelling = draw(st.integers(0, 9))  # mostly as is; else the same path percent-encoded another way
    if spelling == 8:    # every character of the path percent-encoded (the slashes kept)
        path = "/".join("".join(c if c == "%" else f"%{ord(c):02X}" for c in seg) if "%" not in seg
                        else seg for seg in path.split("/"))
    elif spelling == 9:  # the slashes after the first percent-encoded, or doubled
        path = "/" + path[1:].replace("/", draw(st.sampled_from(["%2F", "%2f", "//"])))
    allowed = sorted(methods - {"OPTIONS", "HEAD"})
    method = draw(st.sampled_from(allowed)) if draw(st.integers(0, 9)) < 8 else draw(st.sampled_from(METHODS))
    query = draw(st.dictionaries(st.one_of(st.sampled_from(["next", "date", "saved", "_method"]), text), value,
                                 max_size=3))
    form = {}  # the app's field names with mostly plausible values, so that requests get past the first check
    for k in draw(st.lists(st.one_of(st.sampled_from(FIELDS), text), max_size=8, unique=True)):
        form[k] = GOOD[k] if k in GOOD and not draw(st.booleans()) else draw(value)
    kind = draw(st.sampled_from(["none", "form", "form", "form", "json", "multipart", "raw", "deep"]))
    headers: list[tuple[str, str]] = []
    body = b""
    if kind == "form":
        body = urllib.parse.urlencode(form).encode()
        headers.append(("Content-Type", "application/x-www-form-urlencoded"))
    elif kind == "json":
        doc = draw(st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | text,
                                lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
                                    st.sampled_from(["item", "value", "csrf"]) | text, inner, max_size=3),
                                max_leaves=6))
        body = json.dumps(doc).encode()
        headers.append(("Content-Type", "application/json"))
    elif kind == "deep":  # JSON nested past any parser's recursion limit
        depth = draw(st.sampled_from([33, 500, 1000, 5000, 20000]))
        opener = draw(st.sampled_from(["[", '{"item": ', '{"value": [']))
        body = (opener * depth + "1" + {"[": "]", '{"item": ': "}", '{"value": [': "]}"}[opener] * depth).encode()
        headers.append(("Content-Type", "application/json"))
    elif kind == "multipart":
        b = "fuzzboundary"
        parts = [f'--{b}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n{v}\r\n' for k, v in form.items()
                 if '"' not in k and "\r" not in k and "\n" not in k]
        name = draw(st.sampled_from(["log.csv", "log.parquet", "", "../x.csv", "é.csv", "log", "a" * 300 + ".csv",
                                     "é" * 200 + ".csv", "x." + "c" * 300, "/" * 300,
                                     "P001\t\x07\u202evsc.csv", "C:\\\\Users\\\\a\\\\log.csv"]))
        content = draw(st.sampled_from(["t_s,v_mps\n0,1\n", "", "\x00\x01", "a,b\n1"]))
        parts.append(f'--{b}\r\nContent-Disposition: form-data; name="file"; filename="{name}"\r\n'
                     f"Content-Type: text/csv\r\n\r\n{content}\r\n--{b}--\r\n")
        body = "".join(parts).encode()
        headers.append(("Content-Type", f"multipart/form-data; boundary={b}"))
    elif kind == "raw":
        body = draw(st.binary(max_size=200))
        headers.append(("Content-Type", draw(st.sampled_from(["application/json", "text/plain", "multipart/form-data",
                                                               "application/x-www-form-urlencoded; charset=latin-9"]))))
    extra = draw(st.lists(st.tuples(st.sampled_from(["X-Requested-With", "X-Forwarded-For", "X-Forwarded-Proto",
                                                     "Accept", "Referer", "Range", "If-None-Match"]),
                                    st.one_of(st.sampled_from(["XMLHttpRequest", "https", "1.2.3.4"]),
                                              st.text(st.characters(min_codepoint=32, max_codepoint=126),
                                                      max_size=20))), max_size=2))
    target = path + ("?" + urllib.parse.urlencode(query) if query else "")
    host = None if draw(st.integers(0, 9)) < 9 else draw(st.sampled_from(BAD_HOSTS))
    return {"method": method, "target": target, "headers": headers + extra, "body": body, "host": host,
            "signed_in": draw(st.integers(0, 4)) < 4, "good_csrf": draw(st.integers(0, 9)) < 9,
            "route": (rule, tuple(sorted(methods)))}


@pytest.mark.slow
def test_no_request_is_answered_5xx_and_refusals_change_nothing(served):
    store, app, server, links = served
    client = Client(app, server)
    rules = routes(app)
    seen: collections.Counter = collections.Counter()
    by_route: collections.Counter = collections.Counter()

    def one(req):
        cookie, csrf = client.cookie(req["signed_in"])
        body = req["body"]
        if req["good_csrf"] and body and req["headers"][0][1] == "application/x-www-form-urlencoded":
            body += b"&csrf=" + urllib.parse.quote(csrf).encode()  # most forms get past the CSRF check
        before = fingerprint(store)
        status, heads, payload = client.send(req["method"], req["target"], [("Cookie", cookie), *req["headers"]],
                                             body, req["host"])
        seen[status] += 1
        by_route[req["route"]] += 1
        assert status < 500, f"{req['method']} {req['target']!r}: {status}\n{payload[:2000]!r}"
        refused = status >= 400 or any(cat == "error" for cat, _ in client.flashes(heads))
        if refused:
            assert fingerprint(store) == before, f"{req['method']} {req['target']!r} was refused ({status}) " \
                                                 "but changed the store"
        page = payload.decode("utf-8", "replace")
        m = re.search(r'<section class="card message" role="alert">\s*<h1>[^<]*</h1>\s*<p>(.*?)</p>', page, re.S)
        if m:
            assert "\n" not in m.group(1), m.group(1)
        for location in heads.get("location", []):
            assert len(location) < 1000, f"a redirect echoed {len(location)} characters"

    for route in rules:  # each route its own run: every route gets PER_ROUTE requests
        run = settings(max_examples=PER_ROUTE, derandomize=True, deadline=None, database=None,
                       suppress_health_check=list(HealthCheck))(given(requests(route, links))(lambda req: one(req)))
        run()
    total = sum(seen.values())
    print(f"\nweb fuzz: {total} requests over {len(by_route)} of {len(rules)} routes; status histogram "
          + ", ".join(f"{code}: {n}" for code, n in sorted(seen.items())))
    assert len(by_route) == len(rules) and min(by_route.values()) >= PER_ROUTE

"""What no single client may do to the survey server: hold the store while it dribbles a body, take every worker
unnoticed, guess passwords in parallel past the throttle, crash a request with its Host header, a deeply nested JSON
body or a long upload file name, or get a link token into the access log by spelling the path differently. The real
server (werkzeug, threaded) over a socket on a real store."""
from __future__ import annotations

import html
import io
import json
import logging
import socket
import threading
import urllib.parse
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from study.logs.importing import ORIGINAL_NAME_MAX
from study.survey import answers as sv
from study.webapp import SurveyServer, create_app, guard
from study.webapp.console import UPLOAD_NAME_MAX, upload_name
from study.webapp.server import redact
from study.webapp.signin import SignInSettings
from tests.study.test_console import snapshot
from tests.study.test_drive_import import make_drive

PASSWORD = "correct horse"


def raw(srv, data: bytes, timeout: float = 30) -> tuple[int, dict, bytes]:
    """Send `data` as is; (status, lower-case headers, body) of the answer."""
    with socket.create_connection((srv.host, srv.port), timeout=timeout) as c:
        c.sendall(data)
        got = b""
        while chunk := c.recv(65536):
            got += chunk
    head, _, body = got.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    heads = {k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
    return int(lines[0].split()[1]), heads, body


def answer(c: socket.socket) -> str:
    """All the server sends until it closes (the status line and the body may come in two packets)."""
    got = b""
    while chunk := c.recv(65536):
        got += chunk
    return got.decode("latin-1")


def post(path: str, body: bytes, ctype: str = "application/json", host: str = "127.0.0.1", length=None) -> bytes:
    return (f"POST {path} HTTP/1.1\r\nHost: {host}\r\nContent-Type: {ctype}\r\nConnection: close\r\n"
            f"Content-Length: {len(body) if length is None else length}\r\n\r\n").encode() + body


@pytest.fixture
def served(console_store):
    """(store, server, tokens of P001 and P002)."""
    tokens = {p: sv.issue_link(console_store, p) for p in ("P001", "P002")}
    srv = SurveyServer(create_app(console_store, PASSWORD), quiet=True).start()
    yield console_store, srv, tokens
    srv.close()


def slow_client(srv, token: str) -> socket.socket:
    """A participant's answer announcing 100 bytes and sending 9, then silent."""
    c = socket.create_connection((srv.host, srv.port))
    c.sendall(post(f"/s/{token}/answer", b'{"item":"', length=100))
    return c


# ---------------------------------------------------------------------------------------------- the store lock
def test_a_stalled_body_never_holds_the_store(console_store, monkeypatch):
    """Ten clients stall mid-body on their own answer URL (the read timeout raised to 60 s, so a lock held while
    waiting would hold it for a minute): another participant's answer and a researcher page are served meanwhile."""
    monkeypatch.setattr(guard, "READ_TIMEOUT_S", 60.0)
    tokens = {p: sv.issue_link(console_store, p) for p in ("P001", "P002")}
    with SurveyServer(create_app(console_store, PASSWORD), quiet=True) as srv:
        slow = [slow_client(srv, tokens["P001"]) for _ in range(10)]
        try:
            status, _, body = raw(srv, post(f"/s/{tokens['P002']}/answer", b'{"item": "PU1", "value": 3}'),
                                  timeout=20)
            assert status == 200 and json.loads(body)["ok"] is True
            assert raw(srv, b"GET /r/login HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", timeout=20)[0] == 200
        finally:
            for c in slow:
                c.close()
    assert set(sv.draft(console_store, "P002")) == {"PU1"} and sv.draft(console_store, "P001") == {}


def test_a_stalled_body_is_answered_408_after_the_read_timeout(console_store, monkeypatch):
    monkeypatch.setattr(guard, "READ_TIMEOUT_S", 0.5)
    token = sv.issue_link(console_store, "P001")
    before = snapshot(console_store)
    with SurveyServer(create_app(console_store, PASSWORD), quiet=True) as srv:
        c = slow_client(srv, token)
        c.settimeout(20)
        head = answer(c)
        c.close()
    assert head.startswith("HTTP/1.1 408") and "did not arrive in time" in head
    assert snapshot(console_store) == before


def test_a_body_shorter_than_announced_is_refused(served):
    store, srv, tokens = served
    before = snapshot(store)
    with socket.create_connection((srv.host, srv.port), timeout=20) as c:
        c.sendall(post(f"/s/{tokens['P001']}/answer", b'{"item":"', length=100))
        c.shutdown(socket.SHUT_WR)            # the client is done: the body ends 91 bytes early
        head = answer(c)
    assert head.startswith("HTTP/1.1 400") and "ended before its announced length" in head
    assert snapshot(store) == before


def test_beyond_its_workers_the_server_answers_503_with_retry_after(console_store):
    with SurveyServer(create_app(console_store, PASSWORD), quiet=True, workers=2) as srv:
        stalled = [socket.create_connection((srv.host, srv.port)) for _ in range(2)]
        try:
            status, heads, body = raw(srv, b"GET /r/login HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            assert status == 503 and int(heads["retry-after"]) > 0 and b"busy" in body
        finally:
            for c in stalled:
                c.close()
        for _ in range(50):  # the two workers come free once their clients have gone
            if raw(srv, b"GET /r/login HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")[0] == 200:
                break
            threading.Event().wait(0.1)
        else:
            pytest.fail("the workers never came free")


# ---------------------------------------------------------------------------------------------- the throttle
@pytest.mark.parametrize("form", ["sign-in", "password change"])
def test_parallel_wrong_passwords_check_at_most_the_limit(console_store, form):
    """30 wrong passwords at once for one name: at most 5 are checked (401/400), the rest refused while locked (429)."""
    app = create_app(console_store, PASSWORD, signin=SignInSettings(max_failures=5, lockout_s=300))
    si = app.extensions["signin"]
    checked = []
    check = si.check
    si.check = lambda pw: checked.append(pw) or check(pw)
    with SurveyServer(app, quiet=True) as srv:
        serializer = app.session_interface.get_signing_serializer(app)
        if form == "sign-in":
            cookie = serializer.dumps({"login_csrf": "t"})
            path, body = "/r/login", b"csrf=t&name=Ann&password=wrong"
        else:
            sid = si.sessions.create("Ann")
            cookie = serializer.dumps({"sid": sid})
            csrf = urllib.parse.quote(si.sessions.get(sid).csrf)
            path, body = "/r/password", f"csrf={csrf}&current=wrong&new=x{'y' * 12}&confirm=x{'y' * 12}".encode()
        request = (f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nCookie: session={cookie}\r\nContent-Type: "
                   f"application/x-www-form-urlencoded\r\nContent-Length: {len(body)}\r\n\r\n").encode() + body
        with ThreadPoolExecutor(max_workers=30) as pool:
            codes = list(pool.map(lambda _: raw(srv, request, timeout=120)[0], range(30)))
    wrong = 401 if form == "sign-in" else 400
    assert len(checked) <= 5 and codes.count(wrong) == len(checked) and codes.count(429) == 30 - len(checked)


# ---------------------------------------------------------------------------------------------- no 5xx
@pytest.mark.parametrize("host", ["a..b", "x" * 64 + ".example", "é.example", "a b", "-a.example", "[::1", ".",
                                  "127.0.0.1:99999999"])
def test_a_host_that_names_no_host_is_400_on_every_route(served, host):
    store, srv, tokens = served
    for path in ("/", "/r/login", f"/s/{tokens['P001']}", "/nope"):
        status, _, body = raw(srv, f"GET {path} HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
        assert status == 400 and b"Host" in body, (host, path, status)
    assert raw(srv, post(f"/s/{tokens['P001']}/answer", b'{"item": "PU1", "value": 3}', host=host))[0] == 400


@pytest.mark.parametrize("host", ["127.0.0.1:8000", "localhost", "survey.lab.example.org", "[::1]:80",
                                  "xn--bcher-kva.example"])
def test_a_good_host_is_served(served, host):
    assert raw(served[1], f"GET /r/login HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())[0] == 200


@pytest.mark.parametrize("depth", [33, 1000, 20_000])
def test_deep_json_is_a_400_not_a_crash(served, depth):
    store, srv, tokens = served
    before = snapshot(store)
    for body in ("[" * depth + "]" * depth, '{"item": ' * depth + "1" + "}" * depth):
        status, _, payload = raw(srv, post(f"/s/{tokens['P001']}/answer", body.encode()))
        assert status == 400 and json.loads(payload)["error"] == "expected item and value"
    assert snapshot(store) == before


def test_json_depth_is_counted_outside_strings():
    assert not guard.json_too_deep('{"item": "' + "[" * 1000 + '", "value": 3}')
    assert not guard.json_too_deep("[" * 32 + "]" * 32) and guard.json_too_deep("[" * 33 + "]" * 33)
    assert guard.json_too_deep(b'{"a": [{"b": "\\"]"' + b"[" * 40)


@pytest.mark.parametrize("name, saved", [("a" * 300 + ".csv", "a" * (UPLOAD_NAME_MAX - 4) + ".csv"),
                                         ("é" * 150 + ".csv", "e" * (UPLOAD_NAME_MAX - 4) + ".csv"), ("../../x.csv", "x.csv"),
                                         ("log." + "p" * 40, "log." + "p" * 40), ("ab" * 100, "ab" * 50)])
def test_an_upload_name_is_saved_short_and_without_a_directory(name, saved):
    assert upload_name(name) == saved and len(saved) <= UPLOAD_NAME_MAX


def upload(client, name: str, n: int = 200, pid: str = "P001", condition: str = "baseline"):
    buf = io.BytesIO()
    make_drive(n).to_csv(buf, index=False)
    return client.post(f"/r/p/{pid}/drive", data={"csrf": client.csrf, "condition": condition,
                                                   "file": (io.BytesIO(buf.getvalue()), name)},
                       content_type="multipart/form-data")


@pytest.fixture
def saved_paths(monkeypatch):
    """The paths the console hands to the importer (the file on the server's disk)."""
    from study.logs import importing

    paths, real = [], importing.import_drive_file
    monkeypatch.setattr(importing, "import_drive_file", lambda st, pid, cond, path, **kw: (
        paths.append(Path(path)), real(st, pid, cond, path, **kw))[1])
    return paths


def test_a_300_byte_upload_file_name_is_saved_short_and_kept_as_255_characters(console_store, console_client,
                                                                              saved_paths):
    name = "é" + "a" * 300 + ".csv"
    assert upload(console_client, name).status_code == 303
    assert saved_paths[0].name == "e" + "a" * (UPLOAD_NAME_MAX - 5) + ".csv"
    assert console_store.one("SELECT file_name FROM drives") == name[:ORIGINAL_NAME_MAX - 1] + "…"


@pytest.mark.parametrize("sent, kept", [
    ("Fahrt 3 – Müller (Kopie).csv", "Fahrt 3 – Müller (Kopie).csv"),
    ("/home/anna/Desktop/P001 baseline.csv", "P001 baseline.csv"),
    ("../../etc/P001.csv", "P001.csv"),
    ("P001\t<b>base\x07line\u202evsc.csv", "P001\\t<b>base\\x07line\\u202evsc.csv"),
])
def test_the_client_file_name_is_kept_with_the_drive_and_shown_while_the_disk_name_is_safe(
        console_store, console_client, saved_paths, sent, kept):
    """The name the lab uploaded is the drive's file_name and the participant page shows it (escaped as HTML);
    the file on disk had a safe name in a fresh folder of its own; the store has no trace of that folder."""
    assert upload(console_client, sent).status_code == 303
    assert console_store.one("SELECT file_name FROM drives") == kept
    with console_client.session_transaction() as sess:
        assert f"read 200 rows from {kept};" in sess["_flashes"][0][1]
    disk = saved_paths[0]
    assert disk.name == upload_name(sent) and disk.parent.name.startswith("pedas-upload-")
    assert not disk.parent.exists()                                      # removed after the import
    page = console_client.get("/r/p/P001").get_data(as_text=True)
    assert html.escape(kept, quote=False) in page and "<b>base" not in page
    assert str(disk.parent) not in console_store.df("SELECT * FROM drives").to_csv()


def test_a_refused_upload_names_the_client_file_not_the_server_path(console_store, console_client, saved_paths):
    r = upload(console_client, "P001 kurz\t.csv", n=1)
    assert r.status_code == 303
    with console_client.session_transaction() as sess:
        message = " ".join(m for _, m in sess.get("_flashes", []))
    assert message.startswith("P001 kurz\\t.csv") and str(saved_paths[0].parent) not in message
    assert console_store.one("SELECT count(*) FROM drives") == 0


# ---------------------------------------------------------------------------------------------- the access log
@pytest.mark.parametrize("spelling", ["/s/{t}", "/s/%{h}{rest}", "/s/{enc}", "/%73/{t}", "/s%2F{t}", "//s/{t}",
                                      "/./s/{t}/answer", "/S/{t}", "/s/{t}?x=1", "/r/login?next=%2Fs%2F{t}",
                                      "/s/%25{h}{rest}"])
def test_the_access_log_never_shows_a_token(spelling):
    t = "Ab3_-xYz0123456789abcdefghijklmnopqrstuvwxy"
    path = spelling.format(t=t, h=f"{ord(t[0]):02X}", rest=t[1:], enc="".join(f"%{b:02x}" for b in t.encode()))
    line = redact(f'"GET {path} HTTP/1.1" 200 -')
    assert t[1:] not in line and t[1:].lower() not in urllib.parse.unquote(line).lower(), line
    assert line.startswith('"GET ') and line.endswith(' HTTP/1.1" 200 -') and "<token>" in line


def test_the_served_access_log_redacts_a_percent_encoded_link(console_store, caplog):
    t = sv.issue_link(console_store, "P001")
    with caplog.at_level(logging.INFO), SurveyServer(create_app(console_store, PASSWORD)) as srv:
        enc = "".join(f"%{b:02X}" for b in t.encode())
        for path in (f"/s/%{ord(t[0]):02X}{t[1:]}", f"/s/{enc}", f"/%73/{t}"):
            assert raw(srv, f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())[0] == 200
    err = caplog.text
    assert err.count("/s/<token>") >= 3 and t[4:] not in err and t[4:] not in urllib.parse.unquote(err)

"""What every request passes before the app sees it (a WSGI middleware): a Host header that names a host, and the
whole body read (size-limited, with a read timeout) before any view runs; and JSON bodies of a bounded depth.

A view may take the store's lock and only then look at the body (a participant's answer is checked and saved under
one lock); were the body still on the wire, a client that announces 100 bytes and sends 9 would hold the lock,
and with it every other request, until it gave up. Read here first, a slow or stalled client costs the one worker
thread serving it, never the store.
"""
from __future__ import annotations

import io
import re
import tempfile
import time
from typing import Callable

from flask.json.provider import DefaultJSONProvider
from werkzeug.wsgi import ClosingIterator

READ_TIMEOUT_S = 10.0          # the longest a client may stay silent while sending a request (socket timeout)
MIN_RATE = 256 * 1024          # bytes/s a body must average beyond the first READ_TIMEOUT_S
IN_MEMORY = 512 * 1024         # bytes of a body kept in memory; a larger one is spooled to a temporary file
_LABEL = r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)"
_HOST = re.compile(rf"(?:{_LABEL}(?:\.{_LABEL})*\.?|\[[0-9A-Fa-f:.]{{2,45}}\])(?::[0-9]{{1,5}})?")


def good_host(host: str) -> bool:
    """Whether `host` (a Host header) is a DNS name of 1-63-character ASCII labels, an IPv4 or a bracketed IPv6
    address, with an optional port: the only hosts a URL can be built for (an IDN arrives punycode-encoded)."""
    return len(host) <= 260 and _HOST.fullmatch(host) is not None


REFUSED = "study.webapp.refused"  # environ key: (status, text) of a body the guard could not read
_REFUSALS = {"timeout": (408, "The request body did not arrive in time."),
             "large": (413, "The request body is larger than this address accepts."),
             "short": (400, "The request body ended before its announced length."),
             "length": (400, "The Content-Length header is not a length.")}


def _plain(start_response, status: str, text: str) -> list[bytes]:
    body = (text + "\n").encode()
    start_response(status, [("Content-Type", "text/plain; charset=utf-8"), ("Content-Length", str(len(body))),
                            ("Connection", "close")])
    return [body]


class Guard:
    """WSGI middleware in front of the app. `limit(path)` = the largest body (bytes) a request to `path` may send.

    * a Host header that is no host name (``a..b``, a label over 63 characters, non-ASCII) -> 400 (plain text:
      no page can be built for such a host);
    * a Content-Length over the limit: left to the app, which refuses it (413) before reading a byte;
    * a body not complete within READ_TIMEOUT_S plus its length at MIN_RATE (or silent for READ_TIMEOUT_S) -> 408,
      a chunked body over the limit -> 413, a body that ends early (the client closed) -> 400: the app gets the
      request without its body and with ``environ[REFUSED] = (status, text)``, and answers that (:func:`refuse`).

    The app then reads the body from memory (or a temporary file), never from the client."""

    def __init__(self, app, limit: Callable[[str], int]) -> None:
        self.app, self.limit = app, limit

    def __call__(self, environ, start_response):
        host = environ.get("HTTP_HOST")
        if host is not None and not good_host(host):
            return _plain(start_response, "400 Bad Request", "Bad request: the Host header names no host.")
        chunked = bool(environ.get("wsgi.input_terminated"))
        try:
            length = int(environ.get("CONTENT_LENGTH") or 0)
        except ValueError:
            length = -1
        if length < 0:
            return self._refused(environ, start_response, "length")
        if not chunked and length == 0:
            return self.app(environ, start_response)
        limit = self.limit(environ.get("PATH_INFO", ""))
        if length > limit:  # the app refuses it (413) from its length, before reading a byte
            return self.app(environ, start_response)
        spool = tempfile.SpooledTemporaryFile(max_size=IN_MEMORY)
        try:
            got = _read(environ["wsgi.input"], spool, None if chunked else length, limit,
                        time.monotonic() + READ_TIMEOUT_S + length / MIN_RATE)
        except OSError:  # the socket timeout: silent for READ_TIMEOUT_S
            got = "timeout"
        if isinstance(got, str):
            spool.close()
            return self._refused(environ, start_response, got)
        spool.seek(0)
        environ["wsgi.input"] = spool
        if chunked:  # a dechunked body now has a known length
            environ["CONTENT_LENGTH"] = str(got)
        try:
            result = self.app(environ, start_response)
        except BaseException:
            spool.close()
            raise
        return ClosingIterator(result, [spool.close])

    def _refused(self, environ, start_response, why: str):
        """The app answers the refusal (its own page or JSON), with no body left to read."""
        environ.update({"wsgi.input": io.BytesIO(b""), "CONTENT_LENGTH": "0", "wsgi.input_terminated": False,
                        REFUSED: _REFUSALS[why]})
        return self.app(environ, start_response)


def refuse() -> None:
    """In the app, before any view: abort with the guard's refusal of the request's body, if there is one."""
    from flask import abort, request

    refused = request.environ.get(REFUSED)
    if refused:
        abort(*refused)


def _read(stream, out, length: int | None, limit: int, deadline: float) -> int | str:
    """Copy `length` bytes (None: to the end) of `stream` into `out`: the count, or "timeout" (past `deadline`),
    "large" (over `limit`), "short" (ended before `length`)."""
    read = getattr(stream, "read1", stream.read)  # read1: one socket read, so a trickle cannot outlast the deadline
    got = 0
    while length is None or got < length:
        if time.monotonic() > deadline:
            return "timeout"
        want = 65536 if length is None else min(65536, length - got)
        data = read(want)
        if not data:
            return got if length is None else "short"
        got += len(data)
        if got > limit:
            return "large"
        out.write(data)
    return got



# ---------------------------------------------------------------------------------------------- JSON depth
MAX_JSON_DEPTH = 32            # nesting levels of a JSON body (an answer is one flat object)
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
_BRACKET = re.compile(r"[\[\]{}]")


def json_too_deep(text: str | bytes, limit: int = MAX_JSON_DEPTH) -> bool:
    """Whether the JSON text nests arrays/objects deeper than `limit` (strings skipped), found without parsing it:
    Python's parser recurses once per level and fails (RecursionError) near 1,000."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text).decode("utf-8", "replace")
    depth = 0
    for m in _BRACKET.finditer(_JSON_STRING.sub("", text)):
        depth += 1 if m.group(0) in "[{" else -1
        if depth > limit:
            return True
    return False


class DepthLimitedJSON(DefaultJSONProvider):
    """Flask's JSON, refusing a body nested deeper than MAX_JSON_DEPTH as malformed (ValueError: a 400, or None
    for ``get_json(silent=True)``) before it is parsed."""

    def loads(self, s, **kwargs):
        if json_too_deep(s):
            raise ValueError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels")
        return super().loads(s, **kwargs)

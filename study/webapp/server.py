"""Running the app: a werkzeug threaded server in a background thread (for `survey serve` and the tests), with a
bounded number of worker threads (a request beyond them is answered 503 with Retry-After at once), a read timeout
on every connection (:data:`study.webapp.guard.READ_TIMEOUT_S`), and an access log that never shows a link token."""
from __future__ import annotations

import re
import threading
import urllib.parse

from flask import Flask

WORKERS = 32      # requests served at once; one more is answered 503 (each stalled client costs one of them)
RETRY_AFTER_S = 2
_TOKEN_PATH = re.compile(r"/+(?:\.+/+)*s/+[^/?#\s\"']+", re.IGNORECASE)
_BUSY_TEXT = b"The survey server is busy. Please try again in a moment.\n"
_BUSY = (b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\nRetry-After: %d\r\n"
         b"Content-Length: %d\r\nConnection: close\r\n\r\n%s" % (RETRY_AFTER_S, len(_BUSY_TEXT), _BUSY_TEXT))


def _decoded(word: str) -> str:
    """`word` percent-decoded until nothing changes (at most three rounds), backslashes read as slashes."""
    for _ in range(3):
        nxt = urllib.parse.unquote(word, errors="replace")
        if nxt == word:
            break
        word = nxt
    return word.replace("\\", "/")


def redact(text: str) -> str:
    """`text` with every participant link path shown as ``/s/<token>``, however it is spelt: percent-encoded
    (``/s/%48…``, ``/%73/…``, ``/s%2F…``), with repeated slashes or dot segments. A word that spells a link path
    is shown decoded and redacted (its control characters escaped); every other word as it was."""
    def one(m: re.Match) -> str:
        word = m.group(0)
        plain = _decoded(word)
        if not _TOKEN_PATH.search(plain):
            return word
        shown = _TOKEN_PATH.sub("/s/<token>", plain)
        return shown.encode("unicode_escape").decode("ascii") if not shown.isprintable() else shown
    return re.sub(r"\S+", one, text)


class SurveyServer:
    """``port=0`` picks a free port; :attr:`url` is the base address; :meth:`close` stops the server. At most
    `workers` requests are served at once."""

    def __init__(self, app: Flask, host: str = "127.0.0.1", port: int = 0, quiet: bool = False,
                 workers: int = WORKERS) -> None:
        self.app = app
        self.server = _server(workers)(host, port, app, _handler(quiet))
        self.host, self.port = host, self.server.server_port
        self.thread = threading.Thread(target=self.server.serve_forever, name="survey-server", daemon=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def start(self) -> "SurveyServer":
        self.thread.start()
        return self

    def close(self) -> None:
        """Stop serving and wait for a request still using the store; the store may be closed afterwards."""
        from study.webapp.context import close

        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=10)
        close(self.app)

    def __enter__(self) -> "SurveyServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


def _server(workers: int):
    """werkzeug's threaded server with at most `workers` request threads: a connection beyond them gets 503 and
    Retry-After from the accepting thread (what arrived of its request read first, so the client sees the answer)."""
    import socket

    from werkzeug.serving import ThreadedWSGIServer

    class Server(ThreadedWSGIServer):
        slots = threading.BoundedSemaphore(workers)

        def process_request(self, request, client_address):
            if not self.slots.acquire(blocking=False):
                try:
                    request.setblocking(False)
                    try:
                        request.recv(65536)
                    except OSError:
                        pass
                    request.setblocking(True)
                    request.settimeout(1.0)
                    request.sendall(_BUSY)
                    request.shutdown(socket.SHUT_WR)
                except OSError:
                    pass
                self.shutdown_request(request)
                return
            try:
                super().process_request(request, client_address)
            except BaseException:
                self.slots.release()
                raise

        def process_request_thread(self, request, client_address):
            try:
                super().process_request_thread(request, client_address)
            finally:
                self.slots.release()

    return Server


def _handler(quiet: bool):
    """A werkzeug request handler with a read timeout, whose access log never shows a participant's link token."""
    from werkzeug.serving import WSGIRequestHandler

    from study.webapp.guard import READ_TIMEOUT_S

    class Handler(WSGIRequestHandler):
        timeout = READ_TIMEOUT_S  # the socket's: a silent client is dropped (request line, headers, body)

        def log_request(self, code="-", size="-"):
            if quiet:
                return
            path = redact(getattr(self, "path", "") or "?")
            self.log("info", '"%s %s %s" %s %s', getattr(self, "command", "-"), path,
                     getattr(self, "request_version", "-"), code, size)

        def log_error(self, *args):
            if not quiet:
                super().log_error(*args)

        def log(self, type, message, *args):
            # every line redacted: http.server puts the raw request line into some errors ("Bad request syntax")
            super().log(type, "%s", redact(message % args if args else message))

    return Handler

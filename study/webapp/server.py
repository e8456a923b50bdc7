"""Running the app: a werkzeug threaded server in a background thread (for `survey serve` and the tests)."""
from __future__ import annotations

import re
import threading

from flask import Flask

_TOKEN_PATH = re.compile(r"/s/[A-Za-z0-9_-]+")


def redact(text: str) -> str:
    """`text` with every participant link path ``/s/<token>`` shown as ``/s/<token>`` (log lines never carry one)."""
    return _TOKEN_PATH.sub("/s/<token>", text)


class SurveyServer:
    """``port=0`` picks a free port; :attr:`url` is the base address; :meth:`close` stops the server."""

    def __init__(self, app: Flask, host: str = "127.0.0.1", port: int = 0, quiet: bool = False) -> None:
        from werkzeug.serving import make_server

        self.app = app
        self.server = make_server(host, port, app, threaded=True, request_handler=_handler(quiet))
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


def _handler(quiet: bool):
    """A werkzeug request handler whose access log never shows a participant's link token."""
    from werkzeug.serving import WSGIRequestHandler

    class Handler(WSGIRequestHandler):
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

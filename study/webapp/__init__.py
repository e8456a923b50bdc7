"""The survey web app: Flask, server-rendered Jinja2 templates, one small CSS and one JS file served locally.

* participant mode ``/s/<token>`` (:mod:`study.webapp.participant`): one participant's questionnaire behind a
  one-time link, answers saved as they are given, atomic submission, read-only afterwards;
* researcher mode ``/r/`` (:mod:`study.webapp.researcher`): password + name (hardened sign-in,
  :mod:`study.webapp.signin`), links, paper-form double entry, discrepancies, resolutions;
* the researcher console ``/r/...`` (:mod:`study.webapp.console`): the study day in one place (agenda,
  registration, phases, exclusions, drive uploads, links with QR code, completeness, exports).

The app opens the store only while a request uses it, one request at a time, so CLI commands can work on the
same file between requests (:mod:`study.webapp.context`, docs/store.md); :class:`SurveyServer` runs it on a
threaded werkzeug server.

The top of study/: it may import every other package of study/ (the console shows and changes all of them).
"""
from __future__ import annotations

import secrets
from pathlib import Path

from flask import Flask, current_app, g, jsonify, render_template, request
from flask.sessions import SecureCookieSessionInterface
from werkzeug.exceptions import HTTPException

from study.common.errors import UserError
from study.webapp import console, participant, researcher
from study.webapp.context import install, message, new_state
from study.webapp.guard import DepthLimitedJSON, Guard, refuse
from study.webapp.server import SurveyServer, redact
from study.webapp.signin import SignIn, SignInSettings
from study.webapp.widgets import check_renderable, widget

__all__ = ["create_app", "SurveyServer", "check_renderable", "widget"]
HERE = Path(__file__).parent
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; form-action 'self'; "
       "frame-ancestors 'none'")


class _App(Flask):
    """Flask, whose error log never shows a participant's link token (the path and the traceback redacted)."""

    def log_exception(self, exc_info) -> None:
        import traceback

        text = "".join(traceback.format_exception(*exc_info)) if exc_info[0] else ""
        self.logger.error(redact(f"Exception on {request.path} [{request.method}]\n{text}".rstrip()))


def _body_limit(app: Flask):
    """The largest body (bytes) a request to a path may send: a drive-log upload's, else the app's limit."""
    def limit(path: str) -> int:
        try:
            endpoint = app.url_map.bind("localhost").match(path, method="POST")[0]
        except Exception:  # no route (404/405/redirect): the general limit
            endpoint = None
        return console.DRIVE_UPLOAD_MAX if endpoint == "console.upload_drive" else app.config["MAX_CONTENT_LENGTH"]
    return limit


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _refused(status: int, title: str, text: str, headers=()):
    """A refused request: JSON {"error"} for the answer endpoint (a script reads it), else the message page."""
    if request.path.endswith("/answer"):
        resp = jsonify(error=text)
        resp.status_code = status
    else:
        resp = current_app.make_response(message(title, text, status))
    for name, value in headers:
        resp.headers[name] = value
    return resp


def http_error(exc: HTTPException):
    """Every HTTP error (404, 405, 413, ...) as one line, keeping the headers that belong to it (Allow, ...)."""
    keep = [(k, v) for k, v in exc.get_headers() if k in ("Allow", "Retry-After", "WWW-Authenticate")]
    return _refused(exc.code or 400, exc.name, _one_line(exc.description or exc.name), keep)


def user_error(exc: UserError):
    """A UserError a view did not answer itself: bad input, so 4xx with its one-line message (a link's own status)."""
    status = getattr(exc, "status", 400)
    return _refused(status if 400 <= status < 500 else 400, "Not possible", _one_line(str(exc)))


class _SessionInterface(SecureCookieSessionInterface):
    """The session cookie gets ``Secure`` when configured so, or ("auto") when the request came over HTTPS."""

    def get_cookie_secure(self, app) -> bool:
        mode = app.extensions["signin"].settings.secure_cookies
        return mode == "always" or bool(request and request.is_secure)


def create_app(st, researcher_password: str, instrument: str | None = None,
               secret_key: str | None = None, signin: SignInSettings | None = None) -> Flask:
    """The Flask app over the store of the open, writable Store `st`, showing the store's study (title,
    description). A participant link shows the form of its own instrument (every instrument of the study, so one
    server serves every questionnaire phase); `instrument` (None = the study's first) is the one the researcher's
    survey-status, paper-entry and discrepancy pages work on. Requests open the store's file themselves (as `st`'s
    actor); `st` may be closed once the app is made. `signin` = how researcher sign-in is guarded and whether a
    TLS proxy is trusted (default :class:`SignInSettings`). An instrument the form cannot show -> UserError."""
    from study.store.studies import definition
    from study.survey.answers import instrument_of

    if not researcher_password:
        raise UserError("a researcher password is required")
    study = definition(st)
    ins = instrument_of(st, instrument)
    check_renderable(ins)
    for other in study.instruments:   # refused at start, never as a link that cannot be shown
        check_renderable(study.instrument(other))
    app = _App(__name__, template_folder=str(HERE / "templates"), static_folder=str(HERE / "static"))
    app.config.update(SECRET_KEY=secret_key or secrets.token_hex(32), SESSION_COOKIE_SAMESITE="Strict",
                      SESSION_COOKIE_HTTPONLY=True, MAX_CONTENT_LENGTH=256 * 1024)
    app.json = DepthLimitedJSON(app)
    app.extensions["survey"] = new_state(st, ins, study)
    app.register_error_handler(HTTPException, http_error)
    app.register_error_handler(UserError, user_error)
    app.before_request(refuse)
    install(app)
    app.extensions["signin"] = SignIn(researcher_password, signin)
    app.session_interface = _SessionInterface()
    app.wsgi_app = Guard(app.wsgi_app, _body_limit(app))  # behind ProxyFix: the host it reports is checked too
    hops = app.extensions["signin"].settings.trust_proxy
    if hops:  # the client address and scheme as the TLS proxy in front reports them (X-Forwarded-For/-Proto)
        from werkzeug.middleware.proxy_fix import ProxyFix

        app.wsgi_app = ProxyFix(app.wsgi_app, x_for=hops, x_proto=hops, x_host=hops)
    app.jinja_env.globals.update(instrument=ins, study=study, widget=widget)
    app.register_blueprint(participant.bp)
    app.register_blueprint(researcher.bp)
    app.register_blueprint(console.bp)

    @app.after_request
    def headers(resp):
        # the link token is in the URL: never send it on as a Referer, never cache a participant page
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["X-Frame-Options"] = "DENY"
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Content-Security-Policy"] = CSP
        if request.endpoint != "static":
            resp.headers["Cache-Control"] = "no-store"
        return resp

    @app.context_processor
    def researcher_context():
        who = g.get("researcher")
        return {"csrf": who.csrf if who else "", "researcher_name": who.name if who else None}

    @app.get("/")
    def home():
        return render_template("home.html")

    return app

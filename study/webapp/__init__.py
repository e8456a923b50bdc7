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
"""
from __future__ import annotations

import secrets
from pathlib import Path

from flask import Flask, g, render_template, request
from flask.sessions import SecureCookieSessionInterface

from study.errors import UserError
from study.instrument import is_scaled
from study.webapp import console, participant, researcher
from study.webapp.context import install, new_state
from study.webapp.server import SurveyServer
from study.webapp.signin import SignIn, SignInSettings

__all__ = ["create_app", "SurveyServer"]
HERE = Path(__file__).parent
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; form-action 'self'; "
       "frame-ancestors 'none'")


def widget(response_type: str) -> str:
    """The form widget of a codebook response type: 'scale' (k radios), 'choice', 'number' or 'text'.

    A type the form cannot show raises UserError: a question without inputs must never be offered."""
    if is_scaled(response_type):
        return "scale"
    if response_type in ("choice", "number", "text"):
        return response_type
    raise UserError(f"the web form cannot show response type {response_type!r}")


def check_renderable(ins) -> None:
    """UserError naming the first item of `ins` the web form cannot show (checked before the server starts)."""
    for item, kind in ins.items["response_type"].items():
        try:
            widget(kind)
        except UserError as exc:
            raise UserError(f"instrument {ins.name}, item {item}: {exc}") from None


class _SessionInterface(SecureCookieSessionInterface):
    """The session cookie gets ``Secure`` when configured so, or ("auto") when the request came over HTTPS."""

    def get_cookie_secure(self, app) -> bool:
        mode = app.extensions["signin"].settings.secure_cookies
        return mode == "always" or bool(request and request.is_secure)


def create_app(st, researcher_password: str, instrument: str | None = None,
               secret_key: str | None = None, signin: SignInSettings | None = None) -> Flask:
    """The Flask app over the store of the open, writable Store `st`, showing the store's study (title,
    description) and `instrument` (None = the study's). Requests open the store's file themselves (as `st`'s
    actor); `st` may be closed once the app is made. `signin` = how researcher sign-in is guarded and whether a
    TLS proxy is trusted (default :class:`SignInSettings`)."""
    from study.studies import definition
    from study.survey import instrument_of

    if not researcher_password:
        raise UserError("a researcher password is required")
    study = definition(st)
    ins = instrument_of(st, instrument)
    check_renderable(ins)
    app = Flask(__name__, template_folder=str(HERE / "templates"), static_folder=str(HERE / "static"))
    app.config.update(SECRET_KEY=secret_key or secrets.token_hex(32), SESSION_COOKIE_SAMESITE="Strict",
                      SESSION_COOKIE_HTTPONLY=True, MAX_CONTENT_LENGTH=256 * 1024)
    app.extensions["survey"] = new_state(st, ins)
    install(app)
    app.extensions["signin"] = SignIn(researcher_password, signin)
    app.session_interface = _SessionInterface()
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

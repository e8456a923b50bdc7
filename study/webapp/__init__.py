"""The survey web app: Flask, server-rendered Jinja2 templates, one small CSS and one JS file served locally.

* participant mode ``/s/<token>`` (:mod:`study.webapp.participant`): one participant's questionnaire behind a
  one-time link, answers saved as they are given, atomic submission, read-only afterwards;
* researcher mode ``/r/`` (:mod:`study.webapp.researcher`): password + name, links, paper-form double entry,
  discrepancies, resolutions.

The app opens the store only while a request uses it, one request at a time, so CLI commands can work on the
same file between requests (:mod:`study.webapp.context`, docs/store.md); :class:`SurveyServer` runs it on a
threaded werkzeug server.
"""
from __future__ import annotations

import secrets
from pathlib import Path

from flask import Flask, render_template, request, session

from study.errors import UserError
from study.instrument import is_scaled
from study.webapp import participant, researcher
from study.webapp.context import install, new_state
from study.webapp.server import SurveyServer

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


def create_app(st, researcher_password: str, instrument: str | None = None,
               secret_key: str | None = None) -> Flask:
    """The Flask app over the store of the open, writable Store `st`, showing the store's study (title,
    description) and `instrument` (None = the study's). Requests open the store's file themselves (as `st`'s
    actor); `st` may be closed once the app is made."""
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
    app.extensions["survey"] = new_state(st, ins, researcher_password)
    install(app)
    app.jinja_env.globals.update(instrument=ins, study=study, widget=widget)
    app.register_blueprint(participant.bp)
    app.register_blueprint(researcher.bp)

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
        return {"csrf": session.get("csrf", ""), "researcher_name": session.get("researcher")}

    @app.get("/")
    def home():
        return render_template("home.html")

    return app

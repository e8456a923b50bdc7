"""The survey web app (Flask, server-rendered Jinja2 templates, one small CSS and JS file served locally).

Participant mode (``/s/<token>``): one participant's questionnaire behind a one-time link. Every answer is saved
server-side as it is given (a small POST per change; the form also works without JavaScript), so a reload or a
crashed tablet resumes where it was; submission is atomic and makes the survey read-only.

Researcher mode (``/r/``, password): issue links, type in paper forms twice (entry rounds 1 and 2), see the
discrepancy report and record resolutions. The researcher's name is recorded in the audit log.

DuckDB allows one writing process per file, so the server owns ONE store connection and every request uses it
under one lock (reads included: a DuckDB connection must not be used by two threads at once).
"""
from __future__ import annotations

import hmac
import re
import secrets
import threading
from contextlib import contextmanager
from study.audit import utcnow
from functools import wraps
from pathlib import Path
from typing import Iterator

from flask import Flask, abort, jsonify, redirect, render_template, request, session, url_for

from study import survey as sv
from study.errors import UserError
from study.instrument import DEFAULT_INSTRUMENT, Answer, load_instrument

HERE = Path(__file__).parent


def create_app(st, researcher_password: str, instrument: str = DEFAULT_INSTRUMENT,
               secret_key: str | None = None) -> Flask:
    """The Flask app over an open, writable Store `st` (the app serialises all access to it)."""
    if not researcher_password:
        raise UserError("a researcher password is required")
    ins = load_instrument(instrument)
    app = Flask(__name__, template_folder=str(HERE / "templates"), static_folder=str(HERE / "static"))
    app.config.update(SECRET_KEY=secret_key or secrets.token_hex(32), SESSION_COOKIE_SAMESITE="Strict",
                      SESSION_COOKIE_HTTPONLY=True, MAX_CONTENT_LENGTH=256 * 1024)
    lock = threading.RLock()
    app.extensions["survey"] = {"store": st, "lock": lock}

    @contextmanager
    def store(actor: str | None = None) -> Iterator:
        with lock:
            if actor is None:
                yield st
            else:
                with sv.acting_as(st, actor):
                    yield st

    app.jinja_env.globals.update(instrument=ins)

    @app.after_request
    def headers(resp):
        # the link token is in the URL: never send it on as a Referer, never cache a participant page
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["X-Frame-Options"] = "DENY"
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Content-Security-Policy"] = ("default-src 'self'; script-src 'self'; style-src 'self'; "
                                                   "img-src 'self'; form-action 'self'; frame-ancestors 'none'")
        if request.endpoint != "static":
            resp.headers["Cache-Control"] = "no-store"
        return resp

    def message(title: str, text: str, status: int):
        return render_template("message.html", title=title, text=text), status

    # ------------------------------------------------------------------------------------ participant mode
    def link_or_error(token: str, as_json: bool = False):
        """(Link, None) or (None, error response): nothing is read or stored for a bad token."""
        with store() as s:
            try:
                link = sv.resolve_token(s, token)
                if link.instrument != instrument:
                    raise sv.LinkError(f"This link belongs to questionnaire {link.instrument}, which this server "
                                       "does not show. Please ask the researcher.", 404)
                return link, None
            except sv.LinkError as exc:
                if as_json:
                    return None, (jsonify(error=str(exc)), exc.status)
                title = "Link not valid" if exc.status == 404 else "Link no longer valid"
                return None, message(title, str(exc), exc.status)

    def form_page(token: str, link, answers: dict[str, Answer], error: str | None = None,
                  invalid: list[str] | None = None, status: int = 200):
        return render_template("survey.html", token=token, participant_id=link.participant_id, answers=answers,
                               error=error, invalid=invalid or [],
                               n_required=len(ins.required_items),
                               n_answered=len([i for i in ins.required_items if i in answers
                                               and not answers[i].missing])), status

    @app.get("/")
    def home():
        return render_template("home.html")

    @app.get("/s/<token>")
    def survey_page(token: str):
        link, err = link_or_error(token)
        if err:
            return err
        if link.submitted:
            return render_template("done.html"), 200
        with store() as s:
            answers = sv.draft(s, link.participant_id, link.instrument)
        return form_page(token, link, answers)

    @app.post("/s/<token>/answer")
    def save_answer(token: str):
        """One answer as it is given (JSON {item, value} or form fields item, value)."""
        with lock:  # the link is checked and used under one lock: a revocation cannot slip in between
            return _save_answer(token)

    def _save_answer(token: str):
        link, err = link_or_error(token, as_json=True)
        if err:
            return err
        data = request.get_json(silent=True) if request.is_json else request.form
        if not data or "item" not in data:
            return jsonify(error="expected item and value"), 400
        if link.submitted:
            return jsonify(error="This survey has been submitted and can no longer be changed."), 409
        try:
            with store(f"web:{link.participant_id}") as s:
                sv.save_draft(s, link.participant_id, {str(data["item"]): data.get("value")}, link.instrument)
        except UserError as exc:
            return jsonify(error=str(exc)), 409 if isinstance(exc, sv.SubmittedError) else 400
        return jsonify(ok=True, saved_at=utcnow().strftime("%H:%M:%S"))

    @app.post("/s/<token>")
    def survey_post(token: str):
        """The whole form (works without JavaScript): save what is posted, then save only or submit."""
        with lock:
            return _survey_post(token)

    def _survey_post(token: str):
        link, err = link_or_error(token)
        if err:
            return err
        if link.submitted:
            return message("Already submitted", "This survey has been submitted and can no longer be changed.", 409)
        posted = {k: v for k, v in request.form.items() if k in ins.items.index}
        unknown = [k for k in request.form if k not in ins.items.index and k != "action"]
        with store(f"web:{link.participant_id}") as s:
            if sv.submission(s, link.participant_id, 1, link.instrument) is not None:  # submitted meanwhile
                return message("Already submitted", "This survey has been submitted and can no longer be changed.",
                               409)
            answers = sv.draft(s, link.participant_id, link.instrument)
            if unknown:
                return form_page(token, link, answers, error=f"unknown item {unknown[0]!r}", status=400)
            try:
                sv.save_draft(s, link.participant_id, posted, link.instrument)
            except UserError as exc:
                return form_page(token, link, answers, error=str(exc), status=400)
            answers = sv.draft(s, link.participant_id, link.instrument)
            if request.form.get("action") != "submit":
                return redirect(url_for("survey_page", token=token) + "#saved", 303)
            missing = sv.missing_required(ins, answers)
            if missing:
                return form_page(token, link, answers, invalid=missing, status=400,
                                 error=f"Please answer every question before submitting ({len(missing)} still "
                                       f"open, marked below).")
            try:
                sv.submit_web(s, link.participant_id, link.instrument)
            except UserError as exc:
                return form_page(token, link, answers, error=str(exc), status=400)
        return redirect(url_for("survey_page", token=token), 303)

    # ------------------------------------------------------------------------------------ researcher mode
    def researcher(view):
        @wraps(view)
        def wrapped(*a, **kw):
            if not session.get("researcher"):
                return redirect(url_for("login", next=request.path))
            if request.method == "POST" and not hmac.compare_digest(
                    request.form.get("csrf", ""), session.get("csrf", "")):
                return message("Form expired", "Please reload the page and try again.", 400)
            return view(*a, **kw)
        return wrapped

    @app.route("/r/login", methods=["GET", "POST"])
    def login():
        error = None
        if request.method == "POST":
            name = request.form.get("name", "").strip()
            ok = hmac.compare_digest(request.form.get("password", "").encode(), researcher_password.encode())
            if ok and name:
                session.clear()
                session.update(researcher=name, csrf=secrets.token_urlsafe(24))
                nxt = request.args.get("next", "")
                return redirect(nxt if nxt.startswith("/r/") else url_for("r_index"), 303)
            error = "Please enter your name." if ok else "Wrong password."
        return render_template("r_login.html", error=error), (401 if error else 200)

    @app.post("/r/logout")
    @researcher
    def logout():
        session.clear()
        return redirect(url_for("login"), 303)

    @app.get("/r/")
    @researcher
    def r_index():
        with store() as s:
            status = sv.survey_status(s, instrument)
        return render_template("r_index.html", status=status.to_dict("records"))

    @app.post("/r/link")
    @researcher
    def r_link():
        pid = request.form.get("participant_id", "").strip()
        try:
            with store(session["researcher"]) as s:
                token = sv.issue_link(s, pid, instrument)
        except UserError as exc:
            return message("No link issued", str(exc), 400)
        url = url_for("survey_page", token=token, _external=True)
        return render_template("r_link.html", participant_id=pid, url=url)

    @app.route("/r/entry/<pid>/<int:entry_round>", methods=["GET", "POST"])
    @researcher
    def r_entry(pid: str, entry_round: int):
        if entry_round not in (1, 2):
            abort(404)
        items = sv.response_items(ins)
        error = None
        with store(session["researcher"]) as s:
            if request.method == "POST":
                raw = {i: request.form.get(i, "") for i in items}
                try:
                    sv.save_entry(s, pid, entry_round, raw, instrument=instrument, replace=True)
                    return redirect(url_for("r_index") + f"#row-{pid}", 303)
                except UserError as exc:
                    error = str(exc)
                    answers = {i: raw[i] for i in items}
            else:
                if not sv._participant_exists(s, pid):
                    return message("Unknown participant", f"There is no participant {pid}.", 404)
                # blind double entry: each round shows only its own earlier values, never the other round's
                answers = {i: (a.text if a.text is not None else ("" if a.value is None else str(a.value)))
                           for i, a in sv.entry_answers(s, pid, entry_round, instrument).items()}
        return render_template("r_entry.html", pid=pid, entry_round=entry_round, items=items, answers=answers,
                               error=error), (400 if error else 200)

    @app.get("/r/discrepancies")
    @researcher
    def r_discrepancies():
        with store() as s:
            d = sv.discrepancies(s, instrument)
        return render_template("r_discrepancies.html", rows=d.to_dict("records"))

    @app.post("/r/resolve")
    @researcher
    def r_resolve():
        pid, item = request.form.get("participant_id", ""), request.form.get("item_id", "")
        try:
            with store(session["researcher"]) as s:
                sv.resolve(s, pid, item, request.form.get("value", ""), request.form.get("note") or None, instrument)
        except UserError as exc:
            return message("Not resolved", str(exc), 400)
        return redirect(url_for("r_discrepancies"), 303)

    @app.context_processor
    def csrf():
        return {"csrf": session.get("csrf", ""), "researcher_name": session.get("researcher")}

    return app


class SurveyServer:
    """The app on a werkzeug threaded server in a background thread (for `survey serve` and the tests).

    ``port=0`` picks a free port; :attr:`url` is the base address; :meth:`close` stops it.
    """

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
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=10)

    def __enter__(self) -> "SurveyServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


_TOKEN_PATH = re.compile(r"/s/[A-Za-z0-9_-]+")


def _handler(quiet: bool):
    """A werkzeug request handler whose access log never shows a participant's link token."""
    from werkzeug.serving import WSGIRequestHandler

    class Handler(WSGIRequestHandler):
        def log_request(self, code="-", size="-"):
            if quiet:
                return
            line = _TOKEN_PATH.sub("/s/<token>", getattr(self, "path", "") or "?")
            self.log("info", '"%s %s %s" %s %s', getattr(self, "command", "-"), line,
                     getattr(self, "request_version", "-"), code, size)

        def log_error(self, *args):
            if not quiet:
                super().log_error(*args)

    return Handler

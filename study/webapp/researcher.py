"""Researcher mode (``/r/``): password sign-in with a name (the audit-log actor), participant links, paper-form
double entry (rounds 1 and 2, the second blind), the discrepancy report and resolutions.

Sign-in (:mod:`study.webapp.signin`): the session lives on the server (the cookie names it), so logout and a password
change end it for good; repeated wrong passwords lock the account name and the client address with back-off;
every form, the sign-in form included, carries a CSRF token."""
from __future__ import annotations

import hmac
import math
import secrets
from functools import wraps

from flask import Blueprint, abort, current_app, flash, g, redirect, render_template, request, session, url_for
from markupsafe import Markup

from study import survey as sv
from study.errors import UserError
from study.webapp.context import message, state, store

bp = Blueprint("researcher", __name__, url_prefix="/r")


def signin():
    """The app's :class:`study.webapp.signin.SignIn`."""
    return current_app.extensions["signin"]


def actor() -> str:
    """The signed-in researcher's name (the audit-log actor of the request's writes)."""
    return g.researcher.name


def researcher(view):
    """Signed-in researchers only (a live server-side session); POSTs must carry the session's CSRF token."""
    @wraps(view)
    def wrapped(*a, **kw):
        g.researcher = signin().sessions.get(session.get("sid"))
        if g.researcher is None:
            session.pop("sid", None)
            return redirect(url_for("researcher.login", next=request.path))
        if request.method == "POST" and not hmac.compare_digest(request.form.get("csrf", ""), g.researcher.csrf):
            return message("Form expired", "Please reload the page and try again.", 400)
        return view(*a, **kw)
    return wrapped


def _login_form(error: str | None = None, status: int = 200, retry_after: float | None = None):
    # the sign-in form's CSRF token lives in the (signed) cookie session until a session exists
    session.setdefault("login_csrf", secrets.token_urlsafe(24))
    resp = current_app.make_response((render_template("r_login.html", error=error,
                                                      login_csrf=session["login_csrf"]), status))
    if retry_after:
        resp.headers["Retry-After"] = str(math.ceil(retry_after))
    return resp


@bp.route("/login", methods=["GET", "POST"])
def login():
    if request.method == "GET":
        return _login_form()
    expected = session.get("login_csrf")
    if not expected or not hmac.compare_digest(request.form.get("csrf", ""), expected):
        return _login_form("The sign-in form expired. Please try again.", 400)
    name = request.form.get("name", "").strip()
    si = signin()
    keys = si.keys(name, request.remote_addr)
    wait = si.throttle.locked_for(keys)
    if wait > 0:  # refused before the password is even checked: guessing gains nothing while locked
        return _login_form(f"Too many failed sign-ins. Please wait {math.ceil(wait)} s and try again.", 429, wait)
    if not si.check(request.form.get("password", "")):
        si.throttle.failed(keys)
        return _login_form("Wrong password.", 401)
    if not name:
        return _login_form("Please enter your name.", 401)
    si.throttle.succeeded(keys)
    si.sessions.end(session.get("sid"))
    session.clear()
    session["sid"] = si.sessions.create(name)
    nxt = request.args.get("next", "")
    return redirect(nxt if nxt.startswith("/r/") else url_for("console.today"), 303)


@bp.post("/logout")
@researcher
def logout():
    signin().sessions.end(session.get("sid"))
    session.clear()
    return redirect(url_for("researcher.login"), 303)


@bp.route("/password", methods=["GET", "POST"])
@researcher
def password():
    """Change the researcher password: every session ends, the one changing it gets a new one."""
    error = None
    if request.method == "POST":
        f = request.form
        try:
            signin().change_password(f.get("current", ""), f.get("new", ""), f.get("confirm", ""))
        except UserError as exc:
            error = str(exc)
        else:
            session.clear()
            session["sid"] = signin().sessions.create(actor())
            flash("Password changed. Every other session has been signed out.")
            return redirect(url_for("researcher.index"), 303)
    return render_template("r_password.html", error=error), (400 if error else 200)


@bp.get("/")
@researcher
def index():
    with store() as s:
        status = sv.survey_status(s, state()["instrument"].name)
    return render_template("r_index.html", status=status.to_dict("records"))


@bp.post("/link")
@researcher
def link():
    pid = request.form.get("participant_id", "").strip()
    try:
        with store(actor()) as s:
            token = sv.issue_link(s, pid, state()["instrument"].name)
    except UserError as exc:
        return message("No link issued", str(exc), 400)
    url = url_for("participant.page", token=token, _external=True)
    return render_template("r_link.html", participant_id=pid, url=url, qr=qr_svg(url))


def qr_svg(text: str) -> Markup:
    """`text` as a QR code, inline SVG (error correction M, 5 px modules, quiet zone 4)."""
    import segno

    return Markup(segno.make(text, error="m").svg_inline(scale=5, title="QR code of the survey link"))


@bp.route("/entry/<pid>/<int:entry_round>", methods=["GET", "POST"])
@researcher
def entry(pid: str, entry_round: int):
    if entry_round not in (1, 2):
        abort(404)
    ins = state()["instrument"]
    items = sv.response_items(ins)
    error = None
    with store(actor()) as s:
        if request.method == "POST":
            raw = {i: request.form.get(i, "") for i in items}
            try:
                sv.save_entry(s, pid, entry_round, raw, instrument=ins.name, replace=True)
                return redirect(url_for("researcher.index") + f"#row-{pid}", 303)
            except UserError as exc:
                error, answers = str(exc), raw
        else:
            if not sv.participant_exists(s, pid):
                return message("Unknown participant", f"There is no participant {pid}.", 404)
            # blind double entry: each round shows only its own earlier values, never the other round's
            answers = {i: (a.text if a.text is not None else ("" if a.value is None else str(a.value)))
                       for i, a in sv.entry_answers(s, pid, entry_round, ins.name).items()}
    return render_template("r_entry.html", pid=pid, entry_round=entry_round, items=items, answers=answers,
                           error=error), (400 if error else 200)


@bp.get("/discrepancies")
@researcher
def discrepancies():
    with store() as s:
        d = sv.discrepancies(s, state()["instrument"].name)
    return render_template("r_discrepancies.html", rows=d.to_dict("records"))


@bp.post("/resolve")
@researcher
def resolve():
    pid, item = request.form.get("participant_id", ""), request.form.get("item_id", "")
    try:
        with store(actor()) as s:
            sv.resolve(s, pid, item, request.form.get("value", ""), request.form.get("note") or None,
                       state()["instrument"].name)
    except UserError as exc:
        return message("Not resolved", str(exc), 400)
    return redirect(url_for("researcher.discrepancies"), 303)

"""Researcher mode (``/r/``): password sign-in with a name (the audit-log actor), participant links, paper-form
double entry (rounds 1 and 2, the second blind), the discrepancy report and resolutions.

Sign-in (:mod:`study.webapp.signin`): the session lives on the server (the cookie names it), so logout and a password
change end it for good; repeated wrong passwords lock the account name and the client address with back-off;
every form, the sign-in form included, carries a CSRF token."""
from __future__ import annotations

import hmac
import math
import re
import secrets
from functools import wraps

from flask import (
    Blueprint,
    abort,
    current_app,
    flash,
    g,
    redirect,
    render_template,
    request,
    session,
    url_for,
)
from markupsafe import Markup

from study.common.errors import UserError
from study.survey import answers as sv
from study.webapp.context import message, state, store
from study.webapp.signin import WrongPassword

bp = Blueprint("researcher", __name__, url_prefix="/r")
# where sign-in may send the researcher back to: a console path of plain characters (never a header's CR/LF, never
# another host, never a long echo of the request)
_NEXT = re.compile(r"/r/[A-Za-z0-9_./-]{0,200}")


def same_token(given, expected: str) -> bool:
    """Constant-time comparison of a posted CSRF token with the expected one; any text (non-ASCII included) or a
    missing value compares as unequal instead of failing (hmac.compare_digest refuses non-ASCII str)."""
    if not isinstance(given, str) or not expected:
        return False
    return hmac.compare_digest(given.encode("utf-8", "surrogatepass"), expected.encode("utf-8"))


def safe_next(path: str | None) -> str | None:
    """`path` when it is a console path sign-in may redirect to (:data:`_NEXT`, no ``..``), else None."""
    if isinstance(path, str) and _NEXT.fullmatch(path) and ".." not in path and "//" not in path:
        return path
    return None


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
            back = safe_next(request.path) if request.method == "GET" else None
            return redirect(url_for("researcher.login", next=back) if back else url_for("researcher.login"))
        if request.method == "POST" and not same_token(request.form.get("csrf"), g.researcher.csrf):
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
    if not isinstance(expected, str) or not same_token(request.form.get("csrf"), expected):
        return _login_form("The sign-in form expired. Please try again.", 400)
    name = request.form.get("name", "").strip()
    si = signin()
    keys = si.keys(name, request.remote_addr)
    # counted before the password is checked (parallel guesses cannot overtake the count); refused while locked
    wait = si.throttle.attempt(keys)
    if wait > 0:
        return _login_form(f"Too many failed sign-ins. Please wait {math.ceil(wait)} s and try again.", 429, wait)
    if not si.check(request.form.get("password", "")):
        return _login_form("Wrong password.", 401)
    si.throttle.succeeded(keys)
    if not name:
        return _login_form("Please enter your name.", 401)
    target = safe_next(request.args.get("next")) or url_for("console.today")  # decided before a session exists
    si.sessions.end(session.get("sid"))
    session.clear()
    session["sid"] = si.sessions.create(name)
    return redirect(target, 303)


@bp.post("/logout")
@researcher
def logout():
    signin().sessions.end(session.get("sid"))
    session.clear()
    return redirect(url_for("researcher.login"), 303)


@bp.route("/password", methods=["GET", "POST"])
@researcher
def password():
    """Change the researcher password: every session ends, the one changing it gets a new one. A wrong current
    password counts as a failed sign-in of the researcher's name and address (same lockout and back-off)."""
    error, status, wait = None, 400, 0.0
    if request.method == "POST":
        f = request.form
        si = signin()
        keys = si.keys(actor(), request.remote_addr)
        wait = si.throttle.attempt(keys)  # counted before the current password is checked, as sign-in is
        if wait > 0:
            status, error = 429, f"Too many wrong passwords. Please wait {math.ceil(wait)} s and try again."
        else:
            try:
                si.change_password(f.get("current", ""), f.get("new", ""), f.get("confirm", ""))
            except WrongPassword as exc:
                error = str(exc)
            except UserError as exc:  # the current password was right
                si.throttle.succeeded(keys)
                error = str(exc)
            else:
                si.throttle.succeeded(keys)
                session.clear()
                session["sid"] = si.sessions.create(actor())
                flash("Password changed. Every other session has been signed out.")
                return redirect(url_for("researcher.index"), 303)
    resp = current_app.make_response((render_template("r_password.html", error=error), status if error else 200))
    if error and wait > 0:
        resp.headers["Retry-After"] = str(math.ceil(wait))
    return resp


@bp.get("/")
@researcher
def index():
    with store() as s:
        status = sv.survey_status(s, state()["instrument"].name)
    return render_template("r_index.html", status=status.to_dict("records"))


@bp.post("/link")
@researcher
def link():
    """A new link of one participant for one questionnaire: the form's ``occasion`` (a questionnaire phase), by
    default the instrument's only occasion or the questionnaire phase the participant is in; earlier links of the
    same occasion stop working (`survey link`)."""
    from study.folder.occasions import study_occasions
    from study.store.studies import definition
    from study.webapp.occasion_rows import occasion_field, rated_label

    pid = request.form.get("participant_id", "").strip()
    try:
        with store(actor()) as s:
            study = definition(s)
            occasion = occasion_field(study, request.form.get("occasion"))
            # a named occasion names its instrument (any of the study's); else the app's instrument
            token = sv.issue_link(s, pid, None if occasion else state()["instrument"].name, occasion)
            occasion = sv.resolve_token(s, token).occasion
            several = len(study_occasions(study)) > 1
    except UserError as exc:
        return message("No link issued", str(exc), 400)
    url = url_for("participant.page", token=token, _external=True)
    return render_template("r_link.html", participant_id=pid, url=url, qr=qr_svg(url),
                           occasion=occasion if several else None, rates=rated_label(study, occasion))


def qr_svg(text: str) -> Markup:
    """`text` as a QR code, inline SVG (error correction M, 5 px modules, quiet zone 4)."""
    import segno

    return Markup(segno.make(text, error="m").svg_inline(scale=5, title="QR code of the survey link"))


@bp.route("/entry/<pid>/<int:entry_round>", methods=["GET", "POST"])
@researcher
def entry(pid: str, entry_round: int):
    """One entry round of a paper form; ``?occasion=PHASE`` names the questionnaire phase it was filled in (the
    form posts back to the same address, so both the page and the save carry it)."""
    from study.store.studies import definition
    from study.webapp.occasion_rows import occasion_field, rated_label

    if entry_round not in (1, 2):
        abort(404)
    ins = state()["instrument"]
    items = sv.response_items(ins)
    error = None
    with store(actor()) as s:
        study = definition(s)
        occasion = occasion_field(study, request.args.get("occasion"))
        if request.method == "POST":
            raw = {i: request.form.get(i, "") for i in items}
            try:
                sv.save_entry(s, pid, entry_round, raw, instrument=ins.name, replace=True, occasion=occasion)
                row = f"{pid}-{occasion}" if occasion and len(sv.occasions(s, ins.name)) > 1 else pid
                return redirect(url_for("researcher.index") + f"#row-{row}", 303)
            except UserError as exc:
                error, answers = str(exc), raw
        else:
            if not sv.participant_exists(s, pid):
                shown = pid if pid.isprintable() else repr(pid)  # a CR/LF in the path stays on the one line
                return message("Unknown participant", f"There is no participant {shown}.", 404)
            # blind double entry: each round shows only its own earlier values, never the other round's
            answers = {i: (a.text if a.text is not None else ("" if a.value is None else str(a.value)))
                       for i, a in sv.entry_answers(s, pid, entry_round, ins.name, occasion).items()}
    return render_template("r_entry.html", pid=pid, entry_round=entry_round, items=items, answers=answers,
                           error=error, occasion=occasion, rates=rated_label(study, occasion)), (400 if error else 200)


@bp.get("/discrepancies")
@researcher
def discrepancies():
    with store() as s:
        d = sv.discrepancies(s, state()["instrument"].name)
    return render_template("r_discrepancies.html", rows=d.to_dict("records"))


@bp.post("/resolve")
@researcher
def resolve():
    from study.store.studies import definition
    from study.webapp.occasion_rows import occasion_field

    pid, item = request.form.get("participant_id", ""), request.form.get("item_id", "")
    try:
        with store(actor()) as s:
            occasion = occasion_field(definition(s), request.form.get("occasion"))
            sv.resolve(s, pid, item, request.form.get("value", ""), request.form.get("note") or None,
                       state()["instrument"].name, occasion)
    except UserError as exc:
        return message("Not resolved", str(exc), 400)
    return redirect(url_for("researcher.discrepancies"), 303)

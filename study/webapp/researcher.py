"""Researcher mode (``/r/``): password sign-in with a name (the audit-log actor), participant links, paper-form
double entry (rounds 1 and 2, the second blind), the discrepancy report and resolutions. Every POST carries the
session's CSRF token."""
from __future__ import annotations

import hmac
import secrets
from functools import wraps

from flask import Blueprint, abort, redirect, render_template, request, session, url_for

from study import survey as sv
from study.errors import UserError
from study.webapp.context import message, state, store

bp = Blueprint("researcher", __name__, url_prefix="/r")


def researcher(view):
    """Signed-in researchers only; POSTs must carry the session's CSRF token."""
    @wraps(view)
    def wrapped(*a, **kw):
        if not session.get("researcher"):
            return redirect(url_for("researcher.login", next=request.path))
        if request.method == "POST" and not hmac.compare_digest(request.form.get("csrf", ""),
                                                                session.get("csrf", "")):
            return message("Form expired", "Please reload the page and try again.", 400)
        return view(*a, **kw)
    return wrapped


@bp.route("/login", methods=["GET", "POST"])
def login():
    error = None
    if request.method == "POST":
        name = request.form.get("name", "").strip()
        ok = hmac.compare_digest(request.form.get("password", "").encode(), state()["password"].encode())
        if ok and name:
            session.clear()
            session.update(researcher=name, csrf=secrets.token_urlsafe(24))
            nxt = request.args.get("next", "")
            return redirect(nxt if nxt.startswith("/r/") else url_for("researcher.index"), 303)
        error = "Please enter your name." if ok else "Wrong password."
    return render_template("r_login.html", error=error), (401 if error else 200)


@bp.post("/logout")
@researcher
def logout():
    session.clear()
    return redirect(url_for("researcher.login"), 303)


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
        with store(session["researcher"]) as s:
            token = sv.issue_link(s, pid, state()["instrument"].name)
    except UserError as exc:
        return message("No link issued", str(exc), 400)
    return render_template("r_link.html", participant_id=pid,
                           url=url_for("participant.page", token=token, _external=True))


@bp.route("/entry/<pid>/<int:entry_round>", methods=["GET", "POST"])
@researcher
def entry(pid: str, entry_round: int):
    if entry_round not in (1, 2):
        abort(404)
    ins = state()["instrument"]
    items = sv.response_items(ins)
    error = None
    with store(session["researcher"]) as s:
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
        with store(session["researcher"]) as s:
            sv.resolve(s, pid, item, request.form.get("value", ""), request.form.get("note") or None,
                       state()["instrument"].name)
    except UserError as exc:
        return message("Not resolved", str(exc), 400)
    return redirect(url_for("researcher.discrepancies"), 303)

"""Participant mode: one participant's questionnaire behind a one-time link ``/s/<token>``.

Every answer is saved server-side as it is given (``POST /s/<token>/answer``, a small request per change), so a
reload or a crashed tablet resumes; without JavaScript the whole form posts to ``/s/<token>`` ("save" or
"submit"). All that a request can see or change is derived from the token; a bad token reads and stores
nothing. Submission is atomic; afterwards the survey is read-only (409).
"""
from __future__ import annotations

from flask import Blueprint, jsonify, redirect, render_template, request, url_for

from study import survey as sv
from study.audit_trail import utcnow
from study.errors import UserError
from study.instrument import Answer
from study.webapp.context import message, state, store

bp = Blueprint("participant", __name__)
SUBMITTED = "This survey has been submitted and can no longer be changed."


def _link(token: str, as_json: bool = False):
    """(Link, None) or (None, error response)."""
    ins = state()["instrument"]
    with store() as s:
        try:
            link = sv.resolve_token(s, token)
            if link.instrument != ins.name:
                raise sv.LinkError(f"This link belongs to questionnaire {link.instrument}, which this server does "
                                   "not show. Please ask the researcher.", 404)
            return link, None
        except sv.LinkError as exc:
            if as_json:
                return None, (jsonify(error=str(exc)), exc.status)
            title = "Link not valid" if exc.status == 404 else "Link no longer valid"
            return None, message(title, str(exc), exc.status)


def _form(token: str, link, answers: dict[str, Answer], error: str | None = None,
          invalid: list[str] | None = None, status: int = 200):
    required = state()["instrument"].required_items
    n_answered = sum(1 for i in required if i in answers and not answers[i].missing)
    return render_template("survey.html", token=token, participant_id=link.participant_id, answers=answers,
                           error=error, invalid=invalid or [], n_required=len(required),
                           n_answered=n_answered, saved=request.args.get("saved") == "1"), status


@bp.get("/s/<token>")
def page(token: str):
    link, err = _link(token)
    if err:
        return err
    if link.submitted:
        return render_template("done.html"), 200
    with store() as s:
        answers = sv.draft(s, link.participant_id, link.instrument)
    return _form(token, link, answers)


@bp.post("/s/<token>/answer")
def answer(token: str):
    """One answer as it is given (form fields or JSON: item, value); JSON back."""
    with state()["lock"]:  # the link is checked and used under one lock: a revocation cannot slip in between
        link, err = _link(token, as_json=True)
        if err:
            return err
        data = request.get_json(silent=True) if request.is_json else request.form
        if not data or "item" not in data:
            return jsonify(error="expected item and value"), 400
        if link.submitted:
            return jsonify(error=SUBMITTED), 409
        try:
            with store(f"web:{link.participant_id}") as s:
                sv.save_draft(s, link.participant_id, {str(data["item"]): data.get("value")}, link.instrument)
        except UserError as exc:
            return jsonify(error=str(exc)), 409 if isinstance(exc, sv.SubmittedError) else 400
    return jsonify(ok=True, saved_at=utcnow().strftime("%H:%M:%S"))


@bp.post("/s/<token>")
def post(token: str):
    """The whole form (works without JavaScript): save what is posted, then stop or submit."""
    ins = state()["instrument"]
    with state()["lock"]:
        link, err = _link(token)
        if err:
            return err
        if link.submitted:
            return message("Already submitted", SUBMITTED, 409)
        posted = {k: v for k, v in request.form.items() if k in ins.items.index}
        unknown = [k for k in request.form if k not in ins.items.index and k != "action"]
        with store(f"web:{link.participant_id}") as s:
            answers = sv.draft(s, link.participant_id, link.instrument)
            if unknown:
                return _form(token, link, answers, error=f"unknown item {unknown[0]!r}", status=400)
            try:
                sv.save_draft(s, link.participant_id, posted, link.instrument)
            except UserError as exc:
                return _form(token, link, answers, error=str(exc), status=400)
            answers = sv.draft(s, link.participant_id, link.instrument)
            if request.form.get("action") != "submit":
                return redirect(url_for("participant.page", token=token, saved=1), 303)
            missing = sv.missing_required(ins, answers)
            if missing:
                return _form(token, link, answers, invalid=missing, status=400,
                             error=f"Please answer every question before submitting ({len(missing)} still open, "
                                   "marked below).")
            try:
                sv.submit_web(s, link.participant_id, link.instrument)
            except UserError as exc:
                return _form(token, link, answers, error=str(exc), status=400)
    return redirect(url_for("participant.page", token=token), 303)

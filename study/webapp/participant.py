"""Participant mode: one participant's questionnaire behind a one-time link ``/s/<token>``.

Every answer is saved server-side as it is given (``POST /s/<token>/answer``, a small request per change), so a
reload or a crashed tablet resumes; without JavaScript the whole form posts to ``/s/<token>`` ("save" or
"submit"). All that a request can see or change is derived from the token; a bad token reads and stores
nothing. Submission is atomic; afterwards the survey is read-only (409).
"""
from __future__ import annotations

from flask import Blueprint, jsonify, redirect, render_template, request, url_for

from study.common.errors import UserError
from study.folder.instrument import Answer
from study.store.audit_trail import utcnow
from study.survey import answers as sv
from study.webapp.context import message, state, store
from study.webapp.widgets import check_renderable

bp = Blueprint("participant", __name__)
SUBMITTED = "This survey has been submitted and can no longer be changed."
WITHDRAWN = "This survey link has been withdrawn by the researcher. Please ask the researcher."


def _replaced(s, token: str) -> bool:
    """Whether the revoked link `token` was replaced by a newer one (issued when it was revoked, for the same
    participant and questionnaire) rather than withdrawn (`survey revoke`, the console's Revoke)."""
    found = s.dicts("SELECT * FROM survey_tokens WHERE token_hash = ?", [sv.hash_token(token)])
    if not found:
        return False
    r = found[0]
    same = [c for c in ("participant_id", "instrument", "occasion") if c in r]
    where = " AND ".join(f'"{c}" IS NOT DISTINCT FROM ?' for c in same)
    return bool(s.one(f"SELECT count(*) FROM survey_tokens WHERE {where} AND issued_at >= ?",
                      [*(r[c] for c in same), r["revoked_at"]]))


def _link(token: str, as_json: bool = False):
    """((Link, its Instrument), None) or (None, error response). Every instrument of the study is served: the link
    says which one (and which occasion) it is for."""
    with store() as s:
        try:
            link = sv.resolve_token(s, token)
            return (link, _instrument(s, link.instrument)), None
        except sv.LinkError as exc:
            if exc.status == 403 and not _replaced(s, token):
                exc = sv.LinkError(WITHDRAWN, 403)
            if as_json:
                return None, (jsonify(error=str(exc)), exc.status)
            title = "Link not valid" if exc.status == 404 else "Link no longer valid"
            return None, message(title, str(exc), exc.status)


def _instrument(s, name: str):
    """The instrument `name` of a link: the app's own, else the study's (any stored version) when the form can
    show it; one the form cannot show is a link that cannot be used (404)."""
    ins = state()["instrument"]
    if name == ins.name:
        return ins
    try:
        other = sv.instrument_of(s, name)
        check_renderable(other)
    except UserError:
        raise sv.LinkError(f"This link belongs to questionnaire {name}, which this server cannot show. Please ask "
                           "the researcher.", 404) from None
    return other


def _form(token: str, link, ins, answers: dict[str, Answer], error: str | None = None,
          invalid: list[str] | None = None, status: int = 200):
    required = ins.required_items
    n_answered = sum(1 for i in required if i in answers and not answers[i].missing)
    return render_template("survey.html", token=token, participant_id=link.participant_id, answers=answers,
                           instrument=ins,
                           error=error, invalid=invalid or [], n_required=len(required),
                           n_answered=n_answered, saved=request.args.get("saved") == "1",
                           rates=_rates(link)), status


def _rates(link) -> str | None:
    """The label of the condition whose drive the link's questionnaire rates (None when it rates none): the form
    names it, since a within-subjects participant answers the same questions after each drive."""
    from study.webapp.occasion_rows import rated_label

    study = state().get("study")
    return rated_label(study, link.occasion) if study is not None else None


@bp.get("/s/<token>")
def page(token: str):
    got, err = _link(token)
    if err:
        return err
    link, ins = got
    if link.submitted:
        return render_template("done.html", rates=_rates(link)), 200
    with store() as s:
        answers = sv.draft(s, link.participant_id, link.instrument, link.occasion)
    return _form(token, link, ins, answers)


@bp.post("/s/<token>/answer")
def answer(token: str):
    """One answer as it is given (form fields or JSON: item, value); JSON back."""
    with state()["lock"]:  # the link is checked and used under one lock: a revocation cannot slip in between
        got, err = _link(token, as_json=True)
        if err:
            return err
        link = got[0]
        data = request.get_json(silent=True) if request.is_json else request.form
        # a JSON body must be an object {"item": text, "value": text | number | null}; anything else is refused
        if not hasattr(data, "get") or not isinstance(data.get("item"), str):
            return jsonify(error="expected item and value"), 400
        if not isinstance(data.get("value"), (str, int, float, type(None))) or isinstance(data.get("value"), bool):
            return jsonify(error="the value must be text, a number or null"), 400
        if link.submitted:
            return jsonify(error=SUBMITTED), 409
        try:
            with store(f"web:{link.participant_id}") as s:
                sv.save_draft(s, link.participant_id, {data["item"]: data.get("value")}, link.instrument, link.occasion)
        except UserError as exc:
            return jsonify(error=str(exc)), 409 if isinstance(exc, sv.SubmittedError) else 400
    return jsonify(ok=True, saved_at=utcnow().strftime("%H:%M:%S"))


@bp.post("/s/<token>")
def post(token: str):
    """The whole form (works without JavaScript): save what is posted, then stop or submit."""
    with state()["lock"]:
        got, err = _link(token)
        if err:
            return err
        link, ins = got
        if link.submitted:
            return message("Already submitted", SUBMITTED, 409)
        posted = {k: v for k, v in request.form.items() if k in ins.items.index}
        unknown = [k for k in request.form if k not in ins.items.index and k != "action"]
        with store(f"web:{link.participant_id}") as s:
            answers = sv.draft(s, link.participant_id, link.instrument, link.occasion)
            if unknown:
                return _form(token, link, ins, answers, error=f"unknown item {unknown[0]!r}", status=400)
            try:
                sv.save_draft(s, link.participant_id, posted, link.instrument, link.occasion)
            except UserError as exc:
                return _form(token, link, ins, answers, error=str(exc), status=400)
            answers = sv.draft(s, link.participant_id, link.instrument, link.occasion)
            if request.form.get("action") != "submit":
                return redirect(url_for("participant.page", token=token, saved=1), 303)
            missing = sv.missing_required(ins, answers)
            if missing:
                return _form(token, link, ins, answers, invalid=missing, status=400,
                             error=f"Please answer every question before submitting ({len(missing)} still open, "
                                   "marked below).")
            try:
                sv.submit_web(s, link.participant_id, link.instrument, link.occasion)
            except UserError as exc:
                return _form(token, link, ins, answers, error=str(exc), status=400)
    return redirect(url_for("participant.page", token=token), 303)

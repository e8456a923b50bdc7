"""The questionnaire occasions as the web pages show them (docs/console.md, "Occasions").

An occasion is a questionnaire phase of the protocol (:mod:`study.folder.occasions`); a within-subjects study answers the same
instrument after each drive. The console lists a participant's occasions, one row each, with the condition the
occasion rates and how far its answers are; the participant's form names the drive it rates. A request names an
occasion by its phase name (form or query field ``occasion``), checked here against the study's occasions before any
`study` function sees it, so that a refusal never echoes a long or odd value.
"""
from __future__ import annotations

import re

from study.common.errors import UserError

#: the status of one occasion's answers, from the first that holds: final, submitted (stored, not yet final: a paper
#: form awaiting its second entry or a resolution), draft (web answers saved, not submitted), link issued, not started
STATUSES = ("final", "submitted", "draft", "link issued", "not started")
_PLAIN = re.compile(r"[A-Za-z0-9_.-]{1,64}")   # a phase name a message may quote


def occasion_field(study, value) -> str | None:
    """The occasion a request names in `value` (None or '' = none named) when it is one of `study`'s questionnaire
    phases; anything else -> UserError listing them (quoting `value` only when it is a short plain name)."""
    from study.folder.occasions import study_occasions

    if value is None or value == "":
        return None
    names = [o.name for o in study_occasions(study)]
    if isinstance(value, str) and value in names:
        return value
    shown = f" {value!r}" if isinstance(value, str) and _PLAIN.fullmatch(value) else ""
    raise UserError(f"unknown questionnaire phase{shown} (the study's: {', '.join(names) or 'none'})")


def condition_label(study, condition: str | None) -> str | None:
    """The declared label of `condition` (its name when it has none), None for no condition."""
    if condition is None:
        return None
    for c in study.conditions:
        if c.name == condition:
            return c.label or c.name
    return condition


def rated_label(study, occasion: str | None) -> str | None:
    """The label of the condition the occasion `occasion` rates, None when it rates none (or is unknown)."""
    from study.folder.occasions import study_occasions

    for o in study_occasions(study):
        if o.name == occasion:
            return condition_label(study, o.rates)
    return None


def status_word(row: dict) -> str:
    """One of :data:`STATUSES` for a row of :func:`study.survey.answers.survey_status`."""
    if row["final"]:
        return "final"
    if row["entry_1"]:
        return "submitted"
    if row["draft_items"]:
        return "draft"
    if row["link"] == "issued":
        return "link issued"
    return "not started"


def participant_occasions(st, study, instrument: str, participant_id: str, proto, phases) -> list[dict]:
    """One dict per occasion of the study (of every instrument) in the participant's protocol `proto`, in the
    participant's order (every occasion of the study when the protocol has none of them): occasion, instrument,
    served (whether it is `instrument`, the one the app's paper-entry pages work on), rates, label (the rated
    condition's), outcome (of the phase: pending, in_progress, completed, ...), status (:func:`status_word`) and
    the fields of the participant's :func:`study.survey.answers.survey_status` row of that occasion (link, draft_items,
    entry_1, entry_2, basis, final, ...)."""
    from study.folder.occasions import base_name, study_occasions
    from study.survey import answers as sv

    mine = {o.name: o for o in study_occasions(study)}
    order = [p.name for p in proto.steps if p.name in mine] or list(mine)
    outcome = dict(zip(phases["phase"], phases["outcome"]))
    rows = []
    for name in order:
        o = mine[name]
        served = base_name(o.instrument) == base_name(instrument)
        status = sv.survey_status(st, instrument if served else o.instrument, name)
        status = status.set_index("participant_id").loc[participant_id].to_dict()
        rows.append({**status, "occasion": name, "instrument": o.instrument, "served": served, "rates": o.rates,
                     "label": condition_label(study, o.rates), "outcome": outcome.get(name, "pending"),
                     "status": status_word(status)})
    return rows

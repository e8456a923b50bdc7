"""Declared instrument scores for the analyses: per instrument and occasion, and on the occasions that rate a
condition. The formula (:func:`compute_scores`, :func:`scored_items`) is :mod:`study.survey.scores`', which the
``survey scores`` command and the exports use as well.
"""
from __future__ import annotations

import pandas as pd

from study.survey.scores import KEYS, _score, compute_scores, scored_items  # noqa: F401  (this module's API)


def instrument_scores(st, instrument: str | None = None, occasion: str | None = None) -> pd.DataFrame:
    """The declared scores of the store's instrument (default: the study's current one) from its final answers
    (``study.survey.answers.final_responses``; exclusions are not applied here), tidy as :func:`compute_scores`. An
    instrument without declared scores gives an empty frame."""
    from study.folder.scores import study_scores
    from study.store.studies import definition
    from study.survey.answers import final_responses, instrument_of

    ins = instrument_of(st, instrument)
    specs = study_scores(definition(st), ins.name)
    wide = final_responses(st, ins.name, occasion=occasion) if occasion else final_responses(st, ins.name)
    return compute_scores(wide, specs, ins)


def score_occasions(st, study, names) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The declared scores `names` on every questionnaire occasion that rates a condition (a protocol phase with
    ``instrument`` and ``rates``, docs/survey.md "Occasions"), from the final answers of each occasion.

    Returns
    -------
    (scores, items)
        scores: participant, condition, occasion, variable (the score's name), label, unit ('' : scores carry no
        unit), value; items: variable, participant, condition, item, value (the scored items, reversed ones
        mapped, for reliability per condition). Exclusions are not applied here.

    Raises
    ------
    UserError
        a name that no instrument of the study declares.
    """
    from study.common.errors import UserError
    from study.folder.occasions import study_occasions
    from study.folder.scores import study_scores
    from study.survey.answers import final_responses, instrument_of

    declared = {s.name: s for s in study_scores(study)}
    unknown = [n for n in names if n not in declared]
    if unknown:
        raise UserError(f"{', '.join(unknown)}: no instrument of study {study.study_id} declares such a score "
                        f"(declared: {', '.join(declared) or 'none'})")
    frames, item_frames = [], []
    for occ in study_occasions(study):
        specs = [declared[n] for n in names if declared[n].instrument == occ.instrument]
        if occ.rates is None or not specs:
            continue
        ins = instrument_of(st, occ.instrument)
        wide = final_responses(st, occ.instrument, occasion=occ.name)
        if wide.empty:
            continue
        for spec in specs:
            frames.append(pd.DataFrame({
                "participant": wide["participant_id"].to_numpy(), "condition": occ.rates, "occasion": occ.name,
                "variable": spec.name, "label": spec.label or spec.name, "unit": "",
                "value": _score(wide, spec, ins).to_numpy(dtype=float)}))
            x = scored_items(wide, spec, ins)
            x.insert(0, "participant", wide["participant_id"].to_numpy())
            long = x.melt(id_vars="participant", var_name="item", value_name="value")
            item_frames.append(long.assign(variable=spec.name, condition=occ.rates))
    scores = (pd.concat(frames, ignore_index=True) if frames else
              pd.DataFrame(columns=["participant", "condition", "occasion", "variable", "label", "unit", "value"]))
    items = (pd.concat(item_frames, ignore_index=True) if item_frames else
             pd.DataFrame(columns=["variable", "participant", "condition", "item", "value"]))
    return scores, items[["variable", "participant", "condition", "item", "value"]]

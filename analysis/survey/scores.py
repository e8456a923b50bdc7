"""Declared instrument scores (study/folder/scores.py) computed from the answers: SUS, NASA-TLX, van der Laan, trust, SSQ
or any score a study declares.

For each score and participant (and occasion, when the answers have one)::

    x_i   = answer to item i, reversed items mapped x -> min + max - x on the item's own scale
    w_i   = the declared weight, the participant's answer to the weight item, or 1
    sum   = sum_i w_i x_i               mean = sum_i w_i x_i / sum_i w_i
    value = aggregate * multiply + add

A score with any of its items or weights unanswered is NaN for that participant (no prorating).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from study.folder.instrument import Instrument
from study.folder.scores import ScoreSpec

KEYS = ("participant_id", "occasion", "condition")   # the columns that say whose answers a row holds
COLUMNS = ["score", "value"]


def compute_scores(responses: pd.DataFrame, specs: list[ScoreSpec], instrument: Instrument) -> pd.DataFrame:
    """Tidy scores of the wide `responses` (participant_id [, occasion, condition], one column per item, raw
    answers as ticked, as ``study.survey.answers.final_responses`` returns them).

    Returns
    -------
    DataFrame
        participant_id [, occasion, condition], score, value (float; NaN = an item or weight unanswered): one row
        per answer row and score, in the order of the rows and then of the declarations.

    Raises
    ------
    ValueError
        (one line) an item column missing, a score of another instrument, a non-numeric answer, or a
        participant's weights not adding up to the declared total (e.g. NASA-TLX tallies that are not 15).

    Examples
    --------
    Brooke's (1996) worked SUS example: contributions 4,1,1,4,1,2,1,1,4,3 (total 22), SUS = 55.

    >>> import pandas as pd
    >>> from analysis.survey.scores import compute_scores
    >>> from study.folder.instrument import Instrument
    >>> from study.folder.instrument_library import LIBRARY
    >>> from study.folder.scores import ScoreSpec
    >>> sus = Instrument.from_csv("sus_v1", (LIBRARY / "sus.csv").read_text())
    >>> spec = ScoreSpec("sus", "sus_v1", tuple(f"SUS{i}" for i in range(1, 11)), "sum",
    ...                  reversed=("SUS2", "SUS4", "SUS6", "SUS8", "SUS10"), multiply=2.5, add=-25)
    >>> answers = pd.DataFrame([["P1", 5, 4, 2, 1, 2, 3, 2, 4, 5, 2]], columns=["participant_id"] + list(spec.items))
    >>> compute_scores(answers, [spec], sus)
      participant_id score  value
    0             P1   sus   55.0
    """
    keys = [k for k in KEYS if k in responses.columns]
    if "participant_id" not in keys:
        raise ValueError("responses need a participant_id column")
    frames = []
    rows = np.arange(len(responses))
    for spec in specs:
        if spec.instrument != instrument.name:
            raise ValueError(f"score {spec.name} belongs to instrument {spec.instrument}, not {instrument.name}")
        value = _score(responses, spec, instrument)
        out = responses[keys].reset_index(drop=True)
        out["_row"] = rows
        out["score"] = spec.name
        out["value"] = value.to_numpy(dtype=float)
        frames.append(out)
    if not frames:
        return pd.DataFrame(columns=keys + COLUMNS)
    tidy = pd.concat(frames, ignore_index=True)   # frames in declaration order: a stable sort keeps it per row
    return tidy.sort_values("_row", kind="stable").drop(columns="_row").reset_index(drop=True)


def _numeric(responses: pd.DataFrame, cols: tuple[str, ...], what: str) -> pd.DataFrame:
    missing = [c for c in cols if c not in responses.columns]
    if missing:
        raise ValueError(f"responses lack the column(s) of {what}: {', '.join(missing)}")
    try:
        return responses[list(cols)].apply(pd.to_numeric, errors="raise").astype(float).reset_index(drop=True)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{what}: answers must be numbers or empty ({exc})") from None


def scored_items(responses: pd.DataFrame, spec: ScoreSpec, instrument: Instrument) -> pd.DataFrame:
    """The answers to a score's items, one column per item, reversed items mapped x -> min + max - x (before
    weighting): the item values behind the score (e.g. for Cronbach's alpha)."""
    x = _numeric(responses, spec.items, f"score {spec.name}")
    for item in spec.reversed:
        lo, hi = instrument.scale(item)
        x[item] = lo + hi - x[item]
    return x


def _score(responses: pd.DataFrame, spec: ScoreSpec, instrument: Instrument) -> pd.Series:
    """The value of one score for every row (NaN where an item or weight is unanswered)."""
    x = scored_items(responses, spec, instrument)
    if spec.weights_from is not None:
        w = _numeric(responses, spec.weights_from, f"the weights of score {spec.name}")
        w.columns = list(spec.items)
        if spec.weights_total is not None:
            total = w.sum(axis=1, skipna=False)
            bad = total.notna() & ~np.isclose(total, spec.weights_total)
            if bad.any():
                k = int(np.flatnonzero(bad.to_numpy())[0])
                raise ValueError(f"score {spec.name}: the weights of {responses['participant_id'].iloc[k]} add up to "
                                 f"{total.iloc[k]:g}, not {spec.weights_total:g} ({', '.join(spec.weights_from)})")
    else:
        weights = spec.weights if spec.weights is not None else (1.0,) * len(spec.items)
        w = pd.DataFrame([weights] * len(x), columns=list(spec.items), dtype=float)
    products = (x * w).sum(axis=1, skipna=False)
    if spec.aggregate == "mean":
        products = products / w.sum(axis=1, skipna=False)
    return products * spec.multiply + spec.add


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

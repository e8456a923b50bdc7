"""Declared instrument scores (study/folder/scores.py) computed from the answers: SUS, NASA-TLX, van der Laan, trust, SSQ
or any score a study declares, and the scores table that ``survey scores`` and the exports write.

For each score and participant (and occasion, when the answers have one)::

    x_i   = answer to item i, reversed items mapped x -> min + max - x on the item's own scale
    w_i   = the declared weight, the participant's answer to the weight item, or 1
    sum   = sum_i w_i x_i               mean = sum_i w_i x_i / sum_i w_i
    value = aggregate * multiply + add

A score with any of its items or weights unanswered is NaN for that participant (no prorating). An item is reversed
once: the score's ``reversed`` list maps the answers as ticked (:func:`study.survey.answers.final_responses` gives
them unreversed, whatever the codebook's ``reverse_scored`` says; that column is for the factor analyses, which
read the codebook, never a score's declaration).
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
    >>> from study.survey.scores import compute_scores
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


def score_table(st) -> pd.DataFrame:
    """Every declared score of the store's study per participant and occasion, wide: participant_id, and when the
    study has several questionnaire occasions ``occasion`` and ``condition`` (the condition it rates, empty for one
    that rates none), then one column per score in declaration order (NaN = an item unanswered). From the final
    answers (:func:`study.survey.answers.final_responses`); exclusions are not applied. A study that declares no
    score gives an empty frame without score columns."""
    from study.folder.scores import study_scores
    from study.store.studies import definition
    from study.survey.answers import final_responses, instrument_of

    specs = study_scores(definition(st))
    by_instrument: dict[str, list[ScoreSpec]] = {}
    for spec in specs:
        by_instrument.setdefault(spec.instrument, []).append(spec)
    wide = None
    for name, group in by_instrument.items():
        answers = final_responses(st, name)
        ins = instrument_of(st, name)
        keys = [k for k in KEYS if k in answers.columns]
        part = answers[keys].reset_index(drop=True)
        for spec in group:
            part[spec.name] = _score(answers, spec, ins).to_numpy(dtype=float)
        wide = part if wide is None else wide.merge(part, on=keys, how="outer")
    if wide is None:
        return pd.DataFrame({"participant_id": pd.Series(dtype=object)})
    keys = [k for k in KEYS if k in wide.columns]
    return wide.sort_values(keys[:1], kind="stable").reset_index(drop=True)[keys + [s.name for s in specs]]

"""Scoring of an acceptance survey: validation of the wide answer frame, reverse scoring from the study's
instrument, the listwise analysis sample and construct composites.

Conventions (docs/contracts.md "Analysis outputs"): answers are raw as ticked, on each item's scale
(scale_min..scale_max of the codebook, any K-point Likert or semantic item); reverse-scored items are mapped
x -> min + max - x; a composite is the mean of a construct's *retained* items after reverse scoring. Missing data:
listwise deletion over all scaled items by default, so every table is computed on the same participants and
reports that n.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from study.folder.instrument import Instrument

ID_COL = "participant_id"


def resolve_instrument(study, instrument=None) -> Instrument:
    """The instrument to analyse: an :class:`Instrument` as given, else the study's instrument of that name (None:
    the study's only one). `study` is a :class:`study.folder.definition.StudyDefinition`.

    Examples
    --------
    >>> from analysis.survey.scoring import resolve_instrument
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> inst = resolve_instrument(load(REPO_ROOT / "studies" / "lane_keeping"))
    >>> inst.name, inst.reverse_items, inst.scale("EE3")
    ('lk_acceptance_v1', ['EE3'], (1, 7))
    """
    if isinstance(instrument, Instrument):
        return instrument
    if study is None:
        raise ValueError("no study given: pass the study definition (or an Instrument)")
    return study.instrument(instrument)


@dataclass(frozen=True)
class ScoredSurvey:
    """The analysis sample. `scored` = participant x scaled item after reverse scoring (index participant_id);
    `raw` = the same rows unreversed; `n_input` rows came in, `dropped` participant ids left out (listwise)."""

    scored: pd.DataFrame
    raw: pd.DataFrame
    constructs: dict[str, list[str]]
    reverse_items: list[str]
    n_input: int
    dropped: list[str]

    @property
    def n(self) -> int:
        return len(self.scored)


def score_responses(responses: pd.DataFrame, instrument: Instrument, *, listwise: bool = True) -> ScoredSurvey:
    """Validate the wide survey frame and return the reverse-scored analysis sample.

    Parameters
    ----------
    responses : DataFrame
        participant_id (optional) + one column per scaled item of the instrument, raw answers as ticked.
    instrument : Instrument
        The study's codebook (``definition.instrument()``).
    listwise : bool
        Leave out participants with any missing scaled answer (default).

    Returns
    -------
    ScoredSurvey

    Raises
    ------
    ValueError
        (one line) A missing item column, answers outside the item's scale or not integers, duplicate
        participants, or an empty sample.

    Examples
    --------
    Synthetic answers to the lane-keeping example study (7-point items): EE3 is reverse scored x -> 1 + 7 - x,
    so raw and scored answers add up to 8:

    >>> from analysis.survey.scoring import score_responses
    >>> from analysis.survey.testing import simulate_study_responses
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> study = load(REPO_ROOT / "studies" / "lane_keeping")
    >>> s = score_responses(simulate_study_responses(study, 24, seed=1), study.instrument())
    >>> s.n, s.reverse_items, list(s.constructs)
    (24, ['EE3'], ['PE', 'EE', 'SI', 'BI'])
    >>> bool(((s.raw["EE3"] + s.scored["EE3"]) == 8).all())
    True
    """
    inst = instrument
    if not isinstance(inst, Instrument):
        raise ValueError("score_responses needs the study's Instrument (definition.instrument())")
    items = inst.scaled_items
    if not isinstance(responses, pd.DataFrame):
        raise ValueError("responses must be a pandas DataFrame (participant_id + one column per item)")
    missing = [c for c in items if c not in responses.columns]
    if missing:
        raise ValueError(f"survey responses lack item column(s): {', '.join(missing)}")
    df = responses.copy()
    if ID_COL not in df.columns:
        df[ID_COL] = [f"row{i + 1}" for i in range(len(df))]
    df[ID_COL] = df[ID_COL].astype(str)
    dup = df[ID_COL][df[ID_COL].duplicated()].unique().tolist()
    if dup:
        raise ValueError(f"duplicate participant_id in survey responses: {', '.join(dup[:5])}")
    raw = df.set_index(ID_COL)[items]
    try:
        raw = raw.apply(pd.to_numeric, errors="raise").astype(float)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"survey answers must be numbers on the item's scale or empty: {exc}") from None
    for item in items:
        lo, hi = inst.scale(item)
        col = raw[item].dropna()
        bad = col[(col < lo) | (col > hi) | (col != np.round(col))]
        if len(bad):
            raise ValueError(f"item {item}: answer {bad.iloc[0]:g} of {bad.index[0]} is outside {lo}..{hi}")
        step = inst.step(item)   # a slider's grid (1 for every other item)
        off = col[(col - lo) % step != 0]
        if len(off):
            raise ValueError(f"item {item}: answer {off.iloc[0]:g} of {off.index[0]} is not a step of {step} "
                             f"from {lo}")
    n_input = len(raw)
    if listwise:
        keep = raw.notna().all(axis=1)
        dropped = raw.index[~keep].tolist()
        raw = raw[keep]
    else:
        dropped = []
    if len(raw) == 0:
        raise ValueError("no complete survey responses to analyse")
    scored = inst.reverse(raw)
    return ScoredSurvey(scored=scored, raw=raw, constructs=inst.constructs, reverse_items=inst.reverse_items,
                        n_input=n_input, dropped=dropped)


def check_not_constant(frame: pd.DataFrame, what: str = "item") -> None:
    """ValueError naming the first column of `frame` without variance (correlations, CFA and alpha need it).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.scoring import check_not_constant
    >>> check_not_constant(pd.DataFrame({"SN1": [1, 2, 3], "SN2": [4, 4, 4]}))
    Traceback (most recent call last):
    ...
    ValueError: item SN2 is constant (every answer = 4); it has no variance to analyse
    """
    for col in frame.columns:
        vals = frame[col].dropna()
        if len(vals) and vals.nunique() < 2:
            raise ValueError(f"{what} {col} is constant (every answer = {vals.iloc[0]:g}); "
                             "it has no variance to analyse")


def composites(scored: pd.DataFrame, retained: dict[str, list[str]]) -> pd.DataFrame:
    """Participant x construct: mean of each construct's retained (already reverse-scored) items.

    With missing answers (``listwise=False``) the mean is over the items a participant answered.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.scoring import composites
    >>> scored = pd.DataFrame({"PU1": [1.0, 4.0], "PU2": [3.0, None], "BI1": [5.0, 2.0], "BI2": [4.0, 2.0]},
    ...                       index=pd.Index(["P001", "P002"], name="participant_id"))
    >>> composites(scored, {"PU": ["PU1", "PU2"], "BI": ["BI1", "BI2"]})
                     PU   BI
    participant_id
    P001            2.0  4.5
    P002            4.0  2.0
    """
    out = {}
    for construct, items in retained.items():
        if not items:
            raise ValueError(f"construct {construct} has no retained items")
        out[construct] = scored[items].mean(axis=1, skipna=True)
    return pd.DataFrame(out, index=scored.index)

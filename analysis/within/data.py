"""The tidy data of a within-subjects comparison, read from a study's store: one row per participant, condition and
dependent variable (:mod:`analysis.within.analyze` takes it).

- **Scores** (``[within] scores``): the instrument's declared scores of each final answer set, on the questionnaire
  occasion that rates a condition (a protocol phase with ``rates``, docs/survey.md "Occasions").
- **KPIs** (``[within] kpis``): each drive's KPI over the whole drive; drives outside a condition (familiarisation,
  practice) are not compared.
- **period**: the position of the participant's drive of that condition among their drives of the compared
  conditions, from the phases they went through (the assigned order when a phase is missing); **order**: the
  assigned order's name.

Participants excluded with scope ``all`` are left out, those excluded with ``subjective`` lose their scores and those
excluded with ``objective`` their KPIs (docs/contracts.md, exclusions).
"""
from __future__ import annotations

import pandas as pd

COLUMNS = ["participant", "condition", "period", "order", "variable", "source", "label", "unit", "value"]
ITEM_COLUMNS = ["variable", "participant", "condition", "item", "value"]


def _excluded(st, scopes: tuple[str, ...]) -> set[str]:
    rows = st.df("SELECT DISTINCT participant_id FROM exclusions WHERE scope IN (SELECT unnest(?))", [list(scopes)])
    return set(rows["participant_id"])


def periods(st, study, conditions) -> pd.DataFrame:
    """participant, condition, period, order of every participant with an assigned or walked protocol: the period
    of each compared condition's drive phase (1, 2, ...)."""
    from study.people.orders import participant_protocol

    drive_phase = {}
    for proto in study.protocols.values():
        for ph in proto.steps:
            if ph.drive and ph.condition in conditions:
                drive_phase[ph.name] = ph.condition
    walked = st.df("SELECT participant_id, phase, seq FROM phase_events ORDER BY participant_id, seq")
    orders = st.df("SELECT participant_id, order_name FROM order_assignments")
    order_of = dict(zip(orders["participant_id"], orders["order_name"]))
    rows = []
    for pid in st.df("SELECT participant_id FROM participants ORDER BY participant_id")["participant_id"]:
        seq = [ph for ph in walked.loc[walked["participant_id"] == pid, "phase"] if ph in drive_phase]
        if len(seq) < len(conditions):      # not walked (yet): the assigned order says what comes when
            seq = [ph for ph in participant_protocol(st, pid).phases if ph in drive_phase]
        for k, ph in enumerate(seq, start=1):
            rows.append({"participant": pid, "condition": drive_phase[ph], "period": k,
                         "order": order_of.get(pid)})
    return pd.DataFrame(rows, columns=["participant", "condition", "period", "order"])


def kpi_values(st, study, spec) -> pd.DataFrame:
    """participant, condition, variable, source, label, unit, value of every declared KPI of every condition's
    drive (whole drive), objective exclusions left out."""
    from analysis.drives.kpis import store_kpis
    from study.folder.kpi_spec import study_spec

    if not spec.kpis:
        return pd.DataFrame(columns=COLUMNS)
    kspec = study_spec(study)
    per = store_kpis(st, spec=kspec)
    per = per[(per["segment"] == "overall") & per["condition"].isin(spec.conditions)]
    per = per[~per["participant_id"].isin(_excluded(st, ("all", "objective")))]
    user = {k.name: k for k in kspec.user_kpis}
    frames = []
    for name in spec.kpis:
        k = user.get(name)
        frames.append(pd.DataFrame({
            "participant": per["participant_id"].to_numpy(), "condition": per["condition"].to_numpy(),
            "variable": name, "source": "kpi", "label": getattr(k, "label", None) or name,
            "unit": kspec.unit(name), "value": pd.to_numeric(per[name], errors="coerce").to_numpy()}))
    return pd.concat(frames, ignore_index=True)


def score_values(st, study, spec) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(participant, condition, variable, source, label, unit, value of every declared score on the occasion that
    rates each condition; the scored items behind each score, for alpha), subjective exclusions left out."""
    from analysis.survey.scores import score_occasions

    if not spec.scores:
        return pd.DataFrame(columns=COLUMNS), pd.DataFrame(columns=ITEM_COLUMNS)
    scores, items = score_occasions(st, study, spec.scores)
    drop = _excluded(st, ("all", "subjective"))
    scores = scores[scores["condition"].isin(spec.conditions) & ~scores["participant"].isin(drop)]
    items = items[items["condition"].isin(spec.conditions) & ~items["participant"].isin(drop)]
    return scores.assign(source="score"), items


def within_data(st, study, spec) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(the long frame of :data:`COLUMNS`, the item frame of :data:`ITEM_COLUMNS`) of a study's ``[within]``
    declaration (:class:`study.folder.within_spec.WithinSpec`)."""
    scores, items = score_values(st, study, spec)
    kpis = kpi_values(st, study, spec)
    data = pd.concat([f for f in (scores, kpis) if not f.empty], ignore_index=True) if not (
        scores.empty and kpis.empty) else pd.DataFrame(columns=COLUMNS)
    data = data.drop(columns=[c for c in ("period", "order") if c in data.columns])
    data = data.merge(periods(st, study, spec.conditions), on=["participant", "condition"], how="left")
    order = {v: i for i, v in enumerate([*spec.scores, *spec.kpis])}
    data = (data.assign(_v=data["variable"].map(order)).sort_values(["_v", "participant", "condition"], kind="stable")
            .drop(columns="_v").reset_index(drop=True))
    return data[COLUMNS], items


def resolutions(st, study, spec) -> dict[str, float | None]:
    """variable -> the step at which its values tie in the rank tests: each compared score's from its declaration
    (:func:`study.folder.scores.score_resolution`); KPIs are left to the default (1e-9 of the largest magnitude,
    :func:`analysis.ranks.resolution_of`)."""
    from study.folder.scores import score_resolution, study_scores
    from study.survey.answers import instrument_of

    declared = {s.name: s for s in study_scores(study)}
    return {name: score_resolution(declared[name], instrument_of(st, declared[name].instrument))
            for name in spec.scores if name in declared}

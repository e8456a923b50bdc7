"""The reference cohort of the paper (Section 4.2) as participants and protocol events.

44 participants P001..P044 (37 male / 7 female). 3 had motion sickness in the baseline drive (excluded, scope
``all``); 7 had technical issues in the pEDAS drive (scope ``objective``); one survey is not in the tables
(scope ``subjective``, reason ``incomplete_survey``) because every table implies 40 respondents while the text says
41 (audit finding "n_implied"). Styles: 7 cautious / 20 normal / 7 sporty among the 34 objective participants, the
other 10 split 2 / 6 / 2 in the same proportion. Eco-familiarity: the printed shares (2.5 / 42.5 / 32.5 / 15 / 7.5 %)
are counts 1 / 17 / 13 / 6 / 3 of the 40 survey respondents; the 4 others are drawn from the same shares.
P006 - the participant of the paper's Figs. 11 and 12 - is an included normal-style driver.
Ages and licence years are not printed: ages are drawn around a university cohort (seeded), licence years
from the age. Timestamps are a plausible seeded schedule (one participant per slot on weekdays).

``events.csv`` (one row per event): ``participant_id, kind`` (``phase`` | ``exclusion``), ``phase``,
``started_at``, ``ended_at`` (ISO 8601, local time), ``outcome`` (completed | aborted), ``scope``, ``reason``,
``note``. Phase rows map to the store's ``phase_events`` table, exclusion rows to ``exclusions``.
"""
from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd

DEFAULT_SEED = 20240
N_ENROLLED = 44
N_FEMALE = 7
N_MOTION_SICKNESS = 3
N_TECHNICAL = 7
N_SURVEY_MISSING = 1          # 41 in the text, 40 in the tables
FIGURE_PARTICIPANT = "P006"   # Figs. 11/12 "participant 6"
STYLE_OBJECTIVE = {"cautious": 7, "normal": 20, "sporty": 7}
STYLE_OTHERS = {"cautious": 2, "normal": 6, "sporty": 2}
ECO_SURVEY = {1: 1, 2: 17, 3: 13, 4: 6, 5: 3}
ECO_SHARES = np.array([2.5, 42.5, 32.5, 15.0, 7.5]) / 100
PHASES = ("familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey")
PHASE_MINUTES = {"familiarisation": 10, "baseline_drive": 20, "pedas_intro": 10, "practice": 10,
                 "pedas_drive": 20, "survey": 15}
START_DATE = datetime(2022, 5, 2, 9, 0)
EVENT_COLUMNS = ["participant_id", "kind", "phase", "started_at", "ended_at", "outcome", "scope", "reason", "note"]


@dataclass
class Cohort:
    """participants (participant_id, age, gender, license_years, style, eco_familiarity) and events."""

    participants: pd.DataFrame
    events: pd.DataFrame
    seed: int

    def excluded(self, scope: str) -> set[str]:
        """Participants excluded for analyses of ``scope`` (objective | subjective): 'all' exclusions count too."""
        ex = self.events[self.events["kind"] == "exclusion"]
        return set(ex.loc[ex["scope"].isin(["all", scope]), "participant_id"])

    def survey_ids(self) -> list[str]:
        """The survey respondents of the tables (40), sorted."""
        return sorted(set(self.participants["participant_id"]) - self.excluded("subjective"))

    def objective_ids(self) -> list[str]:
        """The 34 participants of the objective analysis, sorted."""
        return sorted(set(self.participants["participant_id"]) - self.excluded("objective"))

    def write(self, out_dir: str | Path) -> list[Path]:
        """Write participants.csv and events.csv (byte-identical for the same seed)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        p1, p2 = out / "participants.csv", out / "events.csv"
        self.participants.to_csv(p1, index=False, lineterminator="\n")
        self.events.to_csv(p2, index=False, lineterminator="\n")
        return [p1, p2]


def make_cohort(seed: int = DEFAULT_SEED) -> Cohort:
    """Generate the reference cohort deterministically from ``seed``."""
    rng = np.random.default_rng(seed)
    ids = [f"P{i:03d}" for i in range(1, N_ENROLLED + 1)]
    others = [p for p in ids if p != FIGURE_PARTICIPANT]
    roles = rng.permutation(others)
    motion = sorted(roles[:N_MOTION_SICKNESS])
    technical = sorted(roles[N_MOTION_SICKNESS:N_MOTION_SICKNESS + N_TECHNICAL])
    missing_survey = sorted(roles[N_MOTION_SICKNESS + N_TECHNICAL:N_MOTION_SICKNESS + N_TECHNICAL + N_SURVEY_MISSING])
    objective = [p for p in ids if p not in motion and p not in technical]
    # styles: P006 normal, the rest of the objective 34 shuffled over 7 / 19 / 7
    style = {FIGURE_PARTICIPANT: "normal"}
    pool = [s for s, k in STYLE_OBJECTIVE.items() for _ in range(k)]
    pool.remove("normal")
    for p, s in zip([p for p in objective if p != FIGURE_PARTICIPANT], rng.permutation(pool)):
        style[p] = str(s)
    rest = [p for p in ids if p not in objective]
    for p, s in zip(rest, rng.permutation([s for s, k in STYLE_OTHERS.items() for _ in range(k)])):
        style[p] = str(s)
    # eco-familiarity: exact printed counts over the 40 respondents, drawn shares for the others
    respondents = [p for p in ids if p not in motion and p not in missing_survey]
    eco = dict(zip(respondents, rng.permutation([lvl for lvl, k in ECO_SURVEY.items() for _ in range(k)])))
    for p in ids:
        if p not in eco:
            eco[p] = int(rng.choice(np.arange(1, 6), p=ECO_SHARES))
    gender = dict(zip(ids, rng.permutation(["female"] * N_FEMALE + ["male"] * (N_ENROLLED - N_FEMALE))))
    # ages: a university cohort, 20-55, right-skewed; licence at 17-21
    age = {p: int(np.clip(round(20 + rng.gamma(2.2, 3.6)), 20, 55)) for p in ids}
    lic = {p: int(max(1, age[p] - int(rng.integers(17, 22)))) for p in ids}
    participants = pd.DataFrame({
        "participant_id": ids, "age": [age[p] for p in ids], "gender": [str(gender[p]) for p in ids],
        "license_years": [lic[p] for p in ids], "style": [style[p] for p in ids],
        "eco_familiarity": [int(eco[p]) for p in ids]})
    events = _events(ids, motion, technical, missing_survey, rng)
    return Cohort(participants=participants, events=events, seed=seed)


def _events(ids, motion, technical, missing_survey, rng) -> pd.DataFrame:
    rows = []
    day, slot = START_DATE, 0
    for p in ids:
        # two slots a day (09:00, 13:30), weekdays only
        start = day + timedelta(hours=4.5 * slot, minutes=int(rng.integers(0, 20)))
        slot += 1
        if slot == 2:
            slot, day = 0, day + timedelta(days=1)
            while day.weekday() >= 5:
                day += timedelta(days=1)
        t = start
        for ph in PHASES:
            end = t + timedelta(minutes=PHASE_MINUTES[ph] + int(rng.integers(-2, 4)))
            outcome, note = "completed", ""
            if p in motion and ph == "baseline_drive":
                end, outcome, note = t + timedelta(minutes=int(rng.integers(3, 12))), "aborted", "motion sickness"
            if p in technical and ph == "pedas_drive":
                outcome, note = "aborted", "technical issue in the simulator during the pEDAS drive"
            if p in missing_survey and ph == "survey":
                outcome, note = "aborted", "survey not complete; not part of the published tables"
            rows.append([p, "phase", ph, t.isoformat(timespec="seconds"), end.isoformat(timespec="seconds"),
                         outcome, "", "", note])
            if outcome == "aborted":
                scope, reason = {"motion sickness": ("all", "motion_sickness")}.get(
                    note, ("objective", "technical_issue") if ph == "pedas_drive" else ("subjective", "incomplete_survey"))
                rows.append([p, "exclusion", ph, end.isoformat(timespec="seconds"), "", "", scope, reason, note])
                if p in motion:
                    break
            t = end + timedelta(minutes=int(rng.integers(1, 5)))
    return pd.DataFrame(rows, columns=EVENT_COLUMNS)


def load_into_store(st, cohort: Cohort) -> None:
    """Insert the cohort into an open ``study.store.store.Store`` that serves the paper's study (``init --study
    studies/pedas_paper``) in one transaction: participants on the study's default protocol with their attributes
    (each checked and typed by the study's declaration), phase_events, exclusions. The caller opens the store;
    nothing is written if any row is refused."""
    from study.store.studies import definition, version

    study = definition(st)
    from analysis.paper.published import paper_study

    if study.study_id != paper_study().study_id:
        raise ValueError(f"the reference cohort belongs to study {paper_study().study_id}; the store serves "
                         f"{study.study_id}")
    protocol, ver = study.protocol().name, version(st)
    names = [a.name for a in study.attributes]
    with st.transaction():
        for r in cohort.participants.to_dict("records"):
            pid = study.validate_id(r["participant_id"])
            st.insert("participants", {"participant_id": pid, "protocol": protocol, "study_version": ver})
            for name in names:
                value = study.attribute(name).parse(r.get(name))
                if value is not None:
                    st.insert("participant_attributes", {"participant_id": pid, "attribute": name,
                                                         "value": str(value)})
        for r in cohort.events.itertuples(index=False):
            if r.kind == "phase":
                st.insert("phase_events", {"participant_id": r.participant_id, "phase": r.phase,
                                           "seq": PHASES.index(r.phase) + 1,
                                           "started_at": r.started_at, "ended_at": r.ended_at or None,
                                           "outcome": r.outcome, "note": r.note or None})
            else:
                st.insert("exclusions", {"participant_id": r.participant_id, "scope": r.scope, "reason": r.reason,
                                         "note": r.note or None})

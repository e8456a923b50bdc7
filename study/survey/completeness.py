"""Data completeness: for each participant, which protocol phases, drives and survey answers the store still lacks.

What a participant needs follows their exclusions: scope ``all`` needs nothing more, ``objective`` needs no drive,
``subjective`` needs no survey. A drive is needed for every drive phase of the participant's protocol (its
``condition``); a phase is done when it ended with outcome ``completed`` (an aborted phase stays missing: it is a
gap the researcher decides about, usually with an exclusion); the survey is done when its answers are final
(:func:`study.survey.answers.final_responses`' rule). An instrument answered on several occasions (questionnaire phases,
:mod:`study.folder.occasions`) is done when the answers of every occasion in the participant's protocol are final; its
``survey`` column then reads ``k/n final``.
"""
from __future__ import annotations

import pandas as pd

COLUMNS = ["participant_id", "protocol", "excluded", "phases_done", "phases_total", "missing_phases",
           "missing_drives", "survey", "complete"]


def completeness(st, instrument: str | None = None) -> pd.DataFrame:
    """One row per participant (ordered by id): participant_id, protocol, excluded (scopes, '' = none),
    phases_done / phases_total (completed phases of the protocol), missing_phases, missing_drives (comma-separated
    names, '' = none), survey (the survey status's basis: none | single | awaiting_second_entry | unresolved |
    double_entry_final), complete (nothing needed is missing)."""
    from study.people.protocol import protocol_of
    from study.survey import answers as sv

    people = st.df("SELECT participant_id FROM participants ORDER BY participant_id")["participant_id"].tolist()
    done = st.df("SELECT participant_id, phase FROM phase_events WHERE outcome = 'completed'")
    drives = st.df("SELECT participant_id, condition FROM drives")
    excl = st.df("SELECT participant_id, scope FROM exclusions")
    survey = sv.survey_status(st, instrument)
    several = "occasion" in survey.columns
    survey = survey.set_index("participant_id")
    rows = []
    for pid in people:
        proto = protocol_of(st, pid)
        scopes = set(excl.loc[excl["participant_id"] == pid, "scope"])
        have_phases = set(done.loc[done["participant_id"] == pid, "phase"])
        have_drives = set(drives.loc[drives["participant_id"] == pid, "condition"])
        missing_phases = [] if "all" in scopes else [p for p in proto.phases if p not in have_phases]
        needs_drives = not scopes & {"all", "objective"}
        missing_drives = [p.condition for p in proto.steps
                          if needs_drives and p.drive and p.condition and p.condition not in have_drives]
        if several:  # the occasions of this participant's protocol, each final
            mine = survey.loc[[pid]]
            mine = mine[mine["occasion"].isin(proto.phases)]
            done_n = int(mine["final"].sum())
            basis, final = f"{done_n}/{len(mine)} final", done_n == len(mine)
        else:
            basis, final = survey.loc[pid, "basis"], bool(survey.loc[pid, "final"])
        survey_missing = not final and not scopes & {"all", "subjective"}
        rows.append({"participant_id": pid, "protocol": proto.name, "excluded": ",".join(sorted(scopes)),
                     "phases_done": len(have_phases & set(proto.phases)), "phases_total": len(proto.phases),
                     "missing_phases": ", ".join(missing_phases), "missing_drives": ", ".join(missing_drives),
                     "survey": basis,
                     "complete": not (missing_phases or missing_drives or survey_missing)})
    return pd.DataFrame(rows, columns=COLUMNS)

"""Exclusions with scope, and the ONE function every analysis uses to apply them.

Scopes: ``all`` removes a participant from objective and subjective analyses (e.g. motion sickness),
``objective`` only from the drive KPIs (e.g. a technical issue in the pEDAS drive: the survey is still
used), ``subjective`` only from the survey analyses. In the paper 44 volunteered, 3 had motion sickness
(N=41 subjective) and 7 more had a technical issue in the pEDAS drive (N=34 objective).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from study.common.errors import UserError, check_choice

if TYPE_CHECKING:  # pandas only in annotations: the CLI reads SCOPES and REASONS for its help
    import pandas as pd

SCOPES = ("all", "objective", "subjective")
REASONS = ("motion_sickness", "technical_issue", "incomplete_survey", "withdrawn", "other")
ANALYSES = ("objective", "subjective", "all")


def exclude(st, participant_id: str, scope: str, reason: str, note: str | None = None) -> dict[str, Any]:
    """Record an exclusion (audited). One exclusion per participant and scope."""
    from study.people.participants import require

    check_choice("scope", scope, SCOPES)
    check_choice("reason", reason, REASONS)
    with st.transaction():
        require(st, participant_id)
        have = st.one("SELECT reason FROM exclusions WHERE participant_id = ? AND scope = ?", [participant_id, scope])
        if have:
            raise UserError(f"{participant_id} is already excluded with scope {scope} ({have})")
        return st.insert("exclusions", {"participant_id": participant_id, "scope": scope, "reason": reason,
                                        "note": note})


def revoke(st, participant_id: str, scope: str) -> None:
    """Withdraw an exclusion (audited as a delete)."""
    with st.transaction():
        if not st.delete("exclusions", {"participant_id": participant_id, "scope": scope}):
            raise UserError(f"{participant_id} has no exclusion with scope {scope}")


# exclusion scopes that remove a participant from an analysis of each kind ("all": every scope counts)
_EXCLUDING = {"objective": ("all", "objective"), "subjective": ("all", "subjective"), "all": SCOPES}


def _excluding_scopes(analysis: str) -> tuple[str, ...]:
    return _EXCLUDING[check_choice("analysis scope", analysis, ANALYSES)]


def included_participants(st, scope: str) -> list[str]:
    """IDs (sorted) of the participants that an analysis of kind `scope` may use.

    `scope` = 'objective' (drive KPIs) drops exclusions of scope all|objective; 'subjective' (survey) drops
    all|subjective; 'all' keeps only participants without any exclusion.
    """
    scopes = _excluding_scopes(scope)
    marks = ", ".join("?" for _ in scopes)
    rows = st.con.execute(
        f"SELECT participant_id FROM participants WHERE participant_id NOT IN "
        f"(SELECT participant_id FROM exclusions WHERE scope IN ({marks})) ORDER BY participant_id",
        list(scopes)).fetchall()
    return [r[0] for r in rows]


def apply_exclusions(st, df: pd.DataFrame, scope: str, column: str = "participant_id") -> pd.DataFrame:
    """The rows of `df` whose participant is included for `scope` (a filter built on included_participants)."""
    keep = set(included_participants(st, scope))
    return df[df[column].isin(keep)].reset_index(drop=True)


def list_exclusions(st, participant_id: str | None = None) -> pd.DataFrame:
    where, params = ("WHERE participant_id = ?", [participant_id]) if participant_id else ("", [])
    return st.df(f"SELECT participant_id, scope, reason, note, created_at FROM exclusions {where} "
                 f"ORDER BY participant_id, scope", params)

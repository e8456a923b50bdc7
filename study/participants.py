"""Participants: pseudonymous IDs and the demographics the paper reports (age, gender, licence years,
self-reported driving style, eco-driving familiarity on the paper's five levels)."""
from __future__ import annotations

import re
from typing import Any

import pandas as pd

from pedas.vocabulary import STYLES
from study.errors import UserError, check_choice

ID_PATTERN = re.compile(r"^P[0-9]{3,}$")  # ASCII digits only, as the schema's CHECK
GENDERS = ("female", "male", "diverse", "undisclosed")
AGE_RANGE = (16, 110)


def validate_id(participant_id: str) -> str:
    if not isinstance(participant_id, str) or not ID_PATTERN.fullmatch(participant_id):
        raise UserError(f"bad participant id {participant_id!r}: use P followed by at least 3 digits, e.g. P001")
    return participant_id


def _int(name: str, value: Any, lo: int, hi: int) -> int | None:
    if value is None:
        return None
    try:
        iv = int(value)
    except (TypeError, ValueError):
        raise UserError(f"{name} must be a whole number, not {value!r}") from None
    if iv != value and not isinstance(value, str):
        raise UserError(f"{name} must be a whole number, not {value!r}")
    if not lo <= iv <= hi:
        raise UserError(f"{name} must be between {lo} and {hi}, not {iv}")
    return iv


def _choice(name: str, value: str | None, allowed: tuple[str, ...]) -> str | None:
    return None if value is None else check_choice(name, value, allowed)


def add_participant(st, participant_id: str, age: int | None = None, gender: str | None = None,
                    license_years: int | None = None, style: str | None = None,
                    eco_familiarity: int | None = None, protocol: str | None = None) -> dict[str, Any]:
    """Register a participant (audited); returns the stored row. Duplicate or invalid values -> UserError."""
    from study.protocol import load_protocol

    row: dict[str, Any] = {
        "participant_id": validate_id(participant_id),
        "age": _int("age", age, *AGE_RANGE),
        "gender": _choice("gender", gender, GENDERS),
        "license_years": _int("license years", license_years, 0, 95),
        "style": _choice("style", style, STYLES),
        "eco_familiarity": _int("eco familiarity", eco_familiarity, 1, 5),
    }
    if row["age"] is not None and row["license_years"] is not None and row["license_years"] > row["age"] - 16:
        raise UserError(f"license years {row['license_years']} impossible at age {row['age']} (licence from 16)")
    if protocol is not None:
        row["protocol"] = load_protocol(protocol).name
    with st.transaction():
        if st.one("SELECT 1 FROM participants WHERE participant_id = ?", [participant_id]):
            raise UserError(f"participant {participant_id} already exists")
        return st.insert("participants", row)


def require(st, participant_id: str) -> None:
    """UserError unless the participant is registered."""
    validate_id(participant_id)
    if not st.one("SELECT 1 FROM participants WHERE participant_id = ?", [participant_id]):
        raise UserError(f"unknown participant {participant_id}")


def list_participants(st) -> pd.DataFrame:
    """Participants with their protocol position and exclusions, one row each, ordered by ID.

    Columns: participant_id, age, gender, license_years, style, eco_familiarity, protocol, phase (last
    phase entered), phase_outcome, excluded (comma-separated scopes, '' when none), created_at.
    """
    return st.df("""
        WITH last AS (
            SELECT participant_id, arg_max(phase, seq) AS phase, arg_max(outcome, seq) AS phase_outcome
            FROM phase_events GROUP BY participant_id),
        exc AS (
            SELECT participant_id, string_agg(scope, ',' ORDER BY scope) AS excluded
            FROM exclusions GROUP BY participant_id)
        SELECT p.participant_id, p.age, p.gender, p.license_years, p.style, p.eco_familiarity, p.protocol,
               last.phase, last.phase_outcome, coalesce(exc.excluded, '') AS excluded, p.created_at
        FROM participants p LEFT JOIN last USING (participant_id) LEFT JOIN exc USING (participant_id)
        ORDER BY p.participant_id""")

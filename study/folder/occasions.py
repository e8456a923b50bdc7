"""Questionnaire occasions: the protocol phases in which an instrument is answered (docs/survey.md, "Occasions").

A protocol phase is a questionnaire when it names the ``instrument`` answered in it; after a drive it may say which
condition it ``rates``::

    {"name": "drive_visual", "drive": true, "condition": "visual"},
    {"name": "survey_after_visual", "instrument": "post_drive", "rates": "visual"},

The phase's name is the **occasion**: every answer is keyed by participant, instrument, occasion, item and entry
round, so one instrument can be answered after each of several drives. A study whose phases name no instrument (the
paper's, the lane-keeping study, every study folder written before occasions) has one occasion: the last phase of its
default protocol that is not a drive (the paper's ``survey``, the lane-keeping study's ``questionnaire``), answering
the study's (first) instrument; with only drive phases, the instrument's name. That is also the occasion the
answers of a store migrated from before occasions get (:func:`fill_migrated`).

This module reads a :class:`study.folder.definition.StudyDefinition` and does not import it (the definition imports this
module for :func:`check_occasions`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

_VERSION = re.compile(r"_v\d+$")
#: the tables whose `occasion` column migration 0050 added (filled with '' for the rows stored before it)
OCCASION_TABLES = ("responses", "survey_tokens", "survey_drafts", "survey_submissions", "survey_resolutions")


@dataclass(frozen=True)
class Occasion:
    """One questionnaire phase: `name` (the phase, the stored occasion), `instrument` (the stored instrument name of
    the study's current version), `rates` (the condition it rates, or None), `declared` (False for the single
    occasion of a study whose phases name no instrument)."""

    name: str
    instrument: str
    rates: str | None = None
    declared: bool = True


def base_name(instrument: str) -> str:
    """An instrument's name without its version suffix (``post_drive_v2`` -> ``post_drive``)."""
    return _VERSION.sub("", instrument)


def instrument_named(study, name: str) -> str | None:
    """The stored name of the study's instrument `name` (given with or without its version), or None."""
    for full in study.instruments:
        if name in (full, base_name(full)):
            return full
    return None


def study_occasions(study) -> tuple[Occasion, ...]:
    """Every occasion of a study, in the order of its protocols' phases (the default protocol first; a phase that
    several protocols share counts once)."""
    out: dict[str, Occasion] = {}
    for proto in study.protocols.values():
        for ph in proto.steps:
            if ph.instrument is not None and ph.name not in out:
                full = instrument_named(study, ph.instrument) or ph.instrument
                out[ph.name] = Occasion(ph.name, full, ph.rates)
    if out or not study.instruments:
        return tuple(out.values())
    return (legacy_occasion(study),)


def legacy_occasion(study) -> Occasion:
    """The single occasion of a study whose phases name no instrument (module docstring)."""
    instrument = next(iter(study.instruments))
    proto = next(iter(study.protocols.values()), None)
    names = [ph.name for ph in proto.steps if not ph.drive] if proto is not None else []
    return Occasion(names[-1] if names else base_name(instrument), instrument, None, declared=False)


def occasions_of(study, instrument: str) -> tuple[Occasion, ...]:
    """The occasions on which `instrument` (a stored name, any version) is answered."""
    base = base_name(instrument)
    return tuple(o for o in study_occasions(study) if base_name(o.instrument) == base)


def several(study) -> bool:
    """True when the study has more than one occasion: only then do survey files and exports carry an `occasion`
    column (a study with one occasion keeps the files it had before occasions, byte for byte)."""
    return len(study_occasions(study)) > 1


def drive_phase(proto, name: str):
    """The drive phase of `proto` without a condition named `name` (a familiarisation or practice drive), or None."""
    for ph in proto.steps:
        if ph.name == name and ph.drive and ph.condition is None:
            return ph
    return None


# ---------------------------------------------------------------------------------------------- study check
def _json_line(text: str, name: str) -> int | None:
    for i, ln in enumerate(text.splitlines(), start=1):
        if re.search(rf'"name"\s*:\s*"{re.escape(name)}"', ln):
            return i
    return None


def check_occasions(study, problems) -> None:
    """`study check`: a questionnaire phase names an instrument of the study and is no drive; `rates` names a
    declared condition, only on a questionnaire phase, and in every order of the protocol the last drive with a
    condition before the phase drives that condition (a phase before any drive cannot rate one); a phase that two
    protocols share names the same instrument and rated condition in both; with questionnaire phases declared,
    every instrument of the study is answered in one."""
    from study.folder.protocol_file import parse_protocol, protocol_orders

    seen: dict[str, tuple[str | None, str | None, str]] = {}
    named: set[str] = set()
    for rel in study.paths.get("protocols", []):
        if rel not in study.files:
            continue
        try:
            proto = parse_protocol(study.files[rel], rel)
            orders = protocol_orders(proto)
        except Exception:  # noqa: BLE001 - the protocol's own problems are reported by the definition's check
            continue
        text = study.files[rel]
        for ph in proto.steps:
            line, fld = _json_line(text, ph.name), f"phases.{ph.name}"
            if ph.instrument is not None:
                full = instrument_named(study, ph.instrument)
                if full is None:
                    problems.add(rel, line, f"{fld}.instrument", f"{ph.instrument!r} is not an instrument of the "
                                 f"study ({', '.join(base_name(n) for n in study.instruments) or 'none declared'})")
                else:
                    named.add(full)
                if ph.drive:
                    problems.add(rel, line, f"{fld}.instrument", "a drive phase cannot be a questionnaire phase")
            if ph.rates is not None:
                if ph.instrument is None:
                    problems.add(rel, line, f"{fld}.rates", "only a questionnaire phase (with an instrument) rates a "
                                                            "condition")
                elif ph.rates not in study.condition_names:
                    problems.add(rel, line, f"{fld}.rates", f"{ph.rates!r} is not a declared condition "
                                                            f"({'|'.join(study.condition_names)})")
                else:
                    _check_rated(proto, orders, ph, rel, line, fld, problems)
            if ph.instrument is not None:
                key = (ph.instrument, ph.rates, rel)
                if ph.name in seen and seen[ph.name][:2] != key[:2]:
                    problems.add(rel, line, fld, f"phase {ph.name} is a questionnaire of {seen[ph.name][0]} rating "
                                                 f"{seen[ph.name][1]} in {seen[ph.name][2]}: one occasion, one meaning")
                seen.setdefault(ph.name, key)
    if seen:
        for full in study.instruments:
            if full not in named:
                problems.add("study.toml", None, "files.instrument",
                             f"instrument {base_name(full)} is answered in no questionnaire phase (give a phase "
                             f"\"instrument\": \"{base_name(full)}\")")


def _check_rated(proto, orders, ph, rel, line, fld, problems) -> None:
    by_name = {p.name: p for p in proto.steps}
    for order, seq in orders.items():
        before = [by_name[n] for n in seq[:seq.index(ph.name)] if by_name[n].drive and by_name[n].condition]
        where = "" if order == "default" else f" in order {order}"
        if not before:
            problems.add(rel, line, f"{fld}.rates", f"rates {ph.rates} but comes before any drive{where}")
        elif before[-1].condition != ph.rates:
            problems.add(rel, line, f"{fld}.rates", f"rates {ph.rates} but the drive before it{where} is "
                                                    f"{before[-1].name} ({before[-1].condition})")


# ---------------------------------------------------------------------------------------------- migrated stores
def fill_migrated(st, study) -> int:
    """Set the occasion of rows stored before occasions (migration 0050 left them empty) to the occasion of their
    instrument in `study`, the store's study (:func:`legacy_occasion` for such a study); returns the rows changed.
    A store without a study keeps them empty until ``init --study`` stores one (which calls this again). Not
    audited: like a migration, it completes a key the store had no column for."""
    pending = sum(int(st.one(f"SELECT count(*) FROM {t} WHERE occasion = ''")) for t in OCCASION_TABLES)
    if not pending:
        return 0
    occasions = study_occasions(study)
    n = 0
    with st.transaction():
        for t in OCCASION_TABLES:
            for (instrument,) in st.con.execute(f"SELECT DISTINCT instrument FROM {t} WHERE occasion = ''").fetchall():
                mine = [o for o in occasions if base_name(o.instrument) == base_name(instrument)] or list(occasions)
                if mine:
                    n += st.con.execute(f"UPDATE {t} SET occasion = ? WHERE occasion = '' AND instrument = ?",
                                        [mine[0].name, instrument]).fetchone()[0]
    return n

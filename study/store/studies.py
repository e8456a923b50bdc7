"""The study a store serves: storing a checked definition (versioned, with its hash) and reading it back.

A store serves one study. ``pedas-study init --study DIR`` stores the folder's definition as version 1. Running it
again with the same files changes nothing; with changed files it is refused while the store holds data, unless
``new_version=True`` (``--new-version``), which stores version N+1 after checking that nothing already stored is
re-interpreted: every stored participant still matches the id pattern and has valid attribute values, every stored
condition and protocol is still declared, and a survey instrument whose name is already in use has exactly the
same items (a changed wording, scale or reverse flag needs a new instrument version, e.g. ``..._v2``).
Every command reads the newest stored version (:func:`definition`), never the folder. It was checked when it was
stored and is not checked again on reading (:func:`study.folder.definition.from_stored`): its model file, for one, is
parsed only by the commands that use the model.
"""
from __future__ import annotations

import json
from pathlib import Path

from study.common.errors import UserError
from study.folder.attributes import run_checks
from study.folder.definition import StudyDefinition, from_stored, load
from study.folder.protocol_file import protocol_orders
from study.store import audit_trail

_CACHE: dict[str, StudyDefinition] = {}


def current(st) -> dict | None:
    """The newest study_definitions row as a dict of Python values (None when the store has no study yet)."""
    rows = st.dicts("SELECT * FROM study_definitions ORDER BY version DESC LIMIT 1")
    return rows[0] if rows else None


def definition(st) -> StudyDefinition:
    """The store's study (newest version), not checked again (:func:`study.folder.definition.from_stored`); a store without
    one -> UserError saying how to add it."""
    cached = getattr(st, "_study_definition", None)
    if cached is not None:
        return cached
    row = current(st)
    if row is None:
        raise UserError(f"store {st.path} has no study; run `pedas-study init --study DIR` "
                        f"(e.g. studies/pedas_paper)")
    study = _CACHE.get(row["hash"])
    if study is None:
        study = _CACHE[row["hash"]] = from_stored(json.loads(row["files"]))
    st._study_definition = study
    return study


def version(st) -> int | None:
    return st.one("SELECT max(version) FROM study_definitions")


def register(st, folder: str | Path, new_version: bool = False,
             study: StudyDefinition | None = None) -> tuple[str, int]:
    """Store the study of `folder` (checked); returns (what happened, version). `study`: the folder already loaded
    (:func:`study.folder.definition.load`), so that it is not read and checked again while the store is open.

    what: 'stored' (first definition), 'unchanged' (same hash), 'new version'. A changed definition of a store
    in use without `new_version`, or one that would re-interpret stored data, -> UserError; the store is unchanged.
    """
    study = load(folder) if study is None else study
    with st.transaction():
        row = current(st)
        if row is not None and row["hash"] == study.hash:
            return "unchanged", int(row["version"])
        if row is not None:
            old = from_stored(json.loads(row["files"]))
            if old.study_id != study.study_id:
                raise UserError(f"store {st.path} serves study {old.study_id!r}, not {study.study_id!r}: "
                                f"use a new store for another study")
            in_use = _in_use(st)
            if in_use and not new_version:
                raise UserError(f"study {study.study_id} in {folder} differs from the stored version {row['version']} "
                                f"and the store holds {in_use}; re-run with --new-version to store it as version "
                                f"{int(row['version']) + 1}")
            _check_compatible(st, study)
        if row is None and _in_use(st):
            # a store upgraded from before studies were data: its data must fit the study it now gets
            _check_compatible(st, study)
        ver = 1 if row is None else int(row["version"]) + 1
        st.insert("study_definitions", {"version": ver, "study_id": study.study_id, "title": study.title,
                                        "hash": study.hash, "files": json.dumps(study.files, sort_keys=True),
                                        "source": str(folder), "loaded_at": audit_trail.utcnow(),
                                        "loaded_by": st.actor})
        _store_instruments(st, study)
    st._study_definition = None
    from study.folder.occasions import fill_migrated

    fill_migrated(st, study)  # answers of a store migrated before it had a study get the study's occasion
    return ("stored" if ver == 1 else "new version"), ver


def _in_use(st) -> str:
    counts = {t: st.one(f"SELECT count(*) FROM {t}") for t in ("participants", "drives", "responses")}
    return ", ".join(f"{n} {t}" for t, n in counts.items() if n)


def _check_compatible(st, study: StudyDefinition) -> None:
    """UserError if `study` would re-interpret anything already stored: a participant id it does not accept, an
    attribute value it does not declare or accept (or that fails one of its checks), a condition, protocol, phase
    or condition order it no longer declares, or an instrument with answers whose items it changes."""
    def refuse(what: str, exc: UserError | str) -> None:
        raise UserError(f"the new version would re-interpret stored data: {what}: {exc}")

    for pid in st.df("SELECT participant_id FROM participants ORDER BY 1")["participant_id"]:
        try:
            study.validate_id(pid)
        except UserError as exc:
            refuse(f"participant {pid}", exc)
    attrs = st.df("SELECT participant_id, attribute, value FROM participant_attributes "
                  "ORDER BY participant_id, attribute")
    for pid, rows in attrs.groupby("participant_id", sort=True):
        try:
            values = {r.attribute: study.attribute(r.attribute).parse(r.value) for r in rows.itertuples()}
            for a in study.attributes:  # a newly required attribute is not a re-interpretation
                values.setdefault(a.name, None)
            run_checks(study, values)
        except UserError as exc:
            refuse(f"participant {pid}", exc)
    for cond in st.df("SELECT DISTINCT condition FROM drives WHERE condition IS NOT NULL ORDER BY 1")["condition"]:
        try:
            study.check_condition(cond)
        except UserError as exc:
            refuse("drives", exc)
    drive_phases = {ph.name for proto in study.protocols.values() for ph in proto.steps
                    if ph.drive and ph.condition is None}
    for phase in st.df("SELECT DISTINCT phase FROM drives WHERE phase IS NOT NULL ORDER BY 1")["phase"]:
        if phase not in drive_phases:
            refuse("drives", f"{phase!r} is no longer a drive phase without a condition")
    from study.folder.occasions import study_occasions

    occasions = {o.name for o in study_occasions(study)}
    for (occasion,) in st.con.execute("SELECT DISTINCT occasion FROM responses WHERE occasion <> '' UNION "
                                      "SELECT DISTINCT occasion FROM survey_submissions WHERE occasion <> '' "
                                      "ORDER BY 1").fetchall():
        if occasion not in occasions:
            refuse("survey answers", f"occasion {occasion!r} is no longer a questionnaire phase "
                                     f"({', '.join(sorted(occasions)) or 'none'})")
    used = st.df("""SELECT protocol, NULL AS phase, NULL AS order_name FROM participants
                    UNION SELECT protocol, NULL, NULL FROM appointments
                    UNION SELECT p.protocol, e.phase, NULL
                          FROM phase_events e JOIN participants p USING (participant_id)
                    UNION SELECT protocol, NULL, order_name FROM order_assignments
                    ORDER BY 1, 2 NULLS FIRST, 3 NULLS FIRST""")
    for r in used.itertuples():
        try:
            proto = study.protocol(r.protocol)
            if isinstance(r.phase, str):
                proto.phase(r.phase)
            if isinstance(r.order_name, str) and r.order_name not in protocol_orders(proto):
                raise UserError(f"protocol {proto.name} has no order {r.order_name!r} any more")
        except UserError as exc:
            refuse("protocols", exc)
    stored = st.df("SELECT instrument, item_id, position, construct, section, text, response_type, scale_min, "
                   "scale_max, anchor_low, anchor_high, choices, reverse_scored, required FROM items "
                   "WHERE list_contains(?, instrument) ORDER BY instrument, position", [sorted(_answered(st))])
    for name, ins in study.instruments.items():
        old = stored[stored["instrument"] == name]
        if old.empty:
            continue
        new = _item_rows(ins)
        if len(new) < len(old) or any(_row_key(a) != _row_key(b) for a, b in zip(old.to_dict("records"), new)):
            refuse(f"instrument {name}", "it already has answers and the new codebook changes its items; a "
                                         "changed codebook needs a new instrument version ([instrument] version "
                                         "in study.toml)")


def _answered(st) -> set[str]:
    """Instruments with answers: stored, submitted or saved as a draft (their items must not change)."""
    return {r[0] for r in st.con.execute("SELECT instrument FROM responses UNION SELECT instrument FROM "
                                         "survey_submissions UNION SELECT instrument FROM survey_drafts").fetchall()}


def _row_key(r: dict) -> tuple:
    import pandas as pd

    def norm(v):
        if v is None or pd.isna(v):
            return None
        return bool(v) if isinstance(v, bool) else int(v) if isinstance(v, (int, float)) and not isinstance(
            v, bool) and float(v).is_integer() else str(v)

    return tuple(norm(r.get(k)) for k in ("item_id", "construct", "section", "text", "response_type", "scale_min",
                                          "scale_max", "anchor_low", "anchor_high", "choices", "reverse_scored",
                                          "required"))


def _item_rows(ins) -> list[dict]:
    """Codebook rows as stored in `items` (empty text -> NULL, flags -> bool, bounds -> int)."""
    import pandas as pd

    out = []
    items = ins.items.reset_index()
    for pos, r in enumerate(items.to_dict("records"), start=1):
        row = {"instrument": ins.name, "item_id": r["item_id"], "position": pos}
        for c in ("construct", "section", "text", "response_type", "anchor_low", "anchor_high", "choices"):
            v = r.get(c)
            row[c] = None if v is None or (isinstance(v, str) and not v.strip()) else v
        for c in ("scale_min", "scale_max"):
            v = r.get(c)
            row[c] = None if v is None or pd.isna(v) else int(v)
        for c in ("reverse_scored", "required"):
            row[c] = bool(int(r[c]))
        out.append(row)
    return out


def _store_instruments(st, study: StudyDefinition) -> None:
    """instruments/items rows of the study's codebooks (reference data, not audited). The items of an instrument
    with answers (stored, submitted or drafts) are kept (only new ones are added; :func:`_check_compatible` refused changes); those of an
    instrument without answers are replaced by the codebook's."""
    for name, ins in study.instruments.items():
        if name not in _answered(st):
            st.con.execute("DELETE FROM items WHERE instrument = ?", [name])
        known = {r[0] for r in st.con.execute("SELECT item_id FROM items WHERE instrument = ?", [name]).fetchall()}
        if not st.one("SELECT 1 FROM instruments WHERE instrument = ?", [name]):
            st.con.execute("INSERT INTO instruments (instrument, version, n_items, loaded_at) VALUES (?, ?, ?, ?)",
                           [name, ins.version, len(ins.items), audit_trail.utcnow()])
        else:
            st.con.execute("UPDATE instruments SET n_items = ? WHERE instrument = ?", [len(ins.items), name])
        for row in _item_rows(ins):
            if row["item_id"] in known:
                continue
            cols = ", ".join(f'"{c}"' for c in row)
            st.con.execute(f"INSERT INTO items ({cols}) VALUES ({', '.join('?' for _ in row)})", list(row.values()))

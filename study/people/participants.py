"""Participants: pseudonymous ids and the attributes the store's study declares (docs/study_folder.md).

The study (``definition(st)``) fixes the id pattern, the attributes (name, type, range or choices, required) and
the ``[[checks]]`` over several attributes. A participant is one ``participants`` row (id, protocol, the study
version it was registered under) plus one ``participant_attributes`` row per attribute with a value, stored as text
and typed again by the declaration when read (:func:`participant_attributes`). One participant is registered by
:func:`add_participant`, a roster of many in one transaction by :func:`import_roster`; both run the same checks
(:func:`check_registration`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

from study.common.errors import UserError
from study.folder.attributes import typed_attributes

if TYPE_CHECKING:  # pandas is imported by the functions that return DataFrames: registering needs none
    import pandas as pd

    from study.common.bulk_rows import BulkRows

#: pandas dtype of each attribute type in the wide tables (integers keep missing values as <NA>)
DTYPES = {"integer": "Int64", "number": "float64", "choice": "object", "text": "object"}


def _study(st):
    from study.store.studies import definition

    return definition(st)


def _as_text(value: Any) -> str:
    """The stored text of a typed attribute value (read back by the declaration's type)."""
    if isinstance(value, float):
        return repr(value)  # shortest text that reads back as the same float
    return str(value)


@dataclass(frozen=True)
class Registration:
    """A participant checked against the study and ready to store: id, protocol name and the typed value of every
    declared attribute (None when not given)."""

    participant_id: str
    protocol: str
    values: dict[str, Any]


def check_registration(study, participant_id: str, attributes: Mapping[str, Any] | None = None,
                       protocol: str | None = None) -> Registration:
    """The checks of a registration that need no store (used by :func:`add_participant` and
    :func:`import_roster`): the id against the study's pattern, each attribute against its declaration, the
    required attributes, the study's [[checks]] and the protocol against the study's protocols (None = the first
    declared). Any problem -> UserError (one line)."""
    study.validate_id(participant_id)
    values = typed_attributes(study, attributes)
    return Registration(participant_id, study.protocol(protocol).name, values)


def _registered(st, participant_id: str) -> bool:
    return bool(st.one("SELECT 1 FROM participants WHERE participant_id = ?", [participant_id]))


def _store(st, reg: Registration, study_version: int) -> dict[str, Any]:
    """Insert a checked registration (the caller owns the transaction); returns the participants row."""
    row = st.insert("participants", {"participant_id": reg.participant_id, "protocol": reg.protocol,
                                     "study_version": study_version})
    for name, value in reg.values.items():
        if value is not None:
            st.insert("participant_attributes", {"participant_id": reg.participant_id, "attribute": name,
                                                 "value": _as_text(value)})
    return row


def add_participant(st, participant_id: str, attributes: Mapping[str, Any] | None = None,
                    protocol: str | None = None, **named: Any) -> dict[str, Any]:
    """Register a participant of the store's study (audited, one transaction); returns the participants row plus
    the typed attribute values.

    `attributes` maps declared attribute names to raw values (text or numbers, parsed by the declaration);
    keyword arguments (``age=30, style="normal"``) are attributes too, and a keyword given as None is ignored.
    `protocol` is one of the study's protocols (default: the first declared). A bad id, an unknown attribute, a
    value out of range, a missing required attribute, a failed check, an unknown protocol or an id already
    registered -> UserError; nothing is stored then.
    """
    from study.store.studies import version

    raw = dict(attributes or {})
    for name, value in named.items():
        if value is None:
            continue
        if name in raw:
            raise UserError(f"attribute {name} given twice")
        raw[name] = value
    reg = check_registration(_study(st), participant_id, raw, protocol)
    with st.transaction():
        if _registered(st, participant_id):
            raise UserError(f"participant {participant_id} already exists")
        row = _store(st, reg, version(st))
    return {**row, **reg.values}


def import_roster(st, frame: "pd.DataFrame | BulkRows", source: str = "roster") -> int:
    """Register every participant of a roster in one transaction (audited); returns how many.

    `frame`: one row per participant, column ``participant_id``, optionally one column per declared attribute
    (raw text or numbers; empty = not given), ``protocol`` (empty = the first declared) and ``order`` (the condition
    order the participant drives, recorded as given: :func:`study.people.orders.assign_order`); its index names the row
    in messages (:func:`study.common.bulk_rows.read_rows` sets it to the line in the file); a
    :class:`study.common.bulk_rows.BulkRows` (:func:`study.common.bulk_rows.read_table`) is taken the same way, its lines naming
    the rows. A column that is neither -> UserError naming the declared ones; a required attribute without a
    column -> UserError. Every row gets the checks of :func:`add_participant` (:func:`check_registration`, then:
    not registered yet, and not twice in the roster); if any row fails, :class:`study.common.bulk_rows.BadRows` (message
    ``SOURCE: N bad row(s)``) names every bad row with its reason and nothing is stored.
    """
    from study.common.bulk_rows import BadRow, BadRows, cell, check_columns, records
    from study.store.studies import version

    study = _study(st)
    names = [a.name for a in study.attributes]
    columns, rows = records(frame)
    check_columns(frame, source, ["participant_id"], [*names, "protocol", "order"])
    lacking = [a.name for a in study.attributes if a.required and a.name not in columns]
    if lacking:
        raise UserError(f"{source}: no column for the required attribute(s) {', '.join(lacking)}")
    given = [n for n in names if n in columns]
    bad: list[BadRow] = []
    regs: list[Registration] = []
    orders: dict[str, str] = {}   # id -> the order the roster gives
    first: dict[str, Any] = {}  # id -> line of its first row
    with st.transaction():  # the existence check and the inserts see the same store
        known = {r[0] for r in st.con.execute("SELECT participant_id FROM participants").fetchall()}
        for line, row in rows:
            pid = cell(row["participant_id"]) or ""
            try:
                reg = check_registration(study, pid, {n: row[n] for n in given},
                                         cell(row["protocol"]) if "protocol" in columns else None)
                if pid in first:
                    raise UserError(f"participant {pid} is also on line {first[pid]}")
                if pid in known:
                    raise UserError(f"participant {pid} already exists")
                order = cell(row["order"]) if "order" in columns else None
                if order is not None:
                    orders[pid] = _check_order(study, reg.protocol, order)
                regs.append(reg)
            except UserError as exc:
                bad.append(BadRow(line, pid, str(exc)))
            first.setdefault(pid, line)
        if bad:
            raise BadRows(source, bad)
        study_version = version(st)
        for reg in regs:
            _store(st, reg, study_version)
        if orders:
            from study.people.orders import assign_order

            for reg in regs:   # in file order: each draw the balance report compares with sees the rows before
                if reg.participant_id in orders:
                    assign_order(st, reg.participant_id, orders[reg.participant_id], f"roster {source}")
    return len(regs)


def _check_order(study, protocol: str, order: str) -> str:
    """`order` if the protocol declares it, else UserError naming its orders."""
    from study.folder.protocol_file import protocol_orders

    names = protocol_orders(study.protocol(protocol))
    if order not in names:
        raise UserError(f"protocol {protocol} has no order {order!r} (orders: {', '.join(names) or 'none'})")
    return order


def require(st, participant_id: str) -> None:
    """UserError unless the participant is registered."""
    if not isinstance(participant_id, str) or not st.one(
            "SELECT 1 FROM participants WHERE participant_id = ?", [participant_id]):
        raise UserError(f"unknown participant {participant_id}")


def participant_attributes(st, ids: list[str] | None = None) -> pd.DataFrame:
    """One row per participant (ordered by id; only `ids` when given): participant_id and one column per declared
    attribute, typed by its declaration (integer -> Int64, number -> float, choice/text -> str, missing -> NA).
    Stored values of attributes the study no longer declares are not shown."""
    import pandas as pd

    study = _study(st)
    people = st.df("SELECT participant_id FROM participants ORDER BY participant_id")["participant_id"].tolist()
    if ids is not None:
        wanted = set(ids)
        people = [p for p in people if p in wanted]
    out = pd.DataFrame({"participant_id": pd.Series(people, dtype=object)})
    long = st.df("SELECT participant_id, attribute, value FROM participant_attributes")
    for a in study.attributes:
        vals = long[long["attribute"] == a.name].set_index("participant_id")["value"].reindex(people)
        if a.type == "integer":
            col = pd.to_numeric(vals, errors="coerce").round().astype("Int64")
        elif a.type == "number":
            col = pd.to_numeric(vals, errors="coerce").astype(float)
        else:
            col = vals.astype(object).where(vals.notna(), None)
        out[a.name] = col.reset_index(drop=True).astype(DTYPES[a.type])
    return out


#: each participant's protocol position and exclusions, ordered by id (the columns after the attributes)
_LISTING = """
    WITH last AS (
        SELECT participant_id, arg_max(phase, seq) AS phase, arg_max(outcome, seq) AS phase_outcome
        FROM phase_events GROUP BY participant_id),
    exc AS (
        SELECT participant_id, string_agg(scope, ',' ORDER BY scope) AS excluded
        FROM exclusions GROUP BY participant_id)
    SELECT p.participant_id, p.protocol, o.order_name AS "order", last.phase, last.phase_outcome,
           coalesce(exc.excluded, '') AS excluded, p.created_at
    FROM participants p LEFT JOIN last USING (participant_id) LEFT JOIN exc USING (participant_id)
         LEFT JOIN order_assignments o USING (participant_id)
    ORDER BY p.participant_id"""


def list_participants(st) -> pd.DataFrame:
    """Participants with their attributes, protocol position and exclusions, one row each, ordered by id.

    Columns: participant_id, one per declared attribute (typed as :func:`participant_attributes`), protocol,
    order (the condition order assigned, None before one is), phase (last phase entered), phase_outcome, excluded (comma-separated scopes, '' when none), created_at.
    :func:`participant_rows` gives the same as Python rows.
    """
    base = st.df(_LISTING)
    attrs = participant_attributes(st)
    return attrs.merge(base, on="participant_id", how="left")[list(attrs.columns) + list(base.columns[1:])]


def _typed_text(kind: str, text: str | None) -> Any:
    """A stored attribute text typed as :func:`participant_attributes` types it, as a Python value: integer -> int
    (the number rounded half to even, as pandas rounds), number -> float, choice/text -> the text; missing or not
    a finite number -> None."""
    if text is None or kind in ("choice", "text"):
        return text
    try:
        num = float(text)
    except ValueError:
        return None
    if num != num or num in (float("inf"), float("-inf")):
        return None
    return int(round(num)) if kind == "integer" else num


def participant_rows(st) -> tuple[list[str], list[tuple]]:
    """:func:`list_participants` without pandas: (column names, one tuple per participant) with the same columns,
    order and values as Python objects — int for an integer attribute, float for a number, str for choice/text,
    None where the DataFrame has a missing value, datetime for created_at. For commands that print the listing
    (``participant list``), which then load no pandas."""
    study = _study(st)
    cur = st.con.execute(_LISTING)
    base_cols = [d[0] for d in cur.description]
    base = cur.fetchall()
    text = {(pid, name): value for pid, name, value in st.con.execute(
        "SELECT participant_id, attribute, value FROM participant_attributes").fetchall()}
    attrs = study.attributes
    rows = [(r[0], *(_typed_text(a.type, text.get((r[0], a.name))) for a in attrs), *r[1:]) for r in base]
    return [base_cols[0], *(a.name for a in attrs), *base_cols[1:]], rows

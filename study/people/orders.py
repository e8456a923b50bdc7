"""Balanced condition orders: assigning a participant one of the orders of a multi-order protocol, and the
protocol a participant follows in that order.

The next participant gets the order with the fewest participants that are *completed or in progress* — everyone
assigned to it who has not dropped out. A dropout is a participant excluded with scope ``all`` or with reason
``withdrawn``, or whose only appointment ended as a no-show or was cancelled before any phase started; a dropout frees
its place. Ties go to the order listed first in the protocol file, so the assignment is deterministic.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from study.common.errors import UserError
from study.folder.protocol_file import Protocol, ordered_protocol, protocol_orders
from study.store.studies import definition

if TYPE_CHECKING:  # pandas only for order_counts' DataFrame: assigning an order needs none
    import pandas as pd


def participant_row(st, participant_id: str) -> dict[str, Any]:
    """participant_id and protocol of a registered participant; unknown participant -> UserError."""
    rows = st.dicts("SELECT participant_id, protocol FROM participants WHERE participant_id = ?", [participant_id])
    if not rows:
        raise UserError(f"unknown participant {participant_id}")
    return rows[0]


def exclusion_of(st, participant_id: str) -> str | None:
    """'scope (reason)' of the participant's first exclusion (by scope), None when not excluded."""
    return st.one("SELECT scope || ' (' || reason || ')' FROM exclusions WHERE participant_id = ? "
                  "ORDER BY scope LIMIT 1", [participant_id])


def participant_protocol(st, participant_id: str) -> Protocol:
    """The protocol of a participant in the order assigned to them (the file's order when none is assigned)."""
    p = participant_row(st, participant_id)
    proto = definition(st).protocol(p["protocol"])
    order = st.one("SELECT order_name FROM order_assignments WHERE participant_id = ?", [participant_id])
    return ordered_protocol(proto, order) if order else proto


def order_counts(st, protocol: str) -> pd.DataFrame:
    """Per order of `protocol`: assigned, dropped_out and active (= assigned − dropped out) participants."""
    import pandas as pd

    return pd.DataFrame(_order_counts(st, protocol), columns=["order_name", "assigned", "dropped_out", "active"])


def _order_counts(st, protocol: str) -> list[tuple[str, int, int, int]]:
    """(order_name, assigned, dropped_out, active) per order of `protocol`, in the protocol file's order."""
    orders = list(protocol_orders(definition(st).protocol(protocol)))
    found = {name: (int(assigned), int(dropped)) for name, assigned, dropped in st.con.execute("""
        SELECT a.order_name,
               count(*) AS assigned,
               count(*) FILTER (WHERE d.participant_id IS NOT NULL) AS dropped_out
        FROM order_assignments a
        LEFT JOIN (
            SELECT participant_id FROM exclusions WHERE scope = 'all' OR reason = 'withdrawn'
            UNION
            SELECT participant_id FROM appointments
            WHERE status IN ('no_show', 'cancelled')
              AND participant_id NOT IN (SELECT participant_id FROM appointments WHERE status IN ('booked', 'attended'))
              AND participant_id NOT IN (SELECT participant_id FROM phase_events)
        ) d USING (participant_id)
        WHERE a.protocol = ?
        GROUP BY a.order_name""", [protocol]).fetchall()}
    out = []
    for o in orders:
        assigned, dropped = found.get(o, (0, 0))
        out.append((o, assigned, dropped, assigned - dropped))
    return out


def assign_order(st, participant_id: str) -> str:
    """Assign (once) and return the participant's condition order; audited. Idempotent for an assigned participant."""
    p = participant_row(st, participant_id)
    with st.transaction():
        have = st.one("SELECT order_name FROM order_assignments WHERE participant_id = ?", [participant_id])
        if have:
            return have
        excluded = exclusion_of(st, participant_id)
        if excluded:
            raise UserError(f"{participant_id} is excluded ({excluded}); no order is assigned")
        counts = _order_counts(st, p["protocol"])
        # fewest active participants; ties -> first order in the protocol file (min keeps the first)
        order = str(min(counts, key=lambda c: c[3])[0])
        st.insert("order_assignments", {"participant_id": participant_id, "protocol": p["protocol"],
                                        "order_name": order})
    return order


def ensure_order(st, participant_id: str) -> str | None:
    """Assign an order if the participant's protocol has several and none is assigned yet; returns the order."""
    p = participant_row(st, participant_id)
    if len(protocol_orders(definition(st).protocol(p["protocol"]))) < 2:
        return None
    return assign_order(st, participant_id)

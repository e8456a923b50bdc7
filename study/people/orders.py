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


def _drawn(st, protocol: str) -> str:
    """The order the balanced assignment draws next: fewest active participants, ties -> first in the file."""
    return str(min(_order_counts(st, protocol), key=lambda c: c[3])[0])


def assign_order(st, participant_id: str, order: str | None = None, reason: str | None = None) -> str:
    """Assign (once) and return the participant's condition order; audited. Idempotent for an assigned participant.

    `order` None draws the balanced order (:func:`_drawn`). A given `order` (the lab's own, fixed beforehand or
    deviating from the draw) is stored with ``given`` = true, the `reason` and the order the draw would have given
    (``drawn``), which :func:`order_balance` reports where it differs. A given order replaces an assigned one only
    while the participant has entered no phase (audited as an update); afterwards -> UserError."""
    p = participant_row(st, participant_id)
    if order is not None:
        orders = protocol_orders(definition(st).protocol(p["protocol"]))
        if order not in orders:
            raise UserError(f"protocol {p['protocol']} has no order {order!r} (orders: {', '.join(orders)})")
    reason = reason.strip() if isinstance(reason, str) and reason.strip() else None
    with st.transaction():
        have = st.one("SELECT order_name FROM order_assignments WHERE participant_id = ?", [participant_id])
        if have and (order is None or order == have):
            return have
        excluded = exclusion_of(st, participant_id)
        if excluded:
            raise UserError(f"{participant_id} is excluded ({excluded}); no order is assigned")
        if have:
            started = st.one("SELECT phase FROM phase_events WHERE participant_id = ? ORDER BY seq LIMIT 1",
                             [participant_id])
            if started:
                raise UserError(f"{participant_id} has order {have} and has started the protocol ({started}); "
                                f"the order cannot change")
            st.update("order_assignments", {"participant_id": participant_id},
                      {"order_name": order, "given": True, "reason": reason})
            return order
        drawn = _drawn(st, p["protocol"])
        st.insert("order_assignments", {"participant_id": participant_id, "protocol": p["protocol"],
                                        "order_name": order or drawn, "given": order is not None, "drawn": drawn,
                                        "reason": reason})
    return order or drawn


def order_balance(st) -> tuple[list[tuple[str, str, int, int, int, int]], list[dict[str, Any]]]:
    """The balance report of every protocol with several orders: (protocol, order_name, assigned, given,
    dropped_out, active) per order, and the deviations from the design — each given order that differs from the
    order the balanced draw would have given then (participant_id, order_name, drawn, reason)."""
    protocols = [r[0] for r in st.con.execute("SELECT DISTINCT protocol FROM order_assignments ORDER BY 1").fetchall()]
    given = {(proto, o): int(n) for proto, o, n in st.con.execute(
        "SELECT protocol, order_name, count(*) FROM order_assignments WHERE given GROUP BY ALL").fetchall()}
    counts = [(proto, o, a, given.get((proto, o), 0), d, act) for proto in protocols
              for o, a, d, act in _order_counts(st, proto)]
    deviations = st.dicts("SELECT participant_id, protocol, order_name, drawn, reason FROM order_assignments "
                          "WHERE given AND order_name IS DISTINCT FROM drawn ORDER BY participant_id")
    return counts, deviations


def ensure_order(st, participant_id: str) -> str | None:
    """Assign an order if the participant's protocol has several and none is assigned yet; returns the order."""
    p = participant_row(st, participant_id)
    if len(protocol_orders(definition(st).protocol(p["protocol"]))) < 2:
        return None
    return assign_order(st, participant_id)

"""`pedas-study session ...`: walk a participant through the protocol phases (advance, abort, complete, status)
and book their simulator slot (schedule, reschedule, cancel, no-show, attended, assign)."""
from __future__ import annotations

import argparse

from pedas_study.cli.bulk import add_ignore_option
from pedas_study.cli.common import add_format_option, format_frame, open_store
from study.common.times import when


# ---------------------------------------------------------------------------------------------- protocol phases
def _advance(args) -> int | None:
    if args.events is not None:
        if args.id is not None or args.note is not None or args.at is not None:
            args.usage_error("--from takes every event from the file: give no ID, PHASE, --note or --at with it")
        return _advance_from(args)
    if args.phase is None:  # ID and PHASE are optional only for --from
        args.usage_error(f"the following arguments are required: {'PHASE' if args.id else 'ID, PHASE'}")
    from study.people.protocol import advance

    with open_store(args) as st:
        r = advance(st, args.id, args.phase, note=args.note, at=args.at)
    done = f" ({r['completed']} completed)" if r["completed"] else ""
    print(f"{args.id}: {r['started']} started{done}")


def _advance_from(args) -> int | None:
    from pedas_study.cli.bulk import apply_file
    from study.people.protocol import apply_event_rows

    return apply_file(args, "events", apply_event_rows,
                      lambda done: f"applied {len(done)} events for {len({d['participant_id'] for d in done})} "
                                   f"participants from {args.events}")


def _abort(args) -> None:
    from study.people.protocol import abort

    with open_store(args) as st:
        phase = abort(st, args.id, args.reason, at=args.at)
    print(f"{args.id}: {phase} aborted ({args.reason})")


def _complete(args) -> None:
    from study.people.protocol import complete

    with open_store(args) as st:
        phase = complete(st, args.id, note=args.note, at=args.at)
    print(f"{args.id}: {phase} completed")


def _status(args) -> None:
    import json

    from study.people.exclusions import list_exclusions
    from study.people.protocol import protocol_of, status

    with open_store(args) as st:
        proto = protocol_of(st, args.id)
        df = status(st, args.id)
        exc = list_exclusions(st, args.id)
        drives = st.df("SELECT coalesce(condition, phase) AS condition, source, n_samples FROM drives "
                       "WHERE participant_id = ? ORDER BY condition", [args.id])
        order = st.dicts("SELECT order_name, given, reason FROM order_assignments WHERE participant_id = ?",
                         [args.id])
    entered = df[~df["outcome"].isin(["pending", "skipped"])]
    current = (f"{entered['phase'].iloc[-1]} ({entered['outcome'].iloc[-1].replace('_', ' ')})"
               if len(entered) else "not started")
    order = order[0] if order else None
    if args.format == "json":
        print(json.dumps({"participant_id": args.id, "protocol": proto.name,
                          "order": order["order_name"] if order else None,
                          "order_given": bool(order["given"]) if order else None,
                          "phases": json.loads(df.to_json(orient="records", date_format="iso")),
                          "exclusions": json.loads(exc.to_json(orient="records", date_format="iso")),
                          "drives": json.loads(drives.to_json(orient="records"))}, indent=1))
        return
    if args.format == "csv":
        print(format_frame(df, "csv"))
        return
    given = (" (given" + (f": {order['reason']}" if order["reason"] else "") + ")") if order and order["given"] else ""
    print(f"{args.id} (protocol {proto.name}" + (f", order {order['order_name']}{given}" if order else "") + ")")
    print(f"current phase: {current}")
    print(format_frame(df.drop(columns=["seq"]), "table"))
    if exc.empty:
        print("exclusions: none")
    for r in exc.itertuples(index=False):
        print(f"excluded: scope {r.scope}, reason {r.reason}" + (f" ({r.note})" if isinstance(r.note, str) else ""))
    print("drives: " + (", ".join(f"{r.condition} ({r.n_samples} samples, {r.source})"
                                  for r in drives.itertuples(index=False)) or "none"))


# ---------------------------------------------------------------------------------------------- appointments
def _schedule(args) -> None:
    from study.people.scheduling import book

    with open_store(args) as st:
        row = book(st, args.id, args.at, simulator=args.simulator, buffer_minutes=args.buffer)
    print(f"{args.id}: {row['simulator']} booked {when(row['starts_at'])}-{row['ends_at']:%H:%M} "
          f"(appointment {row['appointment_id']})")


def _reschedule(args) -> None:
    from study.people.scheduling import reschedule

    with open_store(args) as st:
        row = reschedule(st, args.id, args.at, simulator=args.simulator)
    print(f"{args.id}: moved to {row['simulator']} {when(row['starts_at'])}-{row['ends_at']:%H:%M}")


def _close(status: str):
    def handler(args) -> None:
        from study.people.scheduling import set_status

        with open_store(args) as st:
            row = set_status(st, args.id, status, note=args.note)
        print(f"{args.id}: appointment {row['appointment_id']} {status.replace('_', '-')}")
    return handler


def _assign(args) -> None:
    from study.people.orders import assign_order

    if args.reason is not None and args.order is None:
        args.usage_error("--reason goes with --order (a drawn order needs none)")
    with open_store(args) as st:
        order = assign_order(st, args.id, args.order, args.reason)
    print(f"{args.id}: order {order}" + (" (given)" if args.order else ""))


def _orders(args) -> None:
    from study.people.orders import order_balance

    with open_store(args, read_only=True) as st:
        counts, deviations = order_balance(st)
    columns = ["protocol", "order_name", "assigned", "given", "dropped_out", "active"]
    if args.format != "table":
        import json

        if args.format == "json":
            print(json.dumps({"orders": [dict(zip(columns, c)) for c in counts], "deviations": deviations},
                             indent=1))
        else:
            from pedas_study.cli.rows_text import format_rows

            print(format_rows(columns, counts, "csv"))
        return
    from pedas_study.cli.rows_text import format_rows

    print(format_rows(columns, counts, "table") if counts else "no orders assigned")
    for proto in dict.fromkeys(c[0] for c in counts):
        active = [c[5] for c in counts if c[0] == proto]
        if max(active) - min(active) > 1:
            print(f"{proto}: active participants per order differ by {max(active) - min(active)} "
                  f"(the design keeps them within 1)")
    for d in deviations:
        why = f": {d['reason']}" if d["reason"] else ""
        print(f"deviation: {d['participant_id']} drove {d['order_name']}, the balanced draw was {d['drawn']}{why}")
    if counts and not deviations:
        print("deviations: none (every given order is the one the balanced draw gives)")


def _add_time(p: argparse.ArgumentParser) -> None:
    p.add_argument("--at", metavar="ISO_TIME", default=None,
                   help="when it happened (ISO 8601, UTC unless an offset is given); default now")


def register(cli) -> None:
    """Declare the `session` group."""
    from study.people.defaults import DEFAULT_BUFFER_MINUTES, DEFAULT_SIMULATOR

    g = cli.group("session", "walk a participant through the protocol phases")
    p = g.command("advance", "start the next protocol phase (completes the one in progress); --from: many events "
                             "from a CSV, all or nothing", _advance)
    p.add_argument("id", metavar="ID", nargs="?")
    p.add_argument("phase", metavar="PHASE", nargs="?", help="the next phase of the participant's protocol (the "
                   "study's protocol file; `session status ID` lists them in order)")
    p.add_argument("--note", default=None)
    _add_time(p)
    p.add_argument("--from", dest="events", metavar="EVENTS.csv", default=None,
                   help="apply the file's events in order instead (columns participant_id, phase and optionally "
                        "action advance|complete|abort, at, note, reason), all or nothing")
    add_ignore_option(p)
    p.set_defaults(usage_error=p.error)
    p = g.command("abort", "abort the phase in progress (e.g. motion sickness)", _abort)
    p.add_argument("id", metavar="ID")
    p.add_argument("--reason", required=True)
    _add_time(p)
    p = g.command("complete", "complete the phase in progress without starting another", _complete)
    p.add_argument("id", metavar="ID")
    p.add_argument("--note", default=None)
    _add_time(p)
    p = g.command("status", "each phase with start, end and outcome; exclusions; drives", _status)
    p.add_argument("id", metavar="ID")
    add_format_option(p)

    p = g.command("schedule", "book a simulator slot for the whole protocol", _schedule)
    p.add_argument("id")
    p.add_argument("--at", required=True, help="local start time, ISO 8601 (e.g. 2026-05-04T09:30)")
    p.add_argument("--simulator", default=DEFAULT_SIMULATOR)
    p.add_argument("--buffer", type=float, default=DEFAULT_BUFFER_MINUTES,
                   help=f"minutes added to the protocol's planned duration (default {DEFAULT_BUFFER_MINUTES:g})")
    p = g.command("reschedule", "move a participant's booked slot", _reschedule)
    p.add_argument("id")
    p.add_argument("--at", required=True)
    p.add_argument("--simulator", default=None)
    for name, status, text in (("cancel", "cancelled", "cancel a participant's booked slot"),
                               ("no-show", "no_show", "record that a participant did not come"),
                               ("attended", "attended", "record that a booked session took place")):
        p = g.command(name, text, _close(status))
        p.add_argument("id")
        p.add_argument("--note", default=None)
    p = g.command("assign", "assign the condition order of a multi-order protocol (balanced draw, or --order as "
                            "it was fixed or happened)", _assign)
    p.add_argument("id")
    p.add_argument("--order", default=None, metavar="NAME",
                   help="the order the participant drives (one of the protocol's orders), recorded as given")
    p.add_argument("--reason", default=None, metavar="TEXT", help="why the order was given (audited)")
    p.set_defaults(usage_error=p.error)
    p = g.command("orders", "the balance of the condition orders: per order assigned, given, dropped out, active; "
                            "each given order that deviates from the balanced draw", _orders)
    add_format_option(p)

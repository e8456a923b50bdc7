"""CLI commands of scheduling: session schedule | reschedule | cancel | no-show | assign, schedule day | export | durations."""
from __future__ import annotations

from study.commands import LIST_FORMATS, _open, format_frame


def _schedule(args) -> None:
    from study.scheduling import book

    with _open(args) as st:
        row = book(st, args.id, args.at, simulator=args.simulator, buffer_minutes=args.buffer)
    print(f"{args.id}: {row['simulator']} booked {row['starts_at']:%Y-%m-%d %H:%M}-{row['ends_at']:%H:%M} "
          f"(appointment {row['appointment_id']})")


def _reschedule(args) -> None:
    from study.scheduling import reschedule

    with _open(args) as st:
        row = reschedule(st, args.id, args.at, simulator=args.simulator)
    print(f"{args.id}: moved to {row['simulator']} {row['starts_at']:%Y-%m-%d %H:%M}-{row['ends_at']:%H:%M}")


def _close(status: str):
    def handler(args) -> None:
        from study.scheduling import set_status

        with _open(args) as st:
            row = set_status(st, args.id, status, note=args.note)
        print(f"{args.id}: appointment {row['appointment_id']} {status.replace('_', '-')}")
    return handler


def _assign(args) -> None:
    from study.scheduling import assign_order

    with _open(args) as st:
        print(f"{args.id}: order {assign_order(st, args.id)}")


def _day(args) -> None:
    from study.scheduling import day_agenda

    with _open(args, read_only=True) as st:
        print(format_frame(day_agenda(st, args.date, args.simulator), args.format))


def _export(args) -> None:
    from study.scheduling import export_ics

    with _open(args, read_only=True) as st:
        n = export_ics(st, args.ics, include_closed=args.all)
    print(f"{n} appointments written to {args.ics}")


def _durations(args) -> None:
    from study.scheduling import phase_durations

    with _open(args, read_only=True) as st:
        print(format_frame(phase_durations(st, args.id), args.format))


def register(cli) -> None:
    from study.scheduling import DEFAULT_BUFFER_MINUTES, DEFAULT_SIMULATOR

    p = cli.subcommand("session", "schedule", "book a simulator slot for the whole protocol", _schedule)
    p.add_argument("id")
    p.add_argument("--at", required=True, help="local start time, ISO 8601 (e.g. 2026-05-04T09:30)")
    p.add_argument("--simulator", default=DEFAULT_SIMULATOR)
    p.add_argument("--buffer", type=float, default=DEFAULT_BUFFER_MINUTES,
                   help=f"minutes added to the protocol's planned duration (default {DEFAULT_BUFFER_MINUTES:g})")
    p = cli.subcommand("session", "reschedule", "move a participant's booked slot", _reschedule)
    p.add_argument("id")
    p.add_argument("--at", required=True)
    p.add_argument("--simulator", default=None)
    for name, status, text in (("cancel", "cancelled", "cancel a participant's booked slot"),
                               ("no-show", "no_show", "record that a participant did not come"),
                               ("attended", "attended", "record that a booked session took place")):
        p = cli.subcommand("session", name, text, _close(status))
        p.add_argument("id")
        p.add_argument("--note", default=None)
    p = cli.subcommand("session", "assign", "assign the condition order of a multi-order protocol (balanced)",
                       _assign)
    p.add_argument("id")

    p = cli.subcommand("schedule", "day", "agenda of one day", _day, group_help="simulator appointments")
    p.add_argument("date", help="ISO date, e.g. 2026-05-04")
    p.add_argument("--simulator", default=None)
    p.add_argument("--format", choices=LIST_FORMATS, default="table")
    p = cli.subcommand("schedule", "export", "write the appointments as an iCalendar (.ics) file", _export)
    p.add_argument("--ics", required=True, metavar="FILE")
    p.add_argument("--all", action="store_true", help="include cancelled and no-show appointments")
    p = cli.subcommand("schedule", "durations", "planned vs actual phase durations", _durations)
    p.add_argument("id", nargs="?", default=None)
    p.add_argument("--format", choices=LIST_FORMATS, default="table")

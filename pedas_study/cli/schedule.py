"""`pedas-study schedule day | export | durations`: the simulator appointments (booking is `session schedule`)."""
from __future__ import annotations

from pedas_study.cli.common import add_format_option, format_frame, open_store


def _day(args) -> None:
    from study.people.scheduling import day_agenda

    with open_store(args, read_only=True) as st:
        df = day_agenda(st, args.date, args.simulator)
    print(format_frame(df, args.format))


def _export(args) -> None:
    from study.people.scheduling import export_ics

    with open_store(args, read_only=True) as st:
        n = export_ics(st, args.ics, include_closed=args.all)
    print(f"{n} appointments written to {args.ics}")


def _durations(args) -> None:
    from study.people.scheduling import phase_durations

    with open_store(args, read_only=True) as st:
        df = phase_durations(st, args.id)
    print(format_frame(df, args.format))


def register(cli) -> None:
    """Declare the `schedule` group."""
    g = cli.group("schedule", "simulator appointments")
    p = g.command("day", "agenda of one day", _day)
    p.add_argument("date", help="ISO date, e.g. 2026-05-04")
    p.add_argument("--simulator", default=None)
    add_format_option(p)
    p = g.command("export", "write the appointments as an iCalendar (.ics) file", _export)
    p.add_argument("--ics", required=True, metavar="FILE")
    p.add_argument("--all", action="store_true", help="include cancelled and no-show appointments")
    p = g.command("durations", "planned vs actual phase durations", _durations)
    p.add_argument("id", nargs="?", default=None)
    add_format_option(p)

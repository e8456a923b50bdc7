"""`pedas-study drive import | list | channels | replay | simulate`: drive logs, from the simulator or simulated."""
from __future__ import annotations

import sys

from pedas_study.cli.common import (DRIVE_CACHE_HELP, add_format_option, add_scenario_option, format_frame, open_store,
                                    scenario_of, simulate_and_store)


def _import(args) -> None:
    from study.logs.importing import import_drive_file
    from study.common.units import units

    units()  # built before the store is held (about a second): the study's route and log mapping read units with it

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    with open_store(args) as st:
        r = import_drive_file(st, args.id, args.condition, args.file, replace=args.replace, route=args.route,
                              progress=progress if args.verbose else None, mapping=args.map, fmt=args.log_format,
                              vehicle=args.vehicle, force=args.force, net=args.net)
    extra = f"; ignored columns: {', '.join(r.ignored_columns)}" if r.ignored_columns else ""
    if r.status == "unchanged":
        print(f"{args.id} {args.condition}: unchanged (same log already stored as drive {r.drive_id})")
        return
    channels = f"; channels: {', '.join(r.channels)}" if r.channels else ""
    print(f"{args.id} {args.condition}: {r.status} drive {r.drive_id}, {r.n_samples} samples "
          f"in {r.seconds:.2f} s ({r.rows_per_second:,.0f} rows/s); energy: {r.energy_source}{channels}{extra}")
    for problem in r.overridden:
        print(f"note: imported with --force despite: {problem}", file=sys.stderr)


def _list(args) -> None:
    from study.logs.stored import list_drives

    with open_store(args) as st:
        df = list_drives(st)
    print(format_frame(df, args.format))


def _channels(args) -> None:
    from study.logs.stored import list_channels

    with open_store(args, read_only=True) as st:
        df = list_channels(st)
    print(format_frame(df, args.format))


def _simulate(args) -> None:
    """Simulate before writing: a failing drive leaves the store unchanged."""
    from pedas.cohort import cohort_tasks
    from study.logs.simulated import participants_to_simulate

    scenario = scenario_of(args)
    with open_store(args, read_only=True) as st:
        people = participants_to_simulate(st, [args.id])
    if not isinstance(people.loc[0, "style"], str):
        print(f"note: {args.id} has no driving style; simulated as 'normal'", file=sys.stderr)
    tasks = [t for t in cohort_tasks(people, base_seed=args.seed, scenario=scenario)
             if t.condition == args.condition]
    simulate_and_store(args, tasks, workers=1, progress=False)


def _replay(args) -> None:
    from analysis.drives.replay import write_replay
    from pedas.hud_theme import check_theme

    try:
        check_theme(args.theme)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    with open_store(args, read_only=True) as st:
        out = args.out or f"replay_{args.id}_{args.condition}.html"
        path = write_replay(st, args.id, args.condition, out, others=not args.only, theme=args.theme)
    print(f"{args.id} {args.condition}: replay written to {path}")
    if args.serve:
        from analysis.drives.replay import serve_file

        serve_file(path, args.host, args.port)


def register(cli) -> None:
    """Declare the `drive` group."""
    from pedas.vocabulary import CONDITIONS

    g = cli.group("drive", "drive logs")
    p = g.command("import", "import a drive log (CSV, Parquet or SUMO FCD XML) for a participant", _import)
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", metavar="CONDITION", help="a condition the study declares, or a drive phase without "
                                                          "one (familiarisation)")
    p.add_argument("file", metavar="FILE")
    p.add_argument("--map", default=None, metavar="FILE",
                   help="log mapping (TOML) for this file instead of the study's; 'none' = a canonical log")
    p.add_argument("--format", dest="log_format", default=None, choices=("csv", "parquet", "sumo-fcd"),
                   help="log format (default: from the file name; .xml = sumo-fcd)")
    p.add_argument("--vehicle", default=None, metavar="ID", help="the vehicle of a SUMO FCD file")
    p.add_argument("--net", default=None, metavar="FILE",
                   help="the SUMO network (.net.xml) of a SUMO FCD file: limits and lights from there")
    p.add_argument("--force", default=None, metavar="REASON",
                   help="import despite plausibility problems (distance, sampling) or a condition other than the "
                        "participant's current drive phase; the reason is recorded")
    p.add_argument("--replace", action="store_true", help="replace a different log stored for this drive")
    p.add_argument("--route", default=None, help="route name stored with the drive (default: the study's route)")
    p.add_argument("--verbose", "-v", action="store_true", help="report progress on stderr")
    p = g.command("list", "list stored drives", _list)
    add_format_option(p)
    p = g.command("channels", "list the extra channels stored with drive samples", _channels)
    add_format_option(p)

    p = g.command("replay", "write (and optionally serve) a self-contained HTML replay of a participant's drive, "
                  "the person's other drives beside it", _replay)
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", metavar="CONDITION", help="the drive shown first")
    p.add_argument("--out", default=None, metavar="FILE", help="the page (default replay_<ID>_<CONDITION>.html)")
    p.add_argument("--only", action="store_true", help="this drive alone, without the person's other drives")
    p.add_argument("--theme", default="light", metavar="NAME", help="HUD theme: light (default) or dark")
    p.add_argument("--serve", action="store_true", help="serve the page over HTTP until Ctrl-C")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8018, help="port to serve on (default 8018)")

    p = g.command("simulate", "simulate one drive of a participant (virtual driver in SUMO traffic)", _simulate)
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", choices=CONDITIONS, help="a condition the simulator drives")
    p.add_argument("--seed", type=int, default=0, help="cohort seed: the virtual person is derived from (seed, ID)")
    p.add_argument("--replace", action="store_true", help="replace a different drive stored for this condition")
    p.add_argument("--cache-dir", dest="cache_dir", default=None, help=DRIVE_CACHE_HELP)
    add_scenario_option(p)

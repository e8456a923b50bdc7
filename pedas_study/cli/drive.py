"""`pedas-study drive import | list | channels | replay | simulate`: drive logs, from the simulator or simulated."""
from __future__ import annotations

import sys

from pedas_study.cli.bulk import add_ignore_option
from pedas_study.cli.common import (DRIVE_CACHE_HELP, add_format_option, add_scenario_option, format_frame, open_store,
                                    scenario_of, simulate_and_store)


def _import(args) -> int | None:
    if args.manifest is not None or args.dir is not None:
        return _import_many(args)
    if args.pattern is not None or args.jobs is not None:
        args.usage_error("--pattern goes with --dir, --jobs with --from or --dir")
    if args.file is None:
        missing = [n for n, v in (("ID", args.id), ("CONDITION", args.condition), ("FILE", args.file)) if v is None]
        args.usage_error(f"the following arguments are required: {', '.join(missing)} (or --from MANIFEST, or "
                         f"--dir DIR --pattern PATTERN)")
    from study.logs.importing import import_drive_file

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


def _import_many(args) -> int | None:
    """`drive import --from MANIFEST` or `--dir DIR --pattern PATTERN`: every log at once, all or nothing."""
    from pedas_study.cli.bulk import refused
    from study.common.bulk_rows import BadRows
    from study.common.errors import shown, split_names
    from study.logs import bulk_import

    if args.id is not None or args.map is not None or args.log_format is not None or args.vehicle is not None \
            or args.net is not None or args.route is not None:
        args.usage_error("--from and --dir take the drives from the list: give no ID, CONDITION, FILE, --map, "
                         "--format, --vehicle, --net or --route with them (a manifest has mapping, format, vehicle "
                         "columns)")
    if (args.manifest is None) == (args.dir is None):
        args.usage_error("give either --from MANIFEST or --dir DIR --pattern PATTERN")
    if args.dir is not None and args.pattern is None:
        args.usage_error("--dir needs --pattern, e.g. --pattern \"{participant}_{condition}.csv\"")
    if args.jobs is not None and args.jobs < 1:
        args.usage_error("--jobs must be at least 1")
    other: list[str] = []
    try:
        if args.manifest is not None:
            items = bulk_import.manifest_items(args.manifest, split_names(args.ignore_columns))
            source = shown(args.manifest)
        else:
            items, other = bulk_import.folder_items(args.dir, args.pattern)
            source = shown(args.dir)
        from study.common.units import units

        units()   # before the store is held, as a single import does
        with open_store(args) as st:
            r = bulk_import.import_many(st, items, source, replace=args.replace, force=args.force, jobs=args.jobs,
                                        progress=_bar)
    except BadRows as exc:
        return refused(exc)
    if other:
        print(f"note: {len(other)} file(s) of {source} do not match the pattern: {', '.join(other[:5])}"
              f"{', ...' if len(other) > 5 else ''}", file=sys.stderr)
    parts = [f"{r.imported} imported"] + [f"{n} {s}" for n, s in ((r.replaced, "replaced"), (r.unchanged, "unchanged"))
                                          if n]
    print(f"{len(items)} drive logs of {r.participants} participant{'s' if r.participants != 1 else ''} from "
          f"{source}: {', '.join(parts)} "
          f"({r.samples:,} samples)")
    for d in r.results:
        for problem in d.overridden:
            print(f"note: {d.participant_id} {d.condition}: imported with --force despite: {problem}", file=sys.stderr)
    return None


def _bar(total: int):
    """A progress bar of the files read (on stderr when it is a terminal)."""
    from tqdm import tqdm

    bar = tqdm(total=total, unit="file", desc="reading", file=sys.stderr, disable=None, leave=False)
    return lambda: bar.update(1)


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
    p = g.command("import", "import a drive log (CSV, Parquet or SUMO FCD XML) for a participant; --from or --dir: "
                            "many logs at once, all or nothing", _import)
    p.add_argument("id", metavar="ID", nargs="?")
    p.add_argument("condition", metavar="CONDITION", nargs="?",
                   help="a condition the study declares, or a drive phase without one (familiarisation)")
    p.add_argument("file", metavar="FILE", nargs="?")
    p.add_argument("--from", dest="manifest", default=None, metavar="MANIFEST.csv",
                   help="import every log the manifest lists (columns participant_id, condition or phase, file "
                        "relative to the manifest; optionally mapping, format, vehicle), all or nothing")
    p.add_argument("--dir", default=None, metavar="DIR", help="import every file of DIR whose name matches --pattern")
    p.add_argument("--pattern", default=None, metavar="PATTERN",
                   help='file names of --dir, e.g. "{participant}_{condition}.csv" ({condition} may name a drive '
                        'phase without a condition)')
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="worker processes reading the files of --from/--dir (default: the machine's cores)")
    add_ignore_option(p)
    p.set_defaults(usage_error=p.error)
    p.add_argument("--map", default=None, metavar="FILE",
                   help="log mapping (TOML) for this file instead of the study's; 'none' = a canonical log")
    p.add_argument("--format", dest="log_format", default=None, choices=("csv", "parquet", "sumo-fcd"),
                   help="log format (default: from the file name; .xml = sumo-fcd)")
    p.add_argument("--vehicle", default=None, metavar="ID", help="the vehicle of a SUMO FCD file")
    p.add_argument("--net", default=None, metavar="FILE",
                   help="the SUMO network (.net.xml) of a SUMO FCD file: limits and lights from there")
    p.add_argument("--force", default=None, metavar="REASON",
                   help="import despite plausibility problems (distance, sampling) or a drive phase the participant "
                        "has not entered; the reason is recorded")
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

"""`pedas-study drive import | list | simulate`: drive logs, from the simulator or simulated."""
from __future__ import annotations

import sys

from pedas_study.cli.common import DRIVE_CACHE_HELP, add_format_option, format_frame, open_store, simulate_and_store


def _import(args) -> None:
    from study.drives import import_drive_file

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    with open_store(args) as st:
        r = import_drive_file(st, args.id, args.condition, args.file, replace=args.replace, route=args.route,
                              progress=progress if args.verbose else None)
    extra = f"; ignored columns: {', '.join(r.ignored_columns)}" if r.ignored_columns else ""
    if r.status == "unchanged":
        print(f"{args.id} {args.condition}: unchanged (same log already stored as drive {r.drive_id})")
    else:
        print(f"{args.id} {args.condition}: {r.status} drive {r.drive_id}, {r.n_samples} samples "
              f"in {r.seconds:.2f} s ({r.rows_per_second:,.0f} rows/s){extra}")


def _list(args) -> None:
    from study.drives import list_drives

    with open_store(args) as st:
        print(format_frame(list_drives(st), args.format))


def _simulate(args) -> None:
    """Simulate before writing: a failing drive leaves the store unchanged."""
    from pedas.cohort import cohort_tasks
    from study.simulated import participants_to_simulate

    with open_store(args, read_only=True) as st:
        people = participants_to_simulate(st, [args.id])
    if not isinstance(people.loc[0, "style"], str):
        print(f"note: {args.id} has no driving style; simulated as 'normal'", file=sys.stderr)
    tasks = [t for t in cohort_tasks(people, base_seed=args.seed) if t.condition == args.condition]
    simulate_and_store(args, tasks, workers=1, progress=False)


def register(cli) -> None:
    """Declare the `drive` group."""
    from pedas.vocabulary import CONDITIONS

    g = cli.group("drive", "drive logs")
    p = g.command("import", "import a simulator drive log (CSV or Parquet) for a participant", _import)
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", choices=CONDITIONS)
    p.add_argument("file", metavar="FILE")
    p.add_argument("--replace", action="store_true", help="replace a different log stored for this drive")
    p.add_argument("--route", default=None, help="route name stored with the drive")
    p.add_argument("--verbose", "-v", action="store_true", help="report progress on stderr")
    p = g.command("list", "list stored drives", _list)
    add_format_option(p)

    p = g.command("simulate", "simulate one drive of a participant (virtual driver in SUMO traffic)", _simulate)
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", choices=CONDITIONS)
    p.add_argument("--seed", type=int, default=0, help="cohort seed: the virtual person is derived from (seed, ID)")
    p.add_argument("--replace", action="store_true", help="replace a different drive stored for this condition")
    p.add_argument("--cache-dir", dest="cache_dir", default=None, help=DRIVE_CACHE_HELP)

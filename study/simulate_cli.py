"""CLI commands of the simulation part: `drive simulate ID baseline|pedas` and `simulate cohort`.

Virtual participants drive the study route in SUMO traffic (pedas.drive); the logs are stored through the
store's drive import (study.drives.import_drive_frame, source 'simulation'). Drives are simulated before the store
is written, so a failing drive (e.g. a safety violation) leaves the store unchanged.
"""
from __future__ import annotations

import sys

ROUTE_NAME = "study-13.2km"


def _participants(st, ids: list[str] | None = None):
    import pandas as pd

    from study.participants import require

    if ids is not None:
        for pid in ids:
            require(st, pid)
    df = st.df("SELECT participant_id, style FROM participants ORDER BY participant_id")
    if ids is not None:
        df = df[df["participant_id"].isin(ids)]
    return df.reset_index(drop=True) if isinstance(df, pd.DataFrame) else df


def _meta(df, task) -> dict:
    info = dict(df.attrs.get("drive", {}))
    info.pop("wall_s", None)  # machine dependent: not part of the stored settings
    info.update({"participant_seed": task.seed, "style": task.style, "route": ROUTE_NAME})
    return info


def _store_results(args, tasks, results) -> list:
    from study.commands import _open
    from study.drives import import_drive_frame

    out = []
    with _open(args) as st:
        for task in tasks:
            df = results[(task.participant_id, task.condition)]
            r = import_drive_frame(st, task.participant_id, task.condition, df, source="simulation",
                                   route=ROUTE_NAME, replace=args.replace, seed=task.seed, meta=_meta(df, task))
            out.append((task, df, r))
    return out


def _summary_line(task, df, r) -> str:
    from pedas.drive import green_crossings

    g = green_crossings(df)
    e_wh = float((df["p_batt"] * df["t"].diff().fillna(0.0)).sum()) / 3600.0
    return (f"{task.participant_id} {task.condition:<8} {task.style:<8} {r.status:<9} {r.n_samples:>5} samples "
            f"{df['t'].iloc[-1]:7.1f} s {e_wh:7.1f} Wh  lights passed in green without a stop "
            f"{int(g['green_pass'].sum())}/{len(g)}")


def _drive_simulate(args) -> None:
    from pedas.cohort import cohort_tasks, simulate_cohort
    from study.commands import _open

    with _open(args, read_only=True) as st:
        people = _participants(st, [args.id])
    if not isinstance(people.loc[0, "style"], str):
        print(f"note: {args.id} has no driving style; simulated as 'normal'", file=sys.stderr)
    tasks = [t for t in cohort_tasks(people, base_seed=args.seed) if t.condition == args.condition]
    results = simulate_cohort(tasks, workers=1, progress=False, cache_dir=args.cache_dir)
    for task, df, r in _store_results(args, tasks, results):
        print(_summary_line(task, df, r))


def _simulate_cohort(args) -> None:
    from pedas.cohort import cohort_tasks, simulate_cohort
    from study.commands import _open
    from study.errors import UserError
    from study.exclusions import included_participants

    if args.workers is not None and args.workers < 1:
        raise UserError("--workers must be >= 1")
    with _open(args, read_only=True) as st:
        ids = included_participants(st, "objective")
        people = _participants(st, ids) if ids else None
    if not ids:
        raise UserError("no participants to simulate (none registered or all excluded from objective analyses)")
    tasks = cohort_tasks(people, base_seed=args.seed)
    results = simulate_cohort(tasks, workers=args.workers, scheduler=args.scheduler,
                              progress=not args.no_progress, cache_dir=args.cache_dir)
    stored = _store_results(args, tasks, results)
    for task, df, r in stored:
        print(_summary_line(task, df, r))
    changed = sum(1 for _, _, r in stored if r.status != "unchanged")
    people_word = "participant" if len(ids) == 1 else "participants"
    print(f"{len(stored)} drives of {len(ids)} {people_word} ({changed} stored, {len(stored) - changed} unchanged)")


def register(cli) -> None:
    """Add this module's commands to the `pedas-study` parser."""
    p = cli.subcommand("drive", "simulate", "simulate one drive of a participant (virtual driver in SUMO traffic)",
                       _drive_simulate, group_help="drive logs")
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", choices=("baseline", "pedas"))
    p.add_argument("--seed", type=int, default=0, help="cohort seed: the virtual person is derived from (seed, ID)")
    p.add_argument("--replace", action="store_true", help="replace a different drive stored for this condition")
    p.add_argument("--cache-dir", dest="cache_dir", default=None,
                   help="cache of simulated drives (default $PEDAS_DRIVE_CACHE or .report-cache/drives)")

    p = cli.subcommand("simulate", "cohort", "simulate both drives of every participant not excluded from the "
                       "objective analysis and store them", _simulate_cohort,
                       group_help="simulate the study with virtual participants")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on a Dask distributed cluster (e.g. tcp://host:8786)")
    p.add_argument("--seed", type=int, default=0, help="cohort seed: the virtual persons derive from (seed, ID)")
    p.add_argument("--replace", action="store_true", help="replace different drives already stored")
    p.add_argument("--no-progress", dest="no_progress", action="store_true", help="no progress bar")
    p.add_argument("--cache-dir", dest="cache_dir", default=None,
                   help="cache of simulated drives (default $PEDAS_DRIVE_CACHE or .report-cache/drives)")

"""`pedas-study simulate cohort`: both drives of every participant not excluded from the objective analysis,
simulated with virtual drivers in SUMO traffic and stored (all drives are simulated before the store is written).
The store's study must declare the conditions the simulator drives; each participant's ``style`` attribute chooses
the virtual driver (study.logs.simulated)."""
from __future__ import annotations

from pedas_study.cli.common import DRIVE_CACHE_HELP, add_scenario_option, open_store, scenario_of, simulate_and_store
from study.common.errors import UserError


def _cohort(args) -> None:
    from pedas.cohort import cohort_tasks
    from pedas_study.extras import require
    from study.people.exclusions import included_participants
    from study.logs.simulated import check_simulable, participants_to_simulate
    from study.store.studies import definition

    if args.workers is not None and args.workers < 1:
        raise UserError("--workers must be >= 1")
    scenario = scenario_of(args)
    if args.scheduler is not None:
        require("distributed", "dask", "--scheduler")
    with open_store(args, read_only=True) as st:
        check_simulable(definition(st))
        ids = included_participants(st, "objective")
        if not ids:
            raise UserError("no participants to simulate (none registered or all excluded from objective analyses)")
        people = participants_to_simulate(st, ids)
    tasks = cohort_tasks(people, base_seed=args.seed, scenario=scenario)
    stored = simulate_and_store(args, tasks, workers=args.workers, scheduler=args.scheduler,
                                progress=not args.no_progress)
    changed = sum(1 for _, _, r in stored if r.status != "unchanged")
    people_word = "participant" if len(ids) == 1 else "participants"
    print(f"{len(stored)} drives of {len(ids)} {people_word} ({changed} stored, {len(stored) - changed} unchanged)")


def _sweep(args) -> None:
    """Thin layer over analysis.sweep.run.run_sweep (docs/sweep.md)."""
    from pathlib import Path

    from analysis.sweep.run import run_sweep
    from analysis.sweep.design import SweepSpec, parse_factors
    from pedas_study.extras import require

    if args.workers is not None and args.workers < 1:
        raise UserError("--workers must be >= 1")
    if args.scheduler is not None:
        require("distributed", "dask", "--scheduler")
    factors = parse_factors(args.factors)
    given = {"trajectories": args.trajectories, "sobol_n": args.sobol_n, "participants": args.participants,
             "styles": tuple(s.strip() for s in args.styles.split(",")) if args.styles else None}
    spec = SweepSpec(factors=factors, top=args.top if args.top is not None else min(3, len(factors)),
                     scenario=scenario_of(args), seed=args.seed,
                     **{k: v for k, v in given.items() if v is not None})  # the others: SweepSpec's defaults
    meta = run_sweep(spec, Path(args.out), workers=args.workers, scheduler=args.scheduler,
                     cache_dir=args.cache_dir, progress=not args.no_progress)
    print(f"{meta['points']} design points, {meta['drives']} drives in {meta['wall_s']:.0f} s; "
          f"Sobol factors: {', '.join(meta['sobol_factors']) or 'none'}; outputs in {args.out}")


def register(cli) -> None:
    """Declare the `simulate` group."""
    g = cli.group("simulate", "simulate the study with virtual participants")
    p = g.command("cohort", "simulate both drives of every participant not excluded from the objective analysis "
                  "and store them", _cohort)
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on a Dask distributed cluster (e.g. tcp://host:8786)")
    p.add_argument("--seed", type=int, default=0, help="cohort seed: the virtual persons derive from (seed, ID)")
    p.add_argument("--replace", action="store_true", help="replace different drives already stored")
    p.add_argument("--no-progress", dest="no_progress", action="store_true", help="no progress bar")
    p.add_argument("--cache-dir", dest="cache_dir", default=None, help=DRIVE_CACHE_HELP)
    add_scenario_option(p)

    p = g.command("sweep", "what-if sweep: the reduced reference cohort over a Morris then Sobol design of "
                  "unpublished settings; which settings move each KPI and where the paper's bands hold "
                  "(docs/sweep.md)", _sweep)
    p.add_argument("--factors", nargs="+", default=None, metavar="NAME[=LO:HI]",
                   help="factors to vary, optionally with their range (default: all of pedas.whatif.FACTORS)")
    p.add_argument("--trajectories", type=int, default=None, metavar="R",
                   help="Morris trajectories r (points: r x (factors + 1); default 6)")
    p.add_argument("--sobol-n", dest="sobol_n", type=int, default=None, metavar="N",
                   help="Sobol base size N, a power of 2 (points: N x (top + 2); 0: no Sobol phase; default 8)")
    p.add_argument("--top", type=int, default=None, metavar="K",
                   help="factors with the largest Morris mu* that the Sobol phase varies (default 3, at most all)")
    p.add_argument("--participants", type=int, default=None, metavar="K",
                   help="people per driving style from data/reference/participants.csv, in id order (default 2)")
    p.add_argument("--styles", default=None, metavar="S[,S...]",
                   help="only these driving styles (default: cautious,normal,sporty)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on a Dask distributed cluster (e.g. tcp://host:8786)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the designs, the index bootstraps and the cohort's persons (default 0)")
    p.add_argument("--out", default="sweep-out", metavar="DIR", help="output folder (default sweep-out)")
    p.add_argument("--no-progress", dest="no_progress", action="store_true", help="no progress bar")
    p.add_argument("--cache-dir", dest="cache_dir", default=None, help=DRIVE_CACHE_HELP)
    add_scenario_option(p)

"""CLI commands of the objective evaluation: ``analyze drives`` and ``bench kpi`` (see `study.cli` for the
registration contract). Handlers are thin; the work is in `analysis.kpis_report` and `analysis.bench_kpi`."""
from __future__ import annotations


def register(cli) -> None:
    """Add ``analyze drives`` and ``bench kpi`` to the `pedas-study` parser."""
    p = cli.subcommand("analyze", "drives", "objective KPIs per drive and driving style, effects of pEDAS, "
                       "reproduction bands and Figs. 9-12", _analyze_drives, group_help="analyses of the study data")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (tables, figures/, objective.md)")
    p.add_argument("--participant", default="P006", metavar="ID",
                   help="participant of Figs. 11 and 12 (default P006, as in the paper)")

    b = cli.subcommand("bench", "kpi", "drive KPIs in DuckDB on a synthetic drive_samples table vs pandas on a "
                       "tenth of it", _bench_kpi, group_help="benchmarks")
    b.add_argument("--rows", type=int, default=None, metavar="N", help="samples (default 100000000)")
    b.add_argument("--repeat", type=int, default=3, metavar="N", help="timed repetitions, median reported (default 3)")
    b.add_argument("--seed", type=int, default=1, help="seed of the synthetic table (default 1)")
    b.add_argument("--memory-limit", default="6GB", help="DuckDB memory_limit (default 6GB)")
    b.add_argument("--threads", type=int, default=None, help="DuckDB threads (default: all cores)")
    b.add_argument("--json", action="store_true", help="print JSON")


def _analyze_drives(args) -> int:
    from study.cli import db_path
    from study.store import Store

    from analysis.kpis_report import analyze_drives

    db = db_path(args)
    if not db.exists():
        raise FileNotFoundError(f"store not found: {db} (run `pedas-study init`)")
    with Store.open(db, actor=getattr(args, "actor", None), read_only=True) as st:
        rep = analyze_drives(st, args.out, participant=args.participant)
    print(rep.text())
    return 0


def _bench_kpi(args) -> int:
    import json

    from analysis.bench_kpi import FULL_ROWS, run_bench

    rows = FULL_ROWS if args.rows is None else args.rows
    if rows < 2:
        raise ValueError("--rows must be at least 2")
    if args.repeat < 1:
        raise ValueError("--repeat must be at least 1")
    res = run_bench(rows=rows, repeat=args.repeat, seed=args.seed, memory_limit=args.memory_limit,
                    threads=args.threads)
    print(json.dumps(res.as_dict(), indent=2) if args.json else res.text())
    return 0

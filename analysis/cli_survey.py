"""CLI commands of the acceptance statistics: ``analyze survey`` and ``bench survey``
(see `study.cli` for the registration contract). Handlers are thin; the work is in `analysis.acceptance`."""
from __future__ import annotations


def register(cli) -> None:
    """Add ``analyze survey`` and ``bench survey`` to the `pedas-study` parser."""
    p = cli.subcommand("analyze", "survey", "acceptance statistics (Tables 3-5): descriptives, CFA, reliability, "
                       "validity, hierarchical regressions, H1-H7", _analyze_survey,
                       group_help="analyses of the study data")
    p.add_argument("--responses", metavar="CSV", default=None,
                   help="wide survey CSV (participant_id + item columns, raw 1-5); default: the store")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory for CSVs and tables")
    p.add_argument("--seed", type=int, default=20240101, help="bootstrap seed (default 20240101)")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N",
                   help="bootstrap resamples (default 2000; 0 = none)")
    p.add_argument("--boot-ci", choices=("percentile", "bca"), default="percentile", help="bootstrap CI method")
    p.add_argument("--instrument", default=None, help="codebook name (default pedas_acceptance_v1)")
    p.add_argument("--cfa-config", metavar="JSON", default=None, help="item-deletion config (default specs/cfa.json)")
    p.add_argument("--models", metavar="JSON", default=None, help="regression models (default specs/models.json)")
    p.add_argument("--hypotheses", metavar="JSON", default=None, help="hypotheses (default specs/hypotheses.json)")
    p.add_argument("--available-case", action="store_true",
                   help="keep participants with missing answers (composites over answered items) instead of listwise")

    b = cli.subcommand("bench", "survey", "time analyze survey on a synthetic 40-row survey", _bench_survey,
                       group_help="benchmarks")
    b.add_argument("--n", type=int, default=40, help="participants (default 40)")
    b.add_argument("--bootstrap", type=int, default=2000, metavar="N", help="bootstrap resamples (default 2000)")
    b.add_argument("--repeats", type=int, default=3, help="timed repetitions (median reported)")
    b.add_argument("--json", action="store_true", help="print JSON")


def _analyze_survey(args) -> int:
    from pathlib import Path

    import pandas as pd

    from analysis.acceptance import analyze_survey, responses_from_store

    if args.bootstrap < 0:
        raise ValueError("--bootstrap must be >= 0")
    if args.responses:
        path = Path(args.responses)
        if not path.exists():
            raise FileNotFoundError(f"survey CSV not found: {path}")
        responses = pd.read_csv(path, dtype={"participant_id": str})
        source = str(path)
    else:
        from study.cli import db_path
        from study.store import Store

        db = db_path(args)
        if not db.exists():
            raise FileNotFoundError(f"store not found: {db} (run `pedas-study init` or pass --responses CSV)")
        with Store.open(db, actor=getattr(args, "actor", None), read_only=True) as st:
            responses = responses_from_store(st, instrument=args.instrument)
        source = f"store {db}"
    res = analyze_survey(responses, instrument=args.instrument, cfa_config=args.cfa_config, models=args.models,
                         hypotheses=args.hypotheses, n_boot=args.bootstrap, seed=args.seed,
                         listwise=not args.available_case, boot_method=args.boot_ci)
    paths = res.write(args.out)
    print(f"survey analysis of {res.n} participants ({source}) -> {args.out}: {len(paths)} files")
    for _, h in res.hypotheses.iterrows():
        verdict = "supported" if h["supported"] else "not supported"
        print(f"  {h['hypothesis']} {h['path']}: beta = {h['beta']:.3f}, p = {h['p']:.3g} -> {verdict}")
    for w in res.warnings:
        print(f"  warning: {w}")
    return 0


def _bench_survey(args) -> int:
    import json

    from analysis.bench_survey import bench_bootstrap, bench_survey

    r = bench_survey(n=args.n, n_boot=args.bootstrap, repeats=args.repeats)
    b = bench_bootstrap(n=args.n, n_boot=args.bootstrap, repeats=max(3, args.repeats))
    if args.json:
        print(json.dumps({"analyze_survey": r, "bootstrap": b}))
    else:
        print(f"analyze survey, n = {r['n']}, {r['n_boot']} bootstrap resamples: median {r['median_s']:.3f} s "
              f"over {r['repeats']} runs; without bootstrap {r['median_s_no_bootstrap']:.3f} s "
              f"(ratio {r['ratio_vs_no_bootstrap']:.2f})")
        print(f"bootstrap of one 3-predictor step, {b['n_boot']} resamples: "
              f"stacked {b['median_s_stacked'] * 1e3:.1f} ms "
              f"vs statsmodels loop {b['median_s_statsmodels_loop'] * 1e3:.0f} ms (speed-up {b['speedup']:.0f}x, "
              f"max |diff| {b['max_abs_diff']:.1e})")
    return 0

"""CLI commands of the drive simulation: `bench drive` (real-time factor of drives, cohort speed-up) and
`bench robustness` (a sweep of many drives, failures counted by kind)."""
from __future__ import annotations


def register(cli) -> None:
    """Add this module's commands to the `pedas-study` parser."""
    p = cli.subcommand("bench", "drive", "wall time and real-time factor of a baseline and a pEDAS drive in SUMO "
                       "traffic; 1- vs 2-worker cohort speed-up", _bench_drive, group_help="benchmarks")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--repeats", type=int, default=1, help="drives per condition (median reported)")
    p.add_argument("--cohort", type=int, default=3, metavar="N",
                   help="participants of the speed-up cohort (2 drives each; 0 skips it)")
    p.add_argument("--seed", type=int, default=1, help="participant seed of the timed drives")

    p = cli.subcommand("bench", "robustness", "robustness sweep: person seeds x styles x conditions x traffic seeds "
                       "drives in SUMO, failures counted by kind; exit code 1 when any drive failed",
                       _bench_robustness, group_help="benchmarks")
    p.add_argument("--seeds", default="1000-1049", metavar="A-B|N",
                   help="person seeds: an inclusive range A-B, or a count N for 1000..1000+N-1 (default 1000-1049)")
    p.add_argument("--styles", default="cautious,normal,sporty", help="comma-separated driving styles")
    p.add_argument("--conditions", default="baseline,pedas", help="comma-separated conditions")
    p.add_argument("--traffic-seeds", type=int, default=1, metavar="K",
                   help="traffic seeds per person: the person seed and K-1 others (default 1)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: CPU count)")
    p.add_argument("--out", metavar="CSV", default=None, help="write the per-drive table to this CSV file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _bench_drive(args) -> int:
    import json

    from pedas.drive_bench import bench_drive

    if args.repeats < 1 or args.cohort < 0:
        raise ValueError("--repeats must be >= 1 and --cohort >= 0")
    res = bench_drive(repeats=args.repeats, cohort=args.cohort, seed=args.seed)
    if args.json:
        print(json.dumps(res, sort_keys=True))
        return 0
    print(f"setup (network, route, DP reference)   {res['setup_s']:8.2f} s")
    for cond in ("baseline", "pedas"):
        r = res[cond]
        print(f"{cond:<8} drive: simulated {r['sim_s']:7.1f} s in {r['wall_s_median']:6.2f} s wall (median of "
              f"{r['repeats']}) -> {r['rtf_median']:6.0f}x real time; {r['ms_per_step']:.2f} ms/step, "
              f"up to {r['max_vehicles']} vehicles")
    print(f"pEDAS / baseline wall-time ratio        {res['pedas_over_baseline']:8.2f}")
    c = res.get("cohort")
    if c:
        print(f"cohort of {c['drives']} drives: 1 worker {c['wall_1']:.1f} s, 2 workers {c['wall_2']:.1f} s "
              f"-> speed-up {c['speedup']:.2f}x")
        print(f"projected 34-participant cohort (68 drives) on 2 workers: {c['projected_68_on_2_s']:.0f} s")
    print(f"goals: pEDAS drive >= 200x real time: {'met' if res['pedas']['rtf_median'] >= 200 else 'NOT met'}"
          + (f"; 68 drives <= 180 s on 2 workers: {'met' if c['projected_68_on_2_s'] <= 180 else 'NOT met'}"
             if c else ""))
    return 0


def _seed_range(text: str) -> list[int]:
    """--seeds: 'A-B' (inclusive) or a count N (1000..1000+N-1)."""
    a, sep, b = text.strip().partition("-")
    try:
        lo, hi = (int(a), int(b)) if sep else (1000, 1000 + int(a) - 1)
    except ValueError:
        raise ValueError(f"--seeds must be a range A-B or a count N, not {text!r}") from None
    if lo < 0 or hi < lo:
        raise ValueError(f"--seeds {text!r} is empty or negative")
    return list(range(lo, hi + 1))


def _names(text: str, allowed: tuple[str, ...], option: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in names if x not in allowed]
    if bad or not names:
        raise ValueError(f"{option}: unknown {bad[0]!r} (expected {'|'.join(allowed)})" if bad
                         else f"{option} is empty")
    return list(dict.fromkeys(names))


def _bench_robustness(args) -> int:
    import json

    from pedas.bench_robustness import robustness_sweep, summarise, traffic_design, wall_time
    from pedas.vocabulary import CONDITIONS, STYLES

    seeds = _seed_range(args.seeds)
    styles = _names(args.styles, STYLES, "--styles")
    conditions = _names(args.conditions, CONDITIONS, "--conditions")
    if args.traffic_seeds < 1:
        raise ValueError("--traffic-seeds must be >= 1")
    if args.workers is not None and args.workers < 1:
        raise ValueError("--workers must be >= 1")
    df = robustness_sweep(seeds, styles, conditions, traffic_design(seeds, args.traffic_seeds),
                          workers=args.workers, progress=not args.no_progress)
    if args.out:
        df.to_csv(args.out, index=False)
    failed = df[~df["ok"]]
    counts = {r.kind: int(r.failures) for r in summarise(df).itertuples() if r.failures > 0}
    wt = wall_time(df)
    if args.json:
        print(json.dumps({"drives": len(df), "workers": df.attrs["workers"], "wall_s": wt, "failures": len(failed),
                          "failures_by_kind": counts, "failed": failed[["seed", "style", "condition", "traffic_seed",
                                                                        "kind", "message"]].to_dict("records")},
                         sort_keys=True, default=str))
        return 1 if len(failed) else 0
    by_cond = ", ".join(f"{c} {w:.1f} s" for c, w in wt["median_by_condition"].items())
    k = args.traffic_seeds
    print(f"{len(df)} drives ({len(seeds)} person seeds x {len(styles)} styles x {len(conditions)} conditions x "
          f"{k} traffic seed{'s' if k > 1 else ''}) on {df.attrs['workers']} workers in {wt['sweep']:.1f} s wall; "
          f"median drive {by_cond}")
    if failed.empty:
        print("failures: 0")
        return 0
    print(f"failures: {len(failed)} (" + ", ".join(f"{k} {n}" for k, n in counts.items()) + ")")
    for row in failed.itertuples(index=False):
        print(f"  {row.kind}: {row.message}")
    return 1

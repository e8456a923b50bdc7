"""`pedas-study bench ...`: the benchmarks of `pedas_study.bench`, each printed as text or one JSON object."""
from __future__ import annotations

from pedas_study.cli.common import add_scenario_option, scenario_of


# ---------------------------------------------------------------------------------------------- bench import
def _import(args) -> None:
    import json

    from pedas_study.bench.store_import import bench_import

    r = bench_import(rows=args.rows, repeats=args.repeats)
    if args.json:
        print(json.dumps(r.as_dict(), indent=1))
        return
    print(f"drive import of a {r.rows:,}-row Parquet log, median of {r.repeats}: {r.import_s_median:.2f} s "
          f"({r.import_rows_per_s:,.0f} rows/s); DuckDB read_parquet peer {r.peer_s_median:.2f} s "
          f"({r.peer_rows_per_s:,.0f} rows/s); ratio {r.ratio:.1f}x")


# ---------------------------------------------------------------------------------------------- bench bulk-import
def _bulk_import(args) -> None:
    import json
    import sys

    from pedas_study.bench.bulk_import import bench_bulk_import

    if args.repeats < 1 or args.single_repeats < 1:
        raise ValueError("--repeats and --single-repeats must be >= 1")
    r = bench_bulk_import(args.repeats, args.single_repeats,
                          progress=None if args.json else lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(r.as_dict(), indent=1) if args.json else r.to_text())


# ---------------------------------------------------------------------------------------------- bench cli
def _cli(args) -> None:
    import json

    from pedas_study.bench.cli import bench_cli

    r = bench_cli(repeats=args.repeats)
    print(json.dumps(r.as_dict(), indent=1) if args.json else r.to_text())


# ---------------------------------------------------------------------------------------------- bench export
def _export(args) -> None:
    import json
    import sys

    from pedas_study.bench.store_export import bench_export, to_text

    if args.samples < 2 or args.log_rows < 2:
        raise ValueError("--samples and --log-rows must be >= 2")
    r = bench_export(samples=args.samples, log_rows=args.log_rows, peers=not args.no_peers,
                     progress=None if args.json else lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(r.as_dict(), indent=1) if args.json else to_text(r))


def _hud(args) -> None:
    import json

    from pedas_study.bench.hud_channels import bench_hud_channels

    if args.copies < 1:
        raise ValueError("--copies must be >= 1")
    r = bench_hud_channels(args.copies)
    print(json.dumps(r.as_dict(), indent=1) if args.json else r.to_text())


# ---------------------------------------------------------------------------------------------- bench mpc
def _mpc(args) -> int:
    import json

    from pedas_study.bench.mpc import run_bench_all

    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if args.peer_steps < 0:
        raise ValueError(f"--peer-steps must be >= 0, got {args.peer_steps}")
    res = run_bench_all(steps=args.steps, peer_steps=min(args.peer_steps, args.steps), seed=args.seed)
    if args.json:
        print(json.dumps({b: r.as_dict() for b, r in res.items()}))
    else:
        print("\n".join(r.to_text() for r in res.values()))
    return 0


# ---------------------------------------------------------------------------------------------- bench live
def _live(args) -> int:
    import json

    from pedas_study.bench.live import bench_live

    if args.messages < 1 or not 0 < args.rate <= 1000:
        raise ValueError("--messages must be >= 1 and --rate in (0, 1000] Hz")
    r = bench_live(messages=args.messages, rate=args.rate, seed=args.seed)
    if args.json:
        print(json.dumps(r, sort_keys=True))
    else:
        print(f"live advice on localhost, {r['messages']} states at {r['rate_hz']:g} Hz in {r['sessions']} logged "
              f"session(s): state in -> advice out median {r['median_ms']:.2f} ms, p99 {r['p99_ms']:.2f} ms, max "
              f"{r['max_ms']:.2f} ms; advice different from the in-process controller's: {r['mismatches']}; "
              f"samples logged: {r['logged_samples']}")
    return 1 if r["mismatches"] else 0


# ---------------------------------------------------------------------------------------------- bench drive
def _drive(args) -> int:
    import json

    from pedas.vocabulary import CONDITIONS
    from pedas_study.bench.drive import bench_drive

    if args.repeats < 1 or args.cohort < 0:
        raise ValueError("--repeats must be >= 1 and --cohort >= 0")
    res = bench_drive(repeats=args.repeats, cohort=args.cohort, seed=args.seed, scenario=scenario_of(args))
    if args.json:
        print(json.dumps(res, sort_keys=True))
        return 0
    print(f"scenario {res['scenario']}; setup (network, route, DP reference) {res['setup_s']:.2f} s")
    other = sorted(k for k, r in res.items() if k.startswith("pedas_") and isinstance(r, dict))
    labels = {}
    for cond in list(CONDITIONS) + other:
        r = res[cond]
        label = labels[cond] = cond if r["backend"] is None else f"{cond.split('_')[0]} ({r['backend']})"
        print(f"{label:<15} drive: simulated {r['sim_s']:7.1f} s in {r['wall_s_median']:6.2f} s wall (median of "
              f"{r['repeats']}) -> {r['rtf_median']:6.0f}x real time; {r['ms_per_step']:.2f} ms/step, "
              f"up to {r['max_vehicles']} vehicles")
    print(f"pEDAS / baseline wall-time ratio        {res['pedas_over_baseline']:8.2f}")
    ta = res["traffic_alone"]
    print(f"traffic alone (SUMO replaying the baseline drive): {ta['ms_per_step']:.2f} ms/step -> "
          f"{ta['rtf_median']:.0f}x real time, the ceiling of any drive in this scenario")
    print(f"  + SUMO's start and the steps before the ego's insertion: {ta['start_s']:.2f} s per drive (in every "
          f"drive's wall time, not in the ms/step above)")
    ratios = [f"{labels[c]} {o['median']:.2f}x ({o['min']:.2f}-{o['max']:.2f})" for c, o in res["over_traffic"].items()]
    print(f"ms/step over the traffic alone's in the same round, median (range) of {ta['repeats']}: "
          + ", ".join(ratios))
    c = res.get("cohort")
    if c:
        print(f"cohort of {c['drives']} drives: 1 worker {c['wall_1']:.1f} s, 2 workers {c['wall_2']:.1f} s "
              f"-> speed-up {c['speedup']:.2f}x")
        print(f"projected 34-participant cohort (68 drives) on 2 workers: {c['projected_68_on_2_s']:.0f} s")
    print(f"goals: pEDAS drive >= 600x real time: {'met' if res['pedas']['rtf_median'] >= 600 else 'NOT met'}"
          + ("" if ta["rtf_median"] >= 600 else " (out of reach: the traffic alone is slower)")
          + (f"; 68 drives <= 180 s on 2 workers: {'met' if c['projected_68_on_2_s'] <= 180 else 'NOT met'}"
             if c else ""))
    return 0


# ---------------------------------------------------------------------------------------------- bench robustness
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


def _robustness(args) -> int:
    """Exit code 1 when any drive failed."""
    import json

    from pedas.vocabulary import CONDITIONS, STYLES
    from pedas_study.bench.robustness import robustness_sweep, summarise, traffic_design, wall_time

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


# ---------------------------------------------------------------------------------------------- bench survey
def _survey(args) -> int:
    import json

    from pedas_study.bench.survey import bench_bootstrap, bench_survey

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


# ---------------------------------------------------------------------------------------------- bench kpi
def _kpi(args) -> int:
    import json

    from pedas_study.bench.kpi import FULL_ROWS, run_bench

    rows = FULL_ROWS if args.rows is None else args.rows
    if args.repeat < 1:
        raise ValueError("--repeat must be at least 1")
    res = run_bench(rows=rows, repeat=args.repeat, seed=args.seed, memory_limit=args.memory_limit,
                    threads=args.threads)
    print(json.dumps(res.as_dict(), indent=2) if args.json else res.text())
    return 0


def _measures(args) -> int:
    import json

    from pedas_study.bench.measures import run_bench

    if args.repeat < 1 or args.rows < 2:
        raise ValueError("--repeat must be at least 1 and --rows at least 2")
    res = run_bench(rows=args.rows, repeat=args.repeat, seed=args.seed, threads=args.threads)
    print(json.dumps(res.as_dict(), indent=2) if args.json else res.text())
    return 0


def register(cli) -> None:
    """Declare the `bench` group."""
    from pedas.vocabulary import CONDITIONS, STYLES

    g = cli.group("bench", "benchmarks")
    p = g.command("cli", "median wall time of everyday commands, each a fresh process, on a store with 100 "
                  "participants (--help, listing, add, advance, drive import, roster import, plan power, analyze) vs "
                  "the bare interpreter start", _cli)
    p.add_argument("--repeats", type=int, default=5, metavar="N", help="runs of each command (default 5)")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = g.command("import", "throughput of drive-log import (rows/s) vs a plain DuckDB load", _import)
    p.add_argument("--rows", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", action="store_true")

    p = g.command("bulk-import", "the takeover study's 72 drive logs (20 Hz, 2,300 samples each) imported after the "
                  "protocol: one `drive import --dir` vs 72 `drive import` calls, each a fresh process; medians, "
                  "ratio, peak memory", _bulk_import)
    p.add_argument("--repeats", type=int, default=3, metavar="N", help="runs of the bulk import (default 3)")
    p.add_argument("--single-repeats", dest="single_repeats", type=int, default=1, metavar="N",
                   help="runs of the 72 one-by-one imports (default 1: ~2 s a call)")
    p.add_argument("--json", action="store_true")

    p = g.command("export", "time and peak memory of exports (parquet, csv, csv --deidentify) of a store of "
                  "synthetic drive samples and of a large CSV drive import, each in its own process, vs plain DuckDB",
                  _export)
    p.add_argument("--samples", type=int, default=10_000_000, metavar="N", help="drive samples in the store "
                   "(default 10000000)")
    p.add_argument("--log-rows", type=int, default=5_000_000, metavar="N", help="rows of the imported CSV log "
                   "(default 5000000)")
    p.add_argument("--no-peers", action="store_true", help="skip the DuckDB floors and the DataFrame peer")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = g.command("hud", "cost of storing the seven HUD channels with a pEDAS drive: import time and store size per "
                  "drive, with and without them", _hud)
    p.add_argument("--copies", type=int, default=10, metavar="N", help="drives imported into each store (default 10)")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = g.command("mpc", "controller-step time and accuracy of the MPCs with each QP backend (DAQP, OSQP) on a "
                  "drive-like sequence vs cvxpy + Clarabel", _mpc)
    p.add_argument("--steps", type=int, default=5000, metavar="N", help="controller steps to time (default 5000)")
    p.add_argument("--peer-steps", type=int, default=300, metavar="N",
                   help="steps on which cvxpy rebuilds and solves the same QP (default 300)")
    p.add_argument("--seed", type=int, default=0, help="seed of the virtual driver and the leader (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")

    p = g.command("live", "latency of live advice (state in -> advice out over WebSocket, server logging the drive) "
                  "and equality with the in-process controller", _live)
    p.add_argument("--messages", type=int, default=10_000, help="states sent (default 10000)")
    p.add_argument("--rate", type=float, default=50.0, help="states per second (default 50)")
    p.add_argument("--seed", type=int, default=1, help="participant seed of the drive whose states are sent")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = g.command("drive", "wall time and real-time factor of a baseline drive and a pEDAS drive with each QP "
                  "backend in SUMO traffic; the traffic simulation alone; "
                  "1- vs 2-worker cohort speed-up", _drive)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--repeats", type=int, default=1, help="drives per condition (median reported)")
    p.add_argument("--cohort", type=int, default=3, metavar="N",
                   help="participants of the speed-up cohort (2 drives each; 0 skips it)")
    p.add_argument("--seed", type=int, default=1, help="participant seed of the timed drives")
    add_scenario_option(p)

    p = g.command("robustness", "robustness sweep: person seeds x styles x conditions x traffic seeds drives in "
                  "SUMO, failures counted by kind; exit code 1 when any drive failed", _robustness)
    p.add_argument("--seeds", default="1000-1049", metavar="A-B|N",
                   help="person seeds: an inclusive range A-B, or a count N for 1000..1000+N-1 (default 1000-1049)")
    p.add_argument("--styles", default=",".join(STYLES), help="comma-separated driving styles")
    p.add_argument("--conditions", default=",".join(CONDITIONS), help="comma-separated conditions")
    p.add_argument("--traffic-seeds", type=int, default=1, metavar="K",
                   help="traffic seeds per person: the person seed and K-1 others (default 1)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: CPU count)")
    p.add_argument("--out", metavar="CSV", default=None, help="write the per-drive table to this CSV file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    p = g.command("survey", "time analyze survey on a synthetic 40-row survey", _survey)
    p.add_argument("--n", type=int, default=40, help="participants (default 40)")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N", help="bootstrap resamples (default 2000)")
    p.add_argument("--repeats", type=int, default=3, help="timed repetitions (median reported)")
    p.add_argument("--json", action="store_true", help="print JSON")

    p = g.command("kpi", "drive KPIs in DuckDB on a synthetic drive_samples table vs pandas on a tenth of it",
                  _kpi)
    p.add_argument("--rows", type=int, default=None, metavar="N", help="samples (default 100000000)")
    p.add_argument("--repeat", type=int, default=3, metavar="N", help="timed repetitions, median reported (default 3)")
    p.add_argument("--seed", type=int, default=1, help="seed of the synthetic table (default 1)")
    p.add_argument("--memory-limit", default="6GB", help="DuckDB memory_limit (default 6GB)")
    p.add_argument("--threads", type=int, default=None, help="DuckDB threads (default: all cores)")
    p.add_argument("--json", action="store_true", help="print JSON")

    p = g.command("measures", "the shipped standard driving measures vs the built-in KPIs' pass on the KPI bench's "
                  "synthetic table (medians and ratio)", _measures)
    p.add_argument("--rows", type=int, default=10_000_000, metavar="N", help="samples (default 10000000)")
    p.add_argument("--repeat", type=int, default=3, metavar="N", help="timed repetitions, median reported (default 3)")
    p.add_argument("--seed", type=int, default=1, help="seed of the synthetic table (default 1)")
    p.add_argument("--threads", type=int, default=None, help="DuckDB threads (default: all cores)")
    p.add_argument("--json", action="store_true", help="print JSON")

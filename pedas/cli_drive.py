"""CLI command of the drive simulation: `bench drive` (real-time factor of drives, cohort speed-up)."""
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

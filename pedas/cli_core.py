"""CLI commands of the simulation core: `kpi energy` (any speed trace -> battery energy) and `bench mpc`."""
from __future__ import annotations


def register(cli) -> None:
    """Add this module's commands to the `pedas-study` parser."""
    _register_kpi(cli)
    _register_bench(cli)


# ------------------------------------------------------------------------------------------------- kpi energy
def _register_kpi(cli) -> None:
    p = cli.subcommand("kpi", "energy", "battery energy (Wh, Wh/km) of a speed trace CSV with columns t, v[, grade]",
                       _kpi_energy, group_help="key performance indicators of traces")
    p.add_argument("--trace", required=True, metavar="CSV",
                   help="CSV with t (s), v (m/s) and optionally grade (rad); one row per sample")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")


def read_trace(path):
    """(t, v, grade|None) from a trace CSV; ValueError with a one-line reason on bad content."""
    from pathlib import Path

    import numpy as np
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trace file not found: {path}")
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path.name}: not a readable CSV ({' '.join(str(exc).split())})") from exc
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in ("t", "v") if c not in df.columns]
    if missing:
        raise ValueError(f"{path.name}: missing column(s) {', '.join(missing)} (need t, v[, grade])")
    cols = ["t", "v"] + (["grade"] if "grade" in df.columns else [])
    num = df[cols].apply(pd.to_numeric, errors="coerce")
    bad = num.isna().any(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0]) + 2  # header is line 1
        raise ValueError(f"{path.name}: line {row}: t, v and grade must be numbers")
    grade = num["grade"].to_numpy(float) if "grade" in num.columns else None
    return num["t"].to_numpy(float), num["v"].to_numpy(float), grade


def _kpi_energy(args) -> int:
    import json

    from pedas.power import trace_energy

    t, v, grade = read_trace(args.trace)
    try:
        res = trace_energy(t, v, grade)
    except ValueError as exc:
        raise ValueError(f"{args.trace}: {exc}") from exc
    out = {"file": str(args.trace), "samples": int(t.size), "duration_s": round(res.duration_s, 3),
           "distance_km": round(res.distance_m / 1000.0, 4), "energy_wh": round(res.wh, 2),
           "wh_per_km": None if res.distance_m <= 0 else round(res.wh_per_km, 2)}
    if args.json:
        print(json.dumps(out))
    else:
        rows = [("samples", f"{out['samples']}"), ("duration", f"{res.duration_s:.1f} s"),
                ("distance", f"{res.distance_m / 1000.0:.3f} km"), ("energy", f"{res.wh:.1f} Wh"),
                ("consumption", "n/a (no distance)" if out["wh_per_km"] is None else f"{res.wh_per_km:.1f} Wh/km")]
        w = max(len(k) for k, _ in rows)
        for k, val in rows:
            print(f"{k:<{w}}  {val}")
    return 0


# ------------------------------------------------------------------------------------------------- bench mpc
def _register_bench(cli) -> None:
    p = cli.subcommand("bench", "mpc", "controller-step time of the OSQP MPCs on a drive-like sequence vs cvxpy",
                       _bench_mpc, group_help="benchmarks (medians and ratios against a peer in the same process)")
    p.add_argument("--steps", type=int, default=5000, metavar="N", help="controller steps to time (default 5000)")
    p.add_argument("--peer-steps", type=int, default=300, metavar="N",
                   help="steps on which cvxpy rebuilds and solves the same QP (default 300)")
    p.add_argument("--seed", type=int, default=0, help="seed of the virtual driver and the leader (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def _bench_mpc(args) -> int:
    import json

    from pedas.bench_mpc import result_dict, run_bench

    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if args.peer_steps < 0:
        raise ValueError(f"--peer-steps must be >= 0, got {args.peer_steps}")
    res = run_bench(steps=args.steps, peer_steps=min(args.peer_steps, args.steps), seed=args.seed)
    if args.json:
        print(json.dumps(result_dict(res)))
    else:
        print(res.to_text())
    return 0

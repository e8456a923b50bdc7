"""`pedas-study kpi energy`: battery energy (Wh, Wh/km) of any speed trace."""
from __future__ import annotations


def _energy(args) -> int:
    import json

    from pedas.power import trace_energy
    from pedas.trace_io import read_trace

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


def register(cli) -> None:
    """Declare the `kpi` group."""
    g = cli.group("kpi", "key performance indicators of traces")
    p = g.command("energy", "battery energy (Wh, Wh/km) of a speed trace CSV with columns t, v[, grade]", _energy)
    p.add_argument("--trace", required=True, metavar="CSV",
                   help="CSV with t (s), v (m/s) and optionally grade (rad); one row per sample")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")

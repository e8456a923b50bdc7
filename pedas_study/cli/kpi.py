"""`pedas-study kpi energy`: battery energy (Wh, Wh/km) of any speed trace — measured when the trace logs the
battery power, else from the vehicle model, and says which."""
from __future__ import annotations

MODELS = {"nissan_leaf": "modelled (Nissan Leaf parameters)", "none": None}
POWER_COLUMN = "p_batt"


def _power(path):
    """The trace's battery power column (W) as floats, None when it has none; ValueError naming the line of a
    value that is not a number."""
    from pathlib import Path

    import numpy as np
    import pandas as pd

    path = Path(path)
    df = pd.read_csv(path)
    df.columns = [str(c).strip() for c in df.columns]
    if POWER_COLUMN not in df.columns:
        return None
    p = pd.to_numeric(df[POWER_COLUMN], errors="coerce")
    if p.isna().any():
        row = int(np.flatnonzero(p.isna().to_numpy())[0]) + 2  # header is line 1
        raise ValueError(f"{path.name}: line {row}: {POWER_COLUMN} must be a number (W)")
    return p.to_numpy(float)


def _energy(args) -> int:
    import json

    import numpy as np

    from pedas.power import trace_energy
    from pedas.trace_io import read_trace

    t, v, grade = read_trace(args.trace)
    try:
        res = trace_energy(t, v, grade)  # also checks the trace (t increasing, v >= 0)
    except ValueError as exc:
        raise ValueError(f"{args.trace}: {exc}") from exc
    power = _power(args.trace)
    note = None
    if power is not None:
        wh, source = float(np.trapezoid(power, t)) / 3600.0, f"measured ({POWER_COLUMN} column)"
    elif MODELS[args.model]:
        wh, source = res.wh, MODELS[args.model]
    else:
        wh, source = None, "unavailable"
        note = f"the trace has no {POWER_COLUMN} column and --model none was given: energy unavailable"
    per_km = None if wh is None or res.distance_m <= 0 else wh / (res.distance_m / 1000.0)
    out = {"file": str(args.trace), "samples": int(t.size), "duration_s": round(res.duration_s, 3),
           "distance_km": round(res.distance_m / 1000.0, 4), "energy_wh": None if wh is None else round(wh, 2),
           "wh_per_km": None if per_km is None else round(per_km, 2), "energy_source": source}
    if note:
        out["note"] = note
    if args.json:
        print(json.dumps(out))
    else:
        consumption = ("n/a (no distance)" if res.distance_m <= 0 else "n/a (no energy)" if per_km is None
                       else f"{per_km:.1f} Wh/km")
        rows = [("samples", f"{out['samples']}"), ("duration", f"{res.duration_s:.1f} s"),
                ("distance", f"{res.distance_m / 1000.0:.3f} km"),
                ("energy", "n/a" if wh is None else f"{wh:.1f} Wh"), ("consumption", consumption),
                ("source", source)] + ([("note", note)] if note else [])
        w = max(len(k) for k, _ in rows)
        for k, val in rows:
            print(f"{k:<{w}}  {val}")
    return 0


def register(cli) -> None:
    """Declare the `kpi` group."""
    g = cli.group("kpi", "key performance indicators of traces")
    p = g.command("energy", "battery energy (Wh, Wh/km) of a speed trace CSV with columns t, v[, grade, p_batt]: "
                  "measured from p_batt when present, else from the vehicle model", _energy)
    p.add_argument("--trace", required=True, metavar="CSV",
                   help="CSV with t (s), v (m/s), optionally grade (rad) and p_batt (battery power, W); one row per "
                        "sample")
    p.add_argument("--model", choices=tuple(MODELS), default="nissan_leaf",
                   help="vehicle model for a trace without p_batt (default nissan_leaf; none = energy unavailable)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")

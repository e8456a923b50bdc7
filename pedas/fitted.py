"""The vehicle model's fitted coefficients, committed as data: the aerodynamic line (p1, p2, Fig. 5a), the traction
limit line (p3, p4, eq. 6a) and the power map a00..a02 (eq. 5).

The fits are exact (:mod:`pedas.exact_lstsq`), so refitting gives the same bits on every machine; committing them
still makes the model reviewable as numbers, and a test checks that :func:`refit` reproduces the file. Reading the
file is :mod:`pedas.coefficients`' job (the vehicle and power models read it there; this module imports them).

Refit after changing `pedas.params.LEAF` or a fitting method: ``python -m pedas.fitted`` (``make refit``).
"""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from pedas.coefficients import FITS_FILE, fit_key
from pedas.params import LEAF, VehicleParams
from pedas.power import fit_power_map
from pedas.vehicle import V_RANGE_DEFAULT, fit_aero, fit_traction_limit


def refit(p: VehicleParams = LEAF, v_range: tuple[float, float] = V_RANGE_DEFAULT) -> dict:
    """The coefficients of `p` over `v_range` (m/s), fitted now: {key, v_range, aero, traction_limit, power_map}."""
    v_lo, v_hi = float(v_range[0]), float(v_range[1])
    p1, p2 = fit_aero(p, v_lo, v_hi)
    p3, p4 = fit_traction_limit(p, v_lo, v_hi)
    pm, _ = fit_power_map(p, (v_lo, v_hi))
    return {"key": fit_key(p, (v_lo, v_hi)), "v_range": [v_lo, v_hi],
            "aero": {"p1": p1, "p2": p2}, "traction_limit": {"p3": p3, "p4": p4}, "power_map": asdict(pm)}


def write(records: list[dict], path: Path = FITS_FILE) -> None:
    """Write the records (floats as their shortest exact repr, so reading them back gives the same bits)."""
    doc = {"about": "Fitted coefficients of the vehicle model (SI units); regenerate with `python -m pedas.fitted`.",
           "fits": records}
    path.write_text(json.dumps(doc, indent=2) + "\n")


def main() -> None:
    """Refit the committed vehicles (the Leaf over 0-130 km/h) and rewrite the file."""
    rec = refit(LEAF, V_RANGE_DEFAULT)
    write([{"vehicle": "Nissan Leaf (pedas.params.LEAF)", **rec}])
    print(f"wrote {FITS_FILE.name}: " + json.dumps({k: rec[k] for k in ("aero", "traction_limit", "power_map")}))


if __name__ == "__main__":
    main()

"""The vehicle model's committed coefficients (`pedas/fitted_coefficients.json`), read: the aerodynamic line (p1, p2,
Fig. 5a), the traction limit line (p3, p4, eq. 6a) and the power map a00..a02 (eq. 5).

A record applies only to the vehicle parameters and speed range it was fitted for (its ``key`` is a hash of both);
:mod:`pedas.vehicle` and :mod:`pedas.power` fit any other vehicle or range on the fly. Writing the file is
:mod:`pedas.fitted`'s job (``python -m pedas.fitted``), which imports the fitting methods; this module imports none,
so the models can read their coefficients without importing the module that refits them.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from functools import lru_cache
from pathlib import Path

from pedas.params import VehicleParams

FITS_FILE = Path(__file__).with_name("fitted_coefficients.json")


def fit_key(p: VehicleParams, v_range: tuple[float, float]) -> str:
    """Hash of the vehicle parameters and the fitted speed range (floats by their exact repr)."""
    blob = json.dumps({"params": asdict(p), "v_range": [float(v_range[0]), float(v_range[1])]}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


@lru_cache(maxsize=1)
def _committed() -> dict[str, dict]:
    if not FITS_FILE.exists():
        return {}
    return {rec["key"]: rec for rec in json.loads(FITS_FILE.read_text())["fits"]}


def committed(p: VehicleParams, v_range: tuple[float, float]) -> dict | None:
    """The committed record for `p` over `v_range`, or None when none was committed for exactly these inputs."""
    return _committed().get(fit_key(p, v_range))

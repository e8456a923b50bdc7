"""The design of the what-if sweep (docs/sweep.md): which settings vary over which ranges, the SALib Morris and
Sobol samples, and the reduced cohort that drives every design point.

A design point is one :class:`pedas.whatif.WhatIf`: the factors of its phase take the sampled values, every other
field keeps its default. Sampled values are rounded to 6 decimals so that a design read back from design.csv is the
same design (and hits the same drive-cache keys).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.drives.savings import BAND_HIGHWAY, BAND_OVERALL, BAND_RED, BAND_VIOLATION
from pedas.paths import REFERENCE_DIR
from pedas.scenario import DEFAULT_SCENARIO
from pedas.vocabulary import STYLES
from pedas.whatif import FACTORS, WhatIf
from study.common.errors import UserError

#: band key -> (band of analysis.drives.savings.reproduction_bands, the KPI column of points.csv it reads)
BANDS = {"overall": (BAND_OVERALL, "saving_overall_pct"),
         "highway": (BAND_HIGHWAY, "highway_minus_urban_pp"),
         "violation": (BAND_VIOLATION, "violation_reduction_pct"),
         "red": (BAND_RED, "red_stop_reduction_pct")}
#: the KPIs of a point (percent, or percentage points for the highway-urban difference)
KPIS = ("saving_overall_pct", "saving_urban_pct", "saving_highway_pct", "highway_minus_urban_pp",
        "violation_reduction_pct", "red_stop_reduction_pct")
#: how the sweep's CSV files are written (the same bytes on every machine)
CSV = {"index": False, "lineterminator": "\n", "float_format": "%.12g"}
#: Morris grid levels (SALib's default; the step is levels / (2 (levels - 1)) of the range)
MORRIS_LEVELS = 4
DIGITS = 6


@dataclass(frozen=True)
class SweepSpec:
    """Everything that fixes a sweep's design and cohort.

    factors: (name, lo, hi) of the Morris factors; trajectories: Morris r (points = r (k + 1)); sobol_n: Saltelli
    base size N (points = N (top + 2); 0 = no Sobol phase); top: factors carried from Morris to Sobol;
    participants: people per driving style of the reference cohort (first in id order); styles: which styles."""
    factors: tuple[tuple[str, float, float], ...]
    trajectories: int = 6
    sobol_n: int = 8
    top: int = 3
    participants: int = 2
    styles: tuple[str, ...] = STYLES
    scenario: str = DEFAULT_SCENARIO
    seed: int = 0
    reference: Path = field(default=REFERENCE_DIR / "participants.csv", compare=False)

    def names(self) -> list[str]:
        return [f for f, _, _ in self.factors]

    def bounds(self) -> dict[str, tuple[float, float]]:
        return {f: (lo, hi) for f, lo, hi in self.factors}


def default_value(name: str) -> float:
    """The default of a what-if field as a number (NaN for None: the scenario's own value)."""
    v = getattr(WhatIf(), name)
    return np.nan if v is None else float(v)


def parse_factors(texts: list[str] | None) -> tuple[tuple[str, float, float], ...]:
    """(name, lo, hi) per ``name`` or ``name=lo:hi`` (default: every factor with its range from FACTORS, in their
    order). Unknown or repeated name, unreadable range or lo >= hi -> UserError."""
    known = FACTORS
    if not texts:
        return tuple((f.name, float(f.lo), float(f.hi)) for f in known.values())
    out: list[tuple[str, float, float]] = []
    for text in texts:
        name, _, rng = text.partition("=")
        name = name.strip()
        if name not in known:
            raise UserError(f"unknown factor {name!r} (known: {', '.join(known)})")
        if name in [f for f, _, _ in out]:
            raise UserError(f"factor {name} given twice")
        lo, hi = float(known[name].lo), float(known[name].hi)
        if rng:
            try:
                a, b = rng.split(":")
                lo, hi = float(a), float(b)
            except ValueError:
                raise UserError(f"--factors {text}: the range must be lo:hi, two numbers") from None
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise UserError(f"--factors {text}: the range must be finite")
        if lo >= hi:
            raise UserError(f"--factors {text}: lo must be below hi")
        for v in (lo, hi):  # the design reaches both ends of the range
            try:
                WhatIf(**{name: v})
            except ValueError as exc:
                raise UserError(f"--factors {text}: {exc}") from None
        out.append((name, lo, hi))
    return tuple(out)


def check_spec(spec: SweepSpec) -> None:
    """UserError for sizes SALib cannot sample or a cohort that would be empty."""
    if len(spec.factors) < 2:
        raise UserError("a sweep needs at least 2 factors")
    if spec.trajectories < 2:
        raise UserError("--trajectories must be >= 2 (Morris needs two trajectories for a spread)")
    if spec.sobol_n < 0 or (spec.sobol_n and spec.sobol_n & (spec.sobol_n - 1)):
        raise UserError("--sobol-n must be 0 (no Sobol phase) or a power of 2 (Sobol sequence balance)")
    if not 1 <= spec.top <= len(spec.factors):
        raise UserError(f"--top must be between 1 and the number of factors ({len(spec.factors)})")
    if spec.participants < 1:
        raise UserError("--participants must be >= 1")
    bad = [s for s in spec.styles if s not in STYLES]
    if bad or not spec.styles or len(set(spec.styles)) < len(spec.styles):
        raise UserError(f"--styles: choose each at most once from {', '.join(STYLES)}")


def problem(factors: tuple[tuple[str, float, float], ...]) -> dict:
    """The SALib problem of `factors`."""
    return {"num_vars": len(factors), "names": [f for f, _, _ in factors],
            "bounds": [[lo, hi] for _, lo, hi in factors]}


def _frame(x: np.ndarray, names: list[str], phase: str, start: int) -> pd.DataFrame:
    cols = list(FACTORS)
    df = pd.DataFrame({c: np.full(len(x), default_value(c)) for c in cols})
    for j, name in enumerate(names):
        df[name] = np.round(x[:, j], DIGITS) + 0.0  # + 0.0: no -0 in design.csv
    df.insert(0, "phase", phase)
    df.insert(0, "point", np.arange(start, start + len(x)))
    return df


def morris_design(spec: SweepSpec) -> pd.DataFrame:
    """The Morris phase: r (k + 1) points (SALib.sample.morris, seeded), columns point, phase, every factor."""
    from SALib.sample import morris

    x = morris.sample(problem(spec.factors), spec.trajectories, num_levels=MORRIS_LEVELS, seed=spec.seed)
    return _frame(x, spec.names(), "morris", 0)


def sobol_design(spec: SweepSpec, top: list[str], start: int) -> pd.DataFrame:
    """The Sobol phase over the factors `top` (ranges of the spec, the others at their defaults): N (k + 2)
    points (SALib.sample.sobol, Saltelli's scheme without second-order terms, scrambled, seeded), numbered from
    `start`."""
    from SALib.sample import sobol

    b = spec.bounds()
    factors = tuple((f, *b[f]) for f in top)
    x = sobol.sample(problem(factors), spec.sobol_n, calc_second_order=False, seed=spec.seed)
    return _frame(x, list(top), "sobol", start)


def whatif_of(row) -> WhatIf:
    """The :class:`pedas.whatif.WhatIf` of a design row (NaN = the field's default)."""
    return WhatIf(**{f: float(row[f]) for f in FACTORS if f in row and pd.notna(row[f])})


def cohort(spec: SweepSpec) -> pd.DataFrame:
    """The reduced cohort: the first `participants` people of each style in `styles` from the reference
    participants file, in id order (all their attributes)."""
    ref = pd.read_csv(spec.reference, dtype={"participant_id": str}).sort_values("participant_id", kind="stable")
    parts = [ref[ref["style"] == s].head(spec.participants) for s in spec.styles]
    people = pd.concat(parts).sort_values("participant_id", kind="stable").reset_index(drop=True)
    short = [s for s, p in zip(spec.styles, parts) if len(p) < spec.participants]
    if short:
        raise UserError(f"the reference cohort has fewer than {spec.participants} people of style "
                        f"{', '.join(short)}")
    return people

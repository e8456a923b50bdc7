"""Physical units read from text (log mappings, route files) and converted, without pint's start-up for the usual ones.

The units labs write (s, ms, km/h, mph, m/s^2, deg, %, kW, ft …) are read from a small table (:data:`KNOWN`) that
holds, for each spelling, pint's name for it, its dimension and pint's own factor to the SI unit of that dimension
(``tests/study/test_units.py`` checks every entry against pint, bit for bit). Any other spelling is read by pint,
imported and its registry built (about half a second) only then, and converted by pint: the same units are accepted
as before and a value is converted to the same float either way (docs/drive_logs.md, "Units").
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from study.common.errors import UserError

# base dimensions with exponents, sorted: the key that says two units measure the same thing
Dimension = tuple[tuple[str, int], ...]
_TIME: Dimension = (("[time]", 1),)
_LENGTH: Dimension = (("[length]", 1),)
_SPEED: Dimension = (("[length]", 1), ("[time]", -1))
_ACCEL: Dimension = (("[length]", 1), ("[time]", -2))
_FORCE: Dimension = (("[length]", 1), ("[mass]", 1), ("[time]", -2))
_POWER: Dimension = (("[length]", 2), ("[mass]", 1), ("[time]", -3))
_NONE: Dimension = ()

#: the SI unit (pint's name) of each dimension of the table; a value in it has factor 1
SI_NAMES = {_TIME: "second", _LENGTH: "meter", _SPEED: "meter / second", _ACCEL: "meter / second ** 2",
            _FORCE: "newton", _POWER: "watt", _NONE: "dimensionless"}
_DIMENSION_TEXT = {_TIME: "[time]", _LENGTH: "[length]", _SPEED: "[length] / [time]",
                   _ACCEL: "[length] / [time] ** 2", _FORCE: "[mass] * [length] / [time] ** 2",
                   _POWER: "[mass] * [length] ** 2 / [time] ** 3", _NONE: "dimensionless"}

#: spelling -> (pint's name, dimension, pint's factor to the SI unit of the dimension)
KNOWN: dict[str, tuple[str, Dimension, float]] = {
    "s": ("second", _TIME, 1.0), "ms": ("millisecond", _TIME, 0.001), "min": ("minute", _TIME, 60.0),
    "h": ("hour", _TIME, 3600.0),
    "m": ("meter", _LENGTH, 1.0), "km": ("kilometer", _LENGTH, 1000.0), "cm": ("centimeter", _LENGTH, 0.01),
    "mm": ("millimeter", _LENGTH, 0.001), "ft": ("foot", _LENGTH, 0.30479999999999996),
    "mi": ("mile", _LENGTH, 1609.344),
    "m/s": ("meter / second", _SPEED, 1.0), "km/h": ("kilometer / hour", _SPEED, 0.2777777777777778),
    "mph": ("mile_per_hour", _SPEED, 0.44704), "ft/s": ("foot / second", _SPEED, 0.30479999999999996),
    "kn": ("knot", _SPEED, 0.5144444444444445),
    "m/s^2": ("meter / second ** 2", _ACCEL, 1.0), "m/s**2": ("meter / second ** 2", _ACCEL, 1.0),
    "ft/s^2": ("foot / second ** 2", _ACCEL, 0.30479999999999996), "g0": ("standard_gravity", _ACCEL, 9.80665),
    "N": ("newton", _FORCE, 1.0), "kN": ("kilonewton", _FORCE, 1000.0),
    "W": ("watt", _POWER, 1.0), "kW": ("kilowatt", _POWER, 1000.0),
    "rad": ("radian", _NONE, 1.0), "deg": ("degree", _NONE, 0.017453292519943295),
    "degree": ("degree", _NONE, 0.017453292519943295),
    "%": ("percent", _NONE, 0.01), "percent": ("percent", _NONE, 0.01), "‰": ("permille", _NONE, 0.001),
    "permille": ("permille", _NONE, 0.001), "1": ("dimensionless", _NONE, 1.0),
    "dimensionless": ("dimensionless", _NONE, 1.0),
}


@dataclass(frozen=True)
class Unit:
    """A unit read from text. name: pint's name for it ("kilometer / hour"); dimension: its base dimensions with
    exponents (sorted; () for a ratio or an angle); factor: a value in this unit times factor is the value in the SI
    unit of its dimension, when the unit is one of :data:`KNOWN` (None: pint converts it)."""

    name: str
    dimension: Dimension
    factor: float | None = None

    @property
    def dimension_text(self) -> str:
        """The dimension as pint writes it, e.g. "[length] / [time]"."""
        if self.dimension in _DIMENSION_TEXT:
            return _DIMENSION_TEXT[self.dimension]
        return " * ".join(d if e == 1 else f"{d} ** {e}" for d, e in self.dimension)


@lru_cache(maxsize=1)
def units():
    """pint's unit registry (built once, about half a second): only for a unit outside :data:`KNOWN`."""
    import pint

    return pint.UnitRegistry()


@lru_cache(maxsize=256)
def _pint_unit(text: str) -> Unit:
    try:
        u = units().Unit(text)
    except Exception:  # noqa: BLE001 - pint raises several error types for bad unit text
        raise UserError(f"unknown unit {text!r} (e.g. km/h, mph, m/s, ms, s, kW, W, ft, m, %, ‰)") from None
    return Unit(str(u), tuple(sorted(dict(u.dimensionality).items())))


def parse_unit(text: Any) -> Unit:
    """The unit of `text` (from :data:`KNOWN`, else read by pint); unknown or malformed units -> UserError."""
    if not isinstance(text, str) or not text.strip():
        raise UserError("needs a unit (e.g. \"km/h\", \"m\", \"kW\", \"%\"; \"1\" for a unitless number)")
    text = text.strip()
    if text in KNOWN:
        return Unit(*KNOWN[text])
    return _pint_unit(text)


def conversion_factor(src: Unit, dst: Unit) -> float:
    """The factor that takes a value in `src` to `dst` (same dimension; else UserError), pint's own factor: from the
    table when `dst` is the SI unit of the dimension, else from pint."""
    if src.dimension != dst.dimension:
        raise UserError(f"cannot convert {src.name!r} to {dst.name!r} (different dimensions)")
    if src.name == dst.name:
        return 1.0
    if src.factor is not None and dst.factor == 1.0:
        return src.factor
    return float(units().Quantity(1.0, units().Unit(src.name)).to(units().Unit(dst.name)).magnitude)


def convert_values(values: np.ndarray, src: Unit, dst: Unit) -> np.ndarray:
    """`values` (float64) from `src` to `dst`: ``values * factor`` as pint computes it (the same floats)."""
    if src.name == dst.name:
        return values
    if src.factor is not None and dst.factor == 1.0 and src.dimension == dst.dimension:
        return np.asarray(values * src.factor, dtype="float64")
    ur = units()
    return np.asarray(ur.Quantity(values, ur.Unit(src.name)).to(ur.Unit(dst.name)).magnitude, dtype="float64")

"""Physical units: the pint unit registry (built once) and reading a unit from text (log mappings, route files)."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

from study.common.errors import UserError


@lru_cache(maxsize=1)
def units():
    """The pint unit registry (built once: it takes about a second)."""
    import pint

    return pint.UnitRegistry()


def parse_unit(text: Any):
    """The pint unit of `text`; unknown or malformed units -> UserError."""
    if not isinstance(text, str) or not text.strip():
        raise UserError("needs a unit (e.g. \"km/h\", \"m\", \"kW\", \"%\"; \"1\" for a unitless number)")
    try:
        return units().Unit(text.strip())
    except Exception:  # noqa: BLE001 - pint raises several error types for bad unit text
        raise UserError(f"unknown unit {text!r} (e.g. km/h, mph, m/s, ms, s, kW, W, ft, m, %, ‰)") from None

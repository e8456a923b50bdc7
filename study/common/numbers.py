"""A column of a log or frame as float64, with a one-line error naming the first cell that is not a number (shared by
the drive import, the log mapping and the HUD channels)."""
from __future__ import annotations

from typing import Callable

import numpy as np
import pandas as pd

from study.common.errors import UserError


def column_floats(s: pd.Series, where: Callable[[int], str]) -> np.ndarray:
    """`s` as float64 (NaN = empty or blank); a cell that is not a number -> UserError
    ``"<where(i)>: <value> is not a number"`` (`i` its 0-based position in `s`). Numeric and boolean columns convert
    as they are: refusing booleans is the caller's rule."""
    if pd.api.types.is_numeric_dtype(s):
        return s.to_numpy(dtype="float64", na_value=np.nan)
    conv = pd.to_numeric(s, errors="coerce")
    bad = conv.isna() & s.notna() & (s.astype("string").str.strip() != "")
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(f"{where(i)}: {s.iloc[i]!r} is not a number")
    return conv.to_numpy(dtype="float64", na_value=np.nan)

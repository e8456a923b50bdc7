"""Speed traces from CSV files: columns t (s), v (m/s) and optionally grade (rad), one row per sample."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def read_trace(path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(t, v, grade|None) from a trace CSV; FileNotFoundError when missing, ValueError with a one-line reason on
    bad content."""
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

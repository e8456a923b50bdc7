"""Item descriptives (paper Table 3, columns Mean and SD): n, mean and SD (n - 1 denominator) per item."""
from __future__ import annotations

import pandas as pd


def item_descriptives(scored: pd.DataFrame, raw: pd.DataFrame | None = None, constructs: dict | None = None,
                      reverse_items=()) -> pd.DataFrame:
    """One row per item: item, n, mean, sd (+ construct, reversed, mean_raw).

    `scored` holds answers after reverse scoring; `mean`/`sd` describe it (the scale every later table uses).
    `mean_raw` is the mean as ticked, so a reader can match a table printed on the raw scale.
    """
    owner = {i: c for c, items in (constructs or {}).items() for i in items}
    rows = []
    for item in scored.columns:
        col = scored[item].dropna()
        rows.append({
            "item": item,
            "n": int(col.size),
            "mean": float(col.mean()) if col.size else float("nan"),
            "sd": float(col.std(ddof=1)) if col.size > 1 else float("nan"),
            "construct": owner.get(item, ""),
            "reversed": item in set(reverse_items),
            "mean_raw": float(raw[item].dropna().mean()) if raw is not None and col.size else float("nan"),
        })
    return pd.DataFrame(rows, columns=["item", "n", "mean", "sd", "construct", "reversed", "mean_raw"])

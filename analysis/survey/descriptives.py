"""Item descriptives (paper Table 3, columns Mean and SD): n, mean and SD (n - 1 denominator) per item."""
from __future__ import annotations

import pandas as pd


def item_descriptives(scored: pd.DataFrame, raw: pd.DataFrame | None = None, constructs: dict | None = None,
                      reverse_items=()) -> pd.DataFrame:
    """One row per item: item, n, mean, sd (+ construct, reversed, mean_raw).

    `scored` holds answers after reverse scoring; `mean`/`sd` describe it (the scale every later table uses).
    `mean_raw` is the mean as ticked, so a reader can match a table printed on the raw scale.

    Parameters
    ----------
    scored : DataFrame
        Participant x item answers after reverse scoring.
    raw : DataFrame, optional
        The same answers as ticked (for `mean_raw`).
    constructs : dict, optional
        Construct -> items (for the `construct` column).
    reverse_items : sequence of str
        The reverse-scored items (the `reversed` column).

    Returns
    -------
    DataFrame
        item, n, mean, sd, construct, reversed, mean_raw; NaN statistics for an item nobody answered.

    Examples
    --------
    PEoU3 ticked 1, 2, 3 is scored 5, 4, 3: mean 4 on the analysis scale, 2 as ticked, SD 1 on both:

    >>> import pandas as pd
    >>> from analysis.survey.descriptives import item_descriptives
    >>> raw = pd.DataFrame({"PU1": [1.0, 2.0, 3.0], "PEoU3": [1.0, 2.0, 3.0]})
    >>> scored = raw.assign(PEoU3=6 - raw["PEoU3"])
    >>> item_descriptives(scored, raw, {"PU": ["PU1"], "PEoU": ["PEoU3"]}, ["PEoU3"])
        item  n  mean   sd construct  reversed  mean_raw
    0    PU1  3   2.0  1.0        PU     False       2.0
    1  PEoU3  3   4.0  1.0      PEoU      True       2.0
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

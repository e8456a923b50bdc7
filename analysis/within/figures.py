"""Figures of a within-subjects comparison: one line per participant across the conditions, with the condition means
and their 95 % confidence intervals (t on n - 1 df) drawn over them."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd


def plot_variable(data: pd.DataFrame, conditions, out_dir: str | Path, stem: str, title: str = "") -> list[Path]:
    """`<stem>.png`/`.pdf`: the values of one variable (columns participant, condition, value), a grey line per
    participant (points only where a condition is missing), the mean of each condition in black with its 95 % CI."""
    from scipy import stats

    from analysis.render import pyplot, save_figure

    plt = pyplot()
    conditions = list(conditions)
    x = {c: i for i, c in enumerate(conditions)}
    wide = data.pivot(index="participant", columns="condition", values="value").reindex(columns=conditions)
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(conditions), 3.4))
    for _, row in wide.sort_index().iterrows():
        ax.plot(range(len(conditions)), row.to_numpy(dtype=float), color="0.72", lw=0.8, marker="o", ms=2.5, zorder=1)
    means, half = [], []
    for c in conditions:
        v = data.loc[data["condition"] == c, "value"].dropna().to_numpy(dtype=float)
        means.append(v.mean() if len(v) else np.nan)
        half.append(stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else np.nan)
    ax.errorbar([x[c] for c in conditions], means, yerr=half, color="black", lw=2, marker="s", ms=6, capsize=4,
                zorder=2, label="mean (95 % CI)")
    ax.set_xticks(range(len(conditions)), conditions)
    ax.set_xlim(-0.4, len(conditions) - 0.6)
    ax.set_ylabel(title)
    ax.legend(loc="best", fontsize=8, frameon=False)
    ax.spines[["top", "right"]].set_visible(False)
    return save_figure(fig, out_dir, stem)

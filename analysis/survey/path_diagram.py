"""The path diagram of the structural model the study's model file declares (its regressions): one box per construct
composite (or covariate), one arrow per predictor -> dependent variable of each model's last step, labelled with the
standardized coefficient beta and its significance stars; non-significant paths dashed.

Which beta an arrow carries: a path on which a hypothesis is read (``H3*ATT``) shows the beta of that model and step
(the hypotheses table's); any other path the beta of the last step of the first model that has it. A dependent
variable's box gives R^2 of each model's last step that predicts it (with the model's name when there are several).
Boxes stand in layers: predictors that nothing predicts on the left, each dependent variable one layer right of its
furthest predictor.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.survey.regression import CONSTANT, ModelSpec

#: significance stars of the paths, the one convention of the figure (stated in its caption)
STARS = ((0.001, "***"), (0.01, "**"), (0.05, "*"))


def stars(p: float) -> str:
    """'***' p < .001, '**' p < .01, '*' p < .05, else ''.

    >>> from analysis.survey.path_diagram import stars
    >>> stars(0.0004), stars(0.02), stars(0.2)
    ('***', '*', '')
    """
    return next((s for cut, s in STARS if p < cut), "")


def path_edges(regressions: pd.DataFrame, hypotheses: pd.DataFrame, models: list[ModelSpec]) -> pd.DataFrame:
    """One row per arrow: source, target, beta, p, hypothesis ('' when none is read on it), model, step.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.path_diagram import path_edges
    >>> from analysis.survey.regression import ModelSpec
    >>> reg = pd.DataFrame({"model": ["1", "1", "2"], "step": [1, 2, 1], "dv": ["BI"] * 3,
    ...                     "predictor": ["ATT", "ATT", "ATT"], "beta": [0.6, 0.5, 0.7], "p": [0.001, 0.01, 0.001]})
    >>> reg = pd.concat([reg, pd.DataFrame({"model": ["1"], "step": [2], "dv": ["BI"], "predictor": ["PU"],
    ...                                     "beta": [0.2], "p": [0.2]})], ignore_index=True)
    >>> hyp = pd.DataFrame({"hypothesis": ["H5"], "model": ["1"], "step": [2], "path": ["PU -> BI"]})
    >>> models = [ModelSpec("1", "BI", (("ATT",), ("PU",))), ModelSpec("2", "BI", (("ATT",),))]
    >>> path_edges(reg, hyp, models)[["source", "target", "beta", "hypothesis", "model"]].values.tolist()
    [['ATT', 'BI', 0.5, '', '1'], ['PU', 'BI', 0.2, 'H5', '1']]
    """
    reg = regressions[regressions["predictor"] != CONSTANT].copy()
    reg["model"] = reg["model"].astype(str)
    read = {}
    for _, h in hypotheses.iterrows():
        src = str(h["path"]).split("->")[0].strip()
        read[(str(h["model"]), int(h["step"]), src)] = str(h["hypothesis"])
    rows: dict[tuple[str, str], dict] = {}
    for m in models:
        last = len(m.steps)
        for pred in m.predictors(last):
            key = (pred, m.dv)
            # the hypothesis read on this path, in whichever step of this model
            hyp = [(s, h) for (mm, s, src), h in read.items() if mm == m.name and src == pred]
            step = hyp[0][0] if hyp else last
            if key in rows and (rows[key]["hypothesis"] or not hyp):
                continue
            r = reg[(reg["model"] == m.name) & (reg["step"] == step) & (reg["predictor"] == pred)]
            if r.empty:
                continue
            rows[key] = {"source": pred, "target": m.dv, "beta": float(r["beta"].iloc[0]),
                         "p": float(r["p"].iloc[0]), "hypothesis": hyp[0][1] if hyp else "", "model": m.name,
                         "step": int(step)}
    return pd.DataFrame(list(rows.values()), columns=["source", "target", "beta", "p", "hypothesis", "model", "step"])


def _layers(edges: pd.DataFrame) -> dict[str, int]:
    """Node -> layer: 0 for a node that nothing predicts, else 1 + the largest layer of its predictors."""
    nodes = list(dict.fromkeys([*edges["source"], *edges["target"]]))
    preds = {n: set(edges.loc[edges["target"] == n, "source"]) for n in nodes}
    layer: dict[str, int] = {}

    def depth(n: str, seen: tuple = ()) -> int:
        if n in layer:
            return layer[n]
        if n in seen:       # a cycle (non-recursive models only are drawn in layers): break it here
            return 0
        layer[n] = 0 if not preds[n] else 1 + max(depth(p, seen + (n,)) for p in preds[n])
        return layer[n]

    for n in nodes:
        depth(n)
    return layer


def _fmt_beta(b: float) -> str:
    s = f"{b:.2f}"
    return s.replace("0.", ".", 1).replace("-", "−") if abs(b) < 1 else s.replace("-", "−")


def plot_path_diagram(edges: pd.DataFrame, r2: dict[str, str], out_dir: str | Path, labels: dict | None = None,
                      stem: str = "path_diagram") -> list[Path]:
    """Draw `edges` (:func:`path_edges`) with the R^2 text of each dependent variable (`r2`: node -> text) and
    the boxes' `labels` (node -> text, default the node); saved as `stem` (analysis.render.save_figure)."""
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    from analysis.render import bare_figure, save_figure

    labels = labels or {}
    layer = _layers(edges)
    cols: dict[int, list[str]] = {}
    for n, k in layer.items():
        cols.setdefault(k, []).append(n)
    tallest = max(len(v) for v in cols.values())
    dx_layer, dy_node, bw, bh = 2.6, 1.25, 1.15, 0.5
    pos = {}
    for k, nodes in cols.items():
        for i, n in enumerate(nodes):
            pos[n] = (dx_layer * k, dy_node * ((len(nodes) - 1) / 2.0 - i))
    mid_y = 0.0
    arrows, texts = [], []
    for _, e in edges.iterrows():
        (x0, y0), (x1, y1) = pos[e["source"]], pos[e["target"]]
        skip = layer[e["target"]] - layer[e["source"]] - 1
        # a path past a layer arcs above (sources in the upper half) or below the boxes between
        rad = 0.0 if skip <= 0 else (0.22 + 0.08 * (skip - 1)) * (-1.0 if y0 >= mid_y else 1.0)
        p0, p1 = (x0 + bw / 2, y0), (x1 - bw / 2, y1)
        ddx, ddy = p1[0] - p0[0], p1[1] - p0[1]
        # the label at the curve's middle (matplotlib's arc3: control point midpoint + rad (dy, -dx))
        t = 0.5 if (rad or abs(ddy) < 1e-9) else 0.4
        lx, ly = p0[0] + t * ddx + 0.5 * rad * ddy, p0[1] + t * ddy - 0.5 * rad * ddx
        arrows.append((p0, p1, rad, bool(e["p"] < 0.05)))
        texts.append((lx, ly, ("" if not e["hypothesis"] else f"{e['hypothesis']}: ")
                      + f"β = {_fmt_beta(e['beta'])}{stars(e['p'])}"))
    xs = [x for x, _ in pos.values()] + [t[0] for t in texts]
    ys = [y for _, y in pos.values()] + [t[1] for t in texts]
    x_lo, x_hi = min(xs) - bw / 2 - 0.2, max(xs) + bw / 2 + 0.2
    y_lo, y_hi = min(ys) - bh / 2 - 0.45, max(ys) + bh / 2 + 0.25
    fig = bare_figure((max(x_hi - x_lo, 5.0) * 0.95, max(y_hi - y_lo, 2.0) * 0.95))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.axis("off")
    for n, (x, y) in pos.items():
        ax.add_patch(FancyBboxPatch((x - bw / 2, y - bh / 2), bw, bh, boxstyle="square,pad=0", fc="white",
                                    ec="black", lw=1.0, zorder=3))
        ax.text(x, y, labels.get(n, n), ha="center", va="center", fontsize=10, zorder=4)
        if n in r2:
            ax.text(x, y - bh / 2 - 0.06, r2[n], ha="center", va="top", fontsize=8, zorder=4)
    for p0, p1, rad, sig in arrows:
        ax.add_patch(FancyArrowPatch(p0, p1, arrowstyle="-|>", mutation_scale=12, lw=1.2 if sig else 0.9,
                                     ls="-" if sig else (0, (4, 3)), color="black" if sig else "0.4",
                                     connectionstyle=f"arc3,rad={rad}", zorder=2))
    for lx, ly, text in texts:
        ax.text(lx, ly, text, ha="center", va="center", fontsize=8, zorder=5,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none"})
    return save_figure(fig, out_dir, stem)


def r2_texts(regressions: pd.DataFrame, models: list[ModelSpec]) -> dict[str, str]:
    """Dependent variable -> 'R² = .62' of its model's last step, or 'R² = .62 (3), .70 (4)' for several models.

    >>> import pandas as pd
    >>> from analysis.survey.path_diagram import r2_texts
    >>> from analysis.survey.regression import ModelSpec
    >>> reg = pd.DataFrame({"model": ["1", "2"], "step": [1, 1], "dv": ["PU", "BI"], "predictor": ["x", "x"],
    ...                     "r2": [0.16, 0.5]})
    >>> r2_texts(reg, [ModelSpec("1", "PU", (("x",),)), ModelSpec("2", "BI", (("x",),))])
    {'PU': 'R² = .16', 'BI': 'R² = .50'}
    """
    reg = regressions.assign(model=regressions["model"].astype(str))
    per: dict[str, list[tuple[str, float]]] = {}
    for m in models:
        r = reg[(reg["model"] == m.name) & (reg["step"] == len(m.steps))]
        if len(r):
            per.setdefault(m.dv, []).append((m.name, float(r["r2"].iloc[0])))
    out = {}
    for dv, vals in per.items():
        out[dv] = ("R² = " + _fmt_beta(vals[0][1]) if len(vals) == 1 else
                   "R² = " + ", ".join(f"{_fmt_beta(v)} ({name})" for name, v in vals))
    return out

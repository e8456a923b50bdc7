"""What a what-if sweep's points say (docs/sweep.md): which settings move each KPI (Morris elementary effects, Sobol
indices; SALib), the share of points where each reproduction band holds and the region of settings where all four
hold, as tidy frames, tables and figures. Everything is recomputed from points.csv and sweep.json, so the report
re-analyses a committed sweep instead of copying its numbers.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.sweep.design import BANDS, CSV, KPIS, problem

INDEX_COLUMNS = ["kpi", "phase", "factor", "mu_star", "mu_star_conf", "sigma", "S1", "S1_conf", "ST", "ST_conf"]
REGION_COLUMNS = ["item", "name", "value", "n", "lo", "hi", "point", "missed", "distance", "note"]
LABELS = {"saving_overall_pct": "Overall saving (%)", "saving_urban_pct": "Urban saving (%)",
          "saving_highway_pct": "Highway saving (%)", "highway_minus_urban_pp": "Highway - urban (pp)",
          "violation_reduction_pct": "Violation reduction (%)", "red_stop_reduction_pct": "Red-stop reduction (%)"}
RESAMPLES = 100  # bootstrap resamples of the confidence intervals (SALib's default)


def morris_indices(points: pd.DataFrame, factors, seed: int = 0, levels: int = 4) -> pd.DataFrame:
    """Morris mu*, its 95 % bootstrap half-width and sigma of every KPI and factor (SALib.analyze.morris) from the
    Morris points in design order; NaN for a KPI with an undefined value at some point. `factors`: (name, lo, hi)."""
    from SALib.analyze import morris

    pts = points[points["phase"] == "morris"].sort_values("point")
    prob = problem(tuple(factors))
    x = pts[prob["names"]].to_numpy(float)
    rows = []
    for kpi in KPIS:
        y = pts[kpi].to_numpy(float)
        res = morris.analyze(prob, x, y, num_resamples=RESAMPLES, num_levels=levels, seed=seed) \
            if np.isfinite(y).all() else None
        for j, name in enumerate(prob["names"]):
            rows.append({"kpi": kpi, "phase": "morris", "factor": name,
                         **{c: float(res[c][j]) if res is not None else np.nan
                            for c in ("mu_star", "mu_star_conf", "sigma")}})
    return pd.DataFrame(rows).reindex(columns=INDEX_COLUMNS)


def sobol_indices(points: pd.DataFrame, factors, seed: int = 0) -> pd.DataFrame:
    """First-order and total Sobol indices with 95 % bootstrap half-widths of every KPI over the Sobol points
    (SALib.analyze.sobol, Saltelli's estimators without second order); NaN for a KPI undefined at some point or
    constant."""
    from SALib.analyze import sobol

    pts = points[points["phase"] == "sobol"].sort_values("point")
    if pts.empty or not factors:
        return pd.DataFrame(columns=INDEX_COLUMNS)
    prob = problem(tuple(factors))
    rows = []
    for kpi in KPIS:
        y = pts[kpi].to_numpy(float)
        # a KPI that never changes has no variance to split: its indices are undefined, not 0
        # a Generator, not the int: SALib's sobol.analyze leaves the bootstrap unseeded for seed 0 ("if seed:")
        res = sobol.analyze(prob, y, calc_second_order=False, num_resamples=RESAMPLES,
                            seed=np.random.default_rng(seed)) \
            if np.isfinite(y).all() and np.ptp(y) > 0 else None
        for j, name in enumerate(prob["names"]):
            rows.append({"kpi": kpi, "phase": "sobol", "factor": name,
                         **{c: float(res[c][j]) if res is not None else np.nan
                            for c in ("S1", "S1_conf", "ST", "ST_conf")}})
    return pd.DataFrame(rows).reindex(columns=INDEX_COLUMNS)


def top_factors(morris: pd.DataFrame, k: int) -> list[str]:
    """The `k` factors that move some KPI most: per KPI, mu* relative to the largest mu* of that KPI; a factor's
    score is its largest relative mu* over the KPIs (so a factor that drives one band is not averaged away).
    Ties and KPIs without indices keep the factors' order."""
    order = list(dict.fromkeys(morris["factor"]))
    rel = morris.assign(rel=morris["mu_star"] / morris.groupby("kpi")["mu_star"].transform("max"))
    score = rel.groupby("factor", sort=False)["rel"].max().reindex(order).fillna(0.0)
    ranked = sorted(order, key=lambda f: (-score[f], order.index(f)))
    return ranked[:k]


def indices(points: pd.DataFrame, meta: dict) -> pd.DataFrame:
    """Morris then Sobol indices of every KPI (columns INDEX_COLUMNS) as sweep.json describes the design."""
    factors = [(f["name"], f["lo"], f["hi"]) for f in meta["factors"]]
    bounds = {f: (lo, hi) for f, lo, hi in factors}
    m = morris_indices(points, factors, meta["seed"], meta["morris_levels"])
    s = sobol_indices(points, [(f, *bounds[f]) for f in meta["sobol_factors"]], meta["seed"])
    return pd.concat([m, s], ignore_index=True) if len(s) else m


def _band_distance(v: float, lo: float, hi: float) -> float:
    """How far a value lies outside [lo, hi] (0 inside; inf when undefined)."""
    if not np.isfinite(v):
        return np.inf
    return max(lo - v, v - hi, 0.0)


def region(points: pd.DataFrame, meta: dict, closest: int = 3) -> pd.DataFrame:
    """What would have to be true: per band the share of points where it holds (item ``band``), the share where
    all four hold (``all``); over those points each varied factor's range (``factor``: lo, hi); when there are
    none, the `closest` points to all four (``closest``: fewest missed bands, then the smallest summed distance to
    the band edges in percent / pp; infinite when a missed band's value is undefined, e.g. no baseline violation),
    with their settings and the bands they miss in ``note``."""
    edges = meta["bands"]
    n = len(points)
    rows = [{"item": "band", "name": key, "value": float(points[f"holds_{key}"].mean()), "n": n,
             "note": edges[key]["band"]} for key in BANDS]
    allfour = points[points["holds_all"].astype(bool)]
    rows.append({"item": "all", "name": "all four bands", "value": len(allfour) / n if n else np.nan, "n": n})
    varied = [f["name"] for f in meta["factors"]]
    if len(allfour):
        for f in varied:
            rows.append({"item": "factor", "name": f, "n": len(allfour), "lo": float(allfour[f].min()),
                         "hi": float(allfour[f].max())})
    else:
        dist = points.apply(lambda r: sum(_band_distance(float(r[e["kpi"]]), e["lo"],
                                                         np.inf if e["hi"] is None else e["hi"])
                                          for e in edges.values()), axis=1)
        missed = (~points[[f"holds_{k}" for k in BANDS]].astype(bool)).sum(axis=1)
        ranked = points.assign(missed=missed, distance=dist).sort_values(["missed", "distance", "point"],
                                                                           kind="stable")
        for r in ranked.head(closest).itertuples(index=False):
            r = r._asdict()
            settings = ", ".join(f"{f}={r[f]:g}" for f in varied)
            misses = ", ".join(k + ("" if np.isfinite(float(r[edges[k]["kpi"]])) else " (undefined)")
                               for k in BANDS if not bool(r[f"holds_{k}"]))
            rows.append({"item": "closest", "name": f"point {r['point']}", "point": int(r["point"]),
                         "missed": int(r["missed"]), "distance": float(r["distance"]),
                         "note": f"{settings}; misses {misses}"})
    return pd.DataFrame(rows).reindex(columns=REGION_COLUMNS)


# ------------------------------------------------------------------------------------------ tables and figures
def _num(x: float, digits: int = 2) -> str:
    return "–" if pd.isna(x) else f"{x:.{digits}f}"


def _int(x) -> str:
    return "" if pd.isna(x) else str(int(x))


def indices_table(ind: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    """(header, rows): Factor | per KPI "mu* / ST" (ST only for the Sobol factors)."""
    rows = []
    for factor in dict.fromkeys(ind["factor"]):
        cells = [factor]
        for kpi in KPIS:
            m = ind[(ind["kpi"] == kpi) & (ind["factor"] == factor) & (ind["phase"] == "morris")]
            s = ind[(ind["kpi"] == kpi) & (ind["factor"] == factor) & (ind["phase"] == "sobol")]
            cell = _num(m["mu_star"].iloc[0]) if len(m) else "–"
            cells.append(cell + (f" / {_num(s['ST'].iloc[0])}" if len(s) else ""))
        rows.append(cells)
    return ["Factor", *(LABELS[k] for k in KPIS)], rows


def region_lines(reg: pd.DataFrame) -> list[str]:
    """The 'what would have to be true' paragraph as Markdown lines."""
    bands = reg[reg["item"] == "band"]
    allfour = reg[reg["item"] == "all"].iloc[0]
    shares = "; ".join(f"{r.note}: {100 * r.value:.0f} %" for r in bands.itertuples())
    out = [f"Share of the {int(allfour.n)} design points where each band holds: {shares}. "
           f"All four hold at {100 * allfour.value:.0f} % of the points."]
    fac = reg[reg["item"] == "factor"]
    if len(fac):
        out.append("Where all four hold, the settings range over: "
                   + "; ".join(f"{r.name} {r.lo:g} to {r.hi:g}" for r in fac.itertuples()) + ".")
    else:
        close = reg[reg["item"] == "closest"]
        out.append("No design point meets all four bands. The closest (fewest missed bands, then the smallest "
                   "summed distance to the band edges):")
        out += [f"- {r.name}: misses {int(r.missed)} band(s), "
                + (f"{r.distance:.2f} % / pp outside; " if np.isfinite(r.distance) else "")
                + str(r.note) for r in close.itertuples()]
    return out


def plot_indices(ind: pd.DataFrame, out: Path) -> list[Path]:
    """sweep_indices.png/.svg/.pdf: per KPI, Morris mu* (bars) and sigma (dots) of every factor on the bottom axis
    (KPI units), and the Sobol total index ST of the Sobol factors with its 95 % interval on the top axis, fixed to
    [0, 1] (ST is a share of the output variance; an interval reaching past 0 or 1 is cut at the axis, its cut end
    marked by an arrow head). One legend below the panels."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from analysis.render import pyplot, save_figure

    plt = pyplot()
    morris_c, sobol_c = "#4c72b0", "#dd8452"
    factors = list(dict.fromkeys(ind["factor"]))
    fig, axes = plt.subplots(3, 2, figsize=(7.2, 9.4), sharey=True, layout="constrained")
    y = np.arange(len(factors))[::-1]  # the first factor on top
    for ax, kpi in zip(axes.flat, KPIS):
        m = ind[(ind["kpi"] == kpi) & (ind["phase"] == "morris")].set_index("factor").reindex(factors)
        ax.barh(y + 0.2, m["mu_star"], height=0.4, color=morris_c)
        ax.plot(m["sigma"], y + 0.2, "o", color="#222222", ms=3.5)
        ax.set_xlabel(r"Morris $\mu^*$, $\sigma$ (KPI units)", fontsize=8)
        ax.set_xlim(0, 1.08 * float(np.nanmax(np.r_[m["mu_star"], m["sigma"], 1e-12])))
        ax.tick_params(labelsize=8)
        ax.set_yticks(y, [f.replace("_", " ") for f in factors], fontsize=8)
        top = ax
        s = ind[(ind["kpi"] == kpi) & (ind["phase"] == "sobol")].set_index("factor").reindex(factors)
        if s["ST"].notna().any():
            top = ax.twiny()
            st = s["ST"].clip(0.0, 1.0).to_numpy(float)
            conf = s["ST_conf"].fillna(0.0).to_numpy(float)
            lo, hi = s["ST"].to_numpy(float) - conf, s["ST"].to_numpy(float) + conf
            top.barh(y - 0.2, st, height=0.4, color=sobol_c)
            ok = np.isfinite(st)
            top.errorbar(st[ok], y[ok] - 0.2, xerr=[st[ok] - np.clip(lo[ok], 0, 1), np.clip(hi[ok], 0, 1) - st[ok]],
                         fmt="none", ecolor="black", elinewidth=0.9, capsize=2)
            for yy, cut_lo, cut_hi in zip(y[ok] - 0.2, lo[ok] < 0, hi[ok] > 1):
                for cut, x, mk in ((cut_lo, 0.0, "<"), (cut_hi, 1.0, ">")):
                    if cut:
                        top.plot(x, yy, mk, color="black", ms=4, clip_on=False)
            top.set_xlim(0, 1)
            top.set_xlabel("Sobol $S_T$", fontsize=8)
            top.tick_params(labelsize=8)
        # on the axis that owns the top edge, so that the title stands above the Sobol ticks, never on them
        top.set_title(LABELS[kpi], fontsize=9, fontweight="bold")
    handles = [Patch(color=morris_c, label=r"Morris $\mu^*$ (bottom axis)"),
               Line2D([], [], ls="none", marker="o", color="#222222", ms=4, label=r"Morris $\sigma$ (bottom axis)"),
               Patch(color=sobol_c, label="Sobol $S_T$ (top axis)"),
               Line2D([], [], color="black", lw=0.9, label="95 % interval of $S_T$ (cut at 0 and 1: arrow head)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    return save_figure(fig, out / "figures", "sweep_indices")


def write_analysis(out: Path, points: pd.DataFrame, meta: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """indices.csv/.md/.tex, region.csv/.md/.tex and figures/sweep_indices.png/.pdf in `out`, from the points;
    the (indices, region) frames written, for the report's paragraph and bands (computed once)."""
    from analysis.render import latex_table, markdown_table

    out.mkdir(parents=True, exist_ok=True)
    ind, reg = indices(points, meta), region(points, meta)
    # 8 significant digits: SALib's bootstrap half-widths and sigma of the same points, computed in two processes,
    # were seen to differ at the 13th (numpy's vectorised reductions are not bit-stable across array placement)
    ind.to_csv(out / "indices.csv", **{**CSV, "float_format": "%.8g"})
    reg.to_csv(out / "region.csv", **CSV)
    notes = [f"Design: {meta['points']} points ({meta['trajectories']} Morris trajectories over "
             f"{len(meta['factors'])} factors; Sobol N = {meta['sobol_n']} over "
             f"{', '.join(meta['sobol_factors']) or 'no factors'}), {meta['drives']} drives, scenario "
             f"{meta['scenario']}, simulation code {meta['code_version']}.",
             "Cells: Morris mu* (mean absolute elementary effect, in the KPI's unit) / Sobol total index ST."]
    title = "What-if sweep: what moves each KPI"
    header, rows = indices_table(ind)
    (out / "indices.md").write_text(markdown_table(header, rows, title, notes=notes), encoding="utf-8")
    (out / "indices.tex").write_text(latex_table(header, rows, title, notes=notes, label="tab:sweep_indices"),
                                     encoding="utf-8")
    title = "What would have to be true for the paper's bands"
    header = ["Item", "Name", "Value", "n", "lo", "hi", "Missed", "Distance", "Note"]
    rows = [[r.item, r.name, _num(r.value), _int(r.n), _num(r.lo), _num(r.hi), _int(r.missed), _num(r.distance),
             "" if pd.isna(r.note) else str(r.note)] for r in reg.itertuples()]
    (out / "region.md").write_text(markdown_table(header, rows, title, notes=region_lines(reg), notes_style="plain"),
                                   encoding="utf-8")
    (out / "region.tex").write_text(latex_table(header, rows, title, label="tab:sweep_region"), encoding="utf-8")
    plot_indices(ind, out)
    return ind, reg


# ------------------------------------------------------------------------------------------ in the report
def ranking_lines(ind: pd.DataFrame) -> list[str]:
    """Per KPI, the factors by Morris mu* (largest first) and, where the Sobol phase ran, its total indices."""
    out = []
    for kpi in KPIS:
        m = ind[(ind["kpi"] == kpi) & (ind["phase"] == "morris")].sort_values("mu_star", ascending=False,
                                                                              kind="stable")
        if m["mu_star"].isna().all():
            out.append(f"- {LABELS[kpi]}: undefined at some design point (no baseline events), no indices")
            continue
        text = ", ".join(f"{r.factor} {r.mu_star:.2f}" for r in m.itertuples())
        s = ind[(ind["kpi"] == kpi) & (ind["phase"] == "sobol")].sort_values("ST", ascending=False, kind="stable")
        if s["ST"].notna().any():
            text += "; Sobol ST " + ", ".join(f"{r.factor} {r.ST:.2f} ± {r.ST_conf:.2f}" for r in s.itertuples())
        out.append(f"- {LABELS[kpi]}: Morris mu* {text}")
    return out


def _failures_line(failures: list[dict]) -> str:
    """How many drives of the sweep failed (each person with a failed drive is left out of that point)."""
    if not failures:
        return "Every drive of the sweep reached the end of the route without a safety or liveness violation."
    kinds = pd.Series([f["kind"] for f in failures]).value_counts()
    return (f"{len(failures)} drive(s) of the sweep failed ({', '.join(f'{k}: {n}' for k, n in kinds.items())}); "
            "their persons are left out of those points' KPIs (points.csv n_failed, sweep.json failures).")


def summary_lines(ind: pd.DataFrame, reg: pd.DataFrame, meta: dict, current_code: str) -> list[str]:
    """The sweep's paragraph of the report (Markdown lines) from its :func:`indices` and :func:`region`: design,
    code version (and whether it is the current one), what moves each KPI, what would have to be true."""
    same = meta["code_version"] == current_code
    lines = [f"The what-if sweep (docs/sweep.md) drove {len(meta['cohort'])} reference participants "
             f"({meta['participants_per_style']} per style: {', '.join(meta['styles'])}) in the {meta['scenario']} "
             f"scenario at {meta['points']} design points ({meta['drives']} drives): Morris screening with "
             f"{meta['trajectories']} trajectories over {', '.join(f['name'] for f in meta['factors'])}, then "
             + (f"Sobol with N = {meta['sobol_n']} over {', '.join(meta['sobol_factors'])}."
                if meta["sobol_factors"] else "no Sobol phase."),
             "",
             _failures_line(meta.get("failures", [])),
             "",
             f"Simulation code of the sweep: {meta['code_version']}; "
             + ("the same as the current code." if same else
                f"**the current code is {current_code}: the sweep was run with other simulation code, so its "
                f"numbers may be stale (rerun `make sweep`).**"),
             "", "What moves each KPI (mean absolute elementary effect in the KPI's unit over the factor's range):",
             "", *ranking_lines(ind), "", "What would have to be true for the paper's four bands:", "",
             *region_lines(reg)]
    return lines


def bands_beside(bands: pd.DataFrame, reg: pd.DataFrame, labels: dict[str, str]) -> tuple[pd.DataFrame, list[str],
                                                                                       list[list[str]]]:
    """The bands of each scenario (``bands``: band, scenario, paper_value, our_value, holds) beside the share of
    sweep points where each holds: (tidy frame band, source, value, holds; header; rows)."""
    shares = reg[reg["item"] == "band"].set_index("note")["value"]
    tidy = pd.concat([bands[["band", "scenario", "our_value", "holds"]].rename(
                          columns={"scenario": "source", "our_value": "value"}),
                      pd.DataFrame({"band": shares.index, "source": "sweep: share of points",
                                    "value": shares.to_numpy(), "holds": np.nan})], ignore_index=True)
    names = list(dict.fromkeys(bands["scenario"]))
    rows = []
    for band in dict.fromkeys(bands["band"]):
        by = bands[bands["band"] == band].set_index("scenario")
        cells = [f"{_num(by.loc[n, 'our_value'])} ({'holds' if bool(by.loc[n, 'holds']) else 'misses'})"
                 if n in by.index else "–" for n in names]
        share = shares.get(band, np.nan)
        paper = by["paper_value"].iloc[0] if "paper_value" in by else np.nan
        rows.append([band, _num(paper), *cells, "–" if pd.isna(share) else f"{100 * share:.0f} %"])
    return tidy, ["Band", "Paper", *(labels.get(n, n) for n in names), "Sweep: points where it holds"], rows

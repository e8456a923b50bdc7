"""The paper's objective-evaluation figures (Sec. 5.1) from a store, PNG + SVG + PDF, matplotlib (Agg backend). A figure
applies to a study that declares a comparison (control vs treatment drive, study.folder.kpi_spec) with the columns
it shows (Figs. 11-12 also need a participant); a figure that does not apply is not mentioned, one that applies but
cannot be drawn from the data is listed with the reason.

* Fig. 9a  box plot of energy savings: urban, highway, overall trip
* Fig. 9b-d savings by self-reported driving style: urban, highway, overall
* Fig. 10  traffic lights crossed in green (without a red stop) without vs with pEDAS, per participant
* Fig. 11  one participant ([comparison] participant): velocity with the limit v_max, acceleration and cumulative battery
           energy over distance, baseline vs pEDAS drive
* Fig. 12  switching between the reference-tracking (rt) and car-following (cf) controllers in one pEDAS drive:
           v, v_advice, leader gap, controller mode shaded
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.render import pyplot, save_figure
from pedas.constants import SENSOR_RANGE

BASE_COLOR, PEDAS_COLOR = "#7f7f7f", "#2ca02c"
MODE_COLORS = {"rt": "#cfe2f3", "cf": "#fde2c4", "none": "#eeeeee"}
MPS_TO_KMH = 3.6  # km/h per m/s, for the axes


def _points(ax, groups, positions):
    """Each participant as a dot over its box, spread evenly (deterministic, no random jitter)."""
    for pos, vals in zip(positions, groups):
        vals = np.asarray(vals, float)
        if len(vals):
            off = np.linspace(-0.12, 0.12, len(vals)) if len(vals) > 1 else np.zeros(1)
            ax.plot(pos + off, vals, "o", ms=3.5, color="black", alpha=0.6, zorder=3)


MEDIAN_COLOR = "#ff7f0e"  # matplotlib's default median line, named in the legend


def _box_legend(ax) -> None:
    """What the marks of :func:`_box` mean, below the axes: a box plot is read differently by different readers."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(facecolor="white", edgecolor="black", label="interquartile range (box)"),
               Line2D([], [], color=MEDIAN_COLOR, lw=1.5, label="median"),
               Line2D([], [], ls="none", marker="^", mfc="white", mec="black", label="mean"),
               Line2D([], [], color="black", lw=1.0, label="whiskers: 1.5 IQR"),
               Line2D([], [], ls="none", marker="o", ms=3.5, color="black", alpha=0.6, label="one participant")]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize=8, frameon=False)


def _box(ax, groups, labels, title):
    data = [np.asarray(g, float)[np.isfinite(np.asarray(g, float))] for g in groups]
    pos = np.arange(1, len(data) + 1)
    nonempty = [i for i, d in enumerate(data) if len(d)]
    if nonempty:
        # every participant is drawn as a dot below, so the box plot's own outlier markers would draw some twice
        ax.boxplot([data[i] for i in nonempty], positions=pos[nonempty], widths=0.5, showmeans=True, showfliers=False,
                   medianprops={"color": MEDIAN_COLOR, "lw": 1.5},
                   meanprops={"marker": "^", "markerfacecolor": "white", "markeredgecolor": "black"})
    _points(ax, data, pos)
    ax.set_xticks(pos, [f"{lab}\n(n={len(d)})" for lab, d in zip(labels, data)])
    ax.tick_params(labelsize=9)
    ax.set_xlim(0.4, len(data) + 0.6)
    ax.axhline(0.0, color="grey", lw=0.8, ls="--")
    ax.set_ylabel("Energy savings (%)", fontsize=10)
    ax.set_title(title, fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    _box_legend(ax)


def fig9a(per: pd.DataFrame, out: Path) -> list[Path]:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4))
    _box(ax, [per["saving_urban_pct"], per["saving_highway_pct"], per["saving_overall_pct"]],
         ["Urban", "Highway", "Overall"], "Energy savings in the driven route")
    return save_figure(fig, out, "fig9a_savings")


def fig9_style(per: pd.DataFrame, out: Path, segment: str, letter: str, styles) -> list[Path]:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4))
    col = f"saving_{segment}_pct"
    _box(ax, [per.loc[per["style"] == s, col] for s in styles], [s.capitalize() for s in styles],
         f"Energy savings according to driving styles: {segment} trip")
    return save_figure(fig, out, f"fig9{letter}_savings_{segment}_by_style")


def fig10(per: pd.DataFrame, out: Path) -> list[Path]:
    plt = pyplot()
    n = len(per)
    # a print column's width at most, so that the tick labels keep their size when the figure is placed
    fig, ax = plt.subplots(figsize=(min(7.2, max(4.5, 0.17 * n + 1.4)), 3.6))
    x = np.arange(n)
    w = 0.4
    # a light counts when crossed in green without a red stop on its approach (analysis.drives.kpis: tl_green_passes)
    ax.bar(x - w / 2, per["tl_green_passes_baseline"], w, label="without pEDAS", color=BASE_COLOR)
    ax.bar(x + w / 2, per["tl_green_passes_pedas"], w, label="with pEDAS", color=PEDAS_COLOR)
    if "tl_crossed_pedas" in per and n:
        ax.plot(x, per["tl_crossed_pedas"], "_", color="black", ms=12, label="lights on the route")
    ax.set_xticks(x, per["participant_id"], rotation=90, fontsize=8)
    ax.tick_params(axis="y", labelsize=9)
    ax.set_xlim(-0.6, n - 0.4)
    ax.set_xlabel("Participant", fontsize=9)
    ax.set_ylabel("Traffic lights crossed in green\n(without stopping at red)", fontsize=9)
    ax.set_title("Comparison of traffic light signals crossed in green phase", fontsize=10)
    ax.yaxis.get_major_locator().set_params(integer=True)
    top = np.nanmax(np.r_[per["tl_green_passes_baseline"], per["tl_green_passes_pedas"],
                          per.get("tl_crossed_pedas", 0), 1])
    ax.set_ylim(0, top * 1.3 + 0.5)
    ax.legend(fontsize=8, ncol=3, loc="upper center", frameon=False)
    ax.grid(axis="y", alpha=0.3)
    return save_figure(fig, out, "fig10_tl_green")


def _cumulative_wh(d: pd.DataFrame) -> np.ndarray:
    p = d["p_batt"].astype(float).to_numpy()
    if np.isnan(p).any():
        from pedas.power import fill_drive_columns
        filled = fill_drive_columns(d[["t", "v", "grade"]])
        p = np.where(np.isnan(p), filled["p_batt"].to_numpy(float), p)
    t = d["t"].to_numpy(float)
    steps = np.diff(t) * (p[1:] + p[:-1]) / 2.0 / 3600.0
    return np.concatenate([[0.0], np.cumsum(steps)])


def fig11(st, participant: str, per: pd.DataFrame, out: Path, control: str = "baseline",
          treatment: str = "pedas") -> list[Path]:
    from study.logs.stored import drive_samples

    plt = pyplot()
    base = drive_samples(st, participant, control)
    ped = drive_samples(st, participant, treatment)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for d, label, color in ((base, "without pEDAS", BASE_COLOR), (ped, "with pEDAS", PEDAS_COLOR)):
        s_km = d["s"].to_numpy(float) / 1000.0
        axes[0].plot(s_km, d["v"] * MPS_TO_KMH, color=color, lw=1.0, label=label)
        a = d["a"].astype(float)
        if a.isna().any():
            from analysis.drives.kpis import fill_acceleration
            a = a.fillna(pd.Series(fill_acceleration(d["t"], d["v"]), index=d.index))
        axes[1].plot(s_km, a, color=color, lw=0.8, label=label)
        axes[2].plot(s_km, _cumulative_wh(d), color=color, lw=1.2, label=label)
    axes[0].plot(base["s"] / 1000.0, base["speed_limit"] * MPS_TO_KMH, color="red", lw=1.0, ls="--", label="$v_{max}$")
    axes[0].set_ylabel("Velocity (km/h)")
    axes[1].set_ylabel("Acceleration (m/s²)")
    axes[2].set_ylabel("Battery energy (Wh)")
    axes[2].set_xlabel("Distance (km)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    row = per[per["participant_id"] == participant]
    sub = ""
    if len(row):
        r = row.iloc[0]
        sub = (f" — savings overall {r['saving_overall_pct']:.1f} %, urban {r['saving_urban_pct']:.1f} %, "
               f"highway {r['saving_highway_pct']:.1f} %")
    fig.suptitle(f"Driving behaviour of {participant} before and after pEDAS{sub}", fontsize=10)
    return save_figure(fig, out, "fig11_driving_behaviour")


def find_switch(st, participant: str | None = None, treatment: str = "pedas") -> tuple[str, float] | None:
    """(participant, t of the first rt -> cf switch) in a drive of the ``treatment`` condition (pEDAS): the given
    participant's drive first, else the first such drive (by participant id) that has one. None when none switches."""
    sql = """
        SELECT d.participant_id, min(s.t) AS t_switch
        FROM (SELECT drive_id, t, controller, lag(controller) OVER (PARTITION BY drive_id ORDER BY idx) AS prev
              FROM drive_samples) s
        JOIN drives d USING (drive_id)
        WHERE d.condition = $treatment AND s.prev = 'rt' AND s.controller = 'cf'
        GROUP BY d.participant_id ORDER BY d.participant_id"""
    hits = st.con.execute(sql, {"treatment": treatment}).df()
    if hits.empty:
        return None
    if participant is not None and participant in set(hits["participant_id"]):
        r = hits[hits["participant_id"] == participant].iloc[0]
    else:
        r = hits.iloc[0]
    return str(r["participant_id"]), float(r["t_switch"])


def fig12(st, participant: str, out: Path, before_s: float = 60.0, after_s: float = 60.0,
          treatment: str = "pedas") -> list[Path] | str:
    """Returns the paths, or the reason the figure could not be drawn."""
    from study.logs.stored import drive_samples

    hit = find_switch(st, participant, treatment)
    if hit is None:
        return "no pEDAS drive switches from the reference-tracking to the car-following controller"
    who, t_sw = hit
    d = drive_samples(st, who, treatment)
    w = d[(d["t"] >= t_sw - before_s) & (d["t"] <= t_sw + after_s)].reset_index(drop=True)
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    s = w["s"].to_numpy(float)
    # shade contiguous runs of one controller mode
    mode = w["controller"].fillna("none").to_numpy()
    starts = np.flatnonzero(np.r_[True, mode[1:] != mode[:-1]])
    ends = np.r_[starts[1:], len(mode)]
    seen = set()
    for a, b in zip(starts, ends):
        m = mode[a]
        for ax in (ax1, ax2):
            ax.axvspan(s[a], s[min(b, len(s) - 1)], color=MODE_COLORS.get(m, "#eeeeee"), lw=0,
                       label=None if m in seen or ax is ax2 else {"rt": "reference-tracking MPC",
                                                                   "cf": "car-following MPC"}.get(m, m))
        seen.add(m)
    ax1.plot(s, w["v"] * MPS_TO_KMH, color="black", lw=1.2, label="$v_h$ (driver)")
    ax1.plot(s, w["v_advice"] * MPS_TO_KMH, color=PEDAS_COLOR, lw=1.2, ls="--", label="$v_{h,opt}$ (pEDAS advice)")
    ax1.plot(s, w["speed_limit"] * MPS_TO_KMH, color="red", lw=0.8, ls=":", label="$v_{max}$")
    ax1.set_ylabel("Velocity (km/h)")
    ax1.legend(fontsize=8, loc="lower left")
    ax2.plot(s, w["leader_gap"], color="tab:blue", lw=1.2, label="gap to preceding vehicle $d_{rel}$")
    ax2.axhline(SENSOR_RANGE, color="grey", ls="--", lw=0.8, label=f"sensor range {SENSOR_RANGE:g} m")
    ax2.set_ylabel("Leader gap (m)")
    ax2.set_xlabel("Distance along the route (m)")
    ax2.legend(fontsize=8, loc="upper right")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    note = "" if who == participant else f" (no switch in {participant}'s drive)"
    fig.suptitle(f"Switching between reference-tracking and car-following controllers, {who}{note}", fontsize=10)
    return save_figure(fig, out, "fig12_controller_switching")


def write_figures(st, result, out_dir: str | Path, participant: str | None = None) -> dict[str, list[Path] | str]:
    """The figures that apply to the study into ``out_dir``; figure name -> paths, or the reason it could not be
    drawn. Figures whose data the study does not declare are absent; Figs. 11-12 need ``participant``."""
    out = Path(out_dir)
    comparison = result.spec.comparison if result.spec is not None else None
    if comparison is None:
        return {}
    per = result.per_participant
    savings = [f"saving_{seg}_pct" for seg in ("urban", "highway", "overall")]
    declared = {name for name, _, _ in comparison.reductions} | ({"style"} if "style" in result.levels else set())
    declared |= {comparison.column(template, cond) for template, _, _ in comparison.columns
                 for cond in (comparison.control, comparison.treatment)}
    applies = {"fig9a": savings, "fig9b": [*savings, "style"], "fig9c": [*savings, "style"],
               "fig9d": [*savings, "style"], "fig10": ["tl_green_passes_baseline", "tl_green_passes_pedas"]}
    names = [k for k, cols in applies.items() if set(cols) <= declared]
    if participant is not None:
        names += (["fig11"] if set(savings) <= declared else []) + ["fig12"]
    if not names:
        return {}
    if per.empty:
        reason = (f"no included participant has both a {comparison.control} and a {comparison.treatment} drive")
        return {k: reason for k in names}
    out.mkdir(parents=True, exist_ok=True)
    made: dict[str, list[Path] | str] = {}
    if "fig9a" in names:
        made["fig9a"] = fig9a(per, out)
    for seg, letter in (("urban", "b"), ("highway", "c"), ("overall", "d")):
        if f"fig9{letter}" in names:
            made[f"fig9{letter}"] = fig9_style(per, out, seg, letter, result.levels.get("style", []))
    if "fig10" in names:
        made["fig10"] = fig10(per, out)
    if "fig11" in names:
        made["fig11"] = (fig11(st, participant, per, out, comparison.control, comparison.treatment)
                         if participant in set(per["participant_id"]) else
                         f"{participant} has no {comparison.control}+{comparison.treatment} pair among the included "
                         f"participants")
    if "fig12" in names:
        made["fig12"] = fig12(st, participant, out, treatment=comparison.treatment)
    return made

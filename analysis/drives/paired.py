"""Paired comparison of each KPI of a declared comparison (``[comparison]`` of the study's kpis.toml; the paper's:
baseline vs pEDAS drive per participant), the statistics a reviewer asks for beside the % savings:

* ``paired``: per KPI column of ``[comparison.columns]`` the means and SDs of both conditions, the mean difference
  control - treatment (positive: the treatment lowered the KPI) with its 95 % t-interval, the paired t-test, d_z and
  the Wilcoxon signed-rank test (:func:`analysis.survey.paired.paired_comparison`);
* ``paired_by_group``: per KPI and declared grouping (``group_by``, e.g. the driving style) the mixed ANOVA
  condition x group (:func:`analysis.survey.paired.mixed_anova`);
* ``figures/paired_<kpi>``: each participant's two values joined by a line (coloured by the first grouping), the
  condition means with their 95 % t-intervals; ``figures/paired_kpis`` every such plot as a panel of one figure
  (the main text's).

A KPI whose difference is the same for every participant (e.g. 0 for the number of traffic lights crossed on a
fixed route) has no test; the table's note names it.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from analysis.render import save_figure, write_table
from analysis.survey.paired import mixed_anova, paired_comparison

#: built-in KPI -> (words, unit) for headers and axes
KPI_WORDS = {"energy_wh": ("Battery energy", "Wh"), "distance_m": ("Distance", "m"), "trip_time_s": ("Trip time", "s"),
             "mean_speed_mps": ("Mean speed", "m/s"), "wh_per_km": ("Energy per km", "Wh/km"),
             "violation_distance_m": ("Distance above the limit", "m"),
             "violation_share": ("Share of distance above the limit", ""),
             "violation_events": ("Speeding episodes", "count"), "tl_crossed": ("Traffic lights crossed", "count"),
             "tl_crossed_green": ("Lights crossed at green", "count"),
             "tl_crossed_yellow": ("Lights crossed at yellow", "count"),
             "tl_crossed_red": ("Lights crossed at red", "count"),
             "tl_green_passes": ("Green passes without a stop", "count"), "red_stops": ("Stops at red", "count"),
             "stops": ("Stops", "count"), "rms_jerk": ("RMS jerk", "m/s³"),
             "mean_abs_a": ("Mean absolute acceleration", "m/s²")}


def kpi_words(kpi: str, spec=None) -> str:
    """A KPI in words for a sentence, without its unit: a study KPI's declared label (its name without one), a
    built-in's words from :data:`KPI_WORDS` (lower case).

    >>> from analysis.drives.paired import kpi_words
    >>> kpi_words("trip_time_s"), kpi_words("my_kpi")
    ('trip time', 'my kpi')
    """
    declared = {k.name: k for k in spec.user_kpis} if spec is not None else {}
    if kpi in declared:
        return declared[kpi].label or kpi
    words = KPI_WORDS.get(kpi, (kpi.replace("_", " "), ""))[0]
    return words[:1].lower() + words[1:]


def kpi_label(kpi: str, segment: str, headings: dict | None = None) -> str:
    """'Battery energy, urban (Wh)': the KPI in words with its segment (none for overall) and unit.

    >>> from analysis.drives.paired import kpi_label
    >>> kpi_label("energy_wh", "urban"), kpi_label("red_stops", "overall")
    ('Battery energy, urban (Wh)', 'Stops at red (count)')
    """
    if headings and kpi in headings:
        words, unit = headings[kpi], ""
    else:
        words, unit = KPI_WORDS.get(kpi, (kpi.replace("_", " "), ""))
    seg = "" if segment in ("", "overall") else f", {segment}"
    return f"{words}{seg}" + (f" ({unit})" if unit else "")


def kpi_stem(template: str) -> str:
    """The figure stem of a comparison column: ``paired_`` + the template without its condition placeholder.

    >>> from analysis.drives.paired import kpi_stem
    >>> kpi_stem("energy_overall_{condition}_wh"), kpi_stem("red_stops")
    ('paired_energy_overall_wh', 'paired_red_stops')
    """
    return "paired_" + re.sub(r"_+", "_", template.replace("{condition}", "")).strip("_")


def _pairs(result) -> list[tuple[str, str, str, str]]:
    """(label, control column, treatment column, stem) per declared comparison column present in the table."""
    comp = result.spec.comparison
    headings = result.spec.headings
    out = []
    for template, kpi, seg in comp.columns:
        a, b = comp.column(template, comp.control), comp.column(template, comp.treatment)
        if a in result.per_participant and b in result.per_participant:
            out.append((kpi_label(kpi, seg, headings), a, b, kpi_stem(template)))
    return out


def paired_tables(result) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(paired, by group, KPIs left out) of an :class:`analysis.drives.savings.ObjectiveResult` with a comparison;
    tidy frames whose headers are words (see the module docstring)."""
    comp = result.spec.comparison
    pp = result.per_participant
    ctrl, treat = comp.control, comp.treatment
    rows, group_rows, constant = [], [], []
    groups = [g for g in result.levels if g in pp and pp[g].nunique() > 1]
    for label, a, b, _ in _pairs(result):
        x, y = pp[a].to_numpy(float), pp[b].to_numpy(float)
        r = paired_comparison(x, y)
        if not r["n"] or not (r["sd_diff"] > 0):
            constant.append(label)
            continue
        rows.append({"KPI": label, "n": r["n"], f"M {ctrl}": r["mean_a"], f"SD {ctrl}": r["sd_a"],
                     f"M {treat}": r["mean_b"], f"SD {treat}": r["sd_b"], "M_diff": r["mean_diff"],
                     "95 % CI LL": r["ci_low"], "95 % CI UL": r["ci_high"], "t": r["t"], "df": r["df"],
                     "p (t)": r["p_t"], "d_z": r["dz"], "W": r["v"], "p (W)": r["p_wilcoxon"],
                     "Wilcoxon": ("exact" if r["wilcoxon_method"] == "exact" else
                                  f"normal, {r['zeros']} zero" + ("s" if r["zeros"] != 1 else "")
                                  + (", ties" if r["ties"] else ""))})
        for g in groups:
            long = pd.DataFrame({"participant": np.repeat(pp["participant_id"].to_numpy(), 2),
                                 "group": np.repeat(pp[g].to_numpy(), 2),
                                 "condition": [ctrl, treat] * len(pp),
                                 "value": np.column_stack([x, y]).ravel()})
            try:
                t = mixed_anova(long)
            except (ValueError, ZeroDivisionError, np.linalg.LinAlgError):
                continue   # a grouping the ANOVA cannot use (one level among complete pairs, no error variance)
            for _, e in t.iterrows():
                source = e["source"].replace("group", g).replace("condition", "Condition")
                group_rows.append({"KPI": label, "Effect": source[0].upper() + source[1:], "F": e["f"],
                                   "df1": e["df1"], "df2": e["df2"], "p": e["p"], "η²p": e["np2"]})
    return pd.DataFrame(rows), pd.DataFrame(group_rows), constant


def _draw_pair(ax, x, y, groups, colours: dict, control: str, treatment: str, label: str, size: float = 9) -> None:
    """One paired plot on `ax`: each participant's two values joined by a line (coloured by group), the condition
    means with their 95 % t-intervals."""
    ok = ~(np.isnan(x) | np.isnan(y))
    for i in np.flatnonzero(ok):
        c = colours.get(groups[i], "0.5") if groups is not None else "0.5"
        ax.plot([0, 1], [x[i], y[i]], "-o", color=c, alpha=0.45, lw=0.8, ms=3)
    for j, v in enumerate((x[ok], y[ok])):
        m = v.mean()
        half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else 0.0
        ax.errorbar([j + (-0.08 if j == 0 else 0.08)], [m], yerr=[[half], [half]], fmt="s", color="black",
                    ms=5, capsize=4, lw=1.4, zorder=5)
    ax.set_xticks([0, 1], [control, treatment])
    ax.set_xlim(-0.35, 1.35)
    ax.set_ylabel(label, fontsize=size)
    ax.tick_params(labelsize=size)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def plot_paired(result, out_dir: str | Path) -> list[Path]:
    """One figure ``paired_<kpi>`` per compared KPI that varies, and ``paired_kpis`` with all of them as panels
    (module docstring); returns the paths written."""
    import textwrap

    from matplotlib.lines import Line2D

    from analysis.render import bare_figure

    comp = result.spec.comparison
    pp = result.per_participant
    group = next((g for g in result.levels if g in pp), None)
    levels = [v for v in result.levels.get(group, []) if (pp[group] == v).any()] if group else []
    colours = {v: c for v, c in zip(levels, ["#1b6ca8", "#d1495b", "#2e8b57", "#8e6c8a", "#edae49", "#555555"])}
    groups = pp[group].to_numpy() if group else None
    handles = [Line2D([], [], color=c, marker="o", ms=3, lw=0.8, label=str(v)) for v, c in colours.items()]
    handles.append(Line2D([], [], color="black", marker="s", ms=5, lw=1.4, label="M ± 95 % CI"))
    shown = []
    for label, a, b, stem in _pairs(result):
        x, y = pp[a].to_numpy(float), pp[b].to_numpy(float)
        ok = ~(np.isnan(x) | np.isnan(y))
        if ok.any() and not np.all(x[ok] == y[ok]):
            shown.append((label, x, y, stem))
    paths = []
    for label, x, y, stem in shown:
        fig = bare_figure((3.6, 3.4))
        ax = fig.add_subplot(1, 1, 1)
        _draw_pair(ax, x, y, groups, colours, comp.control, comp.treatment, label)
        ax.legend(handles=handles, fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        paths += save_figure(fig, out_dir, stem)
    if shown:
        # every compared KPI in one figure for the main text: panels of a page's width, the legend once below
        cols = min(4, len(shown))
        rows = -(-len(shown) // cols)
        fig = bare_figure((1.75 * cols + 0.4, 1.9 * rows + 0.5))
        for k, (label, x, y, _) in enumerate(shown):
            ax = fig.add_subplot(rows, cols, k + 1)
            _draw_pair(ax, x, y, groups, colours, comp.control, comp.treatment, "", size=7)
            ax.set_title("\n".join(textwrap.wrap(label, 24)), fontsize=7)
        fig.legend(handles=handles, fontsize=7, frameon=False, loc="lower center", ncol=len(handles))
        fig.tight_layout(rect=(0, 0.5 / (1.9 * rows + 0.5), 1, 1), h_pad=0.8, w_pad=0.6)
        paths += save_figure(fig, out_dir, "paired_kpis")
    return paths


def write_paired(result, out: str | Path) -> list[Path]:
    """Write ``paired`` and ``paired_by_group`` (csv, md, tex; analysis.render.write_table) into `out` and the
    figures into `out`/figures, for a result with a comparison (else nothing). Returns the paths written."""
    comp = result.spec.comparison
    if comp is None or result.per_participant.empty:
        return []
    out = Path(out)
    paired, by_group, constant = paired_tables(result)
    notes = [f"M_diff = {comp.control} − {comp.treatment} per participant (positive: lower with {comp.treatment}); "
             "95 % CI of the mean difference and the paired t-test on n − 1 df; d_z = M_diff / SD of the "
             "differences. W: Wilcoxon signed-rank statistic (sum of the ranks of the positive differences, R's V); "
             "exact without ties or zero differences, else the normal approximation with continuity and tie "
             "correction, zero differences dropped."]
    if constant:
        notes.append("Not tested (the difference between the drives is the same for every participant, so the tests "
                     f"are undefined): {', '.join(constant)}.")
    paths = write_table(paired, out, "paired", f"Paired comparison of the KPIs, {comp.control} vs {comp.treatment}",
                        notes)
    if len(by_group):
        groups = " and ".join(dict.fromkeys(g for g in result.levels if g in result.per_participant))
        paths += write_table(by_group, out, "paired_by_group",
                             f"Mixed ANOVA of the KPIs: condition ({comp.control}, {comp.treatment}) × {groups}",
                             ["Condition within participants, group between; F on (df1, df2), partial η². With two "
                              "conditions the interaction tests whether the mean difference differs between groups."])
    return paths + plot_paired(result, out / "figures")

"""Per-participant effects of pEDAS (baseline drive vs pEDAS drive) and their summary by driving style.

For every participant included in the objective analysis (``study.exclusions.included_participants(st,
"objective")``) who has both drives:

* ``saving_<segment>_pct`` = 100 (E_baseline - E_pEDAS) / E_baseline of the battery energy per segment (urban,
  highway) and for the whole trip (Sec. 5.1.1). Positive = pEDAS saved energy.
* ``violation_reduction_pct`` = 100 (V_b - V_p) / V_b with V the share of distance driven above the limit plus
  tolerance (Sec. 5.1.2; see analysis.kpis).
* ``red_stop_reduction_pct`` = 100 (R_b - R_p) / R_b with R the number of red stops (Sec. 5.1.3).
* ``jerk_reduction_pct`` likewise for the RMS jerk (Sec. 5.1.4 reports it for participant 6).

A reduction against a baseline of 0 (no violation / no red stop without pEDAS) is undefined: NaN, left out of the
means and medians, and the summary's ``n`` says how many participants carry the statistic. The pooled red-stop
reduction 100 (sum R_b - sum R_p) / sum R_b is reported beside it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.kpis import store_kpis
from pedas.vocabulary import STYLES


#: The per-participant statistics summarised by style, in the order the paper reports them.
SUMMARY_METRICS = ("saving_overall_pct", "saving_urban_pct", "saving_highway_pct", "violation_reduction_pct",
                   "red_stop_reduction_pct", "jerk_reduction_pct")

def reduction_pct(baseline, pedas) -> np.ndarray:
    """100 (baseline - pedas) / baseline, elementwise; NaN where the baseline is 0 or missing."""
    b = np.asarray(baseline, dtype=float)
    p = np.asarray(pedas, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * (b - p) / b
    return np.where(b == 0, np.nan, out)


@dataclass
class ObjectiveResult:
    """What :func:`objective_results` computes: the KPIs per drive, the per-participant table, the summary by
    style, and who was left out (and why)."""
    kpis: pd.DataFrame
    per_participant: pd.DataFrame
    summary: pd.DataFrame
    excluded: list[str] = field(default_factory=list)
    incomplete: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.per_participant)


def participant_effects(kpis: pd.DataFrame, styles: pd.Series | dict | None = None) -> pd.DataFrame:
    """One row per participant having both drives in ``kpis`` (output of :func:`analysis.kpis.store_kpis`):
    the KPIs of both drives side by side and the savings/reductions of the module docstring. ``styles`` maps
    participant_id -> cautious|normal|sporty."""
    k = kpis.set_index(["participant_id", "condition", "segment"])
    conds = set(kpis["condition"])
    cols = {}

    def pick(cond, segment, col):
        if cond not in conds:
            return pd.Series(dtype=float)
        try:
            sub = k.xs((cond, segment), level=("condition", "segment"))
        except KeyError:  # no drive of this condition has samples in this segment
            return pd.Series(dtype=float)
        return sub[col].astype(float)

    for seg in ("overall", "urban", "highway"):
        cols[f"energy_{seg}_baseline_wh"] = pick("baseline", seg, "energy_wh")
        cols[f"energy_{seg}_pedas_wh"] = pick("pedas", seg, "energy_wh")
    for col, name in (("violation_share", "violation_share"), ("violation_events", "violation_events"),
                      ("red_stops", "red_stops"), ("tl_crossed_green", "tl_green"),
                      ("tl_green_passes", "tl_green_passes"), ("tl_crossed", "tl_crossed"),
                      ("stops", "stops"), ("rms_jerk", "rms_jerk"), ("mean_abs_a", "mean_abs_a"),
                      ("mean_speed_mps", "mean_speed_mps"), ("trip_time_s", "trip_time_s")):
        cols[f"{name}_baseline"] = pick("baseline", "overall", col)
        cols[f"{name}_pedas"] = pick("pedas", "overall", col)
    wide = pd.DataFrame(cols)
    wide.index.name = "participant_id"
    both = wide["energy_overall_baseline_wh"].notna() & wide["energy_overall_pedas_wh"].notna()
    wide = wide[both].reset_index().sort_values("participant_id", ignore_index=True)
    for seg in ("overall", "urban", "highway"):
        wide[f"saving_{seg}_pct"] = reduction_pct(wide[f"energy_{seg}_baseline_wh"], wide[f"energy_{seg}_pedas_wh"])
    wide["violation_reduction_pct"] = reduction_pct(wide["violation_share_baseline"], wide["violation_share_pedas"])
    wide["red_stop_reduction_pct"] = reduction_pct(wide["red_stops_baseline"], wide["red_stops_pedas"])
    wide["jerk_reduction_pct"] = reduction_pct(wide["rms_jerk_baseline"], wide["rms_jerk_pedas"])
    style_map = dict(styles) if styles is not None else {}
    wide.insert(1, "style", [style_map.get(p) for p in wide["participant_id"]])
    return wide


def summarise(per_participant: pd.DataFrame, metrics=SUMMARY_METRICS) -> pd.DataFrame:
    """Tidy summary by style: style (all, cautious, normal, sporty), metric, n, mean, median, sd, min, max.
    NaN (undefined reductions) are left out; ``n`` counts the participants with a value."""
    rows = []
    groups = [("all", per_participant)]
    for style in STYLES:
        groups.append((style, per_participant[per_participant["style"] == style]))
    for style, g in groups:
        for m in metrics:
            x = g[m].astype(float).dropna() if m in g else pd.Series(dtype=float)
            rows.append({"style": style, "metric": m, "n": int(len(x)),
                         "mean": x.mean() if len(x) else np.nan,
                         "median": x.median() if len(x) else np.nan,
                         "sd": x.std(ddof=1) if len(x) > 1 else np.nan,
                         "min": x.min() if len(x) else np.nan, "max": x.max() if len(x) else np.nan})
    out = pd.DataFrame(rows)
    if len(per_participant):
        b, p = per_participant["red_stops_baseline"].sum(), per_participant["red_stops_pedas"].sum()
        pooled = float(reduction_pct([b], [p])[0])
        out = pd.concat([out, pd.DataFrame([{"style": "all", "metric": "red_stop_reduction_pooled_pct",
                                             "n": len(per_participant), "mean": pooled, "median": np.nan,
                                             "sd": np.nan, "min": np.nan, "max": np.nan}])], ignore_index=True)
    return out


def objective_results(st, params=None) -> ObjectiveResult:
    """KPIs of every drive in the store ``st``, effects per included participant and the summary by style."""
    from study.exclusions import included_participants

    included = set(included_participants(st, "objective"))
    everyone = st.df("SELECT participant_id, style FROM participants ORDER BY participant_id")
    excluded = sorted(set(everyone["participant_id"]) - included)
    drives = st.df("SELECT drive_id, participant_id FROM drives ORDER BY drive_id")
    use = drives[drives["participant_id"].isin(included)]["drive_id"].tolist()
    kpis = store_kpis(st, drive_ids=use, params=params)
    styles = everyone.set_index("participant_id")["style"]
    per = participant_effects(kpis, styles)
    with_drives = set(kpis["participant_id"])
    incomplete = sorted(with_drives - set(per["participant_id"]))
    return ObjectiveResult(kpis=kpis, per_participant=per, summary=summarise(per), excluded=excluded,
                           incomplete=incomplete)


# ------------------------------------------------------------------------------------------ reproduction bands
def _published(quantity: str, row: str, column: str = "all") -> float:
    try:
        from analysis.paper.published import value
        return value(quantity, row, column, table="kpi")
    except (ImportError, KeyError, FileNotFoundError):
        return np.nan


BAND_OVERALL = "mean overall energy savings within 5-15 %"
BAND_HIGHWAY = "highway savings above urban savings (difference of means, pp)"
BAND_VIOLATION = "speed-violation reduction within 30-60 %"
BAND_RED = "red stops reduced by 40-80 %"


def reproduction_bands(summary: pd.DataFrame) -> pd.DataFrame:
    """The reproduction bands of docs/contracts.md for a (simulated) cohort beside the paper's numbers: band, paper_value,
    our_value, holds (bool), note. Paper values come from ``analysis.paper.published`` (NaN when absent)."""
    def ours(metric, stat="mean", style="all"):
        hit = summary[(summary["style"] == style) & (summary["metric"] == metric)]
        return float(hit[stat].iloc[0]) if len(hit) and pd.notna(hit[stat].iloc[0]) else np.nan

    def n(metric):
        hit = summary[(summary["style"] == "all") & (summary["metric"] == metric)]
        return int(hit["n"].iloc[0]) if len(hit) else 0

    rows = []
    o = ours("saving_overall_pct")
    rows.append({"band": BAND_OVERALL, "lo": 5.0, "hi": 15.0,
                 "paper_value": _published("energy_saving_mean", "overall"), "our_value": o,
                 "holds": bool(5.0 <= o <= 15.0) if pd.notna(o) else False,
                 "note": f"n={n('saving_overall_pct')}"})
    hw, ur = ours("saving_highway_pct"), ours("saving_urban_pct")
    p_hw, p_ur = _published("energy_saving_mean", "highway"), _published("energy_saving_mean", "urban")
    rows.append({"band": BAND_HIGHWAY, "lo": 0.0,
                 "hi": np.inf, "paper_value": p_hw - p_ur, "our_value": hw - ur,
                 "holds": bool(hw > ur) if pd.notna(hw) and pd.notna(ur) else False,
                 "note": f"ours: highway {hw:.2f} % vs urban {ur:.2f} %"
                         + (f"; paper {p_hw:g} % vs {p_ur:g} %" if pd.notna(p_hw) else "")})
    o = ours("violation_reduction_pct")
    rows.append({"band": BAND_VIOLATION, "lo": 30.0, "hi": 60.0,
                 "paper_value": _published("speed_violation_reduction_mean", "overall"), "our_value": o,
                 "holds": bool(30.0 <= o <= 60.0) if pd.notna(o) else False,
                 "note": f"mean over n={n('violation_reduction_pct')} participants with baseline violations"})
    o = ours("red_stop_reduction_pct")
    pooled = ours("red_stop_reduction_pooled_pct")
    rows.append({"band": BAND_RED, "lo": 40.0, "hi": 80.0,
                 "paper_value": _published("red_stop_reduction_mean", "overall"), "our_value": o,
                 "holds": bool(40.0 <= o <= 80.0) if pd.notna(o) else False,
                 "note": f"mean over n={n('red_stop_reduction_pct')} participants with baseline red stops; "
                         f"pooled {pooled:.1f} %"})
    return pd.DataFrame(rows)[["band", "lo", "hi", "paper_value", "our_value", "holds", "note"]]

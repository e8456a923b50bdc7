"""The objective evaluation as the study declares it (study.folder.kpi_spec): KPIs per drive, summaries by group, and
— only where the study declares a comparison — per-participant effects of the treatment against the control drive.

With a comparison (the paper's: control ``baseline``, treatment ``pedas``), for every participant included in the
objective analysis (``study.people.exclusions.included_participants(st, "objective")``) who has both drives:

* the declared ``[comparison.columns]``: KPIs of both drives side by side;
* each declared reduction ``name = "kpi[@segment]"`` = 100 (K_control - K_treatment) / K_control — the paper's
  ``saving_<segment>_pct`` of the battery energy per segment (Sec. 5.1.1; positive = pEDAS saved energy),
  ``violation_reduction_pct`` of the share of distance above the limit plus tolerance (Sec. 5.1.2),
  ``red_stop_reduction_pct`` (Sec. 5.1.3) and ``jerk_reduction_pct`` (Sec. 5.1.4);
* each declared pooled reduction 100 (sum K_control - sum K_treatment) / sum K_control over the participants.

A reduction against a control value of 0 (no violation / no red stop without pEDAS) is undefined: NaN, left out of
the means and medians, and the summary's ``n`` says how many participants carry the statistic.

Summaries are by the declared grouping: every participant (``all``) and each value of each declared participant
attribute (e.g. the paper's self-reported driving style); without a comparison, per drive and by condition.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from analysis.drives.kpis import store_kpis_with_sources

STATS = ("n", "mean", "median", "sd", "min", "max")


def reduction_pct(baseline, pedas) -> np.ndarray:
    """100 (baseline - pedas) / baseline, elementwise; NaN where the baseline is 0 or missing."""
    b = np.asarray(baseline, dtype=float)
    p = np.asarray(pedas, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 100.0 * (b - p) / b
    return np.where(b == 0, np.nan, out)


@dataclass
class ObjectiveResult:
    """What :func:`objective_results` computes: the KPIs per drive, the per-participant table (the comparison's
    effects; empty without a comparison), the summary by group, who was left out (and why), the declared KPIs
    (``spec``), the levels of each grouping, and where each drive's energy comes from."""
    kpis: pd.DataFrame
    per_participant: pd.DataFrame
    summary: pd.DataFrame
    excluded: list[str] = field(default_factory=list)
    incomplete: list[str] = field(default_factory=list)
    spec: object = None
    levels: dict = field(default_factory=dict)
    energy_sources: pd.DataFrame | None = None

    @property
    def n(self) -> int:
        """Participants in the summary: with both drives under a comparison, else with any drive."""
        if self.spec is not None and self.spec.comparison is None:
            return int(self.kpis["participant_id"].nunique()) if len(self.kpis) else 0
        return len(self.per_participant)


def _pick(k: pd.DataFrame, conds: set, cond: str, segment: str, col: str) -> pd.Series:
    """KPI ``col`` of the ``cond`` drives in ``segment``, by participant (empty when there is none)."""
    if cond not in conds:
        return pd.Series(dtype=float)
    try:
        sub = k.xs((cond, segment), level=("condition", "segment"))
    except KeyError:  # no drive of this condition has samples in this segment
        return pd.Series(dtype=float)
    return sub[col].astype(float)


def participant_effects(kpis: pd.DataFrame, comparison, groups: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per participant having both drives of ``comparison`` (:class:`study.folder.kpi_spec.Comparison`) in
    ``kpis`` (output of :func:`analysis.drives.kpis.store_kpis`): the declared columns of both drives side by side, then
    the declared reductions. ``groups``: participant attributes (index participant_id), inserted after the id."""
    k = kpis.set_index(["participant_id", "condition", "segment"])
    conds = set(kpis["condition"])
    ctrl, treat = comparison.control, comparison.treatment
    overall = kpis[kpis["segment"] == "overall"]
    both = sorted(set(overall.loc[overall["condition"] == ctrl, "participant_id"])
                  & set(overall.loc[overall["condition"] == treat, "participant_id"]))
    cols = {}
    for template, kpi, seg in comparison.columns:
        for cond in (ctrl, treat):
            cols[comparison.column(template, cond)] = _pick(k, conds, cond, seg, kpi)
    wide = pd.DataFrame(cols, index=pd.Index(both, name="participant_id"), dtype=float) if not cols else \
        pd.DataFrame(cols).reindex(pd.Index(both, name="participant_id"))
    wide.index.name = "participant_id"
    wide = wide.reset_index()
    for name, kpi, seg in comparison.reductions:
        wide[name] = reduction_pct(_pick(k, conds, ctrl, seg, kpi).reindex(both).to_numpy(float),
                                   _pick(k, conds, treat, seg, kpi).reindex(both).to_numpy(float))
    for pos, col in enumerate(groups.columns if groups is not None else (), start=1):
        values = groups[col]
        wide.insert(pos, col, [_value(values.get(p)) for p in wide["participant_id"]])
    return wide


def _value(x):
    return None if x is None or pd.isna(x) else x


def _stats(x: pd.Series) -> dict:
    x = x.astype(float).dropna()
    return {"n": int(len(x)), "mean": x.mean() if len(x) else np.nan, "median": x.median() if len(x) else np.nan,
            "sd": x.std(ddof=1) if len(x) > 1 else np.nan, "min": x.min() if len(x) else np.nan,
            "max": x.max() if len(x) else np.nan}


def _group_frames(frame: pd.DataFrame, levels: dict[str, list], label_all: bool = True
                  ) -> list[tuple[dict, pd.DataFrame]]:
    """(labels, rows): everybody ('all' in every grouping column; a column ``group`` = 'all' without groupings
    when ``label_all``), then each level of each grouping (marginal)."""
    all_labels = {g: "all" for g in levels} or ({"group": "all"} if label_all else {})
    out = [(all_labels, frame)]
    for g, values in levels.items():
        for v in values:
            out.append(({**all_labels, g: v}, frame[frame[g] == v] if g in frame else frame.iloc[0:0]))
    return out


def summarise(per_participant: pd.DataFrame, comparison, levels: dict[str, list]) -> pd.DataFrame:
    """Tidy summary of the comparison's reductions by group: one column per grouping attribute (``all`` or a
    level), metric, n, mean, median, sd, min, max; NaN (undefined reductions) are left out, ``n`` counts the
    participants with a value. The pooled reductions follow as rows of the ``all`` group (mean = the value)."""
    rows = []
    for labels, g in _group_frames(per_participant, levels):
        for m, _, _ in comparison.reductions:
            rows.append({**labels, "metric": m, **_stats(g[m] if m in g else pd.Series(dtype=float))})
    out = pd.DataFrame(rows)
    if len(per_participant):
        all_labels = {g: "all" for g in levels} or {"group": "all"}
        for name, kpi in comparison.pooled:
            template = next(t for t, kk, seg in comparison.columns if kk == kpi and seg == "overall")
            b = per_participant[comparison.column(template, comparison.control)].sum()
            p = per_participant[comparison.column(template, comparison.treatment)].sum()
            pooled = float(reduction_pct([b], [p])[0])
            out = pd.concat([out, pd.DataFrame([{**all_labels, "metric": name, "n": len(per_participant),
                                                 "mean": pooled, "median": np.nan, "sd": np.nan, "min": np.nan,
                                                 "max": np.nan}])], ignore_index=True)
    return out


def summarise_drives(kpis: pd.DataFrame, spec, levels: dict[str, list], conditions) -> pd.DataFrame:
    """Without a comparison: tidy summary of every declared KPI over the drives, per segment (``overall`` first,
    then the segments in order of appearance) and group: condition (when grouped by it), one column per grouping
    attribute (``all`` or a level), segment, metric, n, mean, median, sd, min, max."""
    segs = ["overall"] + [s for s in dict.fromkeys(kpis["segment"]) if s != "overall"]
    by_cond = "condition" in spec.group_by
    rows = []
    for cond in (conditions if by_cond else [None]):
        sub = kpis[kpis["condition"] == cond] if by_cond else kpis
        for labels, g in _group_frames(sub, levels, label_all=not by_cond):
            for seg in segs:
                gs = g[g["segment"] == seg]
                for m in spec.columns:
                    if seg != "overall" and any(k.name == m and not k.per_segment for k in spec.user_kpis):
                        continue
                    rows.append({**({"condition": cond} if by_cond else {}), **labels, "segment": seg,
                                 "metric": m, **_stats(gs[m])})
    return pd.DataFrame(rows)


def participant_groups(st, names) -> pd.DataFrame:
    """The participant attributes ``names`` (typed by the study's declaration; missing = None), index
    participant_id."""
    from study.people.participants import participant_attributes

    wide = participant_attributes(st).set_index("participant_id")[list(names)]
    return wide.astype(object).where(wide.notna(), None)


def group_levels(st, groups: pd.DataFrame) -> dict[str, list]:
    """Levels of each grouping attribute: a choice attribute's declared choices (in order), else the values that
    occur, sorted."""
    from study.store.studies import definition

    study = definition(st)
    out = {}
    for name in groups.columns:
        attr = study.attribute(name)
        out[name] = list(attr.choices) if attr.type == "choice" else sorted(groups[name].dropna().unique())
    return out


def objective_results(st, params=None, spec=None) -> ObjectiveResult:
    """KPIs of every drive in the store ``st`` of the participants included in the objective analysis, and the
    summary the study declares (``spec``: default the store's study's KPI file)."""
    from study.folder.kpi_spec import study_spec
    from study.people.exclusions import included_participants
    from study.store.studies import definition

    spec = spec or study_spec(definition(st))
    included = set(included_participants(st, "objective"))
    everyone = st.df("SELECT participant_id FROM participants ORDER BY participant_id")
    excluded = sorted(set(everyone["participant_id"]) - included)
    drives = st.df("SELECT drive_id, participant_id FROM drives ORDER BY drive_id")
    use = drives[drives["participant_id"].isin(included)]["drive_id"].tolist()
    kpis, sources = store_kpis_with_sources(st, drive_ids=use, params=params, spec=spec)
    groups = participant_groups(st, spec.attributes)
    levels = group_levels(st, groups)
    with_drives = set(kpis["participant_id"])
    if spec.comparison is None:
        k = kpis.merge(groups, left_on="participant_id", right_index=True, how="left") if len(groups.columns) \
            else kpis
        summary = summarise_drives(k, spec, levels, definition(st).condition_names)
        return ObjectiveResult(kpis=kpis, per_participant=pd.DataFrame(), summary=summary, excluded=excluded,
                               incomplete=[], spec=spec, levels=levels, energy_sources=sources)
    per = participant_effects(kpis, spec.comparison, groups)
    incomplete = sorted(with_drives - set(per["participant_id"]))
    return ObjectiveResult(kpis=kpis, per_participant=per, summary=summarise(per, spec.comparison, levels),
                           excluded=excluded, incomplete=incomplete, spec=spec, levels=levels,
                           energy_sources=sources)


# ------------------------------------------------------------------------------------------ reproduction bands
def _published(quantity: str, row: str, column: str = "all", published: pd.DataFrame | None = None) -> float:
    try:
        from analysis.paper.published import value
        return value(quantity, row, column, table="kpi", published=published)
    except (ImportError, KeyError, FileNotFoundError):
        return np.nan


def study_published(st) -> pd.DataFrame | None:
    """The published values the store's study declares (``[files] published``), None when it declares none."""
    import io

    from study.store.studies import definition

    text = definition(st).text("published")
    return None if text is None else pd.read_csv(io.StringIO(text))


BAND_OVERALL = "mean overall energy savings within 5-15 %"
BAND_HIGHWAY = "highway savings above urban savings (difference of means, pp)"
BAND_VIOLATION = "speed-violation reduction within 30-60 %"
BAND_RED = "red stops reduced by 40-80 %"
#: the unit of each band's value (paper's and ours): a mean reduction in %, a difference of mean savings in pp
BAND_UNITS = {BAND_OVERALL: "%", BAND_HIGHWAY: "pp", BAND_VIOLATION: "%", BAND_RED: "%"}


def reproduction_bands(summary: pd.DataFrame, published: pd.DataFrame | None = None) -> pd.DataFrame:
    """The reproduction bands of docs/contracts.md for a (simulated) cohort beside the paper's numbers: band, paper_value,
    our_value, holds (bool), note. ``summary``: :func:`summarise` of the paper's comparison. Paper values come from
    ``published`` (the study's published values; default ``analysis.paper.published``), NaN when absent."""
    grouping = list(summary.columns[:list(summary.columns).index("metric")]) if "metric" in summary else []
    everyone = (summary[grouping] == "all").all(axis=1) if grouping else pd.Series(True, index=summary.index)

    def _published(quantity, row, column="all"):
        return globals()["_published"](quantity, row, column, published)

    def ours(metric, stat="mean"):
        hit = summary[everyone & (summary["metric"] == metric)]
        return float(hit[stat].iloc[0]) if len(hit) and pd.notna(hit[stat].iloc[0]) else np.nan

    def n(metric):
        hit = summary[everyone & (summary["metric"] == metric)]
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

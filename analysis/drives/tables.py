"""Tables of the objective evaluation, each as CSV (machine-readable), Markdown and LaTeX booktabs (rendered from the
same frame). With a comparison: means and medians of the labelled reductions by group (the paper's per-style table,
Sec. 5.1) and the per-participant table; without: means and SDs of every declared KPI by condition and group."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis import apa
from analysis.render import fmt_cell, latex_table, markdown_table


def _grouping(summary: pd.DataFrame) -> list[str]:
    """The grouping columns of a tidy summary (those before ``metric``)."""
    return list(summary.columns[:list(summary.columns).index("metric")])


def style_table(summary: pd.DataFrame, comparison) -> pd.DataFrame:
    """Wide table of the comparison's labelled reductions by group: the grouping column(s), n, then
    ``<metric>_n``, ``<metric>_mean`` and ``<metric>_median`` (%); rows each group level, then ``all``. ``n`` is
    the n of the first labelled reduction."""
    metrics = [m for m, _ in comparison.labels]
    group_cols = _grouping(summary)
    rows = []
    keys = summary[group_cols].drop_duplicates()
    ordered = [k for k in keys.itertuples(index=False) if any(v != "all" for v in k)] + \
        [k for k in keys.itertuples(index=False) if all(v == "all" for v in k)]
    for key in ordered:
        mask = (summary[group_cols] == pd.Series(list(key), index=group_cols)).all(axis=1)
        s = summary[mask].set_index("metric")
        label = next((v for v in key if v != "all"), "all")
        r = {group_cols[0] if len(group_cols) == 1 else "group": label,
             "n": int(s.loc[metrics[0], "n"]) if metrics and metrics[0] in s.index else 0}
        for m in metrics:
            r[f"{m}_n"] = int(s.loc[m, "n"]) if m in s.index else 0
            r[f"{m}_mean"] = s.loc[m, "mean"] if m in s.index else np.nan
            r[f"{m}_median"] = s.loc[m, "median"] if m in s.index else np.nan
        rows.append(r)
    return pd.DataFrame(rows)


# column labels of the per-participant table (the comparison's columns and reductions that have one, in this order)
PARTICIPANT_COLUMNS = (
    ("participant_id", "Participant"), ("style", "Style"),
    ("saving_urban_pct", "Urban sav. %"), ("saving_highway_pct", "Highway sav. %"),
    ("saving_overall_pct", "Overall sav. %"),
    ("violation_share_baseline", "Viol. share w/o"), ("violation_share_pedas", "Viol. share with"),
    ("violation_reduction_pct", "Viol. red. %"),
    ("red_stops_baseline", "Red stops w/o"), ("red_stops_pedas", "Red stops with"),
    ("tl_green_passes_baseline", "TL green pass w/o"), ("tl_green_passes_pedas", "TL green pass with"),
    ("jerk_reduction_pct", "Jerk red. %"),
)


def participant_table(per_participant: pd.DataFrame) -> pd.DataFrame:
    """The per-participant table (the columns of :data:`PARTICIPANT_COLUMNS` that the comparison has)."""
    cols = [c for c, _ in PARTICIPANT_COLUMNS if c in per_participant]
    return per_participant[cols].copy()


# ------------------------------------------------------------------------------------------ rendering
def _fmt(x, nd=2) -> str:
    """A KPI cell: `nd` decimals, integers as integers, missing as an en dash."""
    return fmt_cell(x, nd, missing="–")


def style_cells(t: pd.DataFrame, comparison) -> tuple[list[str], list[list[str]]]:
    """Header and cells of the table by group (:func:`style_table`): "mean (median)" per labelled reduction, with
    [n=k] when a metric has fewer participants than the group."""
    group = t.columns[0]
    header = [group.replace("_", " ").capitalize(), "n"] + [label + " mean (median)" for _, label in comparison.labels]
    rows = []
    for _, r in t.iterrows():
        cells = [str(r[group]), str(int(r["n"]))]
        for m, _ in comparison.labels:
            cell = f"{_fmt(r[f'{m}_mean'])} ({_fmt(r[f'{m}_median'])})"
            if int(r[f"{m}_n"]) != int(r["n"]):
                cell += f" [n={int(r[f'{m}_n'])}]"
            cells.append(cell)
        rows.append(cells)
    return header, rows


def _participant_cells(t: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    labels = dict(PARTICIPANT_COLUMNS)
    header = [labels.get(c, c) for c in t.columns]
    rows = []
    for _, r in t.iterrows():
        cells = []
        for c in t.columns:
            nd = 3 if c.startswith("violation_share") else 2
            v = r[c]
            if c.startswith(("red_stops", "tl_green")) and pd.notna(v):
                v = int(v)
            cells.append(_fmt(v, nd))
        rows.append(cells)
    return header, rows


def kpi_markdown(header, rows, title: str, notes=(), text_columns: int = 1) -> str:
    """A KPI table in Markdown: bold title, the first ``text_columns`` columns left-aligned, the rest right."""
    align = "l" * text_columns + "r" * (len(header) - text_columns)
    return markdown_table(header, rows, title, notes, align=align, title_style="bold")


def _texts(comparison) -> dict:
    """Title, note and participant title of the tables: the comparison's declared texts, else generic ones."""
    t = dict(comparison.table)
    c, tr = comparison.control, comparison.treatment
    return {"title": t.get("title", "Effects of the comparison by group, mean (median) in %"),
            "note": t.get("note", f"Reductions = ({c} - {tr}) / {c} per participant. Reductions against a {c} "
                                  f"value of 0 are undefined and left out ([n=...] when fewer)."),
            "participant_title": t.get("participant_title", f"KPIs per participant ({c} and {tr} drive)")}


def kpi_summary_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Without a comparison: one row per group and segment, ``<kpi>_mean`` and ``<kpi>_sd`` per declared KPI
    and n (drives)."""
    keys = [c for c in summary.columns[:list(summary.columns).index("metric")]]
    rows = []
    for key, g in summary.groupby(keys, sort=False):
        r = dict(zip(keys, key if isinstance(key, tuple) else (key,)))
        r["n"] = int(g["n"].max())
        for m in g["metric"]:
            hit = g[g["metric"] == m].iloc[0]
            r[f"{m}_mean"], r[f"{m}_sd"] = hit["mean"], hit["sd"]
        rows.append(r)
    return pd.DataFrame(rows)


def informative_summary(summary: pd.DataFrame, spec=None) -> tuple[pd.DataFrame, list[str]]:
    """The KPI summary without what says nothing, and a note line per left-out part: a KPI constant across every
    drive (SD 0 in each group and one value throughout; named with its value and unit as `spec`, the study's
    :class:`study.folder.kpi_spec.KpiSpec`, declares them) and, on a route of one segment, that segment's rows (they
    repeat the whole drive's).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.drives.tables import informative_summary
    >>> s = pd.DataFrame({"condition": ["a"] * 4, "segment": ["overall", "overall", "motorway", "motorway"],
    ...                   "metric": ["trip_time_s", "energy_wh"] * 2, "n": 5, "mean": [75.0, 9.0, 75.0, 9.0],
    ...                   "sd": [0.0, 1.0, 0.0, 1.0], "min": [75.0, 8.0, 75.0, 8.0], "max": [75.0, 10.0, 75.0, 10.0]})
    >>> kept, notes = informative_summary(s)
    >>> list(kept["metric"]), notes[0]
    (['energy_wh'], 'Constant across all drives and left out: trip time = 75.00 s.')
    """
    from analysis.drives.paired import kpi_words
    from study.folder.kpi_spec import DEFAULT_SPEC

    spec = spec if spec is not None else DEFAULT_SPEC
    notes = []
    out = summary
    if {"metric", "sd", "min", "max"} <= set(summary.columns):
        constant = [m for m, g in summary.groupby("metric", sort=False)
                    if (g["sd"].fillna(0) == 0).all() and g["min"].min() == g["max"].max()]
        if constant:
            vals = summary.drop_duplicates("metric").set_index("metric")["min"]
            notes.append("Constant across all drives and left out: " + ", ".join(
                f"{kpi_words(m, spec)} = {apa.quantity(vals[m], spec.unit(m), spec.decimals(m))}"
                for m in constant) + ".")
            out = out[~out["metric"].isin(constant)]
    if "segment" in out.columns:
        segments = [s for s in out["segment"].astype(str).unique() if s != "overall"]
        if len(segments) == 1 and "overall" in set(out["segment"]):
            keys = [c for c in out.columns[:list(out.columns).index("metric")] if c != "segment"] + ["metric"]
            seg = out[out["segment"] == segments[0]].set_index(keys)["mean"]
            whole = out[out["segment"] == "overall"].set_index(keys)["mean"].reindex(seg.index)
            if len(seg) and np.allclose(seg.to_numpy(float), whole.to_numpy(float), equal_nan=True):
                notes.append(f"The route has one segment ({segments[0]}): its rows repeat the whole drive's and are "
                             "left out.")
                out = out[out["segment"] != segments[0]]
    return out.reset_index(drop=True), notes


def _summary_cells(t: pd.DataFrame, spec=None) -> tuple[list[str], list[list[str]]]:
    """Header and cells of :func:`kpi_summary_table`: "mean (SD)" per KPI; a KPI the study declares itself is
    headed "Label (unit)" (``spec``: its :class:`study.folder.kpi_spec.KpiSpec`), a built-in by its column name."""
    metrics = [c[:-5] for c in t.columns if c.endswith("_mean")]
    keys = [c for c in t.columns if c != "n" and not c.endswith(("_mean", "_sd"))]
    headings = spec.headings if spec is not None else {}
    # rounded for reading by the KPI's unit (kpi_table.csv and summary.csv keep full precision)
    dec = {m: spec.decimals(m) if spec is not None else 3 for m in metrics}
    header = [k.capitalize() for k in keys] + ["n"] + [f"{headings.get(m, apa.header(m))} mean (SD)" for m in metrics]
    rows = [[str(r[k]) for k in keys] + [str(int(r["n"]))]
            + [f"{_fmt(r[f'{m}_mean'], dec[m])} ({_fmt(r[f'{m}_sd'], dec[m])})" for m in metrics]
            for _, r in t.iterrows()]
    return header, rows


def write_tables(result, out_dir: str | Path) -> list[Path]:
    """Write kpis.csv and summary.csv into ``out_dir``, and with a comparison per_participant.csv,
    style_table.{csv,md,tex} and participant_table.{csv,md,tex}, without one kpi_table.{csv,md,tex}; returns the
    paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name, text):
        p = out / name
        p.write_text(text, encoding="utf-8")
        written.append(p)

    def table(stem, frame, cells, title, label, notes=(), text_columns=1):
        """<stem>.csv from the frame, .md and .tex from its cells."""
        frame.to_csv(out / f"{stem}.csv", index=False)
        written.append(out / f"{stem}.csv")
        h, r = cells(frame)
        put(f"{stem}.md", kpi_markdown(h, r, title, notes, text_columns))
        put(f"{stem}.tex", latex_table(h, r, title, notes, label))

    written += write_phases(result, out)
    comparison = result.spec.comparison
    if comparison is None:
        for name, df in (("kpis.csv", result.kpis), ("summary.csv", result.summary)):
            df.to_csv(out / name, index=False)
            written.append(out / name)
        # the CSV keeps every KPI, the rendering the informative ones
        kept, notes = informative_summary(result.summary, result.spec)
        summary = kpi_summary_table(kept)
        table("kpi_table", kpi_summary_table(result.summary), lambda _: _summary_cells(summary, result.spec),
              f"Objective KPIs per drive, mean (SD) (N = {result.n} participants)", "tab:kpis", notes,
              text_columns=list(summary.columns).index("n"))
        return written
    for name, df in (("kpis.csv", result.kpis), ("per_participant.csv", result.per_participant),
                     ("summary.csv", result.summary)):
        df.to_csv(out / name, index=False)
        written.append(out / name)
    texts = _texts(comparison)
    table("style_table", style_table(result.summary, comparison), lambda t: style_cells(t, comparison),
          f"{texts['title']} (N = {result.n})", "tab:kpi_styles", (texts["note"],))
    table("participant_table", participant_table(result.per_participant), _participant_cells,
          texts["participant_title"], "tab:kpi_participants")
    return written


def bands_markdown(bands: pd.DataFrame) -> str:
    """The reproduction bands as a Markdown table."""
    header = ["Band", "Holds", "Note", "Paper", "Ours"]
    rows = [[b["band"], "yes" if b["holds"] else "no", b["note"], _fmt(b["paper_value"]), _fmt(b["our_value"])]
            for _, b in bands.iterrows()]
    return kpi_markdown(header, rows, "Reproduction bands", text_columns=3)


#: the drives outside the compared conditions (familiarisation, practice), summarised apart
PHASES = "phases"


def phase_summary(kpis: pd.DataFrame, spec) -> pd.DataFrame:
    """phase, metric, n, mean, median, sd, min, max of every declared KPI over the whole drive of the drives that
    belong to a drive phase without a condition (e.g. the familiarisation drive's takeover time); empty when the
    store has none."""
    from analysis.drives.savings import _stats

    cols = ["phase", "metric", "n", "mean", "median", "sd", "min", "max"]
    if "phase" not in kpis.columns:
        return pd.DataFrame(columns=cols)
    k = kpis[kpis["phase"].notna() & (kpis["segment"] == "overall")]
    rows = [{"phase": ph, "metric": m, **_stats(g[m])} for ph, g in k.groupby("phase", sort=False)
            for m in spec.columns]
    return pd.DataFrame(rows, columns=cols)


def write_phases(result, out: Path) -> list[Path]:
    """phases.csv (full precision), .md and .tex (each KPI to the decimals of its unit) when the store has drives
    outside the conditions; the report's drive section shows the table apart from the compared conditions."""
    table = phase_summary(result.kpis, result.spec)
    if table.empty:
        return []
    title = "KPIs of the drives outside the compared conditions (whole drive, e.g. familiarisation; in no comparison)"
    header = list(table.columns)
    rows = [[r.phase, r.metric, str(int(r.n))] + [_fmt(getattr(r, c), result.spec.decimals(r.metric))
                                                  for c in header[3:]] for r in table.itertuples(index=False)]
    paths = [out / f"{PHASES}.csv", out / f"{PHASES}.md", out / f"{PHASES}.tex"]
    table.to_csv(paths[0], index=False)
    paths[1].write_text(markdown_table(header, rows, title), encoding="utf-8")
    paths[2].write_text(latex_table(header, rows, title, (), f"tab:{PHASES}"), encoding="utf-8")
    return paths

"""Tables of the objective evaluation: per-style means and medians (as Sec. 5.1 reports them) and the
per-participant table, each as CSV (machine-readable), Markdown and LaTeX booktabs (rendered from the same frame)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.render import fmt_cell, latex_table, markdown_table
from pedas.vocabulary import STYLES

# (metric, column label) of the per-style table, in the paper's order
STYLE_TABLE_METRICS = (
    ("saving_overall_pct", "Overall savings"),
    ("saving_urban_pct", "Urban savings"),
    ("saving_highway_pct", "Highway savings"),
    ("violation_reduction_pct", "Violation reduction"),
    ("red_stop_reduction_pct", "Red-stop reduction"),
)


def style_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Wide per-style table: style, n, then ``<metric>_mean`` and ``<metric>_median`` (%) for the metrics of
    :data:`STYLE_TABLE_METRICS`; rows cautious, normal, sporty, all."""
    rows = []
    for style in (*STYLES, "all"):
        s = summary[summary["style"] == style].set_index("metric")
        r = {"style": style,
             "n": int(s.loc["saving_overall_pct", "n"]) if "saving_overall_pct" in s.index else 0}
        for m, _ in STYLE_TABLE_METRICS:
            r[f"{m}_n"] = int(s.loc[m, "n"]) if m in s.index else 0
            r[f"{m}_mean"] = s.loc[m, "mean"] if m in s.index else np.nan
            r[f"{m}_median"] = s.loc[m, "median"] if m in s.index else np.nan
        rows.append(r)
    return pd.DataFrame(rows)


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
    """The per-participant table (columns of :data:`PARTICIPANT_COLUMNS`)."""
    cols = [c for c, _ in PARTICIPANT_COLUMNS if c in per_participant]
    return per_participant[cols].copy()


# ------------------------------------------------------------------------------------------ rendering
def _fmt(x, nd=2) -> str:
    """A KPI cell: `nd` decimals, integers as integers, missing as an en dash."""
    return fmt_cell(x, nd, missing="–")


def style_cells(t: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    """Header and cells of the per-style table (:func:`style_table`): "mean (median)" per metric, with [n=k]
    when a metric has fewer participants than the style."""
    header = ["Style", "n"] + [label + " mean (median)" for _, label in STYLE_TABLE_METRICS]
    rows = []
    for _, r in t.iterrows():
        cells = [str(r["style"]), str(int(r["n"]))]
        for m, _ in STYLE_TABLE_METRICS:
            cell = f"{_fmt(r[f'{m}_mean'])} ({_fmt(r[f'{m}_median'])})"
            if int(r[f"{m}_n"]) != int(r["n"]):
                cell += f" [n={int(r[f'{m}_n'])}]"
            cells.append(cell)
        rows.append(cells)
    return header, rows


def _participant_cells(t: pd.DataFrame) -> tuple[list[str], list[list[str]]]:
    labels = dict(PARTICIPANT_COLUMNS)
    header = [labels[c] for c in t.columns]
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


STYLE_NOTES = ("Savings = (baseline - pEDAS) / baseline of battery energy; reductions likewise. "
               "Reductions against a baseline of 0 are undefined and left out ([n=...] when fewer).",)


def write_tables(result, out_dir: str | Path) -> list[Path]:
    """Write kpis.csv, per_participant.csv, summary.csv, style_table.{csv,md,tex},
    participant_table.{csv,md,tex} into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name, text):
        p = out / name
        p.write_text(text, encoding="utf-8")
        written.append(p)

    def table(stem, frame, cells, title, label, notes=()):
        """<stem>.csv from the frame, .md and .tex from its cells."""
        frame.to_csv(out / f"{stem}.csv", index=False)
        written.append(out / f"{stem}.csv")
        h, r = cells(frame)
        put(f"{stem}.md", kpi_markdown(h, r, title, notes))
        put(f"{stem}.tex", latex_table(h, r, title, notes, label))

    for name, df in (("kpis.csv", result.kpis), ("per_participant.csv", result.per_participant),
                     ("summary.csv", result.summary)):
        df.to_csv(out / name, index=False)
        written.append(out / name)
    table("style_table", style_table(result.summary), style_cells,
          f"Objective KPIs by driving style, mean (median) in % (N = {result.n})", "tab:kpi_styles", STYLE_NOTES)
    table("participant_table", participant_table(result.per_participant), _participant_cells,
          "Objective KPIs per participant (w/o = baseline drive, with = pEDAS drive)", "tab:kpi_participants")
    return written


def bands_markdown(bands: pd.DataFrame) -> str:
    """The reproduction bands as a Markdown table."""
    header = ["Band", "Holds", "Note", "Paper", "Ours"]
    rows = [[b["band"], "yes" if b["holds"] else "no", b["note"], _fmt(b["paper_value"]), _fmt(b["our_value"])]
            for _, b in bands.iterrows()]
    return kpi_markdown(header, rows, "Reproduction bands", text_columns=3)

"""The report as one readable HTML document (`index.html`) for any study, written as a manuscript's results: a main
text (method and results with at most ~10 numbered tables and figures) and a numbered appendix with everything else.

Everything is generated from what the report steps wrote beside it (tables as Markdown in `tables/`, figures as PNG
in `figures/`, the survey analysis in `survey/`, the drive analysis in `drives/`, `reproduction.csv`), from the
store's study definition (:func:`study.store.studies.definition`: title, conditions, instrument, model file, alpha,
hypothesis signs) and from the store's participants, protocol events and exclusions. The page is self-contained
(inline CSS, no scripts, no external resources; images and links by relative path, so it opens from the file
system), every text is HTML-escaped, and the bytes depend only on those inputs and the installed software's
versions (no times, no absolute paths): an unchanged report renders the same file.

Sections, in order (docs/report.md): the data and verdicts box · Study · Method (with Participants) · Results
(measurement model, structural model and hypotheses, within-subjects comparisons, objective measures) · Appendix.
Every table and figure is numbered (Table 1 / Table A1) and listed in `exhibits.json` (analysis.report.exhibits).
"""
from __future__ import annotations

import html
import importlib.metadata
import json
import platform
import re
from pathlib import Path
from typing import Callable, Sequence

import pandas as pd

from analysis import apa
from analysis.render import write_table

#: section headings (h2) in document order
SECTIONS = ("Study", "Method", "Results", "Appendix")
#: software the methods name, as (label, distribution, the part of a run that uses it: None = every run, "survey" =
#: the survey analysis, "simulation" = drives simulated by the report; the QP solver is the controller's backend)
SOFTWARE = (("numpy", "numpy", None), ("pandas", "pandas", None), ("DuckDB", "duckdb", None),
            ("semopy", "semopy", "survey"), ("statsmodels", "statsmodels", "survey"),
            ("pingouin", "pingouin", "within"), ("statsmodels", "statsmodels", "within"), ("QP", "qp", "simulation"),
            ("SUMO", "eclipse-sumo", "simulation"), ("matplotlib", "matplotlib", None))
#: the controller's QP backend -> (label, distribution)
QP_SOLVERS = {"daqp": ("DAQP", "daqp"), "osqp": ("OSQP", "osqp")}

CSS = ("body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1100px;margin:2em auto;"
       "padding:0 1em;color:#222;line-height:1.45}"
       "h1{font-size:1.7em;margin-bottom:.2em}h2{border-bottom:2px solid #2b5d8a;padding-bottom:.15em;"
       "margin-top:2em}h3{margin-top:1.5em}"
       "img{max-width:100%;height:auto}figure{margin:1.2em 0}"
       "figcaption{font-size:.92em;color:#333}"
       ".exhibit{margin:1.4em 0}.xlabel{font-weight:700;margin:0}.xtitle{font-style:italic;margin:0 0 .3em}"
       ".scroll{overflow-x:auto;max-width:100%;margin:.6em 0 1.2em}"
       # APA tables: horizontal rules only (the booktabs look), no grid
       "table{border-collapse:collapse;font-size:.86em;border-top:2px solid #222;border-bottom:2px solid #222;"
       "margin:.3em 0}td,th{border:0;padding:.2em .6em;vertical-align:top}thead th{border-bottom:1px solid #222;"
       "font-weight:600;text-align:left}td.r,th.r{text-align:right}td.c,th.c{text-align:center}"
       "caption{caption-side:top;text-align:left;font-weight:600;padding:.3em 0}"
       ".note{font-size:.85em;color:#444;margin:.2em 0}.skipped{background:#fbf3e6;border-left:4px solid #d08b1c;"
       "padding:.4em .8em}.verdict{background:#eef6ee;border-left:4px solid #3a7d3a;padding:.4em .8em}"
       ".verdict.mixed{background:#fbf3e6;border-left-color:#d08b1c}.verdict ul{margin:.3em 0;padding-left:1.2em}"
       "code{background:#f4f4f4;padding:0 .2em}dl{display:grid;grid-template-columns:max-content 1fr;"
       "gap:.2em 1em}dt{font-weight:600}dd{margin:0}ul.files{columns:2;font-size:.88em}")


def esc(x) -> str:
    return html.escape(str(x), quote=True)


# ---------------------------------------------------------------------------------------------- Markdown
def _inline(text: str, base: str = "") -> str:
    """One line of the Markdown the analysis writes, as HTML: escaped, then `code`, **bold**, _italic_ and
    [text](link) (relative links resolved against `base`, the folder of the Markdown file)."""
    out = esc(text)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", out)
    out = re.sub(r"(?<![\w\\])_(\S(?:.*?\S)?)_(?!\w)", r"<em>\1</em>", out)

    def link(m: re.Match) -> str:
        href = html.unescape(m.group(2))
        if base and not re.match(r"^[a-z]+:|^/|^#", href):
            href = f"{base}/{href}"
        return f"<a href=\"{esc(href)}\">{m.group(1)}</a>"

    return re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", link, out)


def _cells(line: str) -> list[str]:
    """Cells of a Markdown table row (`\\|` is a pipe inside a cell)."""
    body = line.strip()
    body = body[1:] if body.startswith("|") else body
    body = body[:-1] if body.endswith("|") and not body.endswith("\\|") else body
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", body)]


def _align(sep: str) -> str:
    sep = sep.strip()
    return "c" if sep.startswith(":") and sep.endswith(":") else "r" if sep.endswith(":") else ""


def _table(lines: list[str], caption: str = "", base: str = "") -> str:
    header, body = apa.table_cells(_cells(lines[0]), [_cells(ln) for ln in lines[2:]])
    aligns = [_align(c) for c in _cells(lines[1])] if len(lines) > 1 else []
    aligns += [""] * (len(header) - len(aligns))

    def cls(k: int) -> str:
        return f' class="{aligns[k]}"' if k < len(aligns) and aligns[k] else ""

    out = ["<div class=\"scroll\"><table>"]
    if caption:
        out.append(f"<caption>{caption}</caption>")
    out.append("<thead><tr>" + "".join(f"<th{cls(k)}>{_inline(h, base)}</th>" for k, h in enumerate(header))
               + "</tr></thead><tbody>")
    for cells in body:
        out.append("<tr>" + "".join(f"<td{cls(k)}>{_inline(c, base)}</td>" for k, c in enumerate(cells)) + "</tr>")
    out.append("</tbody></table></div>")
    return "".join(out)


def markdown_to_html(text: str, base: str = "", heading_offset: int = 2) -> str:
    """The Markdown the analysis writes (headings, bold titles, GitHub tables, notes, lists, paragraphs) as HTML.

    A bold or heading line directly above a table becomes the table's caption; the lines under a table, up to the
    next heading, list or table, are its notes (one small paragraph each). Headings move down by `heading_offset` levels
    (a file's `#` becomes `<h3>` inside a section). `base`: the folder links are relative to.
    """
    lines = text.splitlines()
    out: list[str] = []
    para: list[str] = []
    pending_caption = ""
    notes = False   # plain lines after a table (up to the next heading, list or table) are its notes

    def flush() -> None:
        nonlocal para
        if para:
            out.append("<p>" + "<br>".join(_inline(p.rstrip(), base) for p in para) + "</p>")
            para = []

    i = 0
    while i < len(lines):
        ln = lines[i]
        st = ln.strip()
        if not st:
            flush()
            i += 1
            continue
        if st.startswith("|"):
            flush()
            block = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                block.append(lines[i])
                i += 1
            out.append(_table(block, pending_caption, base))
            pending_caption, notes = "", True
            continue
        m = re.match(r"^(#{1,6})\s+(.*)$", st)
        bold = re.fullmatch(r"\*\*(.+)\*\*", st)
        nxt = next((lines[j].strip() for j in range(i + 1, len(lines)) if lines[j].strip()), "")
        if (m or bold) and nxt.startswith("|"):
            flush()
            notes = False
            pending_caption = _inline(m.group(2) if m else bold.group(1), base)
            i += 1
            continue
        if pending_caption:  # a title that did not head a table after all
            out.append(f"<p><strong>{pending_caption}</strong></p>")
            pending_caption = ""
        if m:
            flush()
            notes = False
            level = min(6, len(m.group(1)) + heading_offset)
            out.append(f"<h{level}>{_inline(m.group(2), base)}</h{level}>")
        elif re.match(r"^(-|\*|\d+\.)\s+", st):
            flush()
            notes = False
            ordered = bool(re.match(r"^\d+\.", st))
            items = []
            while i < len(lines) and re.match(r"^(-|\*|\d+\.)\s+", lines[i].strip()):
                items.append(re.sub(r"^(-|\*|\d+\.)\s+", "", lines[i].strip()))
                i += 1
            tag = "ol" if ordered else "ul"
            out.append(f"<{tag}>" + "".join(f"<li>{_inline(x, base)}</li>" for x in items) + f"</{tag}>")
            continue
        elif notes:  # one small paragraph per note line
            out.append(f"<p class=\"note\">{_inline(st, base)}</p>")
        else:
            para.append(st)
        i += 1
    flush()
    if pending_caption:
        out.append(f"<p><strong>{pending_caption}</strong></p>")
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------- numbers
def _fmt(x, digits: int = 1) -> str:
    """A number of a sentence (analysis.apa: true minus sign, an en dash where missing)."""
    return apa.num(x, digits)


def _read_csv(path: Path) -> pd.DataFrame | None:
    try:
        return pd.read_csv(path) if path.is_file() else None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
        return None


def software_versions(parts=("survey", "simulation")) -> list[tuple[str, str]]:
    """(name, version) of Python and the libraries a run used (installed distributions): those every run uses and
    those of the `parts` that ran ("survey", "within", "simulation"), each once."""
    out = [("Python", platform.python_version())]
    for label, dist, part in SOFTWARE:
        if part is not None and part not in parts or any(label == name for name, _ in out):
            continue
        if dist == "qp":
            from pedas.params import CONTROLLER

            label, dist = QP_SOLVERS[CONTROLLER.qp_backend]
        try:
            out.append((label, importlib.metadata.version(dist)))
        except importlib.metadata.PackageNotFoundError:
            out.append((label, "not installed"))
    try:
        out.append(("pedas-study", importlib.metadata.version("pedas-study")))
    except importlib.metadata.PackageNotFoundError:
        pass
    return out


# ---------------------------------------------------------------------------------------------- figure readings
def _summary_metric(out: Path, metric: str, style: str = "all"):
    df = _read_csv(out / "drives" / "summary.csv")
    if df is None or not {"style", "metric", "mean"} <= set(df.columns):
        return None
    row = df[(df["style"].astype(str) == style) & (df["metric"] == metric)]
    return None if row.empty else float(row["mean"].iloc[0])


def _reading_savings(out: Path, _study) -> str | None:
    urban, highway = _summary_metric(out, "saving_urban_pct"), _summary_metric(out, "saving_highway_pct")
    overall = _summary_metric(out, "saving_overall_pct")
    if urban is None or highway is None:
        return None
    (a, va), (b, vb) = sorted((("urban", urban), ("highway", highway)), key=lambda t: -t[1])
    tail = f"; {_fmt(overall)} % over the whole drive" if overall is not None else ""
    return f"Mean energy savings were larger in {a} ({_fmt(va)} %) than {b} ({_fmt(vb)} %) sections{tail}."


def _reading_by_style(metric: str, where: str) -> Callable[[Path, object], str | None]:
    def reading(out: Path, _study) -> str | None:
        df = _read_csv(out / "drives" / "summary.csv")
        if df is None or not {"style", "metric", "mean"} <= set(df.columns):
            return None
        rows = df[(df["metric"] == metric) & (df["style"].astype(str) != "all")].dropna(subset=["mean"])
        if len(rows) < 2:
            return None
        rows = rows.sort_values("mean", ascending=False)
        hi, lo = rows.iloc[0], rows.iloc[-1]
        return (f"{where} savings were largest for {hi['style']} drivers ({_fmt(hi['mean'])} %) and smallest for "
                f"{lo['style']} drivers ({_fmt(lo['mean'])} %).")
    return reading


def _reading_green(out: Path, _study) -> str | None:
    df = _read_csv(out / "drives" / "per_participant.csv")
    cols = ("tl_green_passes_baseline", "tl_green_passes_pedas", "tl_crossed_baseline")
    if df is None or not set(cols) <= set(df.columns):
        return None
    base, ped, crossed = (float(df[c].sum()) for c in cols)
    return (f"Lights passed in green without a stop: {base:.0f} in the baseline drives and {ped:.0f} with pEDAS "
            f"(of {crossed:.0f} lights crossed per condition, {len(df)} participants).")


def _reading_flow(out: Path, _study) -> str | None:
    df = _read_csv(out / "tables" / "participant_flow.csv")
    if df is None or not {"stage", "n"} <= set(df.columns):
        return None
    n = {r.stage: int(r.n) for r in df.itertuples() if not isinstance(r.reason, str)}
    if "enrolled" not in n:
        return None
    samples = [f"{n[k]} in the {k}" for k in ("survey sample", "drive sample") if k in n]
    return f"{n['enrolled']} enrolled" + (f"; {' and '.join(samples)}." if samples else ".")


def _reading_likert(out: Path, study) -> str | None:
    resp = _read_csv(out / "survey" / "responses.csv")
    if resp is None or not study.instruments:
        return None
    ins = study.instrument()
    above = total = 0
    for item in ins.scaled_items:
        if item not in resp.columns:
            continue
        lo, hi = ins.scale(item)
        x = pd.to_numeric(resp[item], errors="coerce").dropna()
        if item in ins.reverse_items:
            x = lo + hi - x
        above += int((x > (lo + hi) / 2).sum())
        total += len(x)
    if not total:
        return None
    return (f"{len(resp)} participants, {total} answers: {100 * above / total:.0f} % above the scale midpoint "
            f"(after reverse scoring).")


#: stem -> (caption, reading from the numbers or None)
FIGURES: dict[str, tuple[str, Callable[[Path, object], str | None] | None]] = {
    "participant_flow": ("Participant flow from enrolment to the analysed samples, with exclusion reasons.",
                         _reading_flow),
    "likert_items": ("Item-level answer distribution (raw answers; diverging bars centred on the midpoint).",
                     _reading_likert),
    "fig9a_savings": ("Energy savings per participant by route section (Fig. 9a).", _reading_savings),
    "fig9b_savings_urban_by_style": ("Urban energy savings by driving style (Fig. 9b).",
                                     _reading_by_style("saving_urban_pct", "Urban")),
    "fig9c_savings_highway_by_style": ("Highway energy savings by driving style (Fig. 9c).",
                                       _reading_by_style("saving_highway_pct", "Highway")),
    "fig9d_savings_overall_by_style": ("Overall energy savings by driving style (Fig. 9d).",
                                       _reading_by_style("saving_overall_pct", "Overall")),
    "fig10_tl_green": ("Traffic lights passed in green without a stop, per participant (Fig. 10).", _reading_green),
    "fig11_driving_behaviour": ("Velocity (with the speed limit), acceleration and cumulative battery energy over "
                                "distance of one participant's drives without and with pEDAS (Fig. 11).", None),
    "fig12_controller_switching": ("Switching between the controllers along the route (Fig. 12).", None),
    "sweep_indices": ("What moves each KPI across the what-if sweep: Morris mu* and sigma of every factor, Sobol "
                      "total indices of the top factors (docs/sweep.md).", None),
    "aero_linearisation": ("Linearisation of the aerodynamic drag in the vehicle model (Fig. 2a).", None),
    "speed_correction": ("Speed correction of the linearised model (Fig. 2b).", None),
    "power_map_fit": ("Fit of the battery power map of the vehicle model.", None),
    "dp_profile": ("Dynamic-programming speed profile on the study route (Fig. 5a).", None),
    "green_wave_space_time": ("Space-time diagram of the green wave on the study route (Fig. 5b).", None),
    "path_diagram": ("Structural model of the model file: standardized coefficients β of the hierarchical regressions "
                     "on the composites (at the step where each hypothesis is read) and R² of each dependent variable; "
                     "* p < .05, ** p < .01, *** p < .001; dashed: p ≥ .05.", None),
}
#: the caption of every paired plot (figures paired_<kpi> of the drive analysis)
PAIRED_CAPTION = ("Each participant's value in both compared conditions (joined by a line, coloured by group) and the "
                  "condition means with their 95 % CIs.")
SURVEY_FIGURES = ("likert_items",)
FLOW_FIGURES = ("participant_flow",)
CORE_FIGURES = ("aero_linearisation", "speed_correction", "power_map_fit", "dp_profile", "green_wave_space_time")
# survey tables in reading order: the paper-shaped tables first, then the tidy ones
SURVEY_TABLES = ("survey_table3", "survey_table4", "survey_table5", "survey_hypotheses", "survey_fit",
                 "survey_item_flags", "survey_loadings", "survey_reliability", "survey_correlations", "survey_htmt",
                 "survey_fornell_larcker", "survey_regressions", "survey_descriptives")
#: the tables a model without regressions has nothing to show in
NO_REGRESSION_TABLES = ("survey_table5", "survey_hypotheses", "survey_regressions")
DRIVE_TABLES = ("drives_style_table", "drives_summary", "drives_bands", "drives_band_diagnostics",
                "scenarios_bands", "scenarios_band_diagnostics",
                "drives_participant_table", "drives_per_participant", "drives_kpis",
                "sweep_bands", "sweep_indices", "sweep_region")


#: APA titles of the tables whose Markdown title is a file label ("survey: fit"); others keep their own title
TITLES = {
    "participant_flow": "Participants From Enrolment to the Analysed Samples",
    "survey_fit": "Fit of the Confirmatory Factor Analysis (Initial and Final Items)",
    "survey_hypotheses": "Hypotheses Tested in the Hierarchical Regressions",
    "survey_item_flags": "Item-Deletion Diagnostics of the Initial Confirmatory Factor Analysis",
    "survey_loadings": "Standardized Loadings of the Confirmatory Factor Analysis",
    "survey_reliability": "Reliability per Construct: Cronbach's α, ω of a One-Factor Model per Construct, CR and AVE",
    "survey_correlations": "Correlations of the Construct Composites",
    "survey_htmt": "Heterotrait–Monotrait Ratios of the Constructs",
    "survey_fornell_larcker": "Fornell–Larcker Criterion per Pair of Constructs",
    "survey_regressions": "Hierarchical Regressions, Every Step and Predictor",
    "survey_descriptives": "Descriptive Statistics of the Items",
    "survey_extended_omega": "ω From the Joint Confirmatory Factor Analysis (semTools compRelSEM): ML and Ordinal "
                             "Estimators",
    "survey_extended_reliability_boot": "Bootstrap Confidence Intervals of the Reliability Estimates",
    "survey_extended_sem_fit": "Fit of the Latent Structural Equation Model",
    "survey_extended_sem_paths": "Standardized Paths of the Latent Structural Equation Model",
    "survey_extended_sem_r2": "Explained Variance of the Latent Structural Equation Model",
    "survey_extended_full_vif": "Full Collinearity VIF of the Construct Composites (Kock, 2015)",
    "survey_extended_harman": "Harman's Single-Factor Test of Common Method Variance",
    "survey_extended_htmt2": "HTMT and HTMT2 Ratios of the Constructs (Roemer et al., 2021)",
    "survey_extended_indirect": "Indirect Effects Along the Chains of the Model, With Bootstrap Confidence Intervals",
    "survey_extended_ordinal_fit": "Fit of the Ordinal Confirmatory Factor Analysis (ULS and DWLS Estimators)",
    "survey_extended_ordinal_loadings": "Standardized Loadings Under the ML, ULS and DWLS Estimators",
    "survey_extended_vif": "Variance Inflation Factors of the Predictors of the Regressions",
    "survey_extended_invariance": "Measurement Invariance Across Groups",
    "survey_pca_loadings": "Loadings on the First Principal Component of Each Construct",
    "survey_pca_reliability": "Reliability per Construct From the Principal-Component Loadings",
    "scenarios_bands": "Objective KPI Targets of the Paper by Traffic Scenario",
    "scenarios_band_diagnostics": "Diagnostics of the Objective KPI Targets by Traffic Scenario",
    "sweep_bands": "Objective KPI Targets by Traffic Scenario and Across the What-If Sweep",
    "drives_bands": "Objective KPI Targets of the Paper: Published Band, Paper's Value and Ours",
    "drives_band_diagnostics": "Diagnostics of the Objective KPI Targets (Baseline and pEDAS Drives)",
    "drives_summary": "Objective KPIs, Summary Statistics by Group and Route Segment",
    "drives_per_participant": "Objective KPIs per Participant",
    "drives_kpis": "Objective KPIs per Drive",
    "paper_audit": "Audit of the Published Statistics",
}
#: the main text's tables and figures by part of the Results, in reading order; a stem prefix ending in "*" takes
#: every table/figure whose stem starts with it (so statistics added later slot in where they belong)
MAIN = {
    "measurement": ("survey_table3", "survey_table4", "survey_fit*"),
    "structural": ("survey_table5", "survey_hypotheses", "survey_regression_diagnostics*", "path_diagram*"),
    "objective": ("drives_style_table", "drives_kpi_table", "drives_bands", "drives_paired*", "fig9a_savings",
                  "paired_kpis"),
}
#: a table wider than this many columns goes to the appendix (the main text is never cut in a scroll box)
MAX_MAIN_COLUMNS = 9


class Exhibits:
    """The numbered tables and figures of the document as it is written: the part (main text or appendix) and
    section they stand in, their numbers (Table 1 / Table A1), and a reference to an appendix item from the main
    text before the appendix is numbered (:meth:`ref`, resolved by :meth:`resolve`)."""

    def __init__(self, provenance: dict[str, str]):
        self.part, self.section = "main", ""
        self.items: list = []
        self.labels: dict[str, str] = {}
        self.deferred: list[tuple[str, Callable[[], str]]] = []   # (stem, render) for the appendix
        self.provenance = provenance   # "survey" / "drives" -> a note sentence on where the data come from

    def number(self, kind: str, stem: str, title: str, note: str, files: dict[str, str]) -> str:
        from analysis.report.exhibits import Exhibit

        prefix = "A" if self.part == "appendix" else ""
        k = 1 + sum(e.kind == kind and e.part == self.part for e in self.items)
        label = f"{'Table' if kind == 'table' else 'Figure'} {prefix}{k}"
        self.items.append(Exhibit(kind, label, self.part, self.section, stem, title, note, files))
        self.labels[stem] = label
        return label

    @staticmethod
    def ref(stem: str) -> str:
        return f"@@ref:{stem}@@"

    def resolve(self, html_text: str) -> str:
        return re.sub(r"@@ref:([\w.-]+)@@", lambda m: (
            f"<a href=\"#x-{m.group(1)}\">{self.labels[m.group(1)]}</a>" if m.group(1) in self.labels
            else "the files"), html_text)


def _split_md(text: str) -> tuple[str, list[str], list[str]]:
    """(title, table lines, note lines) of a Markdown table file the analysis wrote."""
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip().startswith("|")), len(lines))
    end = next((i for i in range(start, len(lines)) if not lines[i].strip().startswith("|")), len(lines))
    title = ""
    for ln in lines[:start]:
        m = re.match(r"^(?:#{1,6}\s+(.*)|\*\*(.+)\*\*)$", ln.strip())
        if m:
            title = m.group(1) or m.group(2)
    notes = [re.sub(r"^_(.*)_$", r"\1", ln.strip()).rstrip() for ln in lines[end:] if ln.strip()]
    return title, lines[start:end], notes


def _note_text(notes: Sequence[str], cells: str, part: str, ex: Exhibits) -> str:
    """The APA note of a table: its own notes, the significance convention where stars are printed without one,
    and where the data come from."""
    out = [n for n in notes]
    if re.search(r"\d\*", cells) and not any("p <" in n or "level" in n for n in notes):
        out.append(apa.stars_note())
    if ex.provenance.get(part):
        out.append(ex.provenance[part])
    return " ".join(out)


def _files(out: Path, rel_dir: str, stem: str, exts: Sequence[str]) -> dict[str, str]:
    return {e: f"{rel_dir}/{stem}.{e}" for e in exts if (out / rel_dir / f"{stem}.{e}").is_file()}


def _exhibit_table(out: Path, rel_dir: str, stem: str, ex: Exhibits, title: str = "",
                   part: str = "") -> str:
    """A table file (`<rel_dir>/<stem>.md`) as a numbered APA table: number, italic title, the table with
    horizontal rules, the note; recorded in `ex`. A table too wide for the main text is moved to the appendix and
    referred to from here."""
    text = (out / rel_dir / f"{stem}.md").read_text(encoding="utf-8")
    own_title, table, notes = _split_md(text)
    if not table:
        return ""
    ncol = len(_cells(table[0]))
    if ex.part == "main" and ncol > MAX_MAIN_COLUMNS:
        ex.deferred.append((stem, lambda: _exhibit_table(out, rel_dir, stem, ex, title, part)))
        return (f"<p class=\"note\">{esc(TITLES.get(stem, title or own_title or stem))}: "
                f"{Exhibits.ref(stem)} in the appendix ({ncol} columns).</p>")
    title = title or TITLES.get(stem) or own_title or stem.replace("_", " ")
    note = _note_text(notes, "\n".join(table), part or stem.split("_")[0], ex)
    files = _files(out, rel_dir, stem, ("md", "tex", "csv"))
    label = ex.number("table", stem, title, note, files)
    body = _table(table, base=rel_dir)
    if ex.part == "main":
        body = body.replace("<div class=\"scroll\">", "<div>", 1)
    links = " · ".join(f"<a href=\"{esc(p)}\">{esc(k)}</a>" for k, p in files.items() if k != "md")
    return (f"<section class=\"exhibit\" id=\"x-{esc(stem)}\"><p class=\"xlabel\">{esc(label)}</p>"
            f"<p class=\"xtitle\">{esc(title)}</p>{body}"
            + (f"<p class=\"note\"><em>Note.</em> {esc(note)}</p>" if note else "")
            + (f"<p class=\"note\">{links}</p>" if links else "") + "</section>")


def _exhibit_figure(out: Path, rel_dir: str, stem: str, ex: Exhibits, title: str, note: str = "") -> str:
    """A figure file (`<rel_dir>/<stem>.png`) as a numbered APA figure: number, italic title, image, note."""
    files = _files(out, rel_dir, stem, ("png", "svg", "pdf"))
    label = ex.number("figure", stem, title, note, files)
    links = " · ".join(f"<a href=\"{esc(p)}\">{esc(k)}</a>" for k, p in files.items() if k != "png")
    return (f"<figure class=\"exhibit\" id=\"x-{esc(stem)}\"><p class=\"xlabel\">{esc(label)}</p>"
            f"<p class=\"xtitle\">{esc(title)}</p><img src=\"{esc(rel_dir)}/{esc(stem)}.png\" alt=\"{esc(title)}\">"
            f"<figcaption>" + (f"<em>Note.</em> {esc(note)} " if note else "") + links + "</figcaption></figure>")


def _paired_kpi(study, stem: str):
    """(KPI, segment, KPI spec) of the paired figure `stem`: the column of the study's comparison it plots
    (:func:`analysis.drives.paired.kpi_stem`); None when the study compares none such."""
    from analysis.drives.paired import kpi_stem
    from study.folder.kpi_spec import study_spec

    spec = study_spec(study)
    if spec.comparison is None:
        return None
    return next(((kpi, seg, spec) for template, kpi, seg in spec.comparison.columns if kpi_stem(template) == stem),
                None)


def _reading_paired(out: Path, study, stem: str) -> str | None:
    """The paired comparison behind figure `stem` in words (drives/paired.csv): the two condition means and their
    difference with the KPI's declared unit, its 95 % CI, the paired t-test and d_z."""
    from analysis.drives.paired import KPI_WORDS, kpi_label, kpi_words

    hit, df = _paired_kpi(study, stem), _read_csv(out / "drives" / "paired.csv")
    if hit is None or df is None or "KPI" not in df.columns:
        return None
    kpi, seg, spec = hit
    row = df[df["KPI"] == kpi_label(kpi, seg, spec.headings)]
    if row.empty:
        return None
    r, (ctrl, treat) = row.iloc[0], (spec.comparison.control, spec.comparison.treatment)
    unit, d = spec.unit(kpi), spec.decimals(kpi)
    if d == 0 or KPI_WORDS.get(kpi, ("", ""))[1] == "count":
        d = 2   # a mean of counts is no count
    words = kpi_words(kpi, spec) + ("" if seg in ("", "overall") else f", {seg}")
    return (f"{words[:1].upper() + words[1:]}: M = {apa.quantity(r[f'M {ctrl}'], unit, d)} with {ctrl} and "
            f"{apa.quantity(r[f'M {treat}'], unit, d)} with {treat}; {ctrl} − {treat} = "
            f"{apa.quantity(r['M_diff'], unit, d)}, 95 % CI {apa.ci(r['95 % CI LL'], r['95 % CI UL'], d)}, "
            f"t({apa.df_text(r['df'])}) = {apa.num(r['t'])}, {apa.p_text(r['p (t)'])}, d_z = {apa.num(r['d_z'])}.")


def _figure(out: Path, stem: str, study, ex: Exhibits) -> str:
    caption, reader = FIGURES.get(stem, (stem.replace("_", " ") + ".", None))
    if stem.startswith("paired_") and stem not in FIGURES:
        from analysis.drives.paired import kpi_label

        hit = _paired_kpi(study, stem)
        caption = (f"{kpi_label(hit[0], hit[1], hit[2].headings)}: {PAIRED_CAPTION[:1].lower()}{PAIRED_CAPTION[1:]}"
                   if hit else PAIRED_CAPTION)
        reader = lambda o, s: _reading_paired(o, s, stem)  # noqa: E731
    reading = None
    if reader is not None:
        try:
            reading = reader(out, study)
        except (KeyError, ValueError, TypeError, IndexError):
            reading = None  # a figure whose numbers are laid out differently keeps its caption only
    return _exhibit_figure(out, "figures", stem, ex, caption.rstrip("."), reading or "")


def _figures(out: Path, stems: Sequence[str], study, used: set[str], ex: Exhibits) -> list[str]:
    parts = []
    for stem in stems:
        if (out / "figures" / f"{stem}.png").exists() and stem not in used:
            used.add(stem)
            parts.append(_figure(out, stem, study, ex))
    return parts


def _md_table(out: Path, stem: str, used: set[str], ex: Exhibits) -> str:
    f = out / "tables" / f"{stem}.md"
    if not f.exists() or stem in used:
        return ""
    used.add(stem)
    return _exhibit_table(out, "tables", stem, ex)


def _expand(out: Path, patterns: Sequence[str], sub: str, ext: str) -> list[str]:
    """Stems of `<out>/<sub>/*.<ext>` matching the patterns in order (a trailing * is a prefix)."""
    have = sorted(p.stem for p in (out / sub).glob(f"*.{ext}")) if (out / sub).exists() else []
    stems = []
    for pat in patterns:
        for st in ([h for h in have if h.startswith(pat[:-1])] if pat.endswith("*") else
                   [pat] if pat in have else []):
            if st not in stems:
                stems.append(st)
    return stems


def _main_exhibits(out: Path, key: str, study, used_tabs: set, used_figs: set, ex: Exhibits) -> list[str]:
    """The main text's tables and figures of one part of the Results (:data:`MAIN`), those present."""
    pats = MAIN[key]
    parts = []
    tabs, figs = _expand(out, pats, "tables", "md"), _expand(out, pats, "figures", "png")
    for pat in pats:
        for stem in [t for t in tabs if t == pat or pat.endswith("*") and t.startswith(pat[:-1])]:
            if stem == "survey_hypotheses":
                parts.append(_hypotheses_verdicts(out, study, ex, used_tabs))
            else:
                parts.append(_md_table(out, stem, used_tabs, ex))
        for stem in [f for f in figs if f == pat or pat.endswith("*") and f.startswith(pat[:-1])]:
            parts += _figures(out, [stem], study, used_figs, ex)
    return [p for p in parts if p]


def _skipped(reason: str) -> str:
    return f"<p class=\"skipped\">Skipped: {esc(reason)}.</p>"


# ---------------------------------------------------------------------------------------------- sections
def _study_section(out: Path, st, study, mode: str, store_name: str) -> list[str]:
    from analysis.report.figures import participant_flow
    from study.store.studies import current

    row = current(st) or {}
    flow = participant_flow(st)
    excluded = st.df("SELECT scope, reason, count(*) AS n FROM exclusions GROUP BY scope, reason "
                     "ORDER BY scope, reason")
    has_drives = bool(st.one("SELECT count(*) FROM drives"))
    # counts per analysis that ran: the survey analysis (its respondents), the within-subjects tests (those with
    # every condition), the drive analysis
    resp = _read_csv(out / "survey" / "responses.csv")
    samples = [f"{len(resp)} in the survey analysis"] if resp is not None else []
    aov = _read_csv(out / "within" / "anova.csv")
    if aov is not None and "n" in aov.columns and len(aov):
        samples.append(f"{int(aov['n'].min())} with every condition in the within-subjects tests")
    if has_drives:
        samples.append(f"{flow.objective_sample} in the drive analysis")
    parts = ["<h2 id=\"study\">Study</h2>"]
    if study.summary:
        parts.append(f"<p>{esc(study.summary)}</p>")
    else:   # the participants' description is not a study description
        parts.append("<p class=\"note\">The study declares no researcher-facing summary (<code>[study] summary"
                     "</code> in study.toml).</p>")
    conds = "; ".join(f"<code>{esc(c.name)}</code> ({esc(c.label)})" for c in study.conditions)
    attrs = ", ".join(f"{esc(a.name)} ({esc(a.type)})" for a in study.attributes) or "none"
    excl = "; ".join(f"{int(r.n)} {esc(str(r.reason).replace('_', ' '))} ({esc(r.scope)})"
                     for r in excluded.itertuples()) or "none"
    parts.append("<dl>"
                 f"<dt>Study</dt><dd><code>{esc(study.study_id)}</code>, version {esc(row.get('version', '–'))}, "
                 f"definition sha256 <code>{esc(study.hash[:12])}</code></dd>"
                 f"<dt>Conditions</dt><dd>{conds}</dd>"
                 f"<dt>Participant attributes</dt><dd>{attrs}</dd>"
                 f"<dt>Participants</dt><dd>{flow.enrolled} registered"
                 + (f"; {', '.join(samples)}" if samples else "") + f"</dd><dt>Exclusions</dt><dd>{excl}</dd>"
                 f"<dt>Report</dt><dd>{esc(mode)}, store <code>{esc(store_name)}</code></dd></dl>")
    return parts


def _flow_main(out: Path, study, used_figs: set, used_tabs: set, ex: Exhibits) -> list[str]:
    """The participant flow of the main text: the flow figure (the table of counts in the appendix)."""
    parts = ["<h3 id=\"participant-flow\">Participants</h3>"]
    figs = _figures(out, FLOW_FIGURES, study, used_figs, ex)
    if (out / "tables" / "participant_flow.md").exists():
        ex.deferred.append(("participant_flow", lambda: _md_table(out, "participant_flow", used_tabs, ex)))
        parts.append(f"<p>Counts per stage: {Exhibits.ref('participant_flow')}; per protocol phase: "
                     f"{Exhibits.ref('protocol_phases')}.</p>")
    return parts + figs


def _phases_table(out: Path, st, study, ex: Exhibits) -> str:
    """Participants per protocol phase (completed, aborted, in progress), a numbered appendix table; its cells also
    as ``tables/protocol_phases.{csv,md,tex}`` (the Word and LaTeX outputs read a table from its files)."""
    ev = st.df("SELECT p.protocol, e.phase, e.outcome, count(*) AS n FROM phase_events e "
               "JOIN participants p USING (participant_id) GROUP BY ALL")
    if ev.empty:
        return "<p>No protocol phase has been recorded in the store.</p>"
    order: list[tuple[str, str]] = []
    for name, proto in study.protocols.items():
        order += [(name, ph) for ph in proto.phases]
    order += sorted({(r.protocol, r.phase) for r in ev.itertuples()} - set(order))
    outcomes = ("completed", "aborted", "in_progress")
    rows, table = [], []
    for proto, phase in order:
        sub = ev[(ev["protocol"] == proto) & (ev["phase"] == phase)]
        if sub.empty and proto not in set(ev["protocol"]):
            continue
        counts = [int(sub.loc[sub["outcome"] == o, "n"].sum()) for o in outcomes]
        table.append((proto, phase, *counts))
        rows.append(f"<tr><td>{esc(proto)}</td><td>{esc(phase)}</td>"
                    + "".join(f"<td class=\"r\">{c}</td>" for c in counts) + "</tr>")
    title = "Participants per Protocol Phase"
    note = "Counts of phase events recorded in the store."
    frame = pd.DataFrame(table, columns=["Protocol", "Phase", "Completed", "Aborted", "In progress"])
    write_table(frame, out / "tables", "protocol_phases", title, [note])
    label = ex.number("table", "protocol_phases", title, note, _files(out, "tables", "protocol_phases",
                                                                        ("md", "tex", "csv")))
    return (f"<section class=\"exhibit\" id=\"x-protocol_phases\"><p class=\"xlabel\">{label}</p>"
            f"<p class=\"xtitle\">{title}</p><div class=\"scroll\"><table><thead><tr>"
            "<th>Protocol</th><th>Phase</th><th class=\"r\">Completed</th><th class=\"r\">Aborted</th>"
            "<th class=\"r\">In progress</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table></div>"
            "<p class=\"note\"><em>Note.</em> Counts of phase events recorded in the store.</p></section>")


def _scale_text(ins, item: str) -> str:
    """'7-point' of a rating scale, 'min-max slider in steps of k' of a slider/VAS item."""
    lo, hi = ins.scale(item)
    if str(ins.items.loc[item, "response_type"]) == "slider":
        return f"{lo}-{hi} slider in steps of {ins.step(item)}"
    return f"{hi - lo + 1}-point"


def _methods_section(out: Path, st, study, ran: tuple[str, ...]) -> list[str]:
    parts = ["<h2 id=\"methods\">Method</h2>"]
    sw = ", ".join(f"{esc(n)} {esc(v)}" for n, v in software_versions(ran))
    parts.append(f"<p><strong>Software.</strong> {sw}.</p>")
    settings = {}
    sfile = out / "survey" / "settings.json"
    if sfile.is_file():
        settings = json.loads(sfile.read_text(encoding="utf-8"))
    if study.instruments:
        ins = study.instrument()
        scales = pd.Series([_scale_text(ins, i) for i in ins.scaled_items], dtype=object).value_counts()
        by_type = ", ".join(f"{n} on {'a ' if 'slider' in k else ''}{k}{'' if 'slider' in k else ' scales'}"
                            for k, n in sorted(scales.items(), key=lambda kv: (-kv[1], kv[0])))
        rev = ", ".join(ins.reverse_items) or "none"
        parts.append(f"<p><strong>Instrument.</strong> <code>{esc(ins.name)}</code>: {len(ins.items)} items"
                     + (f" ({esc(by_type)})" if by_type else "") + f"; reverse-scored: {esc(rev)}.</p>")
    model = study.model
    if model is not None:
        mm = "; ".join(f"{esc(c)} =~ {esc(' + '.join(items))}" for c, items in model.measurement.items())
        analysis = study.settings.get("analysis", {})
        dropped = settings.get("dropped_items") or []
        parts.append("<p><strong>Measurement model.</strong> Confirmatory factor analysis by maximum likelihood "
                     "(semopy) in two stages: every scaled item on its construct (initial; items with a "
                     f"standardized loading below {esc(apa.num(analysis.get('min_loading', 0.7), 2, bounded=True))} "
                     "flagged), then the "
                     f"model file's measurement model (final): {mm}."
                     + (f" Items left out of the final model: {esc(', '.join(dropped))}." if dropped else "")
                     + " Reliability and validity on the final items (Cronbach's α, composite reliability, AVE, "
                       "Fornell-Larcker, HTMT); construct scores are the means of the retained items"
                     + (", participants with a missing answer left out (listwise)." if settings.get("listwise", True)
                        else ".") + "</p>")
        regs = []
        for m in model.regressions:
            steps = "; ".join(f"step {k}: {esc(' + '.join(b))}" for k, b in enumerate(m.blocks, start=1))
            regs.append(f"<li>model {esc(m.name)}, {esc(m.dv)}: {steps}</li>")
        boot = settings.get("n_boot")
        boot_txt = (f" Bootstrap confidence intervals of B: {esc(boot)} {esc(settings.get('boot_method', ''))} "
                    f"resamples (seed {esc(settings.get('seed'))})." if boot else "")
        parts.append("<p><strong>Regressions.</strong> Hierarchical ordinary least squares regressions "
                     "(statsmodels) on the construct scores and declared participant attributes, predictors "
                     "entered block by block with the F test of ΔR²." + boot_txt + "</p><ul>" + "".join(regs)
                     + "</ul>")
        # the p value is the two-sided one as printed in the regression table; the sign is the expected direction
        signs = {">": "expected positive: β > 0 and two-sided p < α",
                 "<": "expected negative: β < 0 and two-sided p < α", "!=": "no expected sign: two-sided p < α"}
        hyps = "".join(f"<li>{esc(h.hypothesis)}: {esc(h.path)} in model {esc(h.model)} step {h.step} "
                       f"({esc(signs.get(h.sign, h.sign))})</li>" for h in model.hypotheses)
        if hyps:
            parts.append(f"<p><strong>Hypotheses</strong> at α = {esc(apa.num(study.alpha, 2, bounded=True))}:</p>"
                         f"<ul>{hyps}</ul>")
    parts += _procedure(study, st)
    src = st.df("SELECT source, count(*) AS n FROM drives GROUP BY source ORDER BY source")
    if not src.empty:
        parts += _measures_methods(study)
        what = ", ".join(f"{int(r.n)} {esc(r.source)}" for r in src.itertuples())
        kpis = study.paths.get("kpis")
        parts.append(f"<p><strong>Drives.</strong> {what} drive(s) in the store; KPIs computed in DuckDB from the "
                     f"drive samples" + (f" as the study declares them (<code>{esc(kpis)}</code>)" if kpis else "")
                     + ("; simulated drives by virtual participants in SUMO traffic (libsumo)"
                        if "simulation" in set(src["source"]) else "") + ".</p>")
    return parts


def _measures_methods(study) -> list[str]:
    """The methods sentences of the study's shipped standard driving measures (SAE J2944 reporting), if any."""
    from analysis.drives.measure_tables import methods_sentences
    from study.folder.kpi_spec import study_spec

    sentences = methods_sentences(study_spec(study))
    return [f"<p><strong>Drive measures.</strong></p><ul>{''.join(f'<li>{esc(x)}</li>' for x in sentences)}</ul>"] \
        if sentences else []


def _admissibility(out: Path) -> tuple[list[str], dict[str, str]]:
    """The warnings of the fits the hypotheses rest on: global ones (the final CFA, the latent SEM's matrix and
    R²) and per path (a standardized SEM path with |β| >= 1), from the survey's warnings files."""
    lines = []
    for f in (out / "survey" / "warnings.txt", out / "survey" / "extended" / "warnings.txt"):
        if f.is_file():
            lines += [w for w in f.read_text(encoding="utf-8").splitlines() if w.strip()]
    per_path: dict[str, str] = {}
    glob = []
    for w in lines:
        m = re.match(r"SEM: standardized path (.+?) = (-?[\d.]+)", w)
        if m:
            per_path[m.group(1).strip()] = f"latent SEM path β = {apa.num(float(m.group(2)), 2)} (|β| ≥ 1, improper)"
        elif w.startswith(("CFA final", "SEM:")) and apa.minus(w.replace("R^2", "R²")) not in glob:
            glob.append(apa.minus(w.replace("R^2", "R²")))
    return glob, per_path


#: what each built-in KPI measures, with its unit (docs/kpis.md has the thresholds)
BUILTIN_KPIS = {
    "energy_wh": "battery energy used (Wh)", "distance_m": "distance driven (m)", "trip_time_s": "trip time (s)",
    "mean_speed_mps": "mean speed (m/s)", "wh_per_km": "energy per distance (Wh/km)",
    "violation_distance_m": "distance above the speed limit plus its tolerance (m)",
    "violation_share": "share of the distance above the limit plus tolerance (0–1)",
    "violation_events": "speeding episodes of at least the minimum duration (count)",
    "tl_crossed": "traffic lights crossed (count)", "tl_crossed_green": "lights crossed in green (count)",
    "tl_crossed_yellow": "lights crossed in yellow (count)", "tl_crossed_red": "lights crossed in red (count)",
    "tl_green_passes": "lights passed in green without a stop (count)", "red_stops": "stops at a red light (count)",
    "stops": "stops (count)", "rms_jerk": "root mean square of the jerk (m/s³)",
    "mean_abs_a": "mean absolute acceleration (m/s²)",
}


def _procedure(study, st) -> list[str]:
    """The drives as the protocol runs them (every phase, familiarisation included, and the order sequences) and
    what each KPI measures with its unit; nothing for a study that stores no drives."""
    from study.folder.protocol_file import protocol_orders

    if not st.one("SELECT count(*) FROM drives"):
        return []
    out = []
    for name, proto in study.protocols.items():
        orders = protocol_orders(proto)
        seq = "; ".join(f"{esc(o)}: {esc(' → '.join(ph))}" for o, ph in orders.items())
        out.append(f"<p><strong>Procedure</strong> (protocol <code>{esc(name)}</code>): "
                   + (f"{len(orders)} order sequences ({seq})" if len(orders) > 1 else f"phases {seq}") + ".</p>")
    from study.folder.kpi_spec import EventKpi, MeasureKpi, study_spec

    spec = study_spec(study)   # the stored study passed its check: its KPI file parses
    kpis = [f"{esc(k)}: {esc(BUILTIN_KPIS[k])}" for k in spec.columns if k in BUILTIN_KPIS]
    for k in spec.user_kpis:
        if isinstance(k, EventKpi):
            what = f"{k.statistic} time from <code>{esc(k.start)}</code> to <code>{esc(k.end)}</code>"
        elif isinstance(k, MeasureKpi):   # its definition is the methods sentence of the drive measures
            what = f"the standard measure <code>{esc(k.measure)}</code>"
        else:
            what = f"<code>{esc(k.sql)}</code>"
        kpis.append(f"{esc(k.heading)}: {what}")
    if kpis:
        out.append("<p><strong>KPIs</strong> per drive (and per route segment): " + "; ".join(kpis) + ".</p>")
    return out


def _hypotheses_verdicts(out: Path, study, ex: Exhibits, used_tabs: set) -> str:
    df = _read_csv(out / "survey" / "hypotheses.csv")
    if df is None or df.empty or study.model is None:
        return ""
    used_tabs.add("survey_hypotheses")
    sign = {h.hypothesis: h.sign for h in study.model.hypotheses}
    expect = {">": "positive", "<": "negative", "!=": "non-zero"}
    glob, per_path = _admissibility(out)
    rows = []
    for r in df.itertuples():
        ok = str(r.supported).strip().lower() in ("true", "1", "yes")
        verdict = "supported" if ok else "not supported"
        if r.path in per_path:
            verdict += f", but {per_path[r.path]}"
        rows.append(f"<tr><td>{esc(r.hypothesis)}</td><td>{esc(r.path)}</td>"
                    f"<td>{expect.get(sign.get(r.hypothesis, '!='), '')}</td>"
                    f"<td class=\"r\">{esc(apa.num(r.beta, 2, bounded=True))}</td>"
                    f"<td class=\"r\">{esc(apa.p_value(r.p))}</td><td>{esc(verdict)}</td></tr>")
    n_ok = sum(str(x).strip().lower() in ("true", "1", "yes") for x in df["supported"])
    n = int(df["n"].iloc[0]) if "n" in df.columns else None
    note = (f"{'N = ' + str(n) + '. ' if n else ''}β: standardized coefficient of the predictor in the step of the "
            f"hierarchical OLS regression the hypothesis names; p two-sided; supported: expected sign and "
            f"p < α = {apa.num(study.alpha, 2, bounded=True)}."
            + (" The fits these estimates rest on are not admissible: " + "; ".join(glob) + "." if glob else ""))
    title = "Hypotheses: Verdicts"
    files = _files(out, "tables", "survey_hypotheses", ("md", "tex", "csv"))
    label = ex.number("table", "survey_hypotheses", title, note, files)
    box = (f"<p class=\"verdict{' mixed' if glob else ''}\">{n_ok} of {len(df)} hypotheses supported at "
           f"α = {esc(apa.num(study.alpha, 2, bounded=True))}"
           + (f", but the solutions they rest on are improper ({esc('; '.join(glob))})" if glob else "") + ".</p>")
    return (box + f"<section class=\"exhibit\" id=\"x-survey_hypotheses\"><p class=\"xlabel\">{label}</p>"
            f"<p class=\"xtitle\">{title}</p><div><table><thead><tr><th>Hypothesis</th>"
            "<th>Path</th><th>Expected</th><th class=\"r\">β</th><th class=\"r\">p</th><th>Verdict</th></tr>"
            "</thead><tbody>" + "".join(rows) + f"</tbody></table></div><p class=\"note\"><em>Note.</em> "
            f"{esc(note)}</p></section>")


def _warnings_list(out: Path) -> list[str]:
    parts = []
    for title, f in (("Warnings of the analysis", out / "survey" / "warnings.txt"),
                     ("Warnings of the extended statistics", out / "survey" / "extended" / "warnings.txt")):
        if f.is_file() and f.read_text(encoding="utf-8").strip():
            items = "".join(f"<li>{esc(apa.minus(w))}</li>" for w in f.read_text(encoding="utf-8").splitlines()
                            if w)
            parts.append(f"<p><strong>{title}</strong></p><ul>{items}</ul>")
    return parts


def _survey_main(out: Path, study, skipped: dict, used_figs: set, used_tabs: set, ex: Exhibits) -> list[str]:
    """The measurement model, the structural model and hypotheses: the main text's survey results."""
    if "survey" in skipped:
        return ["<h3 id=\"measurement-model\">Measurement model</h3>", _skipped(skipped["survey"])]
    if not (out / "survey").exists():
        return ["<h3 id=\"measurement-model\">Measurement model</h3>", _skipped("the survey step did not run")]
    ex.section = "Measurement model"
    parts = ["<h3 id=\"measurement-model\">Measurement model</h3>"]
    parts += _main_exhibits(out, "measurement", study, used_tabs, used_figs, ex)
    parts += _warnings_list(out)
    ex.section = "Structural model and hypotheses"
    parts.append("<h3 id=\"structural-model\">Structural model and hypotheses</h3>")
    regressions = _read_csv(out / "survey" / "regressions.csv")
    if regressions is not None and regressions.empty:
        parts.append("<p>The analysis model declares no regressions: no regression table and no hypotheses.</p>")
        used_tabs.update(NO_REGRESSION_TABLES)
    else:
        parts += _main_exhibits(out, "structural", study, used_tabs, used_figs, ex)
    return parts


def _within_section(out: Path, skipped: dict, used_tabs: set, ex: Exhibits) -> list[str]:
    """The within-subjects comparison (analysis.within): the generated methods and results sentences, the test
    tables and a figure of individual lines per variable in the main text; the order counts, mixed model,
    reliability and item tables in the appendix. Absent for a study without [within]."""
    d = out / "within"
    if "within" not in skipped and not d.exists():
        return []
    ex.section = "Within-subjects comparisons"
    parts = ["<h3 id=\"within\">Within-subjects comparisons</h3>"]
    if "within" in skipped:
        return parts + [_skipped(skipped["within"])]
    text = (d / "methods.md").read_text(encoding="utf-8")
    parts.append(markdown_to_html(text.split("\n", 1)[1], heading_offset=3))
    used_tabs.update(f"within_{p.stem}" for p in d.glob("*.md"))   # the copies in tables/ are the same tables
    if _within_summary(d):
        parts.append(_exhibit_table(out, "within", "summary_table", ex, part="within"))
    for stem in ("descriptives", "anova", "posthoc"):
        if (d / f"{stem}.md").is_file() and len(pd.read_csv(d / f"{stem}.csv")):
            ex.deferred.append((f"within_{stem}", lambda stem=stem: _within_table(out, stem, ex)))
    variables = pd.read_csv(d / "descriptives.csv")["variable"].drop_duplicates()
    labels = _within_labels(d)
    for variable in variables:
        if (d / f"lines_{variable}.png").is_file():
            parts.append(_exhibit_figure(
                out, "within", f"lines_{variable}", ex, f"{labels.get(variable, variable)} by Condition",
                "One grey line per participant; the condition means with their 95 % confidence intervals in black."))
    for stem in ("orders", "friedman", "mixed", "mixed_fit", "reliability", "item_descriptives"):
        if (d / f"{stem}.md").is_file() and len(pd.read_csv(d / f"{stem}.csv")):
            ex.deferred.append((f"within_{stem}", lambda stem=stem: _within_table(out, stem, ex)))
    return parts


def _within_table(out: Path, stem: str, ex: Exhibits) -> str:
    """A within-subjects table, from its copy in tables/ (stem ``within_<stem>``) where the collect step made one."""
    if (out / "tables" / f"within_{stem}.md").is_file():
        return _exhibit_table(out, "tables", f"within_{stem}", ex, part="within")
    return _exhibit_table(out, "within", stem, ex, part="within")


def _within_labels(d: Path) -> dict[str, str]:
    """'label (unit)' of each within-subjects variable (``within/variables.csv``); empty for an older folder."""
    from analysis.within.analyze import axis_label

    found = _read_csv(d / "variables.csv")
    if found is None or not {"variable", "label", "unit"} <= set(found.columns):
        return {}
    return {str(v.variable): axis_label(v) for v in found.itertuples()}


def _within_summary(d: Path) -> bool:
    """Write `within/summary_table.{csv,md,tex}`: per variable, M (SD) under each condition and the
    repeated-measures ANOVA (F with its df, p, partial η², Greenhouse–Geisser ε) in one APA table of the main text;
    False when the comparison wrote no descriptives or ANOVA."""
    from analysis.render import latex_table, markdown_table

    desc, aov = _read_csv(d / "descriptives.csv"), _read_csv(d / "anova.csv")
    if desc is None or aov is None or desc.empty or aov.empty:
        return False
    conds = list(dict.fromkeys(desc["condition"].astype(str)))
    aov = aov.set_index("variable")
    labels = _within_labels(d)
    header = ["Variable"] + [f"{c} M (SD)" for c in conds] + ["df", "F", "p", "ηp²", "ε (GG)"]
    rows, frame = [], []
    for v, g in desc.groupby("variable", sort=False):
        g = g.set_index(g["condition"].astype(str))
        cells = [f"{apa.num(g.loc[c, 'mean'], 2)} ({apa.num(g.loc[c, 'sd'], 2)})" if c in g.index else "–"
                 for c in conds]
        a = aov.loc[v] if v in aov.index else None
        test = ([f"{apa.df_text(a['df1'])}, {apa.df_text(a['df2'])}", apa.num(a["f"], 2), apa.p_value(a["p"]),
                 apa.num(a["np2"], 2, bounded=True), apa.num(a["eps_gg"], 2, bounded=True)]
                if a is not None else ["–"] * 5)
        rows.append([labels.get(str(v), str(v))] + cells + test)
        frame.append(dict(zip(header, rows[-1])))
    n = int(aov["n"].min()) if "n" in aov.columns else None
    title = "Dependent Variables by Condition: Means, Standard Deviations and Repeated-Measures ANOVA"
    notes = [(f"n = {n} participants with every condition in the ANOVA; " if n else "")
             + "descriptives use every available value. ηp²: partial eta squared; ε (GG): Greenhouse–Geisser "
             "epsilon (the corrected p is in the appendix table of the ANOVA)."]
    pd.DataFrame(frame).to_csv(d / "summary_table.csv", index=False)
    (d / "summary_table.md").write_text(markdown_table(header, rows, title, notes, title_style="bold"),
                                        encoding="utf-8")
    (d / "summary_table.tex").write_text(latex_table(header, rows, title, notes, label="tab:within_summary"),
                                         encoding="utf-8")
    return True


def _drives_main(out: Path, study, skipped: dict, used_figs: set, used_tabs: set, ex: Exhibits) -> list[str]:
    ex.section = "Objective measures"
    parts = ["<h3 id=\"drive-results\">Objective measures</h3>"]
    if "drives" in skipped:
        return parts + [_skipped(skipped["drives"])]
    if not (out / "drives").exists():
        return parts + [_skipped("the drives step did not run")]
    parts += _main_exhibits(out, "objective", study, used_tabs, used_figs, ex)
    for replay in sorted((out / "drives").glob("replay_*.html")):
        who = replay.stem.removeprefix("replay_")
        parts.append(f"<p>Replay of {esc(who)}'s drives (time slider, the HUD as the driver saw it): "
                     f"<a href=\"drives/{esc(replay.name)}\">{esc(replay.name)}</a></p>")
    return parts


def _reproduction_section(out: Path, skipped: dict, used_tabs: set, ex: Exhibits) -> list[str]:
    ex.section = "Reproduction of the published values"
    parts = ["<h3 id=\"reproduction\">Reproduction of the published values</h3>"]
    if "reproduction" in skipped:
        return parts + [_skipped(skipped["reproduction"])]
    df = _read_csv(out / "reproduction.csv")
    if df is None or "status" not in df.columns:
        return parts + [_skipped("the reproduction step wrote no reproduction.csv")]
    counts = df["status"].value_counts()
    parts.append("<p>Every published value, its status: " + "; ".join(
        f"{esc(k)}: {int(v)}" for k, v in sorted(counts.items())) + ". Details: <a href=\"reproduction.md\">"
        "reproduction.md</a> · <a href=\"reproduction.csv\">reproduction.csv</a> · "
        "<a href=\"paper/audit.md\">paper/audit.md</a>.</p>")
    tab = _md_table(out, "paper_audit", used_tabs, ex)
    return parts + ([tab] if tab else [])


def _verdict_box(out: Path, st, study, mode: str) -> tuple[str, dict[str, str]]:
    """The first screen: where the data of each part come from, and separate verdicts (published survey values,
    objective KPI targets). Returns the box and the provenance sentence per part for the tables' notes."""
    items, prov = [], {}
    reference = mode == "reference study"
    missed_band = False
    if study.instruments:
        n_resp = _read_csv(out / "survey" / "responses.csv")
        n_txt = f"{len(n_resp)} respondents" if n_resp is not None else "the stored answers"
        if reference:
            prov["survey"] = ("Data: reconstructed survey answers fitted to the published tables "
                              "(data/reference/README.md), not the original participants' answers.")
            items.append(f"<li><strong>Survey data</strong>: a <em>reconstruction</em> ({n_txt}) fitted to the "
                         "paper's published Tables 3–5 (<code>data/reference/README.md</code>), not the study's "
                         "raw answers, which were never published: agreement with those tables is largely by "
                         "construction.</li>")
        else:
            items.append(f"<li><strong>Survey data</strong>: {n_txt} as entered or imported into the store.</li>")
    src = st.df("SELECT source, count(*) AS n FROM drives GROUP BY source ORDER BY source")
    if not src.empty:
        sim = int(src.loc[src["source"] == "simulation", "n"].sum())
        rec = int(src["n"].sum()) - sim
        what = []
        if sim:
            what.append(f"{sim} drives <em>simulated</em> by the simulation core (virtual participants in SUMO "
                        "traffic), not recorded from people")
            prov["drives"] = "Data: drives simulated by the simulation core (virtual participants)."
        if rec:
            what.append(f"{rec} drive logs recorded in the simulator and imported")
        items.append(f"<li><strong>Drive data</strong>: {'; '.join(what)}.</li>")
    rep = _read_csv(out / "reproduction.csv")
    if rep is not None and "status" in rep.columns and len(rep):
        status = rep["status"].astype(str)
        met = int(status.str.startswith(("match", "within tolerance")).sum())
        explained = int(status.str.startswith("audit finding").sum())
        missed = int((status == "miss").sum())
        tables = ", ".join(sorted({str(t).replace("table", "Table ") for t in rep["table"].dropna().unique()}))
        items.append(f"<li><strong>Published survey values</strong> ({esc(tables)}, {len(rep)} values): {met} met "
                     f"(match or within tolerance), {explained} explained by audit findings (contradicted by other "
                     f"published values), {missed} missed"
                     + (" — on the reconstructed data, so this checks the analysis code, not the study's result"
                        if reference else "") + ".</li>")
    bands = _read_csv(out / "tables" / "drives_bands.csv")
    if bands is not None and {"band", "holds"} <= set(bands.columns) and len(bands):
        from analysis.drives.band_diagnostics import COUNT_UNITS
        from analysis.drives.savings import BAND_UNITS

        diag = _read_csv(out / "tables" / "drives_band_diagnostics.csv")
        held = bands["holds"].astype(str).str.lower().isin(("true", "1", "yes"))
        missed_band = not held.all()
        met = "; ".join(esc(b) for b in bands.loc[held, "band"])
        miss = []
        for r in bands[~held].itertuples():
            why = ""
            if diag is not None and "band" in diag.columns:
                d = diag[diag["band"] == r.band]
                if len(d):
                    q = d.iloc[0]
                    if q["unit"] in COUNT_UNITS:   # a count: "2 baseline vs 1 pEDAS drives"
                        why = (f"; {q['quantity']}: {apa.num(q['baseline'], 0)} baseline vs "
                               f"{apa.num(q['pedas'], 0)} pEDAS {q['unit']}")
                    else:
                        why = (f"; {q['quantity']}: {apa.quantity(q['baseline'], q['unit'], 1)} baseline vs "
                               f"{apa.quantity(q['pedas'], q['unit'], 1)} pEDAS")
            unit = BAND_UNITS.get(r.band, "")
            miss.append(f"{esc(r.band)} (ours {esc(apa.quantity(r.our_value, unit, 1))}, paper "
                        f"{esc(apa.quantity(r.paper_value, unit, 1))}{esc(why)})")
        items.append(f"<li><strong>Objective KPI targets</strong>: {int(held.sum())} of {len(bands)} bands met"
                     + (f" — met: {met}" if met else "") + (f"; missed: {'; '.join(miss)}" if miss else "")
                     + f". Details: {Exhibits.ref('drives_bands')}.</li>")
    if not items:
        return "", prov
    cls = "verdict mixed" if reference or missed_band else "verdict"
    return f"<div class=\"{cls}\"><p><strong>Data and verdicts</strong></p><ul>{''.join(items)}</ul></div>", prov


def _appendix(out: Path, st, study, steps, skipped: dict, used_figs: set, used_tabs: set, core: bool,
              absent: set[str], ex: Exhibits) -> list[str]:
    """Everything the main text does not show, numbered Table A1…/Figure A1…: the tables moved out of the main
    text, the remaining survey and drive tables and figures, the simulation core, the audit, the files."""
    ex.part = "appendix"
    parts = ["<h2 id=\"appendix\">Appendix</h2>",
             "<p>Tables and figures not shown in the main text, numbered A1, A2, … in the order the main text "
             "refers to them, then by part.</p>"]
    ex.section = "Sample"
    parts.append("<h3>Sample</h3>")
    for stem, render in [d for d in ex.deferred if d[0] == "participant_flow"]:
        parts.append(render())
    parts.append(_phases_table(out, st, study, ex))
    used_tabs.add("protocol_phases")   # the files it writes into tables/ are this table, not another one
    ex.section = "Moved from the main text"
    moved = [d for d in ex.deferred if d[0] != "participant_flow"]
    if moved:
        parts.append("<h3>Tables moved from the main text</h3>")
        parts += [render() for _, render in moved]
    if "survey" not in absent and (out / "survey").exists() and "survey" not in skipped:
        ex.section = "Survey"
        parts.append("<h3>Survey</h3>")
        parts += _figures(out, SURVEY_FIGURES, study, used_figs, ex)
        stems = list(SURVEY_TABLES) + sorted(p.stem for p in (out / "tables").glob("survey_*.md"))
        parts += [t for t in (_md_table(out, s, used_tabs, ex) for s in stems) if t]
    if (out / "drives").exists() and "drives" not in skipped:
        ex.section = "Drives"
        parts.append("<h3>Drives</h3>")
        known = list(FIGURES)
        drive_figs = sorted((p.stem for p in (out / "drives" / "figures").glob("*.png")),
                            key=lambda stem: (known.index(stem) if stem in known else len(known), stem)) \
            if (out / "drives" / "figures").exists() else []
        stems = list(DRIVE_TABLES) + sorted(p.stem for p in (out / "tables").glob("drives_*.md"))
        parts += [t for t in (_md_table(out, s, used_tabs, ex) for s in stems) if t]
        parts += _figures(out, drive_figs + ["sweep_indices"], study, used_figs, ex)
    if core:
        ex.section = "Simulation core"
        parts.append("<h3 id=\"simulation-core\">Simulation core</h3>")
        if "core figures" in skipped:
            parts.append(_skipped(skipped["core figures"]))
        else:
            figs = _figures(out, CORE_FIGURES, study, used_figs, ex)
            parts += (["<p>Figures of the vehicle model and the controller of the simulator.</p>"] + figs
                      if figs else [_skipped("the core figures step did not run")])
    if "reproduction" not in absent:
        parts += _reproduction_section(out, skipped, used_tabs, ex)
    rest_tabs = [p.stem for p in sorted((out / "tables").glob("*.md")) if p.stem not in used_tabs] \
        if (out / "tables").exists() else []
    rest_figs = [p.stem for p in sorted((out / "figures").glob("*.png")) if p.stem not in used_figs] \
        if (out / "figures").exists() else []
    if rest_tabs or rest_figs:
        ex.section = "Other tables and figures"
        parts.append("<h3>Other tables and figures</h3>")
        parts += [t for t in (_md_table(out, s, used_tabs, ex) for s in rest_tabs) if t]
        parts += _figures(out, rest_figs, study, used_figs, ex)
    return parts + _files_section(out, steps, skipped)


def _files_section(out: Path, steps, skipped: dict) -> list[str]:
    parts = ["<h3 id=\"files\">Steps and files</h3>"]
    rows = []
    for s in steps:
        reason = skipped.get(s.name)
        rows.append(f"<tr><td>{esc(s.name)}</td><td>{'skipped: ' + esc(reason) if reason else 'produced'}</td></tr>")
    for part, reason in sorted(skipped.items()):
        if part not in {s.name for s in steps}:
            rows.append(f"<tr><td>{esc(part)}</td><td>skipped: {esc(reason)}</td></tr>")
    parts.append("<div class=\"scroll\"><table><caption>Steps</caption><thead><tr><th>step</th><th>outcome</th>"
                 "</tr></thead><tbody>" + "".join(rows) + "</tbody></table></div>")
    for title, sub in (("Survey analysis", "survey"), ("Drive analysis", "drives"), ("Paper audit", "paper"),
                       ("Tables", "tables"), ("Figures", "figures")):
        d = out / sub
        if d.exists():
            files = sorted(f for f in d.iterdir() if f.is_file())
            if files:
                links = "".join(f"<li><a href=\"{esc(sub)}/{esc(f.name)}\">{esc(f.name)}</a></li>" for f in files)
                parts.append(f"<h4>{esc(title)} (<code>{esc(sub)}/</code>)</h4><ul class=\"files\">{links}</ul>")
    top = [f for f in ("reproduction.md", "reproduction.csv") if (out / f).exists()] + ["exhibits.json"]
    if top:
        parts.append("<p>" + " · ".join(f"<a href=\"{esc(f)}\">{esc(f)}</a>" for f in top) + "</p>")
    return parts


def render_document(out: Path, st, steps, skipped: dict[str, str], mode: str = "lab store",
                    store_name: str = "", core: bool = True, absent: set[str] = frozenset()) -> Path:
    """Write `out/index.html`: the whole report as one document (module docstring) for the study of the open
    store `st`, and `out/exhibits.json`, its numbered tables and figures in reading order
    (:mod:`analysis.report.exhibits`); `steps` are the pipeline's StepResults, `skipped` the parts not produced with
    their reasons; `core`: whether the simulation core's figures belong to the study (without them there is no such
    section); `absent`: the parts the study's declaration rules out (no section either,
    :func:`analysis.report.build.absent_parts`)."""
    from analysis.report.exhibits import write_exhibits
    from study.store.studies import definition

    out = Path(out)
    study = definition(st)
    used_figs: set[str] = set()
    used_tabs: set[str] = set()
    box, prov = _verdict_box(out, st, study, mode)
    ex = Exhibits(prov)
    body = [f"<h1>{esc(study.title)}</h1>", "<p class=\"note\">Report of study <code>"
            f"{esc(study.study_id)}</code> generated by pedas-study from the study store. Main text: "
            "<a href=\"#study\">Study</a> · <a href=\"#methods\">Method</a> · <a href=\"#results\">Results</a>; "
            "<a href=\"#appendix\">Appendix</a>.</p>", box]
    body += _study_section(out, st, study, mode, store_name)
    ex.section = "Method"
    ran = (*(("survey",) if "survey" not in skipped else ()),
           *(("within",) if (out / "within" / "anova.csv").is_file() and "within" not in skipped else ()),
           *(("simulation",) if mode == "reference study" else ()))
    body += _methods_section(out, st, study, ran)
    ex.section = "Participants"
    body += _flow_main(out, study, used_figs, used_tabs, ex)
    body.append("<h2 id=\"results\">Results</h2>")
    if "survey" not in absent:
        body += _survey_main(out, study, skipped, used_figs, used_tabs, ex)
    body += _within_section(out, skipped, used_tabs, ex)
    if (out / "drives").exists() or "drives" in skipped:
        body += _drives_main(out, study, skipped, used_figs, used_tabs, ex)
    body += _appendix(out, st, study, steps, skipped, used_figs, used_tabs, core, absent, ex)
    page = ("<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{esc(study.title)}: report</title><style>{CSS}</style></head><body>\n"
            + ex.resolve("\n".join(body)) + "\n</body></html>\n")
    path = out / "index.html"
    path.write_text(page, encoding="utf-8")
    write_exhibits(out, ex.items)
    return path

"""The report as one readable HTML document (`index.html`) for any study: summary, participant flow, methods,
results with every table and figure inline, the reproduction verdict, the files.

Everything is generated from what the report steps wrote beside it (tables as Markdown in `tables/`, figures as PNG
in `figures/`, the survey analysis in `survey/`, the drive analysis in `drives/`, `reproduction.csv`), from the
store's study definition (:func:`study.store.studies.definition`: title, conditions, instrument, model file, alpha,
hypothesis signs) and from the store's participants, protocol events and exclusions. The page is self-contained
(inline CSS, no scripts, no external resources; images and links by relative path, so it opens from the file
system), every text is HTML-escaped, and the bytes depend only on those inputs and the installed software's
versions (no times, no absolute paths): an unchanged report renders the same file.

Sections, in order (a part the study or its store does not have says why, e.g. a survey-only study has no drive
KPIs): Study · Participant flow · Methods · Survey results · Drive results · Simulation core · Reproduction ·
Steps and files.
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

#: section headings (h2) in document order
SECTIONS = ("Study", "Participant flow", "Methods", "Survey results", "Drive results", "Simulation core",
            "Reproduction", "Steps and files")
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
       "img{max-width:100%;height:auto;border:1px solid #ddd}figure{margin:1.2em 0}"
       "figcaption{font-size:.92em;color:#333}figcaption .reading{display:block;color:#2b5d8a}"
       ".scroll{overflow-x:auto;max-width:100%;margin:.6em 0 1.2em}"
       "table{border-collapse:collapse;font-size:.86em}td,th{border:1px solid #ccc;padding:.2em .5em;"
       "vertical-align:top}th{background:#eef3f8}td.r,th.r{text-align:right}td.c,th.c{text-align:center}"
       "caption{caption-side:top;text-align:left;font-weight:600;padding:.3em 0}"
       ".note{font-size:.85em;color:#444;margin:.2em 0}.skipped{background:#fbf3e6;border-left:4px solid #d08b1c;"
       "padding:.4em .8em}.verdict{background:#eef6ee;border-left:4px solid #3a7d3a;padding:.4em .8em}"
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
    header = _cells(lines[0])
    aligns = [_align(c) for c in _cells(lines[1])] if len(lines) > 1 else []
    aligns += [""] * (len(header) - len(aligns))

    def cls(k: int) -> str:
        return f' class="{aligns[k]}"' if k < len(aligns) and aligns[k] else ""

    out = ["<div class=\"scroll\"><table>"]
    if caption:
        out.append(f"<caption>{caption}</caption>")
    out.append("<thead><tr>" + "".join(f"<th{cls(k)}>{_inline(h, base)}</th>" for k, h in enumerate(header))
               + "</tr></thead><tbody>")
    for ln in lines[2:]:
        cells = _cells(ln)
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
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return f"{v:.{digits}f}" if v == v else "–"


def _p(p) -> str:
    try:
        v = float(p)
    except (TypeError, ValueError):
        return "p = –"
    return "p < 0.001" if v < 0.001 else f"p = {v:.3f}"


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
    return (f"{n['enrolled']} enrolled; {n.get('survey sample', 0)} in the survey sample and "
            f"{n.get('drive sample', 0)} in the drive sample.")


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


def _figure(out: Path, stem: str, study) -> str:
    caption, reader = FIGURES.get(stem, (PAIRED_CAPTION if stem.startswith("paired_") else
                                         stem.replace("_", " ") + ".", None))
    reading = None
    if reader is not None:
        try:
            reading = reader(out, study)
        except (KeyError, ValueError, TypeError, IndexError):
            reading = None  # a figure whose numbers are laid out differently keeps its caption only
    pdf = f" · <a href=\"figures/{esc(stem)}.pdf\">pdf</a>" if (out / "figures" / f"{stem}.pdf").exists() else ""
    read = f"<span class=\"reading\">{esc(reading)}</span>" if reading else ""
    return (f"<figure id=\"fig-{esc(stem)}\"><img src=\"figures/{esc(stem)}.png\" alt=\"{esc(caption)}\">"
            f"<figcaption><strong>{esc(stem)}</strong>: {esc(caption)}{pdf}{read}</figcaption></figure>")


def _figures(out: Path, stems: Sequence[str], study, used: set[str]) -> list[str]:
    parts = []
    for stem in stems:
        if (out / "figures" / f"{stem}.png").exists() and stem not in used:
            used.add(stem)
            parts.append(_figure(out, stem, study))
    return parts


def _md_table(out: Path, stem: str, used: set[str]) -> str:
    f = out / "tables" / f"{stem}.md"
    if not f.exists() or stem in used:
        return ""
    used.add(stem)
    links = " · ".join(f"<a href=\"tables/{esc(stem)}{ext}\">{ext[1:]}</a>" for ext in (".csv", ".tex")
                       if (out / "tables" / f"{stem}{ext}").exists())
    body = markdown_to_html(f.read_text(encoding="utf-8"), base="tables", heading_offset=2)
    return f"<section id=\"tab-{esc(stem)}\">{body}<p class=\"note\">{esc(stem)}: {links}</p></section>"


def _skipped(reason: str) -> str:
    return f"<p class=\"skipped\">Skipped: {esc(reason)}.</p>"


# ---------------------------------------------------------------------------------------------- sections
def _study_section(st, study, mode: str, store_name: str) -> list[str]:
    from analysis.report.figures import participant_flow
    from study.store.studies import current

    row = current(st) or {}
    flow = participant_flow(st)
    excluded = st.df("SELECT scope, reason, count(*) AS n FROM exclusions GROUP BY scope, reason "
                     "ORDER BY scope, reason")
    n_excl = int(st.one("SELECT count(DISTINCT participant_id) FROM exclusions") or 0)
    drives = (f"{flow.objective_sample} in the drive analysis" if st.one("SELECT count(*) FROM drives")
              else "no drives stored")
    parts = ["<h2 id=\"study\">Study</h2>"]
    if study.description:
        parts.append(f"<p>{esc(study.description)}</p>")
    conds = "; ".join(f"<code>{esc(c.name)}</code> ({esc(c.label)})" for c in study.conditions)
    attrs = ", ".join(f"{esc(a.name)} ({esc(a.type)})" for a in study.attributes) or "none"
    parts.append("<dl>"
                 f"<dt>Study</dt><dd><code>{esc(study.study_id)}</code>, version {esc(row.get('version', '–'))}, "
                 f"definition sha256 <code>{esc(study.hash[:12])}</code></dd>"
                 f"<dt>Conditions</dt><dd>{conds}</dd>"
                 f"<dt>Participant attributes</dt><dd>{attrs}</dd>"
                 f"<dt>Protocols</dt><dd>{esc(', '.join(study.protocols))}</dd>"
                 f"<dt>Participants</dt><dd>{flow.enrolled} registered; {flow.subjective_sample} included in the "
                 f"survey analysis, {drives}; {n_excl} with an exclusion</dd>"
                 f"<dt>Report</dt><dd>{esc(mode)}, store <code>{esc(store_name)}</code></dd></dl>")
    if not excluded.empty:
        rows = "".join(f"<tr><td>{esc(r.scope)}</td><td>{esc(str(r.reason).replace('_', ' '))}</td>"
                       f"<td class=\"r\">{int(r.n)}</td></tr>" for r in excluded.itertuples())
        parts.append("<div class=\"scroll\"><table><caption>Exclusions by scope and reason</caption><thead><tr>"
                     "<th>scope</th><th>reason</th><th class=\"r\">n</th></tr></thead><tbody>" + rows +
                     "</tbody></table></div>")
    return parts


def _flow_section(out: Path, st, study, used_figs: set, used_tabs: set) -> list[str]:
    parts = ["<h2 id=\"participant-flow\">Participant flow</h2>"]
    ev = st.df("SELECT p.protocol, e.phase, e.outcome, count(*) AS n FROM phase_events e "
               "JOIN participants p USING (participant_id) GROUP BY ALL")
    if ev.empty:
        parts.append("<p>No protocol phase has been recorded in the store.</p>")
    else:
        order: list[tuple[str, str]] = []
        for name, proto in study.protocols.items():
            order += [(name, ph) for ph in proto.phases]
        known = set(order)
        order += sorted({(r.protocol, r.phase) for r in ev.itertuples()} - known)
        outcomes = ("completed", "aborted", "in_progress")
        rows = []
        for proto, phase in order:
            sub = ev[(ev["protocol"] == proto) & (ev["phase"] == phase)]
            if sub.empty and proto not in set(ev["protocol"]):
                continue
            counts = [int(sub.loc[sub["outcome"] == o, "n"].sum()) for o in outcomes]
            rows.append(f"<tr><td>{esc(proto)}</td><td>{esc(phase)}</td>"
                        + "".join(f"<td class=\"r\">{c}</td>" for c in counts) + "</tr>")
        parts.append("<div class=\"scroll\"><table><caption>Participants per protocol phase</caption><thead><tr>"
                     "<th>protocol</th><th>phase</th><th class=\"r\">completed</th><th class=\"r\">aborted</th>"
                     "<th class=\"r\">in progress</th></tr></thead><tbody>" + "".join(rows) +
                     "</tbody></table></div>")
    parts += _figures(out, FLOW_FIGURES, study, used_figs)
    tab = _md_table(out, "participant_flow", used_tabs)
    if tab:
        parts.append(tab)
    return parts


def _scale_text(ins, item: str) -> str:
    """'7-point' of a rating scale, 'min-max slider in steps of k' of a slider/VAS item."""
    lo, hi = ins.scale(item)
    if str(ins.items.loc[item, "response_type"]) == "slider":
        return f"{lo}-{hi} slider in steps of {ins.step(item)}"
    return f"{hi - lo + 1}-point"


def _methods_section(out: Path, st, study, ran: tuple[str, ...]) -> list[str]:
    parts = ["<h2 id=\"methods\">Methods</h2>"]
    sw = ", ".join(f"{esc(n)} {esc(v)}" for n, v in software_versions(ran))
    parts.append(f"<p><strong>Software.</strong> {sw}.</p>")
    settings = {}
    sfile = out / "survey" / "settings.json"
    if sfile.is_file():
        settings = json.loads(sfile.read_text(encoding="utf-8"))
    if study.instruments:
        ins = study.instrument()
        scales = sorted({_scale_text(ins, i) for i in ins.scaled_items})
        rev = ", ".join(ins.reverse_items) or "none"
        parts.append(f"<p><strong>Instrument.</strong> <code>{esc(ins.name)}</code>: {len(ins.items)} items, "
                     f"{len(ins.scaled_items)} on {esc(' and '.join(scales))} scales; reverse-scored: "
                     f"{esc(rev)}.</p>")
    model = study.model
    if model is not None:
        mm = "; ".join(f"{esc(c)} =~ {esc(' + '.join(items))}" for c, items in model.measurement.items())
        analysis = study.settings.get("analysis", {})
        dropped = settings.get("dropped_items") or []
        parts.append("<p><strong>Measurement model.</strong> Confirmatory factor analysis by maximum likelihood "
                     "(semopy) in two stages: every scaled item on its construct (initial; items with a "
                     f"standardized loading below {esc(analysis.get('min_loading', 0.7))} flagged), then the "
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
            parts.append(f"<p><strong>Hypotheses</strong> at α = {esc(study.alpha)}:</p><ul>{hyps}</ul>")
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


def _hypotheses_verdicts(out: Path, study) -> str:
    df = _read_csv(out / "survey" / "hypotheses.csv")
    if df is None or df.empty or study.model is None:
        return ""
    sign = {h.hypothesis: h.sign for h in study.model.hypotheses}
    expect = {">": "positive", "<": "negative", "!=": "non-zero"}
    rows = []
    for r in df.itertuples():
        ok = str(r.supported).strip().lower() in ("true", "1", "yes")
        rows.append(f"<tr><td>{esc(r.hypothesis)}</td><td>{esc(r.path)}</td>"
                    f"<td>{expect.get(sign.get(r.hypothesis, '!='), '')}</td><td class=\"r\">β = {_fmt(r.beta, 3)}"
                    f"</td><td class=\"r\">{esc(_p(r.p))}</td><td>{'supported' if ok else 'not supported'}</td></tr>")
    n_ok = sum(str(x).strip().lower() in ("true", "1", "yes") for x in df["supported"])
    return (f"<p class=\"verdict\">{n_ok} of {len(df)} hypotheses supported at α = {esc(study.alpha)}.</p>"
            "<div class=\"scroll\"><table><caption>Hypotheses: verdicts</caption><thead><tr><th>hypothesis</th>"
            "<th>path</th><th>expected</th><th class=\"r\">β</th><th class=\"r\">p</th><th>verdict</th></tr>"
            "</thead><tbody>" + "".join(rows) + "</tbody></table></div>")


def _survey_section(out: Path, study, skipped: dict, used_figs: set, used_tabs: set) -> list[str]:
    parts = ["<h2 id=\"survey-results\">Survey results</h2>"]
    if "survey" in skipped:
        return parts + [_skipped(skipped["survey"])]
    if not (out / "survey").exists():
        return parts + [_skipped("the survey step did not run")]
    verdicts = _hypotheses_verdicts(out, study)
    if verdicts:
        parts.append(verdicts)
    warnings = out / "survey" / "warnings.txt"
    if warnings.is_file() and warnings.read_text(encoding="utf-8").strip():
        items = "".join(f"<li>{esc(w)}</li>" for w in warnings.read_text(encoding="utf-8").splitlines() if w)
        parts.append(f"<p><strong>Warnings of the analysis</strong></p><ul>{items}</ul>")
    ext_warnings = out / "survey" / "extended" / "warnings.txt"
    if ext_warnings.is_file() and ext_warnings.read_text(encoding="utf-8").strip():
        items = "".join(f"<li>{esc(w)}</li>" for w in ext_warnings.read_text(encoding="utf-8").splitlines() if w)
        parts.append(f"<p><strong>Warnings of the extended statistics</strong></p><ul>{items}</ul>")
    parts += _figures(out, SURVEY_FIGURES, study, used_figs)
    stems = [s for s in SURVEY_TABLES] + sorted(p.stem for p in (out / "tables").glob("survey_*.md"))
    regressions = _read_csv(out / "survey" / "regressions.csv")
    if regressions is not None and regressions.empty:
        parts.append("<p>The analysis model declares no regressions: no regression table and no hypotheses.</p>")
        stems = [s for s in stems if s not in NO_REGRESSION_TABLES]
    parts += [t for t in (_md_table(out, s, used_tabs) for s in stems) if t]
    return parts


def _within_section(out: Path, skipped: dict, used_tabs: set) -> list[str]:
    """The within-subjects comparison (analysis.within): the generated methods and results sentences, the order
    counts, a figure of individual lines per variable and the test tables. Absent for a study without [within]."""
    d = out / "within"
    if "within" not in skipped and not d.exists():
        return []
    parts = ["<h2 id=\"within\">Within-subjects comparison</h2>"]
    if "within" in skipped:
        return parts + [_skipped(skipped["within"])]
    text = (d / "methods.md").read_text(encoding="utf-8")
    parts.append(markdown_to_html(text.split("\n", 1)[1], heading_offset=2))
    for stem in ("orders", "descriptives", "anova", "friedman", "posthoc", "mixed", "mixed_fit", "reliability",
                 "item_descriptives"):
        md = d / f"{stem}.md"
        if md.is_file() and len(pd.read_csv(d / f"{stem}.csv")):
            used_tabs.add(f"within_{stem}")
            parts.append(markdown_to_html(md.read_text(encoding="utf-8"), base="within/"))
        if stem == "descriptives":
            variables = pd.read_csv(d / "descriptives.csv")["variable"].drop_duplicates()
            for variable in variables:
                png = d / f"lines_{variable}.png"
                if not png.is_file():
                    continue
                parts.append(f"<figure><img src=\"within/{esc(png.name)}\" alt=\"{esc(variable)} by condition\">"
                             f"<figcaption>{esc(variable)} by condition: one grey line per participant, the "
                             f"condition means with their 95 % confidence intervals in black.</figcaption></figure>")
    return parts


def _drives_section(out: Path, study, skipped: dict, used_figs: set, used_tabs: set) -> list[str]:
    parts = ["<h2 id=\"drive-results\">Drive results</h2>"]
    if "drives" in skipped:
        return parts + [_skipped(skipped["drives"])]
    if not (out / "drives").exists():
        return parts + [_skipped("the drives step did not run")]
    known = list(FIGURES)  # the paper's figure order (9a-d, 10, 11, 12), then any other figure by name
    drive_figs = sorted((p.stem for p in (out / "drives" / "figures").glob("*.png")),
                        key=lambda stem: (known.index(stem) if stem in known else len(known), stem)) \
        if (out / "drives" / "figures").exists() else []
    stems = [s for s in DRIVE_TABLES] + sorted(p.stem for p in (out / "tables").glob("drives_*.md"))
    parts += [t for t in (_md_table(out, s, used_tabs) for s in stems[:3]) if t]
    parts += _figures(out, drive_figs, study, used_figs)
    for replay in sorted((out / "drives").glob("replay_*.html")):
        who = replay.stem.removeprefix("replay_")
        parts.append(f"<p>Replay of {esc(who)}'s drives (time slider, the HUD as the driver saw it): "
                     f"<a href=\"drives/{esc(replay.name)}\">{esc(replay.name)}</a></p>")
    parts += [t for t in (_md_table(out, s, used_tabs) for s in stems[3:]) if t]
    return parts + _figures(out, ("sweep_indices",), study, used_figs)


def _core_section(out: Path, study, skipped: dict, used_figs: set, core: bool) -> list[str]:
    if not core:
        return []
    parts = ["<h2 id=\"simulation-core\">Simulation core</h2>"]
    if "core figures" in skipped:
        return parts + [_skipped(skipped["core figures"])]
    figs = _figures(out, CORE_FIGURES, study, used_figs)
    return parts + (["<p>Figures of the vehicle model and the controller of the simulator.</p>"] + figs
                    if figs else [_skipped("the core figures step did not run")])


def _reproduction_section(out: Path, skipped: dict, used_tabs: set) -> list[str]:
    parts = ["<h2 id=\"reproduction\">Reproduction</h2>"]
    if "reproduction" in skipped:
        return parts + [_skipped(skipped["reproduction"])]
    df = _read_csv(out / "reproduction.csv")
    if df is None or "status" not in df.columns:
        return parts + [_skipped("the reproduction step wrote no reproduction.csv")]
    counts = df["status"].value_counts()
    n = len(df)
    # "match (PCA)" / "within tolerance (PCA)": met under the paper's procedure (principal-component loadings)
    ok = int(sum(v for k, v in counts.items() if str(k).startswith(("match", "within tolerance"))))
    audit = int(sum(v for k, v in counts.items() if str(k).startswith("audit finding")))
    miss = int(counts.get("miss", 0))
    verdict = ("every published value is met or explained" if miss == 0 else f"{miss} published value(s) missed")
    parts.append(f"<p class=\"verdict\">Verdict: {verdict}. Of {n} published values, {ok} match or lie within "
                 f"tolerance, {audit} contradict other published values (audit findings) and {miss} are missed. "
                 "Details: <a href=\"reproduction.md\">reproduction.md</a> · "
                 "<a href=\"reproduction.csv\">reproduction.csv</a>.</p>")
    rows = "".join(f"<tr><td>{esc(k)}</td><td class=\"r\">{int(v)}</td></tr>" for k, v in sorted(counts.items()))
    parts.append("<div class=\"scroll\"><table><caption>Published values by status</caption><thead><tr>"
                 "<th>status</th><th class=\"r\">count</th></tr></thead><tbody>" + rows + "</tbody></table></div>")
    tab = _md_table(out, "paper_audit", used_tabs)
    if tab:
        parts.append("<h3>Audit of the published statistics</h3>"
                     "<p>Details: <a href=\"paper/audit.md\">paper/audit.md</a>.</p>" + tab)
    return parts


def _files_section(out: Path, steps, skipped: dict, used_figs: set, used_tabs: set, study) -> list[str]:
    parts = ["<h2 id=\"files\">Steps and files</h2>"]
    rows = []
    for s in steps:
        reason = skipped.get(s.name)
        rows.append(f"<tr><td>{esc(s.name)}</td><td>{'skipped: ' + esc(reason) if reason else 'produced'}</td></tr>")
    for part, reason in sorted(skipped.items()):
        if part not in {s.name for s in steps}:
            rows.append(f"<tr><td>{esc(part)}</td><td>skipped: {esc(reason)}</td></tr>")
    parts.append("<div class=\"scroll\"><table><caption>Steps</caption><thead><tr><th>step</th><th>outcome</th>"
                 "</tr></thead><tbody>" + "".join(rows) + "</tbody></table></div>")
    # anything written that the sections above did not show
    rest_tabs = [p.stem for p in sorted((out / "tables").glob("*.md")) if p.stem not in used_tabs] \
        if (out / "tables").exists() else []
    rest_figs = [p.stem for p in sorted((out / "figures").glob("*.png")) if p.stem not in used_figs] \
        if (out / "figures").exists() else []
    if rest_tabs or rest_figs:
        parts.append("<h3>Other tables and figures</h3>")
        parts += [t for t in (_md_table(out, s, used_tabs) for s in rest_tabs) if t]
        parts += _figures(out, rest_figs, study, used_figs)
    for title, sub in (("Survey analysis", "survey"), ("Drive analysis", "drives"), ("Paper audit", "paper"),
                       ("Tables", "tables"), ("Figures", "figures")):
        d = out / sub
        if d.exists():
            files = sorted(f for f in d.iterdir() if f.is_file())
            if files:
                links = "".join(f"<li><a href=\"{esc(sub)}/{esc(f.name)}\">{esc(f.name)}</a></li>" for f in files)
                parts.append(f"<h3>{esc(title)} (<code>{esc(sub)}/</code>)</h3><ul class=\"files\">{links}</ul>")
    top = [f for f in ("reproduction.md", "reproduction.csv") if (out / f).exists()]
    if top:
        parts.append("<p>" + " · ".join(f"<a href=\"{esc(f)}\">{esc(f)}</a>" for f in top) + "</p>")
    return parts


def render_document(out: Path, st, steps, skipped: dict[str, str], mode: str = "lab store",
                    store_name: str = "", core: bool = True, absent: set[str] = frozenset()) -> Path:
    """Write `out/index.html`: the whole report as one document (module docstring) for the study of the open
    store `st`; `steps` are the pipeline's StepResults, `skipped` the parts not produced with their reasons; `core`:
    whether the simulation core's figures belong to the study (without them there is no such section); `absent`:
    the parts the study's declaration rules out (no section either, :func:`analysis.report.build.absent_parts`)."""
    from study.store.studies import definition

    out = Path(out)
    study = definition(st)
    used_figs: set[str] = set()
    used_tabs: set[str] = set()
    body = [f"<h1>{esc(study.title)}</h1>", "<p class=\"note\">Report of study <code>"
            f"{esc(study.study_id)}</code> generated by pedas-study from the study store.</p>"]
    body += _study_section(st, study, mode, store_name)
    body += _flow_section(out, st, study, used_figs, used_tabs)
    ran = (*(("survey",) if "survey" not in skipped else ()),
           *(("within",) if (out / "within" / "anova.csv").is_file() and "within" not in skipped else ()),
           *(("simulation",) if mode == "reference study" else ()))
    body += _methods_section(out, st, study, ran)
    if "survey" not in absent:
        body += _survey_section(out, study, skipped, used_figs, used_tabs)
    body += _within_section(out, skipped, used_tabs)
    body += _drives_section(out, study, skipped, used_figs, used_tabs)
    body += _core_section(out, study, skipped, used_figs, core)
    if "reproduction" not in absent:
        body += _reproduction_section(out, skipped, used_tabs)
    body += _files_section(out, steps, skipped, used_figs, used_tabs, study)
    page = ("<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{esc(study.title)}: report</title><style>{CSS}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")
    path = out / "index.html"
    path.write_text(page, encoding="utf-8")
    return path

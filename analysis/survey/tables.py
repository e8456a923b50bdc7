"""Human renderings (Markdown and LaTeX booktabs) of the acceptance statistics, shaped like the paper's
Table 3 (descriptives, loadings, alpha, CR, AVE), Table 4 (inter-construct correlations, sqrt(AVE) on the
diagonal) and Table 5 (hierarchical regressions). Rendered from the same frames `SurveyAnalysis.write` saves; the
construct labels of Table 3 and the titles of Tables 4 and 5 come from the study (``settings`` of the analysis:
``construct_labels``, ``table_titles``; :func:`analysis.survey.acceptance.table_titles`).

Table 3 shows, for a retained item, its loading in the final CFA and, for an omitted item, its loading in the
initial CFA marked with a double dagger (the paper marks it *, which the report keeps for significance); reverse-scored
items carry a dagger. Tables 4 and 5 mark significance by the report's one convention (analysis.apa.STARS:
* p < .05, ** p < .01, *** p < .001, two-tailed); the CI column is the 95 % t-interval of B as [LL, UL], the
bootstrap CI is printed beside it.
"""
from __future__ import annotations

from analysis.render import fmt_cell, latex_table, markdown_table
from analysis import apa

# what λ is, per `analyze_survey(loadings=...)`
LOADING_NOTES = {"cfa": "standardized factor loading of the CFA",
                 "pca": "loading on the first principal component of the construct's items (SPSS FACTOR default)",
                 "paf": "loading of a one-factor principal axis factoring of the construct's items"}


def table3_rows(res) -> tuple[list[str], list[list[str]], list[str]]:
    desc = res.descriptives.set_index("item")
    lo = res.loadings
    ini = lo[lo["stage"] == "initial"].set_index("item")
    fin = lo[lo["stage"] == "final"].set_index("item")
    rel = res.reliability.set_index("construct")
    header = ["Constructs", "Mean", "SD", "λ", "Cα", "CR", "AVE"]
    labels = res.settings.get("construct_labels", {})
    rows = []
    for c in ini["construct"].unique():
        r = rel.loc[c] if c in rel.index else None
        rows.append([f"**{labels.get(c, c)}**", "", "", "", fmt_cell(r["alpha"]) if r is not None else "",
                     fmt_cell(r["cr"]) if r is not None else "", fmt_cell(r["ave"]) if r is not None else ""])
        for item in ini.index[ini["construct"] == c]:
            name = item + ("†" if bool(desc.loc[item, "reversed"]) else "")
            lam = fmt_cell(fin.loc[item, "loading"]) if item in fin.index else fmt_cell(ini.loc[item, "loading"]) + "‡"
            rows.append([name, fmt_cell(desc.loc[item, "mean"]), fmt_cell(desc.loc[item, "sd"]), lam, "", "", ""])
    notes = [f"N = {res.n}. λ = {LOADING_NOTES[res.settings.get('loadings', 'cfa')]} (final items; ‡ all items "
             "of the construct, item omitted from the analysis), "
             "Cα = Cronbach's alpha, CR = composite reliability, AVE = average variance extracted (final items).",
             "† reverse-scored item (mean and SD after reverse scoring)."]
    return header, rows, notes


def table4_rows(res) -> tuple[list[str], list[list[str]], list[str]]:
    cons = list(res.reliability["construct"])
    sq = res.reliability.set_index("construct")["sqrt_ave"]
    corr = {(r.a, r.b): r for r in res.correlations.itertuples()}
    header = ["Factors"] + cons
    rows = []
    for i, a in enumerate(cons):
        row = [a]
        for j, b in enumerate(cons):
            if j < i:
                r = corr.get((b, a)) or corr.get((a, b))
                row.append(f"{apa.num(r.r, 3, bounded=True)}{apa.stars(r.p)}" if r is not None else "")
            elif j == i:
                row.append(f"**{apa.num(sq[a], 3, bounded=True)}**")
            else:
                row.append("")
        rows.append(row)
    notes = [f"N = {res.n}. Diagonal (bold): square root of AVE; below: Pearson correlations of the composites.",
             f"{apa.stars_note()} (two-tailed)"]
    return header, rows, notes


def table5_rows(res) -> tuple[list[str], list[list[str]], list[str]]:
    reg = res.regressions
    header = ["Models", "R²", "Adj. R²", "ΔR²", "B", "SE B", "β", "95 % CI", "Bootstrap 95 % CI"]
    idioms = res.settings.get("paper_idioms", False)
    rows = []
    for name, m in reg.groupby("model", sort=False):
        label = m["label"].iloc[0] or name
        rows.append([f"**{name}. {label}**", "", "", "", "", "", "", "", ""])
        for step, s in m.groupby("step", sort=True):
            top = s.iloc[0]
            step_label = (f"Step {step}: Dependent Variable - {top['dv']}" if idioms
                          else f"Step {step} (DV: {top['dv']})")
            rows.append([step_label, fmt_cell(top["r2"]),
                         fmt_cell(top["adj_r2"]), fmt_cell(top["delta_r2"]) + ("*" if top["p_change"] < 0.05 else ""),
                         "", "", "", "", ""])
            for _, r in s[s["predictor"] != "(Constant)"].iterrows():
                rows.append([f"Independent Variable - {r['predictor']}" if idioms else f" {r['predictor']}",
                             "", "", "", fmt_cell(r["b"]),
                             fmt_cell(r["se_b"]), fmt_cell(r["beta"]) + apa.stars(r["p"]),
                             apa.ci(r["ci_low"], r["ci_high"], 3), apa.ci(r["boot_ci_low"], r["boot_ci_high"], 3)])
    boot = res.settings.get("n_boot", 0)
    notes = [f"N = {res.n}. Stars on β: {apa.stars_note()} (two-tailed); ΔR²*: F change significant at p < .05.",
             f"95% CI: t-interval of B; bootstrap: {res.settings.get('boot_method', 'percentile')} CI of B, "
             f"{boot} case resamples, seed {res.settings.get('seed')}."]
    return header, rows, notes


def item_flags_rows(res) -> tuple[list[str], list[list[str]], list[str]]:
    """The deletion rules per item of the initial CFA next to the declared decision (retained or dropped)."""
    ini = res.loadings[res.loadings["stage"] == "initial"]
    rules = res.settings.get("rules", {})
    header = ["Item", "Construct", "λ (initial)", "item-rest r", "strongest other construct", "r", "rules fired",
              "retained"]
    rows = [[r["item"], r["construct"], fmt_cell(r["loading"]), fmt_cell(r["own_r"]), str(r["cross_construct"]),
             fmt_cell(r["cross_r"]), r["rule"] or "-", "yes" if r["retained"] else "no (config)"]
            for _, r in ini.iterrows()]
    notes = [f"Rules: λ < {apa.num(rules.get('min_loading', 0.7), 2, bounded=True)}; negative λ; cross-construct: "
             f"|r| with another construct's composite >= item-rest r of its own construct (margin "
             f"{rules.get('cross_margin', 0.0)}). The rules inform; the deletion itself is the declared configuration."]
    return header, rows, notes


TITLES = {"item_flags": "Item deletion rules of the initial measurement model",
          "table3": "Descriptive statistics, standardized factor loadings, Cronbach's alpha, composite reliability "
                    "and average variance extracted",
          "table4": "Inter-construct correlation matrix",
          "table5": "Hierarchical regression analysis"}


def title(res, name: str) -> str:
    """The title of table `name`: the study's (``settings["table_titles"]``) or the generic one of TITLES."""
    return res.settings.get("table_titles", {}).get(name) or TITLES[name]


# the paper's tables in print order, then the item flags; each builder returns (header, rows, notes)
TABLES = {"table3": table3_rows, "table4": table4_rows, "table5": table5_rows, "item_flags": item_flags_rows}
PAPER_TABLES = ("table3", "table4", "table5")
FORMATS = ("md", "tex", "csv")


def _format(name: str, header, rows, notes, fmt: str, caption: str = "") -> str:
    caption = caption or TITLES[name]
    if fmt == "md":
        # bold title and verbatim notes (they carry the * significance marks) as the paper prints them
        return markdown_table(header, rows, caption, notes, title_style="bold", notes_style="plain")
    if fmt == "tex":
        return latex_table(header, rows, caption, notes, align="l" + "c" * (len(header) - 1))
    if fmt == "csv":
        import csv
        import io

        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows([header] + [[c.replace("**", "") for c in r] for r in rows])
        return buf.getvalue()
    raise ValueError(f"unknown table format {fmt!r} (one of {', '.join(FORMATS)})")


def render_table(res, name: str, fmt: str = "md") -> str:
    """One table of `res` (a :class:`analysis.survey.acceptance.SurveyAnalysis`) as text: `name` one of :data:`TABLES`
    (table3, table4, table5, item_flags), `fmt` "md", "tex" or "csv" -- the text `write` saves as
    ``<name>.<fmt>``."""
    if name not in TABLES:
        raise ValueError(f"unknown table {name!r} (one of {', '.join(TABLES)})")
    if fmt not in FORMATS:
        raise ValueError(f"unknown table format {fmt!r} (one of {', '.join(FORMATS)})")
    return _format(name, *TABLES[name](res), fmt, title(res, name))


def render_all(res) -> dict[str, str]:
    """file name -> text for table3/4/5 (and the item flags) in Markdown (.md), LaTeX booktabs (.tex) and CSV (.csv:
    the cells as printed, one header row; the notes are in the .md and .tex)."""
    out = {}
    for name, fn in TABLES.items():
        header, rows, notes = fn(res)
        for fmt in FORMATS:
            out[f"{name}.{fmt}"] = _format(name, header, rows, notes, fmt, title(res, name))
    return out

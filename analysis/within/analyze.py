"""The within-subjects part of a study's analysis: every declared score and drive KPI compared across the study's
conditions (:func:`analysis.survey.within.compare_within` for each), the counts of the protocol orders, and the
methods and results sentences (docs/report.md, "Within-subjects studies").

Input is one tidy long frame, one row per participant, condition and dependent variable (columns ``participant``,
``condition``, ``variable``, ``value``, optionally ``period``, ``order``, ``label``, ``unit``); :mod:`analysis.within.data`
builds it from a store.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis import apa

from study.common.errors import UserError

#: the tables of a within-subjects analysis, in the order the report shows them
TABLES = ("orders", "descriptives", "anova", "friedman", "posthoc", "mixed", "mixed_fit", "item_descriptives",
          "reliability")
#: Mauchly's p below the analysis alpha: the Greenhouse-Geisser corrected p is the one the sentences quote
CORRECTION = "Greenhouse-Geisser"


@dataclass(frozen=True)
class WithinStudy:
    """Every dependent variable of a within-subjects study compared across its conditions.

    Attributes
    ----------
    conditions : tuple of str
        The compared conditions in their declared order (the first is the mixed model's reference).
    variables : DataFrame
        variable, source (score | kpi), label, unit: what was compared, in order.
    orders : DataFrame
        order, n: participants per protocol order (the Latin square's balance).
    descriptives, anova, friedman, posthoc, mixed, mixed_fit : DataFrame
        :class:`analysis.survey.within.WithinComparison`'s frames of every variable, stacked.
    item_descriptives : DataFrame
        variable, item, condition, n, mean, sd, median of each score's items (reversed ones mapped) per condition.
    reliability : DataFrame
        variable, condition, n, k, alpha (Cronbach, with its 95 % CI), omega (McDonald, one factor) of each score's
        items per condition (empty when no score has two or more items).
    alpha : float
        The analysis' significance level (``[analysis] alpha``).
    warnings : tuple of str
    """
    conditions: tuple[str, ...]
    variables: pd.DataFrame
    orders: pd.DataFrame
    descriptives: pd.DataFrame
    anova: pd.DataFrame
    friedman: pd.DataFrame
    posthoc: pd.DataFrame
    mixed: pd.DataFrame
    mixed_fit: pd.DataFrame
    item_descriptives: pd.DataFrame
    reliability: pd.DataFrame
    alpha: float = 0.05
    warnings: tuple[str, ...] = field(default=())

    def tables(self) -> dict[str, pd.DataFrame]:
        return {name: getattr(self, name) for name in TABLES}

    def write(self, out: str | Path, data: pd.DataFrame | None = None) -> list[Path]:
        """Write every table (CSV full precision, Markdown, LaTeX), the figure of each variable
        (:mod:`analysis.within.figures`, when `data` is given), methods.md and warnings.txt into `out`."""
        from analysis.render import write_table
        from analysis.within.figures import plot_variable

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, frame in self.tables().items():
            paths += write_table(frame, out, name, title=TITLES[name], digits=3)
        # each variable's label and unit: the report names the variables by them, not by their identifiers
        paths += write_table(self.variables, out, "variables", title="Dependent variables: source, label and unit")
        if data is not None:
            for v in self.variables.itertuples():
                paths += plot_variable(data[data["variable"] == v.variable], self.conditions, out,
                                       stem=f"lines_{v.variable}", title=axis_label(v))
        paths.append(out / "methods.md")
        paths[-1].write_text(methods_markdown(self), encoding="utf-8")
        paths.append(out / "warnings.txt")
        paths[-1].write_text("".join(w + "\n" for w in self.warnings), encoding="utf-8")
        return paths


TITLES = {
    "orders": "Participants per protocol order",
    "descriptives": "Descriptives by condition",
    "anova": "Repeated-measures ANOVA with Mauchly's test and Greenhouse-Geisser / Huynh-Feldt corrections",
    "friedman": "Friedman test with Kendall's W",
    "posthoc": "Paired post-hoc tests (Holm-corrected) with Cohen's d_z",
    "mixed": "Linear mixed model: fixed effects",
    "mixed_fit": "Linear mixed model: fit",
    "item_descriptives": "Items of each score by condition (reversed items mapped)",
    "reliability": "Cronbach's alpha and McDonald's omega of each score's items by condition",
}


def axis_label(v) -> str:
    """'label (unit)' of a row of :attr:`WithinStudy.variables`."""
    unit = f" ({v.unit})" if isinstance(v.unit, str) and v.unit else ""
    return f"{v.label}{unit}"


def analyze_within(data: pd.DataFrame, conditions, *, items: pd.DataFrame | None = None,
                   alpha: float = 0.05, resolutions: dict[str, float | None] | None = None) -> WithinStudy:
    """Compare every variable of `data` across `conditions` (:func:`compare_within`, with the period as a fixed
    effect of the mixed model when `data` has a ``period`` column).

    Parameters
    ----------
    data : DataFrame
        participant, condition, variable, value[, period, order, source, label, unit]; one row per participant,
        condition and variable. Rows of other conditions (e.g. familiarisation drives) are left out.
    conditions : sequence of str
        The compared conditions in order.
    items : DataFrame, optional
        variable, participant, condition, item, value: the item answers behind each score, for Cronbach's alpha per
        condition.
    alpha : float
        Significance level of the sentences and of the sphericity decision.
    resolutions : dict, optional
        variable -> the step at which its values tie in the rank tests (:mod:`analysis.ranks`; a score's from its
        declaration, :func:`analysis.within.data.resolutions`); a variable not named is compared at 1e-9 of its
        largest magnitude.
    """
    from analysis.survey.omega import omega_stack
    from analysis.survey.reliability import cronbach_alpha
    from analysis.survey.within import compare_within

    need = {"participant", "condition", "variable", "value"}
    if missing := sorted(need - set(data.columns)):
        raise UserError(f"within-subjects data lack column(s) {', '.join(missing)}")
    conditions = tuple(conditions)
    data = data[data["condition"].isin(conditions)]
    if data.empty:
        raise UserError(f"no values of the conditions {', '.join(conditions)} to compare")
    variables = _variables(data)
    has_period = "period" in data.columns and data["period"].notna().all()
    parts, warnings = [], []
    for v in variables["variable"]:
        d = data[data["variable"] == v]
        r = compare_within(d, period="period" if has_period and d["period"].nunique() > 1 else None,
                           conditions=conditions, variable=v, resolution=(resolutions or {}).get(v))
        parts.append(r)
        warnings += list(r.warnings)

    def stack(name):
        return pd.concat([getattr(r, name) for r in parts], ignore_index=True)

    item_desc = pd.DataFrame(columns=["variable", "item", "condition", "n", "mean", "sd", "median"])
    rel = []
    if items is not None and not items.empty:
        it = items[items["condition"].isin(conditions)].dropna(subset=["value"])
        g = it.groupby(["variable", "item", "condition"], sort=False)["value"]
        item_desc = g.agg(n="count", mean="mean", sd="std", median="median").reset_index()
        item_desc["condition"] = pd.Categorical(item_desc["condition"], categories=list(conditions))
        order = {v: i for i, v in enumerate(variables["variable"])}
        item_desc = (item_desc.assign(_o=item_desc["variable"].map(order)).sort_values(["_o", "condition"], kind="stable")
                     .drop(columns="_o").reset_index(drop=True))
        item_desc["condition"] = item_desc["condition"].astype(str)
        for (v, c), g in items[items["condition"].isin(conditions)].groupby(["variable", "condition"], sort=False):
            wide = g.pivot(index="participant", columns="item", values="value").dropna()
            if wide.shape[1] < 2 or len(wide) < 3:
                continue
            a, lo, hi = cronbach_alpha(wide)
            # McDonald's omega of the one-factor model (analysis.survey.omega; NaN when it does not converge)
            omega = float(omega_stack(np.cov(wide.to_numpy(dtype=float), rowvar=False)[None])[0])
            rel.append({"variable": v, "condition": c, "n": len(wide), "k": wide.shape[1], "alpha": a,
                        "ci_low": lo, "ci_high": hi, "omega": omega})
    reliability = pd.DataFrame(rel, columns=["variable", "condition", "n", "k", "alpha", "ci_low", "ci_high",
                                             "omega"])
    if not reliability.empty:
        reliability["condition"] = pd.Categorical(reliability["condition"], categories=list(conditions))
        order = {v: i for i, v in enumerate(variables["variable"])}
        reliability = (reliability.assign(_o=reliability["variable"].map(order))
                       .sort_values(["_o", "condition"]).drop(columns="_o").reset_index(drop=True))
        reliability["condition"] = reliability["condition"].astype(str)
    return WithinStudy(conditions=conditions, variables=variables, orders=_orders(data), descriptives=stack("descriptives"),
                       anova=stack("anova"), friedman=stack("friedman"), posthoc=stack("posthoc"),
                       mixed=stack("mixed"), mixed_fit=stack("mixed_fit"), item_descriptives=item_desc,
                       reliability=reliability, alpha=alpha,
                       warnings=tuple(warnings))


def _variables(data: pd.DataFrame) -> pd.DataFrame:
    """variable, source, label, unit in order of first appearance."""
    first = data.drop_duplicates("variable")
    out = pd.DataFrame({"variable": first["variable"].astype(str).to_numpy()})
    for col, default in (("source", ""), ("label", None), ("unit", "")):
        vals = first[col].to_numpy() if col in first.columns else [default] * len(first)
        out[col] = [x if isinstance(x, str) and x else (default if default is not None else v)
                    for x, v in zip(vals, out["variable"])]
    return out


def _orders(data: pd.DataFrame) -> pd.DataFrame:
    """Participants per protocol order (one order per participant; 'unknown' without an order column)."""
    if "order" not in data.columns:
        return pd.DataFrame({"order": ["unknown"], "n": [data["participant"].nunique()]})
    per = data.drop_duplicates("participant")[["participant", "order"]]
    counts = per["order"].fillna("unknown").astype(str).value_counts().sort_index()
    return pd.DataFrame({"order": counts.index.to_list(), "n": counts.to_numpy(dtype=int)})


# ---------------------------------------------------------------------------------------------- sentences
def _p(p: float) -> str:
    """APA p in a sentence: 'p < .001' or 'p = .023' (analysis.apa)."""
    return apa.p_text(p)


def _num(x: float, digits: int = 2, bounded: bool = False) -> str:
    return apa.num(x, digits, bounded)


def result_sentence(study: WithinStudy, variable: str) -> str:
    """One APA-style paragraph of a variable: its rm-ANOVA (with the correction when Mauchly's test rejects
    sphericity) and Friedman test, the condition means, the pairs that differ with their mean differences and the
    mixed model's condition effects, every measured value with the variable's unit (none for a score), e.g.
    'Takeover time: F(2, 34) = 113.17, p < .001, ... none: M = 3.03 s, SD = 0.49 s; ...'."""
    v = study.variables.set_index("variable").loc[variable]
    unit = v["unit"] if isinstance(v.get("unit"), str) else ""
    a = study.anova[study.anova["variable"] == variable].iloc[0]
    f = study.friedman[study.friedman["variable"] == variable].iloc[0]
    text = (f"{v['label']}: F({apa.df_text(a['df1'])}, {apa.df_text(a['df2'])}) = {_num(a['f'])}, "
            f"{_p(a['p'])}, partial η² = {_num(a['np2'], bounded=True)}, generalised η² = "
            f"{_num(a['ng2'], bounded=True)}")
    if pd.notna(a["mauchly_p"]):
        if a["mauchly_p"] < study.alpha:
            text += (f"; sphericity rejected (Mauchly's W = {_num(a['mauchly_w'], bounded=True)}, {_p(a['mauchly_p'])}), "
                     f"{CORRECTION} ε = {_num(a['eps_gg'], bounded=True)}, corrected {_p(a['p_gg'])}")
        else:
            text += (f"; sphericity not rejected (Mauchly's W = {_num(a['mauchly_w'], bounded=True)}, "
                     f"{_p(a['mauchly_p'])})")
    text += (f"; Friedman χ²({apa.df_text(f['df'])}) = {_num(f['chi2'])}, {_p(f['p'])}, Kendall's W = "
             f"{_num(f['kendall_w'], bounded=True)}.")
    d = study.descriptives[study.descriptives["variable"] == variable].set_index("condition")
    means = [f"{c}: M = {apa.quantity(d.loc[c, 'mean'], unit)}, SD = {apa.quantity(d.loc[c, 'sd'], unit)}"
             for c in study.conditions if c in d.index]
    if means:
        text += " " + "; ".join(means) + "."
    ph = study.posthoc[(study.posthoc["variable"] == variable) & (study.posthoc["test"] == "t")]
    sig = [f"{r.a} vs {r.b} ({r.a} − {r.b} = {apa.quantity(r.mean_diff, unit)}, d_z = {_num(r.dz)}, "
           f"Holm {_p(r.p_holm)})" for r in ph.itertuples() if r.p_holm < study.alpha]
    text += (" Paired t-tests differ for " + "; ".join(sig) + "." if sig
             else " No pair of conditions differs in the Holm-corrected paired t-tests.")
    mixed = study.mixed[(study.mixed["variable"] == variable) & (study.mixed["effect"] == "condition")]
    if len(mixed):
        text += (f" Mixed model (every available value), difference from {study.conditions[0]}: " + "; ".join(
            f"{r.level} {apa.quantity(r.coef, unit)}, 95 % CI {apa.ci(r.ci_low, r.ci_high)}, {_p(r.p)}"
            for r in mixed.itertuples()) + ".")
    return text


def methods_markdown(study: WithinStudy) -> str:
    """The methods paragraph and one result sentence per variable, generated from the analysis."""
    n = int(study.orders["n"].sum())
    k = len(study.conditions)
    # the repeated-measures tests use the participants with every condition: df2 = (k - 1)(n - 1)
    complete = int(round(study.anova["df2"].min() / (k - 1))) + 1 if len(study.anova) and k > 1 else n
    orders = "; ".join(f"{r.order}: {r.n}" for r in study.orders.itertuples())
    has_period = study.mixed["term"].astype(str).str.contains("period").any()
    lines = [
        "# Within-subjects comparison", "",
        (f"Each of the {n} participants was measured under the {k} conditions ({', '.join(study.conditions)}); "
         if complete >= n else
         f"Of the {n} participants, {complete} were measured under all {k} conditions "
         f"({', '.join(study.conditions)}; the repeated-measures tests use these {complete}, the mixed model every "
         f"available value); ") + f"participants per protocol order: {orders}.",
        "",
        "For each dependent variable, a one-way repeated-measures ANOVA (pingouin) tested the condition effect, with "
        "Mauchly's test of sphericity and the Greenhouse-Geisser and Huynh-Feldt corrections; effect sizes are "
        "partial and generalised η². A Friedman test with Kendall's W checked the result without the normality "
        "assumption. Pairs of conditions were compared with paired t-tests and Wilcoxon signed-rank tests, "
        f"Holm-corrected, with Cohen's d_z. A linear mixed model (statsmodels MixedLM, REML) with condition"
        f"{' and period' if has_period else ''} as fixed effects and a random intercept per participant used every "
        f"available value. Significance level α = {apa.num(study.alpha, 2, bounded=True)}.",
        "",
        "## Results",
        "",
    ]
    lines += [f"- {result_sentence(study, v)}" for v in study.variables["variable"]]
    if study.warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in study.warnings]
    return "\n".join(lines) + "\n"


def analyze_store_within(st, study=None) -> tuple[WithinStudy, pd.DataFrame]:
    """(the analysis, its long data) of the ``[within]`` declaration of the store's study
    (:mod:`analysis.within.data`); UserError when the study declares none or the store has nothing to compare."""
    from analysis.within.data import resolutions, within_data
    from study.store.studies import definition
    from study.folder.within_spec import within_spec

    study = study if study is not None else definition(st)
    spec = within_spec(study)
    if spec is None:
        raise UserError(f"study {study.study_id} declares no within-subjects comparison ([within] in study.toml)")
    data, items = within_data(st, study, spec)
    if data.empty:
        raise UserError("the store has no scores or KPIs of the compared conditions yet")
    return analyze_within(data, spec.conditions, items=items, alpha=study.alpha,
                          resolutions=resolutions(st, study, spec)), data

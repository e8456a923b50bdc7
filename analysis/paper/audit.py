"""Consistency audit of the paper's published statistics (Tables 3-5, Section 4.2 cohort counts).

Every check is one row: ``check``, ``where`` (table/row and LaTeX line), ``reported``, ``recomputed``, ``status``
(``ok`` | ``inconsistent`` | ``note``), ``explanation``, ``group`` (a stable key of the finding the row belongs to)
and ``finding`` (1, 2, ... numbered in order of first appearance for groups with at least one inconsistent row).
Findings are reported, never corrected here; :mod:`analysis.paper.reconstruct` documents which targets it uses.

Conventions the checks rely on (stated in docs/paper_reproduction.md):
- Table 3 means and SDs are printed with trailing zeros dropped: "4.35" is 4.350 (3 decimals), unless fewer than
  3 digits survive where SD values show 2 decimals ("1.21") - we take the printed digit count for SDs.
- Standardized loadings imply inter-item correlations r_ij = λ_i λ_j (one-factor congeneric model).
- Composite = mean of a construct's retained items (docs/contracts.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis import apa
from analysis.paper import grim
from analysis.paper import published as P
from analysis.render import markdown_table, md_cell
from analysis.survey.reliability import alpha_from_cov
from analysis.survey.validity import stars

N_TEXT = 41          # Section 4.2 / 5.2.1 text: "N=41" surveys
N_CANDIDATES = (40, 41)
MEAN_DECIMALS = 3    # Table 3 means: 3 decimals, trailing zeros dropped

FINDING_TITLES = {
    "n_implied": "The tables imply N = 40 survey respondents, the text says N = 41",
    "grim_pbc2": "PBC2 mean 4.208 is impossible for N = 40 (GRIM)",
    "sd_truncated": "Table 3 SDs are truncated, not rounded",
    "peou_diagonal": "Table 4 PEoU diagonal (.641) is not √AVE of Table 3 (√.537 = .733)",
    "t4_t5": "Table 4 PEoU correlations disagree with Table 5",
    "bi_alpha": "2-item BI: Cα .792 is impossible with λ = .911, .911",
    "loadings_vs_alpha": "Printed λ are too high for the printed Cα and for Table 5's B/β ratios",
    "ci_not_t": "Two Table 5 CIs (PEoU-only steps) are not B ± t·SE; they fit the Table 4 PEoU composite",
    "style_shares": "Driving-style shares 20.54 % do not equal 7/34",
    "extraction": "The printed λ are first-principal-component loadings (SPSS FACTOR default), not CFA loadings",
}


# What each finding means, in words (the numbers are in the rows).
FINDING_NOTES = {
    "n_implied": "Item means, eco-familiarity shares, adjusted R² and SE B all fit 40 respondents; the text's 41 "
                 "fits almost none of them.",
    "grim_pbc2": "No 40 integer answers have this mean; the reconstruction uses the nearest possible mean.",
    "sd_truncated": "Many printed SDs cannot be rounded values of any 1-5 distribution with the printed mean; "
                    "every one fits when the digits are cut off instead of rounded.",
    "peou_diagonal": "The Fornell-Larcker diagonal for PEoU was computed before PEoU3 was deleted.",
    "loadings_vs_alpha": "Cα and the item SDs imply composite SDs that reproduce Table 5's B/β ratios; the printed "
                         "λ imply higher inter-item correlations, higher Cα and composite SDs that miss B/β. CR and "
                         "AVE agree with λ, so λ/CR/AVE and Cα/Table 5 cannot describe the same data.",
    "bi_alpha": "For two items α is a function of their one correlation; the printed loadings fix that correlation "
                "at a value whose α is far from the printed one, and at N = 40 the printed α is not reachable.",
    "t4_t5": "Table 5's one-predictor steps fix r = β; for PEoU these differ from Table 4, while models 3 and 4 "
             "agree with Table 4 exactly.",
    "ci_not_t": "The other CIs are B ± t·SE; the PEoU-only ones are t-intervals of a different fit whose r equals "
                "Table 4's PEoU correlation (4-item PEoU composite). Nor are they SPSS bootstrap intervals: on the "
                "reconstructed data (which meets the rest of the paper), 1000 case resamples with any of 500 seeds "
                "give percentile and BCa intervals whose ends never come near the printed ones, while the t-based "
                "model 3 step 1 CI lies inside that range.",
    "style_shares": "The printed percentages are not whole counts of the objective sample.",
    "extraction": "For each construct: is there a correlation matrix whose extraction gives exactly the printed λ and, "
                  "with the item SDs, the printed Cα (CR and AVE follow from λ)? For 2 and 3 items the extraction "
                  "fixes the matrix, so Cα is determined by λ: a proof either way. Principal components fit PU, "
                  "PBC, SN and BI, and ATT when all 9 items are extracted together (a witness matrix); a factor "
                  "model (ML factor analysis = one-construct CFA, or principal axis factoring) is ruled out for "
                  "every construct where the test is decidable (not for ATT's 9-item extraction, where the search "
                  "found no matrix - evidence, not proof). PEoU fits no extraction: principal components come "
                  "closest (Cα at most .589 vs .596). Proven: ML/CFA and PAF cannot have produced the λ of PU, "
                  "PEoU, ATT (4 items), PBC, SN, BI together with their Cα. Consistent only: PCA is one procedure "
                  "that reproduces them; for PU and ATT other matrices (and procedures) may as well.",
}


@dataclass(frozen=True)
class Check:
    """One audit row before numbering."""

    check: str
    where: str
    reported: str
    recomputed: str
    status: str
    explanation: str
    group: str = ""


# Numbers in the rows' text, APA 7 (analysis.apa) by what each check compares: values bounded by 1 (r, β, α, λ,
# CR, AVE, R²) without a leading zero, B, SE, SDs, ratios and differences with one, p never 0.000, a true minus.
def _b(x: float, d: int = 3) -> str:
    """A value bounded by 1 (r, β, Cα, λ, CR, AVE, √AVE, R²) to `d` decimals: ``.879``, ``−.087``."""
    return apa.num(x, d, bounded=True)


def _n(x: float, d: int = 3) -> str:
    """An unbounded value (B, SE, a mean, an SD, a ratio, a difference, t) to `d` decimals: ``0.478``, ``−1.06``."""
    return apa.num(x, d)


def _g(x: float, bounded: bool = False) -> str:
    """A published value with the digits it was printed with (``:g``): ``.792`` (bounded), ``4.35``, ``−0.212``."""
    s = apa.minus(f"{x:g}")
    return apa.no_leading_zero(s) if bounded else s


def _d(x: float, d: int = 3) -> str:
    """A signed difference: ``+0.049``, ``−0.146``."""
    return ("+" if round(x, d) > 0 else "") + apa.num(x, d)


def _pct(x: float, d: int = 1) -> str:
    """A percentage with its unit: ``20.59 %``, ``−0.2 %``."""
    return apa.quantity(x, "%", d)


def _line(pub: pd.DataFrame, table: str, quantity: str, row: str, column: str = "") -> int:
    m = (pub["table"] == table) & (pub["quantity"] == quantity) & (pub["row"] == row)
    if column:
        m &= pub["column"] == column
    return int(pub.loc[m, "line"].iloc[0])


def _decimals(pub: pd.DataFrame, table: str, quantity: str, row: str, column: str = "") -> int:
    m = (pub["table"] == table) & (pub["quantity"] == quantity) & (pub["row"] == row)
    if column:
        m &= pub["column"] == column
    return int(pub.loc[m, "decimals"].iloc[0])


# ----------------------------------------------------------------------------------------------------------------
# Shared derived quantities
# ----------------------------------------------------------------------------------------------------------------

def cr_ave(loadings: np.ndarray) -> tuple[float, float]:
    """Hair et al. composite reliability and AVE from standardized loadings.

    CR = (Σλ)² / ((Σλ)² + Σ(1 - λ²)),  AVE = mean(λ²)."""
    lam = np.asarray(loadings, float)
    s = lam.sum() ** 2
    return float(s / (s + (1 - lam ** 2).sum())), float((lam ** 2).mean())


def implied_item_cov(sd: np.ndarray, loadings: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Item covariance with r_ij = scale·λ_i λ_j off the diagonal and the item SDs on it."""
    lam = np.asarray(loadings, float)
    r = scale * np.outer(lam, lam)
    np.fill_diagonal(r, 1.0)
    return np.outer(sd, sd) * r


def composite_sd_from_alpha(sd: np.ndarray, alpha: float) -> float:
    """SD of the mean of k items implied by Cα and the item SDs: Var(sum) = Σs² / (1 - α(k-1)/k)."""
    sd = np.asarray(sd, float)
    k = len(sd)
    var_sum = (sd ** 2).sum() / (1 - alpha * (k - 1) / k)
    return float(np.sqrt(var_sum) / k)


def composite_sd_from_loadings(sd: np.ndarray, loadings: np.ndarray) -> float:
    """SD of the mean of k items when r_ij = λ_i λ_j."""
    cov = implied_item_cov(sd, loadings)
    return float(np.sqrt(cov.sum()) / len(sd))


def retained(t3: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Table 3 items kept in the final model, per construct (Table 4 order)."""
    keep = t3[~t3["omitted"]]
    return {c: keep[keep["construct"] == c] for c in P.TABLE4_ORDER}


def composite_sds(published: pd.DataFrame | None = None, source: str = "alpha") -> dict[str, float]:
    """Composite SDs implied by Table 3: ``source='alpha'`` (Cα + item SDs) or ``'loadings'`` (λ + item SDs)."""
    t3, tc = P.table3(published), P.table3_constructs(published).set_index("construct")
    out = {}
    for c, g in retained(t3).items():
        if source == "alpha":
            out[c] = composite_sd_from_alpha(g["sd"].values, tc.loc[c, "alpha"])
        elif source == "loadings":
            out[c] = composite_sd_from_loadings(g["sd"].values, g["loading"].values)
        else:
            raise ValueError(f"unknown source {source!r} (alpha | loadings)")
    return out


def table5_consistent_correlations(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 4's correlation matrix with the correlations that Table 5's one-predictor steps fix (r = β)
    put in their place. This is the target the reconstruction uses; the audit shows every other Table 5
    number agrees with it."""
    m = P.table4_matrix(published)
    co = P.table5_coefficients(published)
    for r in co.itertuples():
        if len(P.TABLE5_MODELS[r.model][1][0]) == 1 and r.step == 1:
            m.loc[r.dv, r.predictor] = m.loc[r.predictor, r.dv] = r.beta
    return m


def _step_predictors(model: int, step: int) -> list[str]:
    dv, steps = P.TABLE5_MODELS[model]
    return [p for s in steps[:step] for p in s]


# ----------------------------------------------------------------------------------------------------------------
# The checks
# ----------------------------------------------------------------------------------------------------------------

def check_sample_size(pub: pd.DataFrame) -> list[Check]:
    """Which N do the item means and the eco-familiarity shares imply?"""
    t3 = P.table3(pub)
    scan = {n: int(sum(grim.grim_consistent(m, n, MEAN_DECIMALS) for m in t3["mean"])) for n in range(20, 61)}
    best = sorted(scan, key=lambda n: (-scan[n], n))
    k = len(t3)
    out = [Check(
        "N implied by item means (GRIM scan N = 20..60)",
        f"Table 3 means (lines {_line(pub, 'table3', 'mean', t3['item'].iloc[0])}-"
        f"{_line(pub, 'table3', 'mean', t3['item'].iloc[-1])}), text line 575",
        f"N = {N_TEXT} (text)",
        f"N = {best[0]}: {scan[best[0]]}/{k} means possible; N = {best[1]}: {scan[best[1]]}/{k}; "
        f"N = {N_TEXT}: {scan[N_TEXT]}/{k}",
        "inconsistent" if best[0] != N_TEXT else "ok",
        f"All means but one are multiples of 1/{best[0]}; with N = {N_TEXT} only {scan[N_TEXT]} of {k} printed means "
        f"can occur. The tables were computed on {best[0]} respondents.", "n_implied")]
    eco = pub[(pub["table"] == "cohort") & (pub["quantity"] == "eco_familiarity_share")]
    shares = eco["value"].values
    ok_n = [n for n in range(20, 61)
            if all(abs(s / 100 * n - round(s / 100 * n)) <= n * grim.half_unit(d) / 100
                   for s, d in zip(shares, eco["decimals"].values)) and sum(round(s / 100 * n) for s in shares) == n]
    out.append(Check(
        "N implied by eco-familiarity shares", f"Section 4.2, line {int(eco['line'].iloc[0])}",
        " / ".join(eco["printed"]) + " %", "N with integer counts summing to N: " + ", ".join(map(str, ok_n)) +
        (f" (counts at N = {ok_n[0]}: " + ", ".join(str(round(s / 100 * ok_n[0])) for s in shares) + ")" if ok_n else ""),
        "inconsistent" if N_TEXT not in ok_n else "ok",
        f"The shares are multiples of 2.5 % = 1/40; {N_TEXT} surveys cannot give them.", "n_implied"))
    return out


def check_grim(pub: pd.DataFrame) -> list[Check]:
    """GRIM for every item mean at each candidate N."""
    t3 = P.table3(pub)
    out = []
    for n in N_CANDIDATES:
        for r in t3.itertuples():
            sums = grim.grim_sums(r.mean, n, MEAN_DECIMALS)
            line = _line(pub, "table3", "mean", r.item)
            if sums:
                rec, status, expl = f"{sums[0]}/{n} = {sums[0] / n:.4f}", "ok", "possible"
            else:
                below = int(np.floor(r.mean * n))
                rec = f"{below}/{n} = {below / n:.4f}, {below + 1}/{n} = {(below + 1) / n:.4f}"
                status = "inconsistent"
                fits = [m for m in range(2, 61) if grim.grim_consistent(r.mean, m, MEAN_DECIMALS)]
                expl = (f"no sum of {n} integers gives this mean; N that fit: {', '.join(map(str, fits[:6]))}"
                        + (" (probably a typo or a different n for this item)" if n == 40 else ""))
            group = "" if status == "ok" else ("grim_pbc2" if n == 40 else "n_implied")
            out.append(Check(f"GRIM mean, N = {n}", f"Table 3 {r.item} (line {line})", f"{r.mean:g}", rec,
                             status, expl, group))
    return out


def check_grimmer(pub: pd.DataFrame) -> list[Check]:
    """GRIMMER for every item SD (sample SD, n - 1) under rounding and under truncation, at each candidate N."""
    t3 = P.table3(pub)
    out = []
    for n in N_CANDIDATES:
        counts, s, q = grim.count_vectors(n)
        for r in t3.itertuples():
            line = _line(pub, "table3", "sd", r.item)
            d = _decimals(pub, "table3", "sd", r.item)
            d_round = max(d, MEAN_DECIMALS) if d >= 2 else d
            sums = grim.grim_sums(r.mean, n, MEAN_DECIMALS)
            if not sums:
                if n == 40:
                    # the nearest possible means, to say whether the SD could fit either
                    below = int(np.floor(r.mean * n))
                    parts = []
                    for S in (below, below + 1):
                        k_t = len(grim.grimmer_candidates(S / n, r.sd, n, 6, d, sd_mode="truncate"))
                        parts.append(f"mean {S / n:.3f}: {k_t} distributions (truncated SD)")
                    out.append(Check(f"GRIMMER SD, N = {n}", f"Table 3 {r.item} (line {line})",
                                     f"M = {r.mean:g}, SD = {r.sd:g}", "; ".join(parts), "note",
                                     "mean fails GRIM; SD checked against the two nearest possible means", "grim_pbc2"))
                continue
            n_round = len(grim.grimmer_candidates(r.mean, r.sd, n, MEAN_DECIMALS, d_round, sd_mode="round"))
            n_trunc = len(grim.grimmer_candidates(r.mean, r.sd, n, MEAN_DECIMALS, d, sd_mode="truncate"))
            near = grim.nearest_sd(sums[0], r.sd, n)
            rec = f"nearest SD {near:.4f}; rounded: {n_round} distributions, truncated: {n_trunc}"
            if n_round:
                status, expl, group = "ok", "possible when rounded", ""
            elif n_trunc:
                status, group = "inconsistent", "sd_truncated"
                expl = (f"no 1-5 distribution with this mean has an SD that rounds to {r.sd:g} "
                        f"({d_round} decimals); {near:.4f} truncated to {d} decimals prints as {r.sd:g}")
            else:
                status, group = "inconsistent", "n_implied" if n != 40 else "sd_truncated"
                expl = "no distribution fits, rounded or truncated"
            out.append(Check(f"GRIMMER SD, N = {n}", f"Table 3 {r.item} (line {line})",
                             f"M = {r.mean:g}, SD = {r.sd:g}", rec, status, expl, group))
    return out


def check_cr_ave(pub: pd.DataFrame) -> list[Check]:
    """CR and AVE recomputed from the retained items' printed λ (Hair formulas)."""
    t3, tc = P.table3(pub), P.table3_constructs(pub).set_index("construct")
    out = []
    for c, g in retained(t3).items():
        cr, ave = cr_ave(g["loading"].values)
        for name, rec in (("cr", cr), ("ave", ave)):
            rep = tc.loc[c, name]
            ok = bool(grim.prints_as(rec, rep, 3, "round") or abs(rec - rep) <= 0.0015)
            out.append(Check(f"{name.upper()} from λ (Hair)", f"Table 3 {c} (line {_line(pub, 'table3', name, c)})",
                             _b(rep), _b(rec, 4), "ok" if ok else "inconsistent",
                             f"retained items {', '.join(g['item'])}" + ("" if ok else " - differs"),
                             "" if ok else "loadings_vs_alpha"))
    return out


def check_sqrt_ave(pub: pd.DataFrame) -> list[Check]:
    """√AVE from Table 3 vs Table 4's diagonal."""
    t3, tc = P.table3(pub), P.table3_constructs(pub).set_index("construct")
    t4 = P.table4(pub)
    out = []
    for r in t4[t4["diagonal"]].itertuples():
        rec = float(np.sqrt(tc.loc[r.a, "ave"]))
        ok = abs(rec - r.r) <= grim.half_unit(_decimals(pub, "table4", "sqrt_ave", r.a)) + 0.0006
        expl = "agrees" if ok else ""
        if not ok:
            all_items = t3[t3["construct"] == r.a]
            _, ave_all = cr_ave(all_items["loading"].values)
            expl = (f"√{_b(tc.loc[r.a, 'ave'])} = {_b(rec, 4)}. The printed diagonal equals √AVE of all "
                    f"{len(all_items)} items including the deleted ones: √{_b(ave_all, 4)} = "
                    f"{_b(np.sqrt(ave_all), 4)}; "
                    "the Fornell-Larcker check in Table 4 used the initial model for this construct")
        out.append(Check("√AVE vs Table 4 diagonal", f"Table 4 {r.a} (line {_line(pub, 'table4', 'sqrt_ave', r.a)})",
                         _g(r.r, bounded=True), _b(rec, 4), "ok" if ok else "inconsistent", expl,
                         "" if ok else "peou_diagonal"))
    return out


def check_alpha_vs_loadings(pub: pd.DataFrame) -> list[Check]:
    """Cα implied by the printed λ (r_ij = λ_i λ_j, item SDs from Table 3) vs the printed Cα."""
    t3, tc = P.table3(pub), P.table3_constructs(pub).set_index("construct")
    out = []
    for c, g in retained(t3).items():
        lam, sd = g["loading"].values, g["sd"].values
        a_raw = alpha_from_cov(implied_item_cov(sd, lam))
        a_std = alpha_from_cov(implied_item_cov(np.ones_like(sd), lam))
        rep = tc.loc[c, "alpha"]
        k = len(g)
        # the mean inter-item correlation the printed α implies (standardized α formula)
        rbar = rep / (k - rep * (k - 1))
        bad = abs(a_raw - rep) > 0.03
        if k == 2:
            expl = (f"two items: r(BI1,BI2) = λ1·λ2 = {_b(lam[0] * lam[1])} gives α = {_b(a_raw)} "
                    f"(standardized {_b(a_std)}); α = {_g(rep, bounded=True)} needs r = {_b(rbar)}, i.e. λ = √r = "
                    f"{_b(np.sqrt(rbar))}")
            group = "bi_alpha"
        else:
            mean_r = np.mean([lam[i] * lam[j] for i in range(k) for j in range(i + 1, k)])
            expl = f"mean r_ij = λ_iλ_j is {_b(mean_r)}; α = {_g(rep, bounded=True)} needs mean r ≈ {_b(rbar)}"
            group = "loadings_vs_alpha"
        out.append(Check("Cα implied by λ", f"Table 3 {c} (line {_line(pub, 'table3', 'alpha', c)})",
                         _g(rep, bounded=True), f"{_b(a_raw)} (standardized {_b(a_std)})",
                         "inconsistent" if bad else "ok", expl if bad else "agrees within 0.03", group if bad else ""))
    return out


def check_two_item_alpha_lattice(pub: pd.DataFrame, n: int = 40) -> list[Check]:
    """For 2-item scales: the α values N answers can reach given the items' printed mean and (truncated) SD.

    Σx, Σx² of each item are fixed by its GRIMMER candidates; Σxy is an integer, so α = 4cov/(v1 + v2 + 2cov)
    with cov = (Σxy - S1·S2/n)/(n - 1) can only take discrete values."""
    t3, tc = P.table3(pub).set_index("item"), P.table3_constructs(pub).set_index("construct")
    out = []
    vals = np.arange(1, 6)
    for c, g in retained(P.table3(pub)).items():
        if len(g) != 2:
            continue
        i1, i2 = g["item"].tolist()
        moments = []
        for it in (i1, i2):
            cands = grim.grimmer_candidates(t3.loc[it, "mean"], t3.loc[it, "sd"], n, MEAN_DECIMALS,
                                            _decimals(pub, "table3", "sd", it), sd_mode="truncate")
            moments.append({(int(cc @ vals), int(cc @ vals ** 2)) for cc in cands})
        alpha = float(tc.loc[c, "alpha"])
        reach = set()
        for s1, q1 in moments[0]:
            v1 = (q1 - s1 ** 2 / n) / (n - 1)
            for s2, q2 in moments[1]:
                v2 = (q2 - s2 ** 2 / n) / (n - 1)
                cov0 = alpha * (v1 + v2) / (4 - 2 * alpha)
                base = np.floor(cov0 * (n - 1) + s1 * s2 / n)
                for sxy in (base - 1, base, base + 1, base + 2):
                    cv = (sxy - s1 * s2 / n) / (n - 1)
                    reach.add(round(4 * cv / (v1 + v2 + 2 * cv), 4))
        near = sorted(reach, key=lambda a: abs(a - alpha))[:2]
        ok = bool(any(grim.prints_as(a, alpha, 3) for a in reach))
        line = _line(pub, "table3", "alpha", c)
        out.append(Check(f"2-item Cα reachable with N = {n}", f"Table 3 {c} (line {line})", _g(alpha, bounded=True),
                         "nearest reachable: " + ", ".join(_b(a, 4) for a in sorted(near)),
                         "ok" if ok else "inconsistent",
                         "reachable" if ok else (f"{i1} and {i2} each have one possible variance at N = {n} "
                                                 f"({len(moments[0])}x{len(moments[1])} (Σx, Σx²) pairs); Σxy is an "
                                                 f"integer, so α jumps between the values shown"),
                         "" if ok else "bi_alpha"))
    return out


def check_table4_vs_table5(pub: pd.DataFrame) -> list[Check]:
    """Table 4 correlations vs Table 5: r = β for one predictor; β = R_xx⁻¹ r_xy and R² = β'r_xy otherwise."""
    t4 = P.table4_matrix(pub)
    tgt = table5_consistent_correlations(pub)
    co, st = P.table5_coefficients(pub), P.table5_steps(pub)
    out = []
    tol = 0.006  # rounding of three-decimal inputs propagated through (1 - r12²)
    for (model, step), g in co.groupby(["model", "step"], sort=True):
        dv = g["dv"].iloc[0]
        preds = _step_predictors(model, step)
        beta = g.set_index("predictor").loc[preds, "beta"].values
        line = int(pub[(pub["table"] == "table5") & (pub["row"] == f"model {model} step {step}")]["line"].min())
        where = f"Table 5 model {model} step {step} (line {line}) vs Table 4"
        r2_rep = float(st[(st["model"] == model) & (st["step"] == step)]["r2"].iloc[0])
        if len(preds) == 1:
            p = preds[0]
            ok = abs(beta[0] - t4.loc[dv, p]) <= tol
            out.append(Check("r(x,y) = β (one predictor)", where, f"Table 4 r({p},{dv}) = {_b(t4.loc[dv, p])}",
                             f"Table 5 β = {_b(beta[0])} (R² = β² = {_b(beta[0] ** 2)}, printed {_b(r2_rep)})",
                             "ok" if ok else "inconsistent",
                             "agrees" if ok else f"differs by {_d(t4.loc[dv, p] - beta[0])}; Table 5's R² = β² "
                             f"agrees with β, so Table 4 is the odd one out (r² = {_b(t4.loc[dv, p] ** 2)})",
                             "" if ok else "t4_t5"))
            continue
        rxx = t4.loc[preds, preds].values
        rxy = t4.loc[preds, dv].values
        b_t4 = np.linalg.solve(rxx, rxy)
        ok = bool(np.all(np.abs(b_t4 - beta) <= tol))
        r2_t4 = float(b_t4 @ rxy)
        # the criterion correlations Table 5's β imply when the one-predictor steps' r replace Table 4's
        rxy_t5 = tgt.loc[preds, preds].values @ beta
        agree_t5 = bool(np.all(np.abs(rxy_t5 - tgt.loc[preds, dv].values) <= tol))
        out.append(Check(
            "β from Table 4 correlations", where, "β = " + ", ".join(f"{p} {_b(b)}" for p, b in zip(preds, beta))
            + f"; R² = {_b(r2_rep)}",
            "β = " + ", ".join(f"{p} {_b(b)}" for p, b in zip(preds, b_t4)) + f"; R² = {_b(r2_t4)}",
            "ok" if ok else "inconsistent",
            ("agrees (two/three-predictor identities β = R_xx⁻¹ r_xy)" if ok else
             "Table 4's correlations do not give Table 5's β") +
            "; with r = β from Table 5's one-predictor steps, β imply r_xy = "
            + ", ".join(f"{p} {_b(v)}" for p, v in zip(preds, rxy_t5))
            + (": consistent" if agree_t5 else ": still inconsistent"),
            "" if ok else "t4_t5"))
    return out


def adj_r2(r2: float, n: int, k: int) -> float:
    """Adjusted R² = 1 - (1 - R²)(n - 1)/(n - k - 1)."""
    return 1 - (1 - r2) * (n - 1) / (n - k - 1)


def check_adj_r2(pub: pd.DataFrame) -> list[Check]:
    """Adjusted R² and ΔR² vs R² for each candidate N (interval arithmetic on the printed digits)."""
    st = P.table5_steps(pub)
    out = []
    for r in st.itertuples():
        k = len(_step_predictors(r.model, r.step))
        line = _line(pub, "table5", "adj_r2", f"model {r.model} step {r.step}")
        lo, hi = grim.interval(r.r2, 3)
        alo, ahi = grim.interval(r.adj_r2, 3)
        recs, fits = [], []
        for n in N_CANDIDATES:
            a_lo, a_hi = adj_r2(lo, n, k), adj_r2(hi, n, k)
            fits.append(a_hi >= alo and a_lo <= ahi)
            recs.append(f"N = {n}: {apa.ci(a_lo, a_hi, 4, bounded=True)}")
        fit_n = [n for n, f in zip(N_CANDIDATES, fits) if f]
        out.append(Check("adj R² vs R²", f"Table 5 model {r.model} step {r.step} (line {line})",
                         f"R² = {_b(r.r2)}, adj = {_b(r.adj_r2)}", "; ".join(recs),
                         "ok" if 40 in fit_n else "inconsistent",
                         "fits N = " + (", ".join(map(str, fit_n)) if fit_n else "none"),
                         "" if 40 in fit_n else "n_implied"))
        prev = st[(st["model"] == r.model) & (st["step"] == r.step - 1)]
        if r.model == 4 and r.step == 2:
            prev = st[(st["model"] == 3) & (st["step"] == 1)]  # "same as model 3 step 1"
        base = float(prev["r2"].iloc[0]) if len(prev) else 0.0
        d = r.r2 - base
        ok = abs(d - r.delta_r2) <= 0.0015
        out.append(Check("ΔR² = R² − R²(previous step)", f"Table 5 model {r.model} step {r.step} (line {line})",
                         _b(r.delta_r2), f"{_b(r.r2)} − {_b(base)} = {_b(d)}", "ok" if ok else "inconsistent",
                         "agrees within rounding" if ok else "differs", "" if ok else "t4_t5"))
    return out


def check_b_beta(pub: pd.DataFrame) -> list[Check]:
    """B/β = SD_y/SD_x vs composite SDs from Table 3 (via Cα, and via λ)."""
    co = P.table5_coefficients(pub)
    sd_a, sd_l = composite_sds(pub, "alpha"), composite_sds(pub, "loadings")
    out = []
    for r in co.itertuples():
        ratio = r.b / r.beta
        # interval of B/β from the printed digits
        b_lo, b_hi = grim.interval(r.b, 3)
        be_lo, be_hi = grim.interval(r.beta, 3)
        cands = [b_lo / be_lo, b_lo / be_hi, b_hi / be_lo, b_hi / be_hi]
        r_lo, r_hi = min(cands), max(cands)
        ra, rl = sd_a[r.dv] / sd_a[r.predictor], sd_l[r.dv] / sd_l[r.predictor]
        rel_a, rel_l = ra / ratio - 1, rl / ratio - 1
        ok_a, ok_l = abs(rel_a) <= 0.015, abs(rel_l) <= 0.015
        line = _line(pub, "table5", "b", f"model {r.model} step {r.step}", r.predictor)
        status = "ok" if ok_a and ok_l else "inconsistent"
        expl = (f"SD_{r.dv}/SD_{r.predictor} from Cα and item SDs: {_n(ra)} ({_d(100 * rel_a, 1)} %); from λ "
                f"(r_ij = λ_iλ_j): {_n(rl)} ({_d(100 * rel_l, 1)} %). Assumes composite = mean of retained items; "
                "item SDs from Table 3")
        out.append(Check("B/β vs composite SD ratio", f"Table 5 model {r.model} step {r.step} {r.predictor} (line {line})",
                         f"B/β = {_n(r.b)}/{_b(r.beta)} = {_n(ratio)} {apa.ci(r_lo, r_hi, 3)}",
                         f"α: {_n(ra)}; λ: {_n(rl)}", status, expl, "" if status == "ok" else "loadings_vs_alpha"))
    return out


def check_se_b(pub: pd.DataFrame, n: int = 40) -> list[Check]:
    """SE B implied by R², the predictors' intercorrelations and B/β: SE_B = (B/β)·√((1-R²)/((n-k-1)(1-R_j²)))."""
    co, st = P.table5_coefficients(pub), P.table5_steps(pub)
    tgt = table5_consistent_correlations(pub)
    out = []
    for r in co.itertuples():
        preds = _step_predictors(r.model, r.step)
        k = len(preds)
        r2 = float(st[(st["model"] == r.model) & (st["step"] == r.step)]["r2"].iloc[0])
        rxx = tgt.loc[preds, preds].values
        vif = float(np.linalg.inv(rxx)[preds.index(r.predictor), preds.index(r.predictor)])
        se_beta = np.sqrt((1 - r2) / (n - k - 1) * vif)
        se_b = se_beta * r.b / r.beta
        ok = abs(se_b - r.se_b) <= 0.004
        line = _line(pub, "table5", "se_b", f"model {r.model} step {r.step}", r.predictor)
        out.append(Check(f"SE B from R², VIF and B/β (N = {n})",
                         f"Table 5 model {r.model} step {r.step} {r.predictor} (line {line})", _n(r.se_b),
                         f"{_n(se_b, 4)} (SE β = {_n(se_beta, 4)}, VIF = {_n(vif)})", "ok" if ok else "inconsistent",
                         "agrees" if ok else "differs by more than rounding", "" if ok else "n_implied"))
    return out


def check_ci(pub: pd.DataFrame, n: int = 40) -> list[Check]:
    """Are the printed 95 % CIs B ± t(.975, n-k-1)·SE?"""
    co = P.table5_coefficients(pub)
    out = []
    for r in co.itertuples():
        k = len(_step_predictors(r.model, r.step))
        t = stats.t.ppf(0.975, n - k - 1)
        lo, hi = r.b - t * r.se_b, r.b + t * r.se_b
        ok = abs(lo - r.ci_low) <= 0.003 and abs(hi - r.ci_high) <= 0.003
        mid = (r.ci_low + r.ci_high) / 2
        half = (r.ci_high - r.ci_low) / 2
        line = _line(pub, "table5", "ci_low", f"model {r.model} step {r.step}", r.predictor)
        if ok:
            expl = "t-based"
        else:
            # read the printed interval as a t-interval of some other fit: B' = midpoint, SE' = half-width / t
            se2 = half / t
            t2 = mid / se2
            expl = (f"not t-based around B = {_n(r.b)}: midpoint {_n(mid)} (offset {_d(mid - r.b)}), width "
                    f"{_n(2 * half)} vs {_n(hi - lo)}. Read as a t-interval it belongs to B' = {_n(mid)}, "
                    f"SE' = {_n(se2)}, t' = {_n(t2, 2)}")
            if k == 1:
                r_implied = t2 / np.sqrt(t2 ** 2 + n - 2)
                expl += (f", i.e. r = t'/√(t'² + {n - 2}) = {_b(r_implied)}: the Table 4 correlation "
                         f"r({r.predictor},{r.dv}), not Table 5's β = {_b(r.beta)}: the CI comes from the "
                         "Table 4 composite")
        out.append(Check(f"CI = B ± t·SE (df = {n - k - 1})",
                         f"Table 5 model {r.model} step {r.step} {r.predictor} (line {line})",
                         apa.ci(r.ci_low, r.ci_high, 3), apa.ci(lo, hi, 3),
                         "ok" if ok else "inconsistent", expl,
                         "" if ok else "ci_not_t"))
    return out


def check_stars(pub: pd.DataFrame, n: int = 40) -> list[Check]:
    """Significance stars: Table 4 (r, two-tailed, * .05 ** .01) and Table 5 (t = B/SE, * .05 ** .001)."""
    out = []
    t4 = P.table4(pub)
    for r in t4[~t4["diagonal"]].itertuples():
        lo, hi = grim.interval(r.r, 3)
        ps = []
        for x in (lo, hi):
            t = abs(x) * np.sqrt((n - 2) / (1 - x * x))
            ps.append(2 * stats.t.sf(t, n - 2))
        expected = {len(stars(p, (0.05, 0.01))) for p in ps}
        ok = r.stars in expected
        line = _line(pub, "table4", "r", r.a, r.b)
        out.append(Check(f"stars of r (N = {n})", f"Table 4 {r.a}-{r.b} (line {line})", f"{_b(r.r)}{'*' * r.stars}",
                         apa.p_text(max(ps), 4) + ("" if len(expected) == 1 else
                                                   f" to {apa.p_value(min(ps), 4)} (on the boundary)"),
                         "ok" if ok else "inconsistent", "agrees" if ok else "stars do not match p", ""))
    co = P.table5_coefficients(pub)
    for r in co.itertuples():
        k = len(_step_predictors(r.model, r.step))
        p = 2 * stats.t.sf(abs(r.b / r.se_b), n - k - 1)
        ok = r.stars == len(stars(p, (0.05, 0.001)))
        line = _line(pub, "table5", "beta", f"model {r.model} step {r.step}", r.predictor)
        out.append(Check(f"stars of β (N = {n})", f"Table 5 model {r.model} step {r.step} {r.predictor} (line {line})",
                         f"{_b(r.beta)}{'*' * r.stars}", f"t = {_n(r.b / r.se_b, 2)}, {apa.p_text(p, 4)}",
                         "ok" if ok else "inconsistent", "agrees (* .05, ** .001 per the table note)" if ok else
                         "stars do not match p", ""))
    return out


def check_cohort(pub: pd.DataFrame) -> list[Check]:
    """Cohort arithmetic of Section 4.2."""
    v = lambda q, row="all", col="count": P.value(q, row, col, "cohort", pub)  # noqa: E731
    line = int(pub[(pub["table"] == "cohort") & (pub["quantity"] == "enrolled")]["line"].iloc[0])
    out = []
    for name, lhs, rhs, txt in (
            ("male + female = enrolled", v("male") + v("female"), v("enrolled"), "37 + 7"),
            ("enrolled − motion sickness = survey N", v("enrolled") - v("motion_sickness"), v("survey_n"), "44 − 3"),
            ("survey N − technical issues = objective N", v("survey_n") - v("technical_issues"), v("objective_n"),
             "41 − 7")):
        out.append(Check(name, f"Section 4.2 (line {line})", f"{rhs:g}", f"{txt} = {lhs:g}",
                         "ok" if lhs == rhs else "inconsistent", "agrees" if lhs == rhs else "differs", ""))
    n_obj = v("objective_n")
    # the style counts of the 34 objective participants (data/reference/README.md); the printed shares are checked
    counts = {"cautious": 7, "normal": 20, "sporty": 7}
    for style, c in counts.items():
        rep = v("style_share", style, "percent")
        rec = 100 * c / n_obj
        ok = abs(rec - rep) <= grim.half_unit(2)
        out.append(Check(f"style share {style} = count/{n_obj:g}", f"Section 4.2 (line {line})", f"{rep:g} %",
                         f"{c}/{n_obj:g} = {_pct(rec, 2)}", "ok" if ok else "inconsistent",
                         "agrees" if ok else (f"no integer count of {n_obj:g} gives {rep:g} % "
                                              f"(7/34 = 20.59 %); the three shares sum to "
                                              f"{_pct(sum(v('style_share', s, 'percent') for s in counts), 2)}"),
                         "" if ok else "style_shares"))
    return out


def check_extraction(pub: pd.DataFrame) -> list[Check]:
    """Feasibility of the printed λ + Cα + item SDs under each extraction (:mod:`analysis.paper.procedure`).

    Rows of the ML extraction (what "standardized factor loadings" of a CFA are) are ``inconsistent`` when rejected;
    PCA/PAF rows are ``ok`` when they fit and a ``note`` otherwise; one row per construct says whether any
    extraction fits (``inconsistent`` when none does)."""
    from analysis.paper import procedure as F

    res = F.feasibility(None if pub.equals(P.load_published()) else pub)
    out = []
    for c in P.TABLE4_ORDER:
        rows = [r for r in res if r.construct == c]
        line = _line(pub, "table3", "alpha", c)
        for r in rows:
            where = f"Table 3 {c} (line {line}), {r.item_set} items"
            if r.how in ("closed form", "family scan"):
                rec = f"Cα allowed by λ: {_b(r.alpha_low, 4)} to {_b(r.alpha_high, 4)}" if np.isfinite(r.alpha_low) \
                    else "no correlation matrix has these λ"
            else:
                rec = "witness matrix found" if r.status == "fits" else "no matrix found"
            proof = {"closed form": f"{r.k} items: the λ fix the correlations (proof)",
                     "family scan": f"{r.k} items: {r.unknowns - r.k}-dimensional family of solutions scanned",
                     "witness": f"{r.k} items, {r.unknowns} correlations: a matrix with these λ and Cα exists",
                     "search": f"{r.k} items, {r.unknowns} correlations: seeded search found none (not a proof)"}[r.how]
            if r.status == "fits":
                status = "ok"
            elif r.method == "ml" and r.status == "rejected":
                status = "inconsistent"
            else:
                status = "note"
            out.append(Check(f"λ and Cα under {F.METHOD_NAMES[r.method]}", where,
                             f"Cα = {_g(r.alpha_printed, bounded=True)}; λ = " + ", ".join(
                                 _g(x, bounded=True) for x in P.table3(pub).set_index("item").loc[r.items, "loading"]),
                             rec, status, proof, "extraction"))
        fits = sorted({f"{F.METHOD_NAMES[r.method]} ({r.item_set} items)" for r in rows if r.status == "fits"})
        out.append(Check("some extraction reproduces λ and Cα", f"Table 3 {c} (line {line})",
                         f"Cα = {_g(rows[0].alpha_printed, bounded=True)}", "; ".join(fits) if fits else "none",
                         "ok" if fits else "inconsistent",
                         "consistent with " + ", ".join(fits) if fits else
                         "no extraction of the retained or of all items gives these λ with this Cα",
                         "extraction"))
    return out


def check_ci_bootstrap(pub: pd.DataFrame) -> list[Check]:
    """Could SPSS's bootstrap (1000 case resamples, percentile or BCa, a random seed) have printed the one-predictor
    CIs? Tried on the reconstructed reference survey with 500 seeds (:mod:`analysis.paper.bootstrap_check`)."""
    from analysis.paper import bootstrap_check as B

    res = B.check_printed_cis(published=pub)
    out = []
    for r in res.itertuples():
        line = _line(pub, "table5", "ci_low", f"model {r.model} step {r.step}", r.predictor)
        t_based = abs(r.printed_low - r.t_low) <= 0.02 and abs(r.printed_high - r.t_high) <= 0.02
        status = "ok" if r.consistent else ("note" if t_based else "inconsistent")
        expl = (f"over {B.N_SEEDS} seeds the {r.method} interval's ends range {_n(r.low_min)} to {_n(r.low_max)} "
                f"and {_n(r.high_min)} to {_n(r.high_max)} (B = {_n(r.b_data)} on the reference data, t-interval "
                f"{apa.ci(r.t_low, r.t_high, 3)}); {_pct(100 * r.share_both)} of seeds print the printed interval. "
                + ("Consistent on this data." if r.consistent else
                   "No seed comes near: not SPSS's bootstrap of this regression on data that meets the rest of the "
                   "paper (a statement about this data set, not a proof for every data set)."))
        out.append(Check(f"CI = SPSS bootstrap ({B.N_BOOT} resamples, {r.method})",
                         f"Table 5 model {r.model} step {r.step} {r.predictor} (line {line})",
                         apa.ci(r.printed_low, r.printed_high, 3),
                         f"lower {_n(r.low_min)} to {_n(r.low_max)}, upper {_n(r.high_min)} to {_n(r.high_max)}",
                         status, expl, "ci_not_t" if status == "inconsistent" else ""))
    return out


CHECKS = (check_sample_size, check_grim, check_grimmer, check_cr_ave, check_sqrt_ave, check_alpha_vs_loadings,
          check_two_item_alpha_lattice,
          check_table4_vs_table5, check_adj_r2, check_b_beta, check_se_b, check_ci, check_stars, check_cohort,
          check_extraction, check_ci_bootstrap)


def run_audit(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """All checks as one tidy frame: id, check, where, reported, recomputed, status, explanation, group, finding."""
    pub = published if published is not None else P.load_published()
    rows = [c for fn in CHECKS for c in fn(pub)]
    df = pd.DataFrame([c.__dict__ for c in rows])
    order: list[str] = []
    for g, s in zip(df["group"], df["status"]):
        if g and s == "inconsistent" and g not in order:
            order.append(g)
    df["finding"] = df["group"].map(lambda g: order.index(g) + 1 if g in order else pd.NA).astype("Int64")
    df.insert(0, "id", [f"A{i + 1:03d}" for i in range(len(df))])
    return df


def findings(audit: pd.DataFrame) -> pd.DataFrame:
    """One row per finding: finding, group, title, n_rows (inconsistent rows), first_row (audit id)."""
    bad = audit[audit["finding"].notna() & (audit["status"] == "inconsistent")]
    out = []
    for k, g in bad.groupby("finding", sort=True):
        grp = g["group"].iloc[0]
        out.append({"finding": int(k), "group": grp, "title": FINDING_TITLES.get(grp, grp),
                    "n_rows": len(g), "first_row": g["id"].iloc[0]})
    return pd.DataFrame(out, columns=["finding", "group", "title", "n_rows", "first_row"])


def finding_for(audit: pd.DataFrame, group: str) -> int | None:
    """The finding number of a group (None when the group has no inconsistent row)."""
    f = audit.loc[(audit["group"] == group) & audit["finding"].notna(), "finding"]
    return int(f.iloc[0]) if len(f) else None


# ----------------------------------------------------------------------------------------------------------------
# Rendering
# ----------------------------------------------------------------------------------------------------------------

#: the audit's columns as a table prints them: column -> header (words)
TABLE_COLUMNS = {"id": "Row", "check": "Check", "where": "Where", "reported": "Reported", "recomputed": "Recomputed",
                 "status": "Status", "finding": "Finding", "explanation": "Explanation"}
TABLE_TITLE = "Audit of the published statistics"
TABLE_NOTES = ("Each row recomputes a printed number from other printed numbers. Status: ok (agrees), inconsistent "
               "(contradicts them), note (a fact the findings rest on). Finding: the number of the finding an "
               "inconsistent row belongs to (paper/audit.md). Stars are the paper's as printed: Table 4 * p < .05, "
               "** p < .01; Table 5 * p < .05, ** p < .001.",)


def table_cells(audit: pd.DataFrame, cols=tuple(TABLE_COLUMNS)) -> tuple[list[str], list[list[str]]]:
    """Header (words, :data:`TABLE_COLUMNS`) and cells of the columns `cols` of the audit: the rows' text as the
    checks wrote it (their numbers in APA form already), the finding number as an integer (a CSV read back holds
    it as a float), empty where a row has none."""
    def cell(col, v) -> str:
        if pd.isna(v):
            return ""
        return str(int(v)) if col == "finding" else str(v)

    return ([TABLE_COLUMNS[c] for c in cols],
            [[cell(c, v) for c, v in zip(cols, row)] for row in audit[list(cols)].itertuples(index=False)])


def write_table_files(audit: pd.DataFrame, out_dir, stem: str) -> list:
    """Every check as one table: ``<stem>.csv`` (the cells as printed), ``.md`` and ``.tex``; returns the paths."""
    import csv
    import io
    from pathlib import Path

    from analysis.render import latex_table

    out = Path(out_dir)
    header, rows = table_cells(audit)
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows([header, *rows])
    texts = {"csv": buf.getvalue(), "md": markdown_table(header, rows, TABLE_TITLE, TABLE_NOTES),
             "tex": latex_table(header, rows, TABLE_TITLE, TABLE_NOTES, label=f"tab:{stem}")}
    for ext, text in texts.items():
        (out / f"{stem}.{ext}").write_text(text, encoding="utf-8")
    return [out / f"{stem}.{ext}" for ext in texts]


def _md_table(df: pd.DataFrame, cols: list[str]) -> list[str]:
    """Markdown lines of the columns `cols` of `df` (:func:`table_cells`)."""
    return markdown_table(*table_cells(df, cols)).splitlines()


def render_markdown(audit: pd.DataFrame) -> str:
    """A readable report: summary, one section per finding with its rows, then every check in a table."""
    f = findings(audit)
    counts = audit["status"].value_counts()
    out = ["# Consistency audit of the published statistics", "",
           "Generated by `pedas-study paper audit` from `studies/pedas_paper/published.csv`. Each check recomputes a printed "
           "number from other printed numbers; findings are reported here and never corrected in the data.", "",
           f"Checks: {len(audit)} - " + ", ".join(f"{k}: {v}" for k, v in counts.items()) +
           f". Findings: {len(f)}.", "", "## Findings", ""]
    for r in f.itertuples():
        rows = audit[(audit["finding"] == r.finding) & (audit["status"] == "inconsistent")]
        out += [f"### Finding #{r.finding}: {r.title}", ""]
        first = rows.iloc[0]
        out += [FINDING_NOTES.get(r.group, ""), "", f"First row: {md_cell(first['explanation'])}", "",
                f"{len(rows)} inconsistent check(s):", ""]
        out += _md_table(rows.head(15), ["id", "check", "where", "reported", "recomputed"])
        if len(rows) > 15:
            out.append(f"| ... | {len(rows) - 15} more rows in audit.csv | | | |")
        out.append("")
    out += ["## All checks", ""]
    out += _md_table(audit, list(TABLE_COLUMNS))
    return "\n".join(out) + "\n"


def write_audit(out_dir, published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Run the audit and write ``audit.csv`` and ``audit.md`` into ``out_dir`` (created); returns the frame."""
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    audit = run_audit(published)
    audit.to_csv(out / "audit.csv", index=False, lineterminator="\n")
    (out / "audit.md").write_text(render_markdown(audit), encoding="utf-8")
    return audit

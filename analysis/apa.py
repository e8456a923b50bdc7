"""APA 7 number formatting, one place for every table writer and every generated sentence.

* p without a leading zero and never 0.000: ``.011``, ``< .001`` (in a sentence ``p = .011``, ``p < .001``);
* no leading zero for values bounded by 1 (r, standardized β, α, ω, λ, CFI, TLI, SRMR, RMSEA, R², AVE, CR, HTMT, p);
* confidence intervals as ``[LL, UL]``;
* a true minus sign (U+2212) in front of a negative number;
* degrees of freedom as integers where they are integers, fractional (corrected) df to two decimals;
* one significance convention per document (:data:`STARS`), stated in each table's note by :func:`stars_note`;
* a measured value in a sentence with its declared unit (:func:`quantity`: ``M = 2.41 s``, ``12.8 %``).

Table writers call :func:`table_cells` with a header and string cells: headers that are identifiers become words and
symbols (:func:`header`), each cell is reformatted by the kind of its column (:func:`column_kind`). Every function
takes what it already returned unchanged (idempotent), so a table that passes two writers is formatted once.
"""
from __future__ import annotations

import math
import re
from typing import Sequence

MINUS = "\u2212"
#: the one significance convention of the report: (threshold, mark), strictest last
STARS = ((0.05, "*"), (0.01, "**"), (0.001, "***"))

#: identifiers of the analysis' tidy frames -> the words and symbols of an APA header
HEADERS = {
    "beta": "β", "b": "B", "se_b": "SE B", "se": "SE", "p": "p", "t": "t", "f": "F", "r": "r", "r2": "R²",
    "adj_r2": "Adj. R²", "delta_r2": "ΔR²", "r2_change": "ΔR²", "f_change": "F (ΔR²)", "p_change": "p (ΔR²)",
    "p_regression": "p", "beta_regression": "β", "f2": "f²", "df": "df", "df1": "df1", "df2": "df2",
    "alpha": "α", "omega": "ω", "omega_ml": "ω (ML)", "omega_ordinal_uls": "ω (ordinal, ULS)",
    "omega_ordinal_dwls": "ω (ordinal, DWLS)", "cr": "CR", "ave": "AVE", "sqrt_ave": "√AVE", "htmt": "HTMT",
    "htmt2": "HTMT2", "cfi": "CFI", "tli": "TLI", "srmr": "SRMR", "rmsea": "RMSEA", "chi2": "χ²",
    "chi2_baseline": "χ² (baseline)", "df_baseline": "df (baseline)", "n": "n", "n_items": "Items",
    "loading": "λ", "loading_ml": "λ (ML)", "loading_uls": "λ (ULS)", "loading_dwls": "λ (DWLS)", "vif": "VIF",
    "std": "SD", "sd": "SD", "mean": "M", "median": "Mdn", "min": "Min", "max": "Max", "estimate": "Estimate",
    "r_latent": "r (latent)", "own_r": "r (own construct)", "cross_r": "r (other construct)",
    "cross_construct": "Other construct", "error_var": "Error variance", "std_latent": "β (latent)",
    "std_composite": "β (composite)", "mean_raw": "M (raw)", "paper_value": "Paper", "our_value": "Ours",
    "participant_id": "Participant", "drive_id": "Drive", "n_params": "Parameters", "n_boot": "Resamples",
    "statistic": "Statistic", "holds": "Holds", "lo": "Lower", "hi": "Upper", "dv": "DV",
    # the diagnostics' columns (docs/contracts.md, survey/extended/): flags as the rule they test
    "stage": "Stage", "construct": "Construct", "item": "Item", "variable": "Variable", "model": "Model",
    "retained": "Retained", "rule": "Rule", "flag_low": "Low λ", "flag_negative": "Negative λ",
    "flag_cross": "Cross-loading", "above_limit": "Above limit", "above_3_3": "VIF > 3.3", "above_085": "Above .85",
    "above_090": "Above .90", "eigenvalue_1": "First eigenvalue", "first_share": "Share of the first factor",
    "above_50": "Above 50 %", "n_components_eigen_gt_1": "Components with eigenvalue > 1", "chain": "Path",
    "x": "From", "y": "To", "estimator": "Estimator", "f_min": "Fit function minimum", "converged": "Converged",
    "admissible": "Admissible", "n_failed": "Failed resamples", "method": "Method", "band": "Band", "note": "Note",
    "hypothesis": "Hypothesis", "path": "Path", "supported": "Supported", "step": "Step",
}
#: pairs of lower/upper columns written as one "[LL, UL]" column, with that column's header
CI_PAIRS = (("boot_ci_low", "boot_ci_high", "Bootstrap 95 % CI"), ("alpha_ci_low", "alpha_ci_high", "95 % CI of α"),
            ("ci_low", "ci_high", "95 % CI"))
#: headers (first word) of values bounded by 1: printed without a leading zero
BOUNDED = {"p", "r", "β", "α", "Cα", "ω", "λ", "CFI", "TLI", "SRMR", "RMSEA", "R²", "ΔR²", "Adj.", "AVE", "CR",
           "√AVE", "HTMT", "HTMT2", "item-rest", "r²", "Share", "η²", "η²p", "η²G"}
_UNITS = (("_pct", " (%)"), ("_wh", " (Wh)"), ("_mps", " (m/s)"), ("_m", " (m)"), ("_s", " (s)"))
_NUM = re.compile(r"^(?P<lt>[<>]\s?)?(?P<sign>[-−]?)(?P<int>\d+)(?P<frac>\.\d+)?(?P<tail>[*†‡a-z]*)$")


def header(name: str) -> str:
    """An identifier header as words and symbols (``beta`` -> ``β``, ``saving_urban_pct`` -> ``saving urban (%)``);
    a header already in words is kept."""
    name = str(name)
    if name in HEADERS:
        return HEADERS[name]
    if "_" not in name:
        return name
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return name[: -len(suffix)].replace("_", " ") + unit
    return name.replace("_", " ")


def column_kind(head: str) -> str:
    """"p" (p values), "df" (degrees of freedom), "bounded" (values bounded by 1) or "number"."""
    first = str(head).split(" ")[0] if str(head).strip() else ""
    if " CI of " in str(head):   # "95 % CI of α": the interval of a quantity is of that quantity's kind
        first = str(head).split(" CI of ")[1].split(" ")[0]
    if first == "p":
        return "p"
    if first in ("df", "df1", "df2"):
        return "df"
    if first in BOUNDED:
        return "bounded"
    return "number"


def minus(text: str) -> str:
    """A hyphen in front of a number as the true minus sign (U+2212): ``-0.5`` -> ``−0.5``; other text unchanged."""
    return re.sub(r"(?<![\w.)\]])-(?=\.?\d)", MINUS, str(text))


def no_leading_zero(text: str) -> str:
    """``0.737`` -> ``.737``, ``-0.2`` -> ``−.2``; a value of 1 or more (an improper standardized estimate) kept."""
    return re.sub(r"(?<![\w.])([-−]?)0(\.\d)", lambda m: (MINUS if m.group(1) else "") + m.group(2), str(text))


def cell(text: str, kind: str = "number") -> str:
    """One string cell reformatted by the kind of its column (:func:`column_kind`); text that is not a number
    (labels, notes) is kept apart from its minus signs."""
    s = str(text).strip()
    m = _NUM.match(s)
    if not m:
        if re.fullmatch(r"\[?[-−]?[\d.]+, [-−]?[\d.]+\]?", s):   # an interval
            return no_leading_zero(minus(s)) if kind in ("bounded", "p") else minus(text)
        return str(text)
    if kind == "p" and not m.group("lt") and not m.group("sign"):
        v = float(m.group("int") + (m.group("frac") or ""))
        digits = max(len(m.group("frac") or "") - 1, 3)
        return (p_value(v, digits) if v > 0 or m.group("frac") else s) + m.group("tail")
    if kind == "df" and m.group("frac") is not None and not m.group("tail"):
        return df_text(float(m.group("sign").replace(MINUS, "-") + m.group("int") + m.group("frac")))
    s = minus(s)
    return no_leading_zero(s) if kind in ("bounded", "p") else s


def table_cells(head: Sequence[str], rows: Sequence[Sequence[str]]) -> tuple[list[str], list[list[str]]]:
    """Header and cells of a table in APA form: identifier headers as words and symbols, cells by column kind."""
    new_head = [header(h) for h in head]
    kinds = [column_kind(h) for h in new_head]
    return new_head, [[cell(c, kinds[k] if k < len(kinds) else "number") for k, c in enumerate(r)] for r in rows]


# ---------------------------------------------------------------------------------------------- numbers
def num(x, digits: int = 2, bounded: bool = False) -> str:
    """A number to `digits` decimals with a true minus sign; `bounded` drops the leading zero (r, β, α, p ...);
    a missing value is an en dash.

    >>> num(-0.4567), num(0.4567, 3, bounded=True), num(12), num(float("nan"))
    ('−0.46', '.457', '12.00', '–')
    """
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(v):
        return "–"
    s = f"{v:.{digits}f}"
    if s.startswith("-") and float(s) == 0:  # −0.00 reads as a negative value
        s = s[1:]
    s = minus(s)
    return no_leading_zero(s) if bounded else s


#: units that name no physical unit: the value is printed bare (a count, a share, a score)
DIMENSIONLESS = ("", "1", "-", "–", "count", "counts")


def quantity(x, unit: str = "", digits: int = 2) -> str:
    """A measured value in a sentence with its unit (as declared: a KPI's ``unit``, the measure library's):
    ``2.41 s``, ``−3.2 Wh/km``, ``12.8 %``; a dimensionless one (:data:`DIMENSIONLESS`) as the number alone;
    `digits` decimals (0 for counts).

    >>> quantity(2.4123, "s"), quantity(-3.21, "Wh/km", 1), quantity(12.84, "%", 1), quantity(3, "count", 0)
    ('2.41 s', '−3.2 Wh/km', '12.8 %', '3')
    """
    s = num(x, digits)
    unit = str(unit or "").strip()
    return s if unit in DIMENSIONLESS or s == "–" else f"{s} {unit}"


def p_value(p, digits: int = 3) -> str:
    """A p value for a table cell: ``.011``, ``< .001`` (never ``0.000``), ``1.000`` -> ``> .999``.

    >>> p_value(0.0114), p_value(0.00002), p_value(0.5), p_value(1.0)
    ('.011', '< .001', '.500', '> .999')
    """
    try:
        v = float(p)
    except (TypeError, ValueError):
        return str(p)
    if not math.isfinite(v):
        return "–"
    floor = 10 ** -digits
    if v < floor:
        return f"< {num(floor, digits, bounded=True)}"
    if v > 1 - floor:
        return f"> {num(1 - floor, digits, bounded=True)}"
    return num(v, digits, bounded=True)


def p_text(p, digits: int = 3) -> str:
    """A p value in a sentence: ``p = .011``, ``p < .001``.

    >>> p_text(0.0114), p_text(0.0)
    ('p = .011', 'p < .001')
    """
    s = p_value(p, digits)
    return f"p {s}" if s[:1] in "<>" else f"p = {s}"


def ci(lo, hi, digits: int = 2, bounded: bool = False) -> str:
    """A confidence interval as ``[LL, UL]``.

    >>> ci(-0.758, 0.243), ci(0.61, 0.84, bounded=True)
    ('[−0.76, 0.24]', '[.61, .84]')
    """
    return f"[{num(lo, digits, bounded)}, {num(hi, digits, bounded)}]"


def df_text(df) -> str:
    """Degrees of freedom: an integer as an integer, a fractional (corrected) df to two decimals.

    >>> df_text(2.0), df_text(17), df_text(16.4321)
    ('2', '17', '16.43')
    """
    v = float(df)
    return str(int(round(v))) if abs(v - round(v)) < 1e-9 else f"{v:.2f}"


def stars(p) -> str:
    """The significance mark of `p` under the report's convention (:data:`STARS`)."""
    try:
        v = float(p)
    except (TypeError, ValueError):
        return ""
    mark = ""
    for threshold, m in STARS:
        if v < threshold:
            mark = m
    return mark


def stars_note() -> str:
    """The sentence that states the convention in a table's note: ``* p < .05. ** p < .01. *** p < .001.``"""
    return " ".join(f"{m} p < {num(t, 3 if t < 0.01 else 2, bounded=True)}." for t, m in STARS)


def ci_columns(columns: Sequence[str]) -> list[tuple[str, str, str]]:
    """The (low, high, header) column pairs of :data:`CI_PAIRS` a frame has (a prefix such as ``beta_`` kept)."""
    cols = [str(c) for c in columns]
    out = []
    for c in cols:
        for low, high, head in CI_PAIRS:
            if c.endswith(low) and c[: -len(low)] + high in cols:
                prefix = c[: -len(low)].rstrip("_")
                out.append((c, c[: -len(low)] + high, f"{head} of {header(prefix)}" if prefix else head))
                break
    return out

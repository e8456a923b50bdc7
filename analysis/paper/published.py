"""The paper's published numbers as data (`studies/pedas_paper/published.csv`, the file the paper's study declares as
``[files] published``), transcribed once from the LaTeX source.

One row per printed number with its provenance: ``table`` (table3 | table4 | table5 | cohort | kpi), ``section``,
``line`` (1-based line of the LaTeX source), ``quantity``, ``row``, ``column``, ``printed`` (the string as printed,
stars kept, e.g. ``0.450**``), ``value`` (the parsed number), ``decimals`` (digits after the point as printed),
``unit`` and ``note``. The accessors below reshape it into tidy frames keyed like the analysis outputs of
docs/contracts.md.

The lines of the LaTeX source that these values cite are kept beside them (``studies/pedas_paper/source_lines.txt``,
:func:`load_source_lines`), so the transcription stays checkable from the repository alone.
"""
from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

import pandas as pd

from pedas.paths import REPO_ROOT

#: the paper's study folder (docs/study_folder.md): codebook, protocols, model file and the published values
PAPER_STUDY_DIR = REPO_ROOT / "studies" / "pedas_paper"
PUBLISHED_CSV = "published.csv"
SOURCE_LINES = "source_lines.txt"


@lru_cache(maxsize=1)
def paper_study():
    """The paper's study definition (:func:`study.folder.definition.load` of :data:`PAPER_STUDY_DIR`)."""
    from study.folder.definition import load

    return load(PAPER_STUDY_DIR)


def _published_path() -> Path:
    return PAPER_STUDY_DIR / paper_study().paths.get("published", PUBLISHED_CSV)
# first and last line of each table body in the LaTeX source; the excerpt keeps them whole, so a test can check that
# no number printed in a table is missing from published.csv
TABLE_BODIES = {"table3": (509, 541), "table4": (559, 564), "table5": (586, 619)}
TABLE4_ORDER = ("PU", "PEoU", "ATT", "PBC", "SN", "BI")

# Table 5's four models (paper Section 5.2.2): dependent variable and the predictors entered per step.
TABLE5_MODELS: dict[int, tuple[str, tuple[tuple[str, ...], ...]]] = {
    1: ("PU", (("PEoU",),)),
    2: ("ATT", (("PEoU",), ("PU",))),
    3: ("BI", (("ATT",), ("PU",))),
    4: ("BI", (("ATT",), ("SN",), ("PBC",))),
}


def stars(printed: str) -> int:
    """Number of significance stars in a printed cell (``'0.450**'`` -> 2)."""
    return len(printed) - len(printed.rstrip("*"))


@lru_cache(maxsize=4)
def _load(path: str) -> pd.DataFrame:
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"published values not found: {p}")
    df = pd.read_csv(p, dtype={"printed": str, "row": str, "column": str, "section": str},
                     keep_default_na=False, na_values={"value": [""]})
    df["value"] = df["value"].astype(float)
    return df


def load_published(path: str | Path | None = None) -> pd.DataFrame:
    """All transcribed values (a copy), one row per printed number, in source order."""
    return _load(str(Path(path) if path else _published_path())).copy()


def excerpt_lines(published: pd.DataFrame | None = None) -> list[int]:
    """The source lines the excerpt keeps: every line published.csv cites, and the table bodies of Tables 3-5."""
    pub = published if published is not None else load_published()
    lines = {int(x) for x in pub["line"]}
    for first, last in TABLE_BODIES.values():
        lines.update(range(first, last + 1))
    return sorted(lines)


_SOURCE_HEADER = """\
# Excerpt of the LaTeX source of the paper "Evaluation of the Driving Performance and User Acceptance of a Predictive
# Eco-Driving Assistance System for Electric Vehicles" (Chada et al.), kept for provenance: short excerpts of the
# paper's tables and results that the reproduction compares against. It holds every line that published.csv cites
# (its `line` column) and the whole table bodies of Tables 3-5 (lines {bodies}), nothing else.
# Format: one row per source line, `line<TAB>text`: `line` is the 1-based line number in the full source, `text` the
# line as it stands there (trailing whitespace removed). sha256 of the full source:
# {digest}
# Written by analysis.paper.published.write_source_lines; checked by tests/test_paper_published.py.
"""


def write_source_lines(latex_source: str | Path, out: str | Path | None = None,
                       published: pd.DataFrame | None = None) -> Path:
    """Write the excerpt of the paper's LaTeX source (``latex_source``) that the published values cite.

    ``out`` defaults to ``studies/pedas_paper/source_lines.txt``. Run once when published.csv changes its citations."""
    raw = Path(latex_source).read_bytes()
    src = raw.decode("utf-8").split("\n")
    wanted = excerpt_lines(published)
    if wanted[-1] > len(src):
        raise ValueError(f"the source has {len(src)} lines; published.csv cites line {wanted[-1]}")
    bodies = ", ".join(f"{a}-{b}" for a, b in TABLE_BODIES.values())
    text = _SOURCE_HEADER.format(bodies=bodies, digest=hashlib.sha256(raw).hexdigest())
    text += "".join(f"{n}\t{src[n - 1].rstrip()}\n" for n in wanted)
    path = Path(out) if out else PAPER_STUDY_DIR / SOURCE_LINES
    path.write_text(text, encoding="utf-8")
    return path


def load_source_lines(path: str | Path | None = None) -> dict[int, str]:
    """The committed excerpt of the LaTeX source: line number in the full source -> the line's text."""
    p = Path(path) if path else PAPER_STUDY_DIR / SOURCE_LINES
    out: dict[int, str] = {}
    for row in p.read_text(encoding="utf-8").split("\n"):
        if row and not row.startswith("#"):
            number, _, text = row.partition("\t")
            out[int(number)] = text
    return out


def table3(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 3 wide per item: construct, item, mean, sd, loading, omitted (bool), + per-construct alpha, cr, ave.

    Returns two frames in one: rows with ``item`` set are items; construct-level values are repeated per item
    and also available from :func:`table3_constructs`."""
    pub = published if published is not None else load_published()
    t = pub[pub["table"] == "table3"]
    items = t[t["quantity"].isin(["mean", "sd", "loading"])]
    wide = items.pivot_table(index="row", columns="quantity", values="value", sort=False).reset_index()
    wide = wide.rename(columns={"row": "item"})
    printed = items[items["quantity"] == "loading"].set_index("row")["printed"]
    wide["omitted"] = wide["item"].map(lambda i: printed[i].endswith("*"))
    wide["construct"] = wide["item"].str.rstrip("0123456789")
    return wide[["construct", "item", "mean", "sd", "loading", "omitted"]]


def table3_constructs(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 3 construct rows: construct, alpha, cr, ave."""
    pub = published if published is not None else load_published()
    t = pub[(pub["table"] == "table3") & pub["quantity"].isin(["alpha", "cr", "ave"])]
    out = t.pivot_table(index="row", columns="quantity", values="value", sort=False).reset_index()
    return out.rename(columns={"row": "construct"})[["construct", "alpha", "cr", "ave"]]


def table4(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 4 lower triangle as rows (a, b, r, stars) plus the diagonal as rows with a == b and r = √AVE."""
    pub = published if published is not None else load_published()
    t = pub[pub["table"] == "table4"]
    return pd.DataFrame({"a": t["row"].values, "b": t["column"].values, "r": t["value"].values,
                         "stars": [stars(p) for p in t["printed"]], "diagonal": (t["quantity"] == "sqrt_ave").values})


def table4_matrix(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 4 correlations as a symmetric 6x6 frame (diagonal = 1, not the printed √AVE)."""
    t = table4(published)
    m = pd.DataFrame(1.0, index=list(TABLE4_ORDER), columns=list(TABLE4_ORDER))
    for row in t[~t["diagonal"]].itertuples():
        m.loc[row.a, row.b] = m.loc[row.b, row.a] = row.r
    return m


def table5(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 5 tidy: model, step, dv, predictor ('' for step-level values), quantity, value, printed, line."""
    pub = published if published is not None else load_published()
    t = pub[pub["table"] == "table5"].copy()
    ms = t["row"].str.extract(r"model (\d) step (\d)").astype(int)
    t["model"], t["step"] = ms[0].values, ms[1].values
    t["dv"] = t["model"].map(lambda m: TABLE5_MODELS[m][0])
    t["predictor"] = t["column"]
    return t[["model", "step", "dv", "predictor", "quantity", "value", "printed", "decimals", "line"]].reset_index(drop=True)


def table5_steps(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 5 step-level values wide: model, step, dv, r2, adj_r2, delta_r2."""
    t = table5(published)
    s = t[t["predictor"] == ""]
    return s.pivot_table(index=["model", "step", "dv"], columns="quantity", values="value").reset_index()[
        ["model", "step", "dv", "r2", "adj_r2", "delta_r2"]]


def table5_coefficients(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 5 coefficient rows wide: model, step, dv, predictor, b, se_b, beta, ci_low, ci_high, stars."""
    t = table5(published)
    c = t[t["predictor"] != ""]
    w = c.pivot_table(index=["model", "step", "dv", "predictor"], columns="quantity", values="value",
                      sort=False).reset_index()
    st = c[c["quantity"] == "beta"].set_index(["model", "step", "predictor"])["printed"].map(stars)
    w["stars"] = [int(st[(m, s, p)]) for m, s, p in zip(w["model"], w["step"], w["predictor"])]
    return w[["model", "step", "dv", "predictor", "b", "se_b", "beta", "ci_low", "ci_high", "stars"]]


def value(quantity: str, row: str, column: str = "", table: str | None = None,
          published: pd.DataFrame | None = None) -> float:
    """One published number by its keys, e.g. ``value('enrolled', 'all', 'count')``."""
    pub = published if published is not None else load_published()
    m = (pub["quantity"] == quantity) & (pub["row"] == row) & (pub["column"] == column)
    if table:
        m &= pub["table"] == table
    hits = pub[m]
    if len(hits) != 1:
        raise KeyError(f"published value {table or '*'}:{quantity}/{row}/{column}: {len(hits)} matches")
    return float(hits["value"].iloc[0])


def kpis(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Section 5.1 KPIs tidy: quantity (e.g. energy_saving_mean), segment, group (all | style | participant 6),
    value (percent), printed, line."""
    pub = published if published is not None else load_published()
    k = pub[pub["table"] == "kpi"]
    return pd.DataFrame({"quantity": k["quantity"].values, "segment": k["row"].values, "group": k["column"].values,
                         "value": k["value"].values, "printed": k["printed"].values, "line": k["line"].values})


def cohort(published: pd.DataFrame | None = None) -> pd.DataFrame:
    """Section 4.2 cohort numbers tidy: quantity, key, value, unit, printed, line."""
    pub = published if published is not None else load_published()
    c = pub[pub["table"] == "cohort"]
    return pd.DataFrame({"quantity": c["quantity"].values, "key": c["row"].values, "value": c["value"].values,
                         "unit": c["unit"].values, "printed": c["printed"].values, "line": c["line"].values})

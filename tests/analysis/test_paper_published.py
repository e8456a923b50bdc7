"""The transcription in studies/pedas_paper/published.csv against the paper's LaTeX source (the cited lines,
committed as studies/pedas_paper/source_lines.txt)."""
from __future__ import annotations

import re
from collections import Counter

import pytest

from analysis.paper import published as P

NUM = re.compile(r"(?<![\w{])-?\d*\.?\d+")


@pytest.fixture(scope="module")
def latex() -> dict[int, str]:
    """Line number in the paper's LaTeX source -> that line (the committed excerpt)."""
    return P.load_source_lines()


@pytest.fixture(scope="module")
def pub():
    return P.load_published()


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.split("\\\\")[0].split("&")]


def _clean(cell: str) -> str:
    """LaTeX cell -> printed string: drop math, bold, and turn \\tnote{**} into **."""
    cell = re.sub(r"\\tnote\{\\ding\{61\}\}", "", cell)
    cell = re.sub(r"\\tnote\{(\*+)\}", r"\1", cell)
    cell = re.sub(r"\\mathbf\{(.*)\}", r"\1", cell)
    return cell.replace("$", "").strip()


def test_every_value_parses_from_its_printed_string(pub):
    for r in pub.itertuples():
        number = float(re.match(r"-?\d*\.?\d+", r.printed).group(0))
        assert number == pytest.approx(r.value), r
        digits = r.printed.rstrip("*").split(".")
        assert r.decimals == (len(digits[1]) if len(digits) > 1 else 0), r


def test_table3_cells_match_latex(latex, pub):
    cols = {"mean": 1, "sd": 2, "loading": 3, "alpha": 4, "cr": 5, "ave": 6}
    t = pub[pub["table"] == "table3"]
    assert len(t) == 25 * 3 + 6 * 3
    for r in t.itertuples():
        cells = _cells(latex[r.line])
        assert r.row in cells[0], r
        assert _clean(cells[cols[r.quantity]]).replace("\\tnote{*}", "*") == r.printed, r


def test_table4_cells_match_latex(latex, pub):
    order = list(P.TABLE4_ORDER)
    t = pub[pub["table"] == "table4"]
    assert len(t) == 15 + 6
    for r in t.itertuples():
        cells = _cells(latex[r.line])
        assert cells[0] == r.row
        assert _clean(cells[1 + order.index(r.column)]) == r.printed, r


def test_table5_cells_match_latex(latex, pub):
    cols = {"r2": 1, "adj_r2": 2, "delta_r2": 3, "b": 4, "se_b": 5, "beta": 6}
    t = pub[pub["table"] == "table5"]
    for r in t.itertuples():
        cells = _cells(latex[r.line])
        if r.column:
            assert cells[0].endswith(f"- {r.column}"), r
        if r.quantity in cols:
            assert _clean(cells[cols[r.quantity]]) == r.printed, r
        else:  # the CI cell "lo-hi" / "lo - hi"
            lo, hi = re.fullmatch(r"(-?\d*\.\d+)\s*-\s*(-?\d*\.\d+)", cells[7]).groups()
            assert (lo if r.quantity == "ci_low" else hi) == r.printed, r


def test_the_excerpt_holds_the_cited_lines_and_the_table_bodies(latex, pub):
    assert sorted(latex) == P.excerpt_lines(pub)
    assert all(latex[ln].strip() for ln in set(pub["line"]))


@pytest.mark.parametrize("table,first,last", [(t, *span) for t, span in P.TABLE_BODIES.items()])
def test_every_number_of_the_tables_is_transcribed(latex, pub, table, first, last):
    """No number printed in a table body is missing (counted per line, item labels like PU1 excluded)."""
    for ln in range(first, last + 1):
        text = re.sub(r"\\tnote\{[^}]*\}|\\textwidth|p\{[^}]*\}|\\multi\w+\{[^}]*\}\{[^}]*\}", "", latex[ln])
        cells = _cells(text)
        body = cells[1:] if len(cells) > 1 and "same as model" not in text else []
        found = Counter(n for c in body for n in NUM.findall(_clean(c)))
        rows = pub[(pub["table"] == table) & (pub["line"] == ln)]
        assert Counter(p.rstrip("*") for p in rows["printed"]) == found, ln


def test_text_values_appear_on_their_line(latex, pub):
    t = pub[pub["table"].isin(["cohort", "kpi"])]
    assert len(t) >= 35
    for r in t.itertuples():
        line = latex[r.line]
        pattern = r"(?<![\d.])" + re.escape(r.printed) + r"(?![\d])"
        assert re.search(pattern, line), r


def test_cohort_counts_are_the_papers(pub):
    v = lambda q: P.value(q, "all", "count", "cohort", pub)  # noqa: E731
    assert (v("enrolled"), v("male"), v("female"), v("motion_sickness"), v("survey_n"), v("technical_issues"),
            v("objective_n")) == (44, 37, 7, 3, 41, 7, 34)


def test_accessors_shape(pub):
    t3 = P.table3(pub)
    assert len(t3) == 25 and t3["omitted"].sum() == 6
    assert set(t3.loc[t3["omitted"], "item"]) == {"PEoU3", "ATT1", "ATT2", "ATT3", "ATT4", "ATT5"}
    m = P.table4_matrix(pub)
    assert (m.values == m.values.T).all() and m.loc["PU", "BI"] == pytest.approx(0.622)
    co = P.table5_coefficients(pub)
    assert len(co) == 12 and co["stars"].sum() == 8
    assert len(P.table5_steps(pub)) == 7


def test_kpi_and_cohort_accessors(pub):
    k = P.kpis(pub)
    overall = k[(k["quantity"] == "energy_saving_mean") & (k["segment"] == "overall") & (k["group"] == "all")]
    assert overall["value"].tolist() == [9.82]
    assert set(k[k["group"] == "participant 6"]["quantity"]) == {"energy_saving", "jerk_reduction"}
    c = P.cohort(pub)
    assert c[c["quantity"] == "style_share"]["key"].tolist() == ["cautious", "normal", "sporty"]

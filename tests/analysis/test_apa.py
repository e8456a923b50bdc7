"""APA 7 formatting (analysis.apa) against hand-worked examples, and the table writers that apply it."""
import pandas as pd

from analysis import apa
from analysis.render import frame_cells, latex_table, markdown_table

M = "\u2212"


def test_p_values():
    assert [apa.p_value(p) for p in (0.0114, 0.0499, 0.0005, 0.0, 0.5, 0.9996)] == \
        [".011", ".050", "< .001", "< .001", ".500", "> .999"]
    assert apa.p_text(0.011) == "p = .011" and apa.p_text(0.0000) == "p < .001"


def test_numbers_ci_df():
    assert apa.num(-0.758, 3) == f"{M}0.758"
    assert apa.num(-0.0001, 3) == "0.000"            # no minus on a value that rounds to zero
    assert apa.num(0.957, 3, bounded=True) == ".957"
    assert apa.num(1.08, 2, bounded=True) == "1.08"   # an improper standardized value keeps its integer part
    assert apa.ci(-0.758, 0.243) == f"[{M}0.76, 0.24]"
    assert apa.ci(0.61, 0.843, bounded=True) == "[.61, .84]"
    assert (apa.df_text(2.0), apa.df_text(17), apa.df_text(16.4321)) == ("2", "17", "16.43")


def test_stars_one_convention():
    assert [apa.stars(p) for p in (0.2, 0.04, 0.009, 0.0004)] == ["", "*", "**", "***"]
    assert apa.stars_note() == "* p < .05. ** p < .01. *** p < .001."


def test_headers_words_and_symbols():
    assert [apa.header(h) for h in ("beta", "se_b", "p_change", "delta_r2", "saving_urban_pct", "Item")] == \
        ["β", "SE B", "p (ΔR²)", "ΔR²", "saving urban (%)", "Item"]


def test_cells_by_column_kind():
    head, rows = apa.table_cells(["path", "beta", "p", "df", "b", "cfi"],
                                 [["PU -> BI", "0.517**", "0.000", "2.000", "-1.250", "0.907"],
                                  ["ATT -> BI", "-0.120", "0.011", "16.432", "0.5", "1.000"]])
    assert head == ["Path", "β", "p", "df", "B", "CFI"]
    assert rows == [["PU -> BI", ".517**", "< .001", "2", f"{M}1.250", ".907"],
                    ["ATT -> BI", f"{M}.120", ".011", "16.43", "0.5", "1.000"]]
    # idempotent: a table formatted twice stays the same
    assert apa.table_cells(head, rows) == (head, rows)


def test_writers_apply_apa():
    df = pd.DataFrame({"path": ["PU -> BI"], "beta": [0.5123], "ci_low": [-0.2], "ci_high": [0.31], "p": [0.0002]})
    head, rows = frame_cells(df)
    assert head == ["path", "beta", "95 % CI", "p"] and rows == [["PU -> BI", "0.512", f"[{M}0.200, 0.310]", "0.000"]]
    md = markdown_table(head, rows)
    assert f"| PU -> BI | .512 | [{M}0.200, 0.310] | < .001 |" in md and "| Path | β | 95 % CI | p |" in md
    assert r"$-$0.200" in latex_table(head, rows)

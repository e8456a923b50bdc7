"""The consistency audit: hand-worked formulas and the findings of docs/paper_reproduction.md."""
from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from analysis.paper import audit as A
from analysis.paper import grim


@pytest.fixture(scope="module")
def audit():
    return A.run_audit()


def rows(audit, group):
    return audit[(audit["group"] == group) & (audit["status"] == "inconsistent")]


# ---- formulas against hand-worked numbers

def test_grim_hand_examples():
    assert grim.grim_sums(4.35, 40, 3) == [174]
    assert grim.grim_sums(4.208, 40, 3) == []          # 168/40 = 4.200, 169/40 = 4.225
    assert grim.grim_sums(4.208, 24, 3) == [101]       # 101/24 = 4.2083
    assert not grim.grim_consistent(3.625, 41, 3)


def test_grimmer_hand_example():
    # 40 answers: 20 fours, 20 fives -> mean 4.5, SD = sqrt(40·0.25/39) = 0.50637
    c = grim.grimmer_candidates(4.5, 0.506, 40, 3, 3, sd_mode="round")
    assert any((row == [0, 0, 0, 20, 20]).all() for row in c)
    assert grim.grimmer_consistent(4.5, 0.506, 40, 3, 3, sd_mode="truncate")
    assert not grim.grimmer_consistent(4.5, 0.507, 40, 3, 3, sd_mode="truncate")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 5), min_size=40, max_size=40))
def test_grimmer_accepts_every_real_sample(xs):
    """Law: the mean and SD of any real 1-5 sample, printed either way, pass GRIM and GRIMMER."""
    x = np.array(xs)
    m, sd = x.mean(), x.std(ddof=1)
    assert grim.grimmer_consistent(round(m, 3), round(sd, 3), 40, 3, 3, sd_mode="round")
    assert grim.grimmer_consistent(round(m, 3), np.floor(sd * 1000) / 1000, 40, 3, 3, sd_mode="truncate")


def test_cr_ave_hand_formula():
    cr, ave = A.cr_ave([0.911, 0.911])
    s = 1.822 ** 2
    assert cr == pytest.approx(s / (s + 2 * (1 - 0.911 ** 2)))
    assert ave == pytest.approx(0.911 ** 2)


def test_alpha_two_items_is_spearman_brown():
    r = 0.5
    assert A.alpha_from_cov(np.array([[1, r], [r, 1]])) == pytest.approx(2 * r / (1 + r))


def test_composite_sd_from_alpha_inverts_alpha():
    sd = np.array([1.0, 0.8, 1.2])
    cov = A.implied_item_cov(sd, [0.7, 0.6, 0.8])
    alpha = A.alpha_from_cov(cov)
    assert A.composite_sd_from_alpha(sd, alpha) == pytest.approx(np.sqrt(cov.sum()) / 3)


def test_adj_r2_hand():
    assert A.adj_r2(0.161, 40, 1) == pytest.approx(1 - 0.839 * 39 / 38)


# ---- the findings of docs/paper_reproduction.md, with their numbers

def test_finds_n_40_from_item_means(audit):
    r = audit[audit["check"].str.startswith("N implied by item means")].iloc[0]
    assert r["status"] == "inconsistent" and r["recomputed"].startswith("N = 40: 24/25")


def test_finds_grim_inconsistent_pbc2(audit):
    bad = audit[(audit["check"] == "GRIM mean, N = 40") & (audit["status"] == "inconsistent")]
    assert bad["where"].str.contains("PBC2").tolist() == [True]


def test_finds_peou_diagonal(audit):
    r = rows(audit, "peou_diagonal")
    assert len(r) == 1 and "PEoU" in r.iloc[0]["where"] and r.iloc[0]["recomputed"] == ".7328"
    assert "√.4121 = .6420" in r.iloc[0]["explanation"]   # √AVE with PEoU3 kept


def test_finds_table4_vs_table5(audit):
    r = rows(audit, "t4_t5")
    assert len(r) == 3
    assert r["where"].str.contains("model 1 step 1").any() and r["where"].str.contains("model 2 step 1").any()
    ok = audit[(audit["check"] == "β from Table 4 correlations") & (audit["status"] == "ok")]
    assert len(ok) == 3   # models 3 and 4 agree with Table 4


def test_finds_bi_alpha(audit):
    r = rows(audit, "bi_alpha").iloc[0]
    assert r["reported"] == ".792" and r["recomputed"].startswith(".904")


def test_finds_non_t_cis(audit):
    r = rows(audit, "ci_not_t")
    r = r[r["check"].str.startswith("CI = B")]      # (the bootstrap rows: tests/analysis/test_paper_bootstrap_check.py)
    assert len(r) == 2 and "= .450: the Table 4 correlation" in r.iloc[0]["explanation"] \
        and "= .328: the Table 4 correlation" in r.iloc[1]["explanation"]
    t_based = audit[audit["check"].str.startswith("CI = B") & (audit["status"] == "ok")]
    assert len(t_based) == 10


def test_sd_truncation_finding(audit):
    r = rows(audit, "sd_truncated")
    assert len(r) == 15
    tr = audit[audit["check"] == "GRIMMER SD, N = 40"]
    assert tr["recomputed"].str.contains(r"truncated: [1-9]").sum() == 24   # every SD fits when truncated


def test_findings_are_numbered_in_order(audit):
    f = A.findings(audit)
    assert f["finding"].tolist() == list(range(1, len(f) + 1))
    assert {"n_implied", "grim_pbc2", "peou_diagonal", "t4_t5", "bi_alpha", "ci_not_t"} <= set(f["group"])


# ---- APA 7 numbers (analysis.apa) by what each check compares

def test_rows_print_their_numbers_the_apa_way(audit):
    """Values bounded by 1 (r, β, Cα, λ, CR, AVE, R²) without a leading zero, B, SE and ratios with one, p never
    0.000, intervals as [LL, UL], a true minus sign."""
    first = lambda check: audit[audit["check"] == check].iloc[0]  # noqa: E731
    assert (first("CR from λ (Hair)")["reported"], first("CR from λ (Hair)")["recomputed"]) == (".879", ".8796")
    assert first("β from Table 4 correlations")["reported"] == "β = PEoU −.087, PU .807; R² = .602"
    assert first("adj R² vs R²")["recomputed"] == "N = 40: [.1384, .1394]; N = 41: [.1390, .1400]"
    assert first("B/β vs composite SD ratio")["reported"] == "B/β = 0.478/.401 = 1.192 [1.189, 1.195]"
    assert first("CI = B ± t·SE (df = 38)")["reported"] == "[0.217, 1.031]"
    assert first("stars of β (N = 40)")["recomputed"] == "t = 2.70, p = .0103"
    assert first("λ and Cα under principal components (SPSS FACTOR default)")["reported"] \
        == "Cα = .799; λ = .837, .792, .747, .837"
    text = " ".join(audit["reported"]) + " " + " ".join(audit["recomputed"]) + " " + " ".join(audit["explanation"])
    # no leading zero where bounded (B/β is a ratio and SE β a standard error: not bounded)
    assert not re.search(r"(?<![\w/])(?<!SE )(?:r|β|α|λ|R²|adj|CR|AVE|p) =? ?[−-]?0\.\d", text)
    assert not re.search(r"(?<![\w.])-\d", text) and "0.000" not in text          # true minus; p never 0.000


def test_the_report_table_of_the_audit_has_words_and_whole_finding_numbers(audit, tmp_path):
    """The report collects paper/audit.csv into its table paper_audit: read back from the CSV the finding is a float
    (NaN where a row has none), printed as the finding's number under word headers in Markdown, LaTeX and CSV."""
    from analysis.render import parse_markdown_table
    from analysis.report.build import ReportConfig, collect_step

    cfg = ReportConfig(out=tmp_path / "reports", db=tmp_path / "unused.duckdb")
    (cfg.out / "paper").mkdir(parents=True)
    audit.to_csv(cfg.out / "paper" / "audit.csv", index=False)
    collect_step(cfg)
    title, header, rows, notes = parse_markdown_table((cfg.out / "tables" / "paper_audit.md").read_text())
    assert header == ["Row", "Check", "Where", "Reported", "Recomputed", "Status", "Finding", "Explanation"]
    want = audit["finding"].map(lambda k: "" if pd.isna(k) else str(int(k))).tolist()
    assert [r[6] for r in rows] == want and "1" in want and "10" in want
    assert [r[3] for r in rows] == audit["reported"].tolist()
    # the stars in Reported are the paper's (two conventions), not the report's: the note says which
    assert "Stars are the paper's as printed: Table 4 * p < .05, ** p < .01; Table 5 * p < .05, ** p < .001." \
        in " ".join(notes)
    printed = pd.read_csv(cfg.out / "tables" / "paper_audit.csv", dtype=str, keep_default_na=False)
    assert printed["Finding"].tolist() == want
    tex = (cfg.out / "tables" / "paper_audit.tex").read_text()
    assert "& inconsistent & 1 &" in tex and "& 1.000 &" not in tex and "Recomputed" in tex
    assert "finding" not in tex.split(r"\midrule")[0]


def test_cli_audit_writes_csv_and_md(cli, tmp_path):
    res = cli("paper", "audit", "--out", tmp_path / "a")
    assert res.code == 0, res.err
    assert (tmp_path / "a" / "audit.csv").exists()
    md = (tmp_path / "a" / "audit.md").read_text()
    assert "## Findings" in md and "Finding #1" in md

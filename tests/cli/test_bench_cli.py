"""`pedas-study bench cli`: its refusals and how it judges the targets (the timings themselves are a benchmark)."""
from __future__ import annotations

from pedas_study.bench.cli import TARGETS, CliBench


def test_bench_cli_refuses_no_repeats(cli):
    r = cli("bench", "cli", "--repeats", "0", db=None)
    assert r.code == 2 and r.err == "pedas-study: error: --repeats must be >= 1, got 0\n"


def test_bench_cli_text_says_which_target_is_met():
    medians = {name: 0.1 for name in TARGETS} | {"participant list": 0.6}
    lines = CliBench(3, 0.05, medians).to_text().splitlines()
    assert lines[0] == "median wall time of 3 runs, each a fresh process (peer: python -c pass 0.050 s)"
    row = {ln.split("  ")[0].strip(): ln for ln in lines[2:]}
    assert row["--help"].endswith("<= 0.15 s: met") and " 2.0 " in row["--help"]
    assert row["participant list"].endswith("<= 0.5 s: NOT met")
    assert row["drive import (9,000 samples)"].endswith("<= 0.8 s: met")
    assert row["analyze survey; analyze extended"].endswith("  -")

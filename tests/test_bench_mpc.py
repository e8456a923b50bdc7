"""`bench mpc`: functional checks only (no timed assertions)."""
from __future__ import annotations

import json

from pedas_study.bench.mpc import run_bench


def test_run_bench_small():
    res = run_bench(steps=120, peer_steps=4, seed=1)
    assert res.steps == 120 and res.peer_steps == 4
    assert 0 < res.median_ms <= res.p95_ms <= res.p99_ms <= res.max_ms
    assert res.peer_median_ms > 0 and res.ratio > 0
    assert res.obj_rel_max <= 1e-3                        # OSQP and Clarabel agree on the benchmark's steps
    assert sum(res.statuses.values()) == 120
    assert res.controller_share["rt"] + res.controller_share["cf"] == 120
    assert "eps_abs" in res.osqp_settings
    assert "ratio" in res.to_text()


def test_cli_bench_mpc_json(cli):
    r = cli("bench", "mpc", "--json", "--steps", "60", "--peer-steps", "2")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["steps"] == 60 and out["peer_steps"] == 2
    for key in ("median_ms", "p95_ms", "p99_ms", "max_ms", "peer_median_ms", "ratio"):
        assert out[key] > 0


def test_cli_bench_mpc_bad_input(cli):
    r = cli("bench", "mpc", "--steps", "0")
    assert r.code == 2 and "--steps" in r.err

"""`bench mpc`: functional checks only (no timed assertions)."""
from __future__ import annotations

import json

import pytest

from pedas_study.bench.mpc import STAGES, run_bench


@pytest.mark.parametrize("backend", ["daqp", "osqp"])
def test_run_bench_small(backend):
    res = run_bench(steps=120, peer_steps=4, seed=1, backend=backend)
    label = "daqp (condensed)" if backend == "daqp" else backend
    assert res.backend == label and res.steps == 120 and res.peer_steps == 4
    assert 0 < res.median_ms <= res.p95_ms <= res.p99_ms <= res.max_ms
    assert res.peer_median_ms > 0 and res.ratio > 0
    # both backends agree with Clarabel at 1e-10 on the benchmark's steps: OSQP within its 1e-3 contract, DAQP exactly
    assert res.obj_gap_max <= (1e-8 if backend == "daqp" else 1e-3)
    assert res.du0_max_n <= (1.0 if backend == "daqp" else 100.0)
    assert sum(res.statuses.values()) == 120
    assert res.controller_share["rt"] + res.controller_share["cf"] == 120
    assert ("eps_abs" if backend == "osqp" else "primal_tol") in res.settings
    assert "ratio" in res.to_text() and f"[{label}]" in res.to_text()
    # the breakdown by stage: every stage of the step timed on the same steps, the solver's calls among them
    stages = res.stages["stages"]
    assert list(stages) == [label for label, _, _ in STAGES]
    # the condensed DAQP backend's data check, vectors and checks are two compiled calls, the others' numpy stages
    checks = (("QP prepare (condensed: compiled data check + vectors)",
               "QP check (condensed: compiled map back, residual, KKT)") if backend == "daqp"
              else ("residual check", "KKT check", "data check (finite q, l, u)"))
    for label in ("predict", "reference", "QP fill: set_step", "solver C calls (update + solve)", *checks,
                  "unpack (plan)", "HUD", "glue (step, MPC solve, Advisory)"):
        assert stages[label]["mean_us"] > 0, label
    if backend == "daqp":
        for label in ("residual check", "KKT check", "data check (finite q, l, u)", "QP fill: backend vectors"):
            assert stages[label]["mean_us"] == 0, label
    assert res.stages["step_median_ms"] > 0 and "breakdown by stage" in res.to_text()


def test_cli_bench_mpc_json(cli):
    r = cli("bench", "mpc", "--json", "--steps", "60", "--peer-steps", "2")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert sorted(out) == ["daqp (condensed)", "daqp (regularised)", "osqp"]
    for res in out.values():
        assert res["steps"] == 60 and res["peer_steps"] == 2
        for key in ("median_ms", "p95_ms", "p99_ms", "max_ms", "peer_median_ms", "ratio"):
            assert res[key] > 0


def test_cli_bench_mpc_bad_input(cli):
    r = cli("bench", "mpc", "--steps", "0")
    assert r.code == 2 and "--steps" in r.err

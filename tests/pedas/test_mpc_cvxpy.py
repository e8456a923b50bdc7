"""OSQP's optimum against the same QP built in cvxpy and solved by Clarabel (independent interior-point solver)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from pedas.constants import DT, N_HORIZON
from pedas.mpc import solve_qp_cvxpy, vehicle_model
from pedas.mpc_cf import CarFollowingMpc
from pedas.params import CONTROLLER
from pedas.mpc_rt import ReferenceTrackingMpc

N = N_HORIZON


def _qp_objective(P, q, x):
    Pf = (P + P.T - sp.diags(P.diagonal())).tocsc()
    return 0.5 * float(x @ (Pf @ x)) + float(q @ x)


def test_200_random_instances_match_clarabel_within_1e_3():
    """Relative objective gap |f_osqp - f_clarabel| / |f_clarabel| <= 1e-3 on 200 random feasible steps
    (100 reference tracking, 100 car following), production OSQP settings; objectives without constants."""
    m = vehicle_model()
    rt, cf = ReferenceTrackingMpc(m), CarFollowingMpc(m)
    rng = np.random.default_rng(2024)
    k = np.arange(1, N + 1)
    gaps = []
    for i in range(200):
        v0 = rng.uniform(0.0, 28.0)
        v_hi = np.maximum(np.full(N, rng.uniform(6.0, 36.0)), v0 - 3.0 * DT * k)
        grade = np.linspace(*rng.uniform(-0.05, 0.05, 2), N)
        v_lin = np.clip(v0 + rng.normal(0.0, 0.8, N), 0.0, None)
        ft_lin = rng.uniform(0.0, 3000.0, N)
        ft_prev = rng.uniform(0.0, 2500.0)
        stop = rng.random() < 0.3
        d0 = rng.uniform(v0 * v0 / 12.0 + 1.0, 150.0) if stop else 0.0
        d_hard = np.zeros(N) if stop else None
        d_s = 5.0 if stop else np.inf
        if i % 2 == 0:
            mpc = rt
            v_lo = np.zeros(N) if stop else np.minimum(np.full(N, rng.uniform(0.0, 0.7) * v_hi[-1]), v0)
            plan = rt.plan(v0, np.full(N, rng.uniform(0.0, v_hi[-1])), v_lo, v_hi, grade, d_its0=d0,
                           d_hard_lo=d_hard, d_s_its=d_s, ft_prev=ft_prev, v_lin=v_lin, ft_lin=ft_lin)
        else:
            mpc = cf
            psi0 = rng.uniform(0.0, 60.0)
            plan = cf.plan(v0, 3.0 + v0 + psi0, rng.uniform(max(0.0, v0 - 5.0), v0 + 4.0), np.zeros(N), v_hi, grade,
                           d_its0=d0, d_hard_lo=d_hard, d_s_its=d_s, ft_prev=ft_prev, v_lin=v_lin, ft_lin=ft_lin,
                           safe_margin=np.minimum(CONTROLLER.safe_backoff, psi0 + 0.2 * k))
        assert plan.ok, plan.status
        P, q, A, l, u, _ = mpc.qp_data()
        status, f_peer, _ = solve_qp_cvxpy(P, q, A, l, u)
        assert status == "optimal"
        f_osqp = _qp_objective(P, q, plan.x)
        assert abs(f_peer) > 1.0  # a relative gap needs an objective away from zero (here >= ~200)
        gaps.append(abs(f_osqp - f_peer) / abs(f_peer))
    assert max(gaps) <= 1e-3, f"worst relative gap {max(gaps):.2e}"

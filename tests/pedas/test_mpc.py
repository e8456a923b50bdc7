"""The two MPCs as sparse OSQP problems: convexity, constant structure, every constraint on the returned plan."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from pedas.constants import DT, N_HORIZON
from pedas.mpc import KN, power_hessian_eigs, vehicle_model
from pedas.mpc_cf import CarFollowingMpc
from pedas.mpc_rt import ReferenceTrackingMpc
from pedas.params import CONTROLLER

N = N_HORIZON
TOL_V = 2e-2   # m/s, m: solver tolerance (eps_abs = eps_rel = 1e-4 on rows of magnitude <= ~100)
TOL_F = 20.0   # N  (0.02 kN inside the QP)
MODEL = vehicle_model()


@pytest.fixture(scope="module")
def rt():
    return ReferenceTrackingMpc(MODEL)


@pytest.fixture(scope="module")
def cf():
    return CarFollowingMpc(MODEL)


def test_power_map_is_indefinite_but_the_qp_hessian_is_psd(rt, cf):
    eig = power_hessian_eigs(MODEL)
    assert eig.min() < 0 < eig.max()      # a11 v F dominates: eq. (5) is not jointly convex in (v, F_t)
    assert not rt.power_convex and not cf.power_convex
    for mpc in (rt, cf):
        P = mpc.P.toarray()
        full = P + P.T - np.diag(np.diag(P))
        assert np.linalg.eigvalsh(full).min() >= -1e-9


@pytest.mark.parametrize("backend", ["osqp", "daqp", "daqp-python"])
def test_structure_built_once(monkeypatch, backend):
    """Setup happens in the constructor only; solving many steps never re-runs it and P, A never change. DAQP is set
    up by the kernel (its C functions called directly), or through its Python interface where the kernel does not
    know the release's layout ("daqp-python")."""
    import daqp
    import osqp

    import pedas.qp as qp_module

    calls = []
    if backend == "osqp":
        orig = osqp.OSQP.setup
        monkeypatch.setattr(osqp.OSQP, "setup", lambda self, *a, **k: (calls.append(1), orig(self, *a, **k))[1])
    else:   # daqp.Model is an extension type: count through a subclass
        class Counted(daqp.Model):
            def setup(self, *a, **k):
                calls.append(1)
                return super().setup(*a, **k)

        monkeypatch.setattr(daqp, "Model", Counted)
        if backend == "daqp-python":
            monkeypatch.setattr(qp_module, "_daqp_direct_path", lambda: None)
    mpc = ReferenceTrackingMpc(MODEL, backend=backend.split("-")[0])
    P0, A0 = mpc.P.copy(), mpc.A.copy()
    for v0 in np.linspace(0, 25, 15):
        plan = mpc.plan(v0, np.full(N, 12.0), np.zeros(N), np.full(N, 30.0), np.zeros(N))
        assert plan.ok
    if backend == "daqp":   # the kernel's DAQP: no Model, and a second setup is refused
        assert calls == [] and not hasattr(mpc.qp, "model")
        with pytest.raises(RuntimeError, match="set up once"):
            mpc.qp.kernel.open_daqp(daqp.__file__, mpc.qp.H, mpc.qp.G.toarray(), mpc.qp._sense0.astype(np.int64),
                                    1e-6, 1000)
    else:
        assert len(calls) == 1
    assert (abs(mpc.P - P0)).nnz == 0 and (abs(mpc.A - A0)).nnz == 0


def _resistance_lin(v, grade):
    m = MODEL
    return m.c_aero * (m.p1 * v + m.p2) + m.m_v * m.g * (m.c_r * np.cos(grade) + np.sin(grade))


def _check_common(plan, v0, v_lo, v_hi, grade, ft_prev, d_hard, d0, d_s, w):
    v, ft, fb = plan.v, plan.ft, plan.fb
    m = MODEL
    assert abs(v[0] - v0) <= TOL_V
    # eq. (3a) with the linearised drag
    v_next = v[:-1] + DT / m.m_eq * (ft - fb - _resistance_lin(v[:-1], grade))
    assert np.max(np.abs(v[1:] - v_next)) <= TOL_V
    # eq. (3b)
    d = plan.d_its
    assert abs(d[0] - d0) <= TOL_V
    assert np.max(np.abs(d[1:] - (d[:-1] - DT * 0.5 * (v[:-1] + v[1:])))) <= TOL_V
    # eq. (6a)-(6c)
    assert ft.min() >= -TOL_F and np.all(ft <= m.p3 * v[:-1] + m.p4 + TOL_F)
    assert fb.min() >= -TOL_F and fb.max() <= m.F_b_max + TOL_F
    assert np.all(v[1:] >= v_lo - TOL_V) and np.all(v[1:] <= v_hi + TOL_V)
    # eq. (8a/b) soft jerk limit with slack e2 >= 0 (k = 0 against the previous force)
    prev = np.r_[ft_prev if ft_prev is not None else ft[0], ft[:-1]]
    assert plan.eps2.min() >= -TOL_F
    assert np.all(np.abs(ft - prev) <= w.dFt_max + plan.eps2 + 2 * TOL_F)
    # eq. (8c) hard stop and (8d) soft stop-line approach
    if d_hard is not None:
        assert np.all(d[1:][d_hard == 0.0] >= -TOL_V)
    assert plan.eps1.min() >= -TOL_V
    if np.isfinite(d_s):
        assert np.all(d[1:] - plan.eps1 <= d_s + TOL_V)


def _random_common(rng):
    v0 = rng.uniform(0.0, 30.0)
    v_max = rng.uniform(5.0, 36.0)
    k = np.arange(1, N + 1)
    v_hi = np.maximum(np.full(N, v_max), v0 - 3.0 * DT * k)   # a limit below v0 is reached at 3 m/s^2
    v_lo = np.minimum(np.full(N, rng.uniform(0.0, 0.8) * v_max), v0) if rng.random() < 0.5 else np.zeros(N)
    v_lo = np.minimum(v_lo, v_hi)
    grade = np.full(N, rng.uniform(-0.06, 0.06))
    ft_prev = rng.uniform(0.0, 3000.0) if rng.random() < 0.7 else None
    v_lin = np.clip(v0 + rng.normal(0.0, 1.0, N), 0.0, None)
    ft_lin = rng.uniform(0.0, 3000.0, N)
    if rng.random() < 0.4:   # a stop sign / red light ahead, far enough for a feasible stop (<= 6 m/s^2)
        d0 = rng.uniform(v0 * v0 / 12.0 + 1.0, 150.0)
        d_hard, d_s = np.zeros(N), 5.0
        v_lo = np.zeros(N)   # the controller drops v_min while a stop is required
    else:
        d0, d_hard, d_s = 0.0, None, np.inf
    return v0, v_lo, v_hi, grade, ft_prev, v_lin, ft_lin, d0, d_hard, d_s


def test_reference_tracking_plans_satisfy_all_constraints(rt):
    rng = np.random.default_rng(6)
    for _ in range(150):
        v0, v_lo, v_hi, grade, ft_prev, v_lin, ft_lin, d0, d_hard, d_s = _random_common(rng)
        v_ref = np.full(N, rng.uniform(0.0, 36.0))
        plan = rt.plan(v0, v_ref, v_lo, v_hi, grade, d_its0=d0, d_hard_lo=d_hard, d_s_its=d_s, ft_prev=ft_prev,
                       v_lin=v_lin, ft_lin=ft_lin)
        assert plan.ok, plan.status
        _check_common(plan, v0, v_lo, v_hi, grade, ft_prev, d_hard, d0, d_s, CONTROLLER.rt_weights)


def test_car_following_plans_satisfy_all_constraints_and_never_enter_d_s(cf):
    rng = np.random.default_rng(7)
    w = CONTROLLER.cf_weights
    k = np.arange(1, N + 1)
    for _ in range(150):
        v0, v_lo, v_hi, grade, ft_prev, v_lin, ft_lin, d0, d_hard, d_s = _random_common(rng)
        v_lo = np.zeros(N)   # behind a leader the controller drops v_min (the leader may be slower)
        psi0 = rng.uniform(0.0, 60.0)
        d_rel0 = w.d_min + w.h_s * v0 + psi0
        v_p = rng.uniform(max(0.0, v0 - 6.0), v0 + 4.0)
        margin = np.minimum(CONTROLLER.safe_backoff, psi0 + 0.2 * k)
        plan = cf.plan(v0, d_rel0, v_p, v_lo, v_hi, grade, d_its0=d0, d_hard_lo=d_hard, d_s_its=d_s,
                       ft_prev=ft_prev, v_lin=v_lin, ft_lin=ft_lin, safe_margin=margin)
        assert plan.ok, plan.status
        _check_common(plan, v0, v_lo, v_hi, grade, ft_prev, d_hard, d0, d_s, w)
        r, v = plan.d_rel, plan.v
        assert abs(r[0] - d_rel0) <= TOL_V
        # eq. (3c) with a frozen-time leader
        assert np.max(np.abs(r[1:] - (r[:-1] + DT * (v_p - 0.5 * (v[:-1] + v[1:]))))) <= TOL_V
        # eq. (7a) hard safe distance incl. the back-off: never inside d_s
        assert np.all(r[1:] >= w.d_min + w.h_s * v[1:] + margin - TOL_V)
        # eq. (7b) soft comfort distance with slack e3 >= 0
        assert plan.eps3.min() >= -TOL_V
        assert np.all(r[1:] - w.h_c * v[1:] - plan.eps3 <= w.d_min + TOL_V)


def test_infeasible_stop_is_reported_not_returned(rt):
    # 20 m/s with a hard stop 3 m ahead: no braking force can satisfy d_ITS >= 0
    plan = rt.plan(20.0, np.full(N, 20.0), np.zeros(N), np.full(N, 30.0), np.zeros(N), d_its0=3.0,
                   d_hard_lo=np.zeros(N), d_s_its=5.0)
    assert not plan.ok
    assert "infeasible" in plan.status
    assert plan.v is None


def test_tracking_reaches_the_reference_and_plans_in_kn_are_reported_in_n(rt):
    plan = rt.plan(10.0, np.full(N, 14.0), np.zeros(N), np.full(N, 14.0), np.zeros(N))
    assert plan.ok
    assert plan.v[-1] > 10.0 and plan.ft[0] > 500.0    # accelerates (forces in N, not kN)
    assert np.all(plan.ft <= MODEL.p3 * plan.v[:-1] + MODEL.p4 + TOL_F)
    assert KN == 1000.0


def test_qp_data_is_the_solved_problem(cf):
    plan = cf.plan(12.0, 40.0, 10.0, np.zeros(N), np.full(N, 14.0), np.zeros(N))
    P, q, A, l, u, const = cf.qp_data()
    x = plan.x
    Ax = A @ x
    assert np.all(Ax >= l - 1e-2) and np.all(Ax <= u + 1e-2)
    Pf = (P + P.T - sp.diags(P.diagonal())).tocsc()
    assert 0.5 * x @ (Pf @ x) + q @ x + const == pytest.approx(cf.objective(x), rel=1e-12, abs=1e-9)

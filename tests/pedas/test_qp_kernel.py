"""The compiled per-step kernel of the condensed DAQP backend (pedas/_qpkernel.c) against the numpy formulation it
replaces: f, DAQP's bounds and x bit for bit (they reach the drive), the residual and the KKT measures to rounding
(they decide a verdict), and bad input refused."""
from __future__ import annotations

import daqp
import numpy as np
import pytest
import scipy.sparse as sp

import pedas.qp as qp_module
from pedas._qpkernel import Kernel
from pedas.mpc import BIG, vehicle_model
from pedas.mpc_cf import CarFollowingMpc
from pedas.mpc_rt import ReferenceTrackingMpc
from pedas.qp import _Kkt, _Residual

MODEL = vehicle_model()


def _numpy_fill(qp, q, l, u):
    """f = Z'q + Z'PE b_eq and the clipped DAQP bounds, as numpy and scipy's CSR product compute them."""
    nx, nf = q.size, qp._f.size
    vec = qp.vec @ np.concatenate([q, l[qp._eq_rows]])
    f = vec[:nf] + vec[nf:2 * nf]
    src = np.concatenate([l, [-np.inf], u, [np.inf]])
    lohi = src[qp._gather].reshape(2, -1) - vec[2 * nf:]
    assert nx == qp._nx
    return f, np.clip(lohi.ravel(), -qp.bound, qp.bound)


def _numpy_x(qp, beq, z):
    xm = qp.map @ np.concatenate([beq, z])
    return xm[:qp._nx] + xm[qp._nx:]


def _random_data(mpc, rng):
    """q, l, u of the MPC's shape: l, u its own (+-BIG where unbounded) with random finite entries moved."""
    q = rng.normal(0.0, 5.0, mpc.nx)
    l, u = mpc.l.copy(), mpc.u.copy()
    fin = np.flatnonzero((l > -BIG) & (u < BIG))
    shift = rng.normal(0.0, 3.0, fin.size)
    l[fin] += shift
    u[fin] += shift + np.abs(rng.normal(0.0, 1.0, fin.size)) * (u[fin] > l[fin])
    return q, l, u


@pytest.mark.parametrize("cls", [ReferenceTrackingMpc, CarFollowingMpc])
def test_fill_and_map_are_the_numpy_bits(cls):
    mpc = cls(MODEL, backend="daqp")
    qp = mpc.qp
    rng = np.random.default_rng(3)
    for _ in range(50):
        q, l, u = _random_data(mpc, rng)
        f, lohi = _numpy_fill(qp, q, l, u)
        assert qp.kernel.fill(q, l, u) is True
        assert qp._f.tobytes() == f.tobytes() and qp._lohi.tobytes() == lohi.tobytes()
        z = rng.normal(0.0, 2.0, qp._f.size)
        x = np.empty(mpc.nx)
        qp.kernel.check(z, None, x)
        assert x.tobytes() == _numpy_x(qp, l[qp._eq_rows], z).tobytes()


@pytest.mark.parametrize("cls", [ReferenceTrackingMpc, CarFollowingMpc])
def test_residual_and_kkt_match_the_numpy_checks(monkeypatch, cls):
    """On solved steps (DAQP's z and lam) and on perturbed ones, the kernel's violation, stationarity and gap are
    the numpy checks' up to rounding; NaN in z or lam gives NaN, lam None gives NaN measures."""
    monkeypatch.setattr(qp_module, "_daqp_direct_path", lambda: None)   # DAQP's z and lam through its interface
    mpc = cls(MODEL, backend="daqp")
    qp = mpc.qp
    N = mpc.n
    kkt = _Kkt(qp.H, qp.G, qp._f.size, qp.bound, drop_infinite=False)
    res = _Residual(mpc.A)
    rng = np.random.default_rng(5)
    args = dict(v0=8.0, v_lo=np.zeros(N), v_hi=np.full(N, 30.0), grade=np.zeros(N))
    if cls is ReferenceTrackingMpc:
        args["v_ref"] = np.full(N, 12.0)
    else:
        args.update(d_rel0=40.0, v_p=10.0)
    mpc.set_step(**args)
    assert qp.kernel.fill(mpc.q, mpc.l, mpc.u)
    qp.model.update(f=qp._f, bupper=qp._hi, blower=qp._lo)
    z, _, flag, info = qp.model.solve()
    assert flag == 1
    nb = qp._lohi.size // 2
    lo, hi = qp._lohi[:nb], qp._lohi[nb:]
    for k in range(20):
        zk = z if k == 0 else z + rng.normal(0.0, 0.1, z.size)
        lam = info["lam"] if k < 10 else info["lam"] + rng.normal(0.0, 0.1, nb)
        x = np.empty(mpc.nx)
        viol, stat, gap = qp.kernel.check(zk, lam, x)
        assert viol == pytest.approx(res(mpc.l, mpc.u, x), rel=1e-12, abs=1e-12)
        s_ref, g_ref = kkt(qp._f, lo, hi, zk, lam)
        assert stat == pytest.approx(s_ref, rel=1e-9, abs=1e-14) and gap == pytest.approx(g_ref, rel=1e-9, abs=1e-14)
        if k == 0:
            assert viol <= 1e-5 and stat <= 1e-6 and gap <= 1e-6   # DAQP's own solution passes
    bad = z.copy()
    bad[3] = np.nan
    assert all(np.isnan(v) for v in qp.kernel.check(bad, info["lam"], np.empty(mpc.nx)))
    lam = info["lam"].copy()
    lam[0] = np.nan
    viol, stat, gap = qp.kernel.check(z, lam, np.empty(mpc.nx))
    assert viol <= 1e-5 and np.isnan(stat) and np.isnan(gap)
    viol, stat, gap = qp.kernel.check(z, None, np.empty(mpc.nx))
    assert viol <= 1e-5 and np.isnan(stat) and np.isnan(gap)


def test_refused_data_change_nothing_and_bad_arguments_are_errors():
    mpc = ReferenceTrackingMpc(MODEL, backend="daqp")
    qp = mpc.qp
    q, l, u = mpc.q.copy(), mpc.l.copy(), mpc.u.copy()
    f0, lohi0 = qp._f.copy(), qp._lohi.copy()
    for vec in (q, l, u):
        for bad in (np.nan, np.inf, 1e200):
            v = vec.copy()
            vec[1] = bad
            assert qp.kernel.fill(q, l, u) is False
            vec[:] = v
    assert qp._f.tobytes() == f0.tobytes() and qp._lohi.tobytes() == lohi0.tobytes()
    with pytest.raises(ValueError, match="q: expected"):
        qp.kernel.fill(q[:-1], l, u)
    with pytest.raises(ValueError, match="float64"):
        qp.kernel.fill(q.astype(np.float32), l, u)
    with pytest.raises(ValueError, match="lam: expected"):
        qp.kernel.check(np.zeros(qp._f.size), np.zeros(3), np.empty(mpc.nx))
    read_only = np.empty(mpc.nx)
    read_only.setflags(write=False)
    with pytest.raises((ValueError, BufferError)):
        qp.kernel.check(np.zeros(qp._f.size), None, read_only)
    with pytest.raises(TypeError):
        qp.kernel.fill(q, l)


def _numpy_set_step(mpc, v0, v_lo, v_hi, grade, v_ref=None, d_its0=0.0, d_hard_lo=None, d_s_its=np.inf,
                    ft_prev=None, d_rel0=0.0, v_p=0.0, v_lin=None, ft_lin=None, safe_margin=0.0):
    """SparseMpc.set_step as numpy computed it (the compiled Stepper replaced this): (q, l, u) of this step."""
    from pedas.mpc import KN, LU

    q, l, u = mpc.q.copy(), mpc.l.copy(), mpc.u.copy()
    rs, N, w = mpc._rs, mpc.n, mpc.w
    l[rs["init_v"]] = u[rs["init_v"]] = v0
    l[rs["init_d"]] = u[rs["init_d"]] = d_its0 / LU
    c = mpc.c_const - ((np.cos(grade) * mpc.model.c_r + np.sin(grade)) * mpc._c_grade)
    l[rs["dyn_v"]] = u[rs["dyn_v"]] = c
    l[rs["v_lim"]], u[rs["v_lim"]] = np.maximum(v_lo, -BIG), np.minimum(v_hi, BIG)
    # k = 0 of the jerk rows holds the previously applied force
    u[rs["jerk_up"].start] = BIG if ft_prev is None else mpc.dFt + ft_prev / KN
    l[rs["jerk_dn"].start] = -BIG if ft_prev is None else -mpc.dFt + ft_prev / KN
    l[rs["d_hard"]] = -BIG if d_hard_lo is None else np.maximum(d_hard_lo, -BIG)
    u[rs["d_soft"]] = min(d_s_its / LU, BIG)
    if mpc.follow:
        l[rs["init_r"]] = u[rs["init_r"]] = d_rel0 / LU
        l[rs["dyn_r"]] = u[rs["dyn_r"]] = mpc.dt * v_p / LU
        l[rs["safe"]] = (np.add(safe_margin, np.zeros(N)) + w.d_min) / LU
    sv0, sft = mpc._sv0, mpc._sft
    if mpc.power_convex:
        q[sv0], q[sft] = mpc.pa10, mpc.pa01
    else:
        vb = np.full(N, float(v0)) if v_lin is None else np.asarray(v_lin, float)
        fb = np.zeros(N) if ft_lin is None else ft_lin / KN
        q[sv0] = fb * mpc.pa11 + mpc.pa10
        q[sft] = vb * mpc.pa11 + mpc.pa01
        if mpc.lin_v2:
            q[sv0] = q[sv0] + vb * (2.0 * mpc.pa20)
        if mpc.lin_f2:
            q[sft] = q[sft] + fb * (2.0 * mpc.pa02)
    q[mpc._ivN] = 0.0
    if not mpc.follow:
        q[mpc._sv1] = q[mpc._sv1] - v_ref * (2.0 * w.zeta1)
    elif w.zeta_v > 0:
        q[mpc._sv1] = q[mpc._sv1] - 2.0 * w.zeta_v * v_p
    return q, l, u


def _convex_model():
    import dataclasses

    pm = MODEL.power
    return dataclasses.replace(MODEL, power=dataclasses.replace(pm, a11=0.0, a20=abs(pm.a20), a02=abs(pm.a02)))


@pytest.mark.parametrize("cls", [ReferenceTrackingMpc, CarFollowingMpc])
@pytest.mark.parametrize("convex", [False, True])
def test_set_step_writes_the_numpy_bits(cls, convex):
    """Every branch of set_step (each optional argument given or not, scalar or per-step margin, infinite bounds,
    both power-map cases) against the numpy formulation, bit for bit, on random data."""
    mpc = cls(_convex_model() if convex else MODEL, backend="osqp")
    assert mpc.power_convex is convex
    N, rng = mpc.n, np.random.default_rng(11)
    for i in range(60):
        kw = dict(v0=rng.uniform(0, 30), v_lo=rng.uniform(-1, 10, N), v_hi=rng.uniform(10, 40, N),
                  grade=rng.normal(0, 0.05, N), d_its0=rng.uniform(0, 300), d_s_its=[np.inf, rng.uniform(1, 9)][i % 2])
        kw["v_hi"][i % N] = np.inf
        kw["v_lo"][(i + 3) % N] = -np.inf
        if cls is ReferenceTrackingMpc:
            kw["v_ref"] = rng.uniform(0, 30, N)
        else:
            kw.update(d_rel0=rng.uniform(5, 90), v_p=rng.uniform(0, 30),
                      safe_margin=[0.5, rng.normal(0, 2, N)][i % 2])
        if i % 3:
            kw["ft_prev"] = rng.normal(0, 2000)
        if i % 4:
            kw["d_hard_lo"] = np.where(rng.random(N) < 0.5, 0.0, -np.inf)
        if i % 5:
            kw["v_lin"], kw["ft_lin"] = rng.uniform(0, 30, N), rng.normal(0, 2000, N)
        q, l, u = _numpy_set_step(mpc, **kw)
        mpc.set_step(**kw)
        assert mpc.q.tobytes() == q.tobytes() and mpc.l.tobytes() == l.tobytes() and mpc.u.tobytes() == u.tobytes()


def test_set_step_refuses_arrays_of_another_shape_or_type():
    mpc = ReferenceTrackingMpc(MODEL, backend="osqp")
    N = mpc.n
    ok = dict(v0=5.0, v_lo=np.zeros(N), v_hi=np.full(N, 30.0), grade=np.zeros(N), v_ref=np.full(N, 10.0))
    mpc.set_step(**ok)
    with pytest.raises(ValueError, match="v_hi: expected 20 contiguous float64"):
        mpc.set_step(**{**ok, "v_hi": np.full(N + 1, 30.0)})
    with pytest.raises(ValueError, match="grade"):
        mpc.set_step(**{**ok, "grade": np.zeros(N, dtype=int)})
    with pytest.raises(TypeError, match="v_ref without a leader"):
        mpc.set_step(**{**ok, "v_ref": None})
    with pytest.raises(TypeError):
        mpc.set_step(**{**ok, "v0": "fast"})


def test_half_set_up_or_misused_objects_raise_instead_of_crashing():
    """An object whose __init__ never ran or failed refuses every call; a second __init__ is refused; a negative
    size, a keyword argument or a non-tuple where a tuple belongs is an error; safe_margin None is a TypeError and a
    0-d or float32 margin is a number."""
    from pedas._qpkernel import Kernel, Stepper

    for obj, call in ((Kernel.__new__(Kernel), lambda k: k.fill(np.zeros(1), np.zeros(1), np.zeros(1))),
                      (Kernel.__new__(Kernel), lambda k: k.check(np.zeros(1), None, np.zeros(1))),
                      (Stepper.__new__(Stepper), lambda s: s.set(*([0.0] * 14)))):
        with pytest.raises(RuntimeError, match="not set up"):
            call(obj)
    mpc = CarFollowingMpc(MODEL, backend="daqp")
    with pytest.raises(RuntimeError, match="set up once"):
        mpc._stepper.__init__(mpc.q, mpc.l, mpc.u, mpc._v_lin, mpc._fb_lin, mpc._v_ref, (), (), ())
    with pytest.raises(RuntimeError, match="set up once"):
        mpc.qp.kernel.__init__()
    e = np.zeros(0, dtype=np.int64)
    csr = (np.zeros(1, dtype=np.int64), e, np.zeros(0), 0, 0)
    bad = Kernel.__new__(Kernel)
    with pytest.raises(ValueError, match="negative"):
        bad.__init__(-1, 0, 1.0, e, e, csr, csr, csr, csr, csr, np.zeros(0), np.zeros(0))
    with pytest.raises(RuntimeError, match="not set up"):          # a failed __init__ leaves it unusable
        bad.fill(np.zeros(0), np.zeros(0), np.zeros(0))
    with pytest.raises(TypeError, match="a tuple"):
        Kernel(0, 0, 1.0, e, e, [0], csr, csr, csr, csr, np.zeros(0), np.zeros(0))
    with pytest.raises(TypeError, match="keyword"):
        Kernel(nx=0)
    N = mpc.n
    args = dict(v0=10.0, d_rel0=40.0, v_p=9.0, v_lo=np.zeros(N), v_hi=np.full(N, 30.0), grade=np.zeros(N))
    with pytest.raises(TypeError, match="safe_margin"):
        mpc.plan(**args, safe_margin=None)
    q = {}
    for margin in (0.5, np.float32(0.5), np.array(0.5), np.full(N, 0.5)):
        assert mpc.plan(**args, safe_margin=margin).ok
        q.setdefault("l", mpc.l.copy())
        assert mpc.l.tobytes() == q["l"].tobytes()


def _plans(cls, direct: bool, monkeypatch, steps: int = 120, seed: int = 11):
    """A random sequence of plans of one MPC (DAQP condensed), DAQP called by the kernel (`direct`) or through its
    Python interface: speeds, references, stop rows, bounds that cannot hold (infeasible: the cold retry), and cold
    starts as a hand-over gives them."""
    if not direct:
        monkeypatch.setattr(qp_module, "_daqp_direct_path", lambda: None)
    mpc = cls(MODEL, backend="daqp")
    monkeypatch.undo()
    assert hasattr(mpc.qp, "model") is not direct
    N, rng = mpc.n, np.random.default_rng(seed)
    v, ft_prev, out = 5.0, None, []
    for i in range(steps):
        v_lo = np.zeros(N)
        v_hi = np.full(N, rng.uniform(8.0, 30.0))
        if i % 17 == 5:
            v_lo[:] = 40.0                       # above v_hi and out of reach: infeasible
        kw = dict(ft_prev=ft_prev)
        if rng.random() < 0.3:                   # a stop line ahead: hard d_ITS rows on a red tail
            d_hard = np.where(np.arange(N) >= rng.integers(0, N), 0.0, -np.inf)
            kw.update(d_its0=rng.uniform(5.0, 80.0), d_hard_lo=d_hard, d_s_its=2.0)
        grade = rng.uniform(-0.04, 0.04, N)
        if cls is ReferenceTrackingMpc:
            plan = mpc.plan(v, np.full(N, rng.uniform(0.0, 25.0)), v_lo, v_hi, grade, **kw)
        else:
            plan = mpc.plan(v, rng.uniform(3.0, 90.0), rng.uniform(0.0, 25.0), v_lo, v_hi, grade,
                            safe_margin=rng.uniform(-2.0, 2.0, N), **kw)
        out.append((plan.status, plan.ok, plan.iterations, None if plan.x is None else plan.x.tobytes()))
        ft_prev = float(plan.ft[0]) if plan.ok else None
        v = max(0.0, float(plan.v[1]) + rng.normal(0.0, 0.3)) if plan.ok else rng.uniform(0.0, 20.0)
        if rng.random() < 0.1:
            mpc.qp.cold_start()
    return out


@pytest.mark.parametrize("cls", [ReferenceTrackingMpc, CarFollowingMpc])
def test_direct_daqp_is_daqp_through_its_python_interface(monkeypatch, cls):
    """DAQP's C functions called by the kernel give what DAQP's Python interface gives, bit for bit: every status,
    iteration count and solution of a sequence with hot starts, cold starts and failed solves."""
    direct, wrapped = _plans(cls, True, monkeypatch), _plans(cls, False, monkeypatch)
    assert direct == wrapped
    statuses = {s for s, *_ in direct}
    assert "solved" in statuses and len(statuses) > 1   # the sequence exercised failures as well
    assert sum(ok for _, ok, *_ in direct) > len(direct) // 2


def test_the_kernel_checks_exactly_the_exits_pedas_calls_solved():
    """The kernel runs its check for DAQP exits 1 and 2 (pedas/_qpkernel.c): the exits _DAQP_STATUS calls solved."""
    assert {flag for flag, s in qp_module._DAQP_STATUS.items() if s == "solved"} == {1, 2}


def test_direct_daqp_refuses_misuse():
    """solve before open_daqp, a daqp module that is not loaded, and arrays of the wrong size are errors."""
    mpc = ReferenceTrackingMpc(MODEL, backend="daqp")
    N = mpc.n
    assert mpc.plan(8.0, np.full(N, 12.0), np.zeros(N), np.full(N, 30.0), np.zeros(N)).ok   # q, l, u of a step
    qp = mpc.qp
    fresh = Kernel.__new__(Kernel)
    with pytest.raises(RuntimeError, match="not set up"):
        fresh.solve(False, np.empty(mpc.nx))
    with pytest.raises(TypeError):
        qp.kernel.solve(False)
    with pytest.raises(ValueError, match="contiguous float64"):
        qp.kernel.solve(False, np.empty(mpc.nx - 1))
    H, G, sense = qp.H, qp.G.toarray(), qp._sense0.astype(np.int64)
    csr = lambda c: (c.indptr.astype(np.int64), c.indices.astype(np.int64), c.data, *c.shape)  # noqa: E731

    def kernel():
        Acsr = sp.csr_matrix(mpc.A)
        Acsr.sort_indices()
        k = Kernel(mpc.nx, Acsr.shape[0], qp.bound, qp._eq_rows, qp._gather, csr(qp.vec), csr(qp.map), csr(Acsr),
                   csr(sp.csr_matrix(H)), csr(qp.G), np.empty_like(qp._f), np.empty_like(qp._lohi))
        assert k.fill(mpc.q, mpc.l, mpc.u)
        return k

    with pytest.raises(ImportError, match="not loaded"):
        kernel().open_daqp("/nonexistent/daqp.so", H, G, sense, 1e-6, 1000)
    with pytest.raises(ValueError, match="H"):
        kernel().open_daqp(daqp.__file__, H[:-1], G, sense, 1e-6, 1000)
    with pytest.raises(ValueError, match="sense"):
        kernel().open_daqp(daqp.__file__, H, G, sense[:-1], 1e-6, 1000)
    k = kernel()
    k.open_daqp(daqp.__file__, H, G, sense, 1e-6, 1000)
    x = np.empty(mpc.nx)
    flag, iters, _, violation, stat, gap = k.solve(True, x)
    assert flag == 1 and iters >= 0 and violation <= 1e-5 and stat <= 1e-6 and gap <= 1e-6
    assert k.solver_seconds > 0.0

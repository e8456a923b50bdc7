"""Bad input never becomes advice, and no bad input leaves a solver broken (docs/controller.md, "Failures").

* the controller refuses a measurement that is not a finite number (``RefusedMeasurement``, status ``refused:<field>``)
  before anything changes: the following steps are those of a controller that never saw it;
* both QP backends refuse non-finite data without calling the solver, and an OSQP whose iterate became NaN is set
  up again: the following plans and iteration counts are those of a fresh MPC;
* a solution is used only with the status "solved" (never OSQP's "maximum iterations reached") and only if it
  passes the KKT check (stationarity and duality gap with the solver's multipliers).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import pedas.qp as qp_module
from pedas.constants import DT
from pedas.controller import PedasController, RefusedMeasurement
from pedas.mpc import vehicle_model
from pedas.mpc_cf import CarFollowingMpc
from pedas.mpc_rt import ReferenceTrackingMpc
from pedas.params import CONTROLLER
from pedas.qp import OSQP_RESIDUAL_TOL, _Kkt
from pedas.route import Route, TrafficLight

NAN, INF = float("nan"), float("inf")
N = 20
MODEL = vehicle_model()
BACKENDS = ["daqp", "osqp"]


def _settings(backend: str):
    return dataclasses.replace(CONTROLLER, qp_backend=backend)


def _route() -> Route:
    return Route.synthetic(length=900.0, lights=[TrafficLight("TL1", 600.0, (("green", 20.0), ("yellow", 3.0),
                                                                              ("red", 20.0)))])


def _inputs(backend: str, steps: int = 120) -> list[tuple]:
    """(t, s, v, leader) of a closed loop with an ideal driver (the next speed is the advice) behind a leader that
    starts 40 m ahead at 8 m/s: car following from the first step."""
    ctrl = PedasController(_route(), settings=_settings(backend))
    t, s, v, s_lead = 0.0, 0.0, 10.0, 40.0
    out = []
    for _ in range(steps):
        lead = (s_lead - s, 8.0)
        out.append((t, s, v, lead))
        v_new = ctrl.step(t, s, v, lead).v_advice
        s, v, t, s_lead = s + 0.5 * DT * (v + v_new), v_new, t + DT, s_lead + 8.0 * DT
    return out


def _replay(ctrl: PedasController, inputs) -> list:
    return [ctrl.step(*x) for x in inputs]


@pytest.mark.parametrize("bad, status", [
    ((0.0, 0.0, NAN, None), "refused:v"),
    ((0.0, 0.0, 10.0, (NAN, 8.0)), "refused:leader_gap"),
    ((0.0, 0.0, 10.0, (30.0, INF)), "refused:leader_v"),
    ((NAN, 0.0, 10.0, None), "refused:t"),
    ((0.0, -INF, 10.0, None), "refused:s"),
])
def test_non_finite_measurements_are_refused_with_a_status(bad, status):
    """A NaN speed gave a NaN advice and a NaN gap was read as "no leader"; now neither is advice."""
    ctrl = PedasController(_route())
    with pytest.raises(RefusedMeasurement, match="not a finite number") as exc:
        ctrl.step(*bad)
    assert exc.value.status == status and isinstance(exc.value, ValueError)
    assert ctrl.stats["steps"] == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_after_a_refused_measurement_the_plans_are_those_of_a_controller_that_never_saw_it(backend):
    inputs = _inputs(backend)
    k = 30
    assert inputs[k][3][0] < 100.0                      # a car-following step
    clean = _replay(PedasController(_route(), settings=_settings(backend)), inputs)
    ctrl = PedasController(_route(), settings=_settings(backend))
    got = _replay(ctrl, inputs[:k])
    t, s, v, (gap, v_p) = inputs[k]
    for bad in ((t, s, NAN, (gap, v_p)), (t, s, v, (NAN, v_p)), (t, s, v, (gap, NAN))):
        with pytest.raises(RefusedMeasurement):
            ctrl.step(*bad)
    got += _replay(ctrl, inputs[k:])
    assert got == clean                                 # every field of every Advisory, bit for bit
    assert all(a.controller == "cf" and not a.fallback for a in got[k:k + 10])
    # a refusal at the very first step: the drive is that of a fresh controller
    ctrl = PedasController(_route(), settings=_settings(backend))
    with pytest.raises(RefusedMeasurement):
        ctrl.step(0.0, 0.0, NAN, inputs[0][3])
    assert _replay(ctrl, inputs) == clean


def _cf_steps():
    """Car-following QPs of a short approach: (v0, d_rel0, v_p) per step."""
    return [(10.0 - 0.1 * i, 40.0 - 0.3 * i, 8.0) for i in range(12)]


def _plan(mpc, v0, d_rel0, v_p):
    return mpc.plan(v0, d_rel0, v_p, np.zeros(N), np.full(N, 20.0), np.zeros(N))


@pytest.mark.parametrize("backend", BACKENDS)
def test_every_backend_recovers_after_nan_data(backend):
    """A NaN reaching the MPC itself (bypassing the controller) is refused before the solver sees it; the next
    plans and iteration counts are those of an MPC that never saw it (for OSQP, before: every later solve ran
    into its 4000-iteration limit on a NaN iterate and was rejected, reset() did not help)."""
    clean, poisoned = CarFollowingMpc(MODEL, backend=backend), CarFollowingMpc(MODEL, backend=backend)
    steps = _cf_steps()
    ref = [_plan(clean, *x) for x in steps]
    assert all(p.ok for p in ref)
    for i, x in enumerate(steps):
        if i == 3:
            for bad in ((NAN, x[1], x[2]), (x[0], NAN, x[2]), (x[0], x[1], INF)):
                p = _plan(poisoned, *bad)
                assert not p.ok and p.status == "rejected:non-finite data" and p.iterations == 0
        p = _plan(poisoned, *x)
        assert p.ok and p.iterations == ref[i].iterations
        assert np.array_equal(p.x, ref[i].x)


def test_a_poisoned_osqp_is_set_up_again():
    """An OSQP whose iterate is NaN (here put there directly) is rebuilt and the solve repeated; reset() rebuilds
    it too. After that it solves as a fresh one: the same plan, the same iterations, on the next steps as well."""
    steps = _cf_steps()
    fresh = CarFollowingMpc(MODEL, backend="osqp")
    ref = [_plan(fresh, *x) for x in steps]
    mpc = CarFollowingMpc(MODEL, backend="osqp")
    _plan(mpc, 12.0, 60.0, 11.0)                         # some other history
    mpc.qp.solver.warm_start(x=np.full(mpc.nx, NAN), y=np.full(mpc.m, NAN))
    p = _plan(mpc, *steps[0])
    assert p.ok and mpc.qp.rebuilds == 1 and np.array_equal(p.x, ref[0].x)
    for x, r in zip(steps[1:], ref[1:]):
        p = _plan(mpc, *x)
        assert p.ok and p.iterations == r.iterations and np.array_equal(p.x, r.x)
    # reset (a new drive): a fresh solver, whatever its state
    mpc.qp.solver.warm_start(x=np.full(mpc.nx, NAN), y=np.full(mpc.m, NAN))
    mpc.reset()
    assert mpc.qp.rebuilds == 2
    got = [_plan(mpc, *x) for x in steps]
    assert [p.iterations for p in got] == [r.iterations for r in ref]


def test_maximum_iterations_is_never_used():
    """OSQP stopped at its iteration limit: before, used when feasible within 1e-2 (objective gap up to 0.64 against
    Clarabel at 1e-10); now no plan, and the controller's fallback."""
    tight = dataclasses.replace(CONTROLLER.osqp, max_iter=10, check_termination=10)
    mpc = CarFollowingMpc(MODEL, backend="osqp", osqp=tight)
    p = _plan(mpc, *_cf_steps()[0])
    assert p.status == "maximum iterations reached" and not p.ok and p.v is None
    ctrl = PedasController(_route(), settings=dataclasses.replace(CONTROLLER, qp_backend="osqp", osqp=tight))
    adv = ctrl.step(0.0, 0.0, 10.0, (40.0, 8.0))
    assert adv.fallback and adv.solve_status == "fallback:maximum iterations reached"
    assert ctrl.stats["fallbacks"] == 1 and ctrl.stats["solved"] == 0


def test_kkt_measures_hand_worked():
    """min 1/2 z^2 - z  s.t.  z <= 0.5: z* = 0.5, lam = 0.5 (z - 1 + lam = 0), gap 0. At the feasible z = 0.4 with
    the same lam: stationarity |0.4 - 1 + 0.5| / max(1, |f|) = 0.1; gap |z^2 - z + lam hi| = |0.16 - 0.4 + 0.25|
    = 0.01 over max(1, |0.08 - 0.4|) = 0.01. A lam on a side at 'infinity' is no certificate."""
    kkt = _Kkt(sp.csr_matrix([[1.0]]), sp.csr_matrix([[1.0]]), 0, 1e30, drop_infinite=True)
    f, lo, hi = np.array([-1.0]), np.array([-1e30]), np.array([0.5])
    assert kkt(f, lo, hi, np.array([0.5]), np.array([0.5])) == (0.0, 0.0)
    stat, gap = kkt(f, lo, hi, np.array([0.4]), np.array([0.5]))
    assert stat == pytest.approx(0.1, abs=1e-15) and gap == pytest.approx(0.01, abs=1e-15)
    stat, _ = kkt(f, lo, np.array([1e30]), np.array([0.5]), np.array([0.5]))
    assert stat == pytest.approx(0.5, abs=1e-15)
    # DAQP's layout: the same QP with z <= 0.5 as the simple bound of z (the identity rows first)
    kkt = _Kkt(np.array([[1.0]]), np.zeros((0, 1)), 1, 1e4, drop_infinite=False)
    assert kkt(f, np.array([-1e4]), hi, np.array([0.5]), np.array([0.5])) == (0.0, 0.0)
    assert np.isnan(kkt(f, np.array([-1e4]), hi, np.array([NAN]), np.array([0.5]))[0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_feasible_but_not_optimal_solution_is_rejected(monkeypatch, backend):
    """The solver says 'solved' and returns a point that satisfies l <= Ax <= u, with its multipliers, but of
    another cost (v_ref only enters q): the residual check passes, the KKT check rejects it. (DAQP through its Python
    interface, where a lie can be told; the kernel's direct path runs the same status logic on the same check.)"""
    if backend == "daqp":
        monkeypatch.setattr(qp_module, "_daqp_direct_path", lambda: None)
    mpc = ReferenceTrackingMpc(MODEL, backend=backend)
    args = (8.0, np.full(N, 12.0), np.zeros(N), np.full(N, 30.0), np.zeros(N))
    other = (8.0, np.full(N, 20.0)) + args[2:]
    if backend == "daqp":
        real = mpc.qp.model
        assert mpc.plan(*other).ok
        z, _, _, info = real.solve()                    # DAQP's own solution of the other QP, and its lambda

        class Lying:
            def update(self, **kw):
                real.update(**kw)

            def solve(self):
                return z, 0.0, 1, {"iterations": 1, "solve_time": 0.0, "lam": info["lam"]}

        mpc.qp.model = Lying()
    else:
        assert mpc.plan(*other).ok
        x, y = mpc.qp._core.solution.x.copy(), mpc.qp._core.solution.y.copy()
        monkeypatch.setattr(mpc.qp, "_core", None)
        monkeypatch.setattr(mpc.qp.solver, "solve", lambda **kw: _Solved(x, y))
    plan = mpc.plan(*args)
    assert not plan.ok and plan.v is None
    assert plan.status in ("rejected:solved:stationarity", "rejected:solved:gap")
    tol = CONTROLLER.daqp.residual_tol if backend == "daqp" else OSQP_RESIDUAL_TOL
    assert mpc.residual(mpc.x_prev) <= tol              # the point itself was feasible (x_prev: the other QP's)


class _Solved:
    """An OSQP result that says solved."""

    def __init__(self, x, y):
        self.x, self.y = x, y
        self.info = type("Info", (), {"status": "solved", "iter": 1, "run_time": 0.0, "obj_val": 0.0})()

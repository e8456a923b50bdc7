"""Time of a controller step (`pedas-study bench mpc`) on a drive-like sequence, against cvxpy rebuilding the same QP.

The sequence: a synthetic urban + highway route (hills, two curves, four traffic lights, one stop sign), a
virtual driver that follows the advice with a first-order lag (so the state deviates from the plan as with a
human), and a leader that appears within sensor range, brakes and accelerates, and disappears again in cycles.
Each timed controller step is ``PedasController.step`` (vector update + QP solve + checks + HUD advisory); the
sequence runs once per QP backend (DAQP, OSQP). The peer builds the very QP of the same step
(``SparseMpc.qp_data``) from scratch in cvxpy and solves it with Clarabel at tolerance 1e-10, on an evenly spread
subset of the steps: it is both the timed peer and the reference of the objective gap and the first-input error.
Those QPs are recorded during the run and solved after it, so that no peer solve runs between two timed steps.
After the timed pass, a second pass of the same steps on a fresh controller times every stage of the step
(:func:`stage_breakdown`: the controller's stages, the QP fill, the solver's own calls, the checks, the unpacking and
the glue between them).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from pedas.constants import DT
from pedas_study.extras import require

DRIVER_LAG = 0.6  # s, first-order lag of the benchmark's virtual driver when tracking the advice


REF_TOL = 1e-10   # Clarabel's gap and feasibility tolerances of the reference solutions


@dataclass
class BenchResult:
    """One backend on the sequence. Timings in ms; ratio = peer median / controller median; obj_gap_max: largest
    relative objective gap |f - f_ref| / max(1, |f_ref|) against Clarabel at 1e-10 on the same QPs (objectives
    evaluated at each solution with the QP's own P, q); du0_max_n: largest |F_t,0 - F_t,0,ref|, |F_b,0 - F_b,0,ref|
    (N) on those QPs."""

    backend: str
    steps: int
    median_ms: float
    p95_ms: float
    p99_ms: float
    max_ms: float
    solve_median_ms: float
    solve_p99_ms: float
    peer_steps: int
    peer_median_ms: float
    ratio: float
    obj_gap_max: float
    obj_gap_over_1e3: dict
    du0_max_n: float
    iter_median: float
    iter_p95: float
    iter_max: int
    fallbacks: int
    corrections: int
    switches: int
    power_hessian_eigs: list = field(default_factory=list)
    qp_hessian_min_eig: float = 0.0
    controller_share: dict = field(default_factory=dict)
    statuses: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON-ready dict of the result."""
        return asdict(self)

    def to_text(self) -> str:
        lines = [
            f"[{self.backend}] controller step (update + solve + advisory) over {self.steps} steps:",
            f"  median {self.median_ms:.3f} ms   p95 {self.p95_ms:.3f} ms   p99 {self.p99_ms:.3f} ms   "
            f"max {self.max_ms:.3f} ms",
            f"  solve alone (solver's timer): median {self.solve_median_ms:.3f} ms, p99 {self.solve_p99_ms:.3f} ms; "
            f"iterations median {self.iter_median:.0f}, p95 {self.iter_p95:.0f}, max {self.iter_max}",
            f"  cvxpy + Clarabel (tol {REF_TOL:g}), same QP rebuilt per step, {self.peer_steps} steps: median "
            f"{self.peer_median_ms:.3f} ms; ratio (cvxpy median / controller median) {self.ratio:.1f}x",
            f"  against the reference on those QPs: max objective gap {self.obj_gap_max:.1e}, max |du0| "
            f"{self.du0_max_n:.2g} N; gaps above 1e-3 by status: {self.obj_gap_over_1e3 or 'none'}",
            f"  controller share {self.controller_share}; fallbacks {self.fallbacks}, speed corrections "
            f"{self.corrections}, switches {self.switches}",
            f"  solve status {self.statuses}",
            f"  convexity: eq. (5) Hessian eigenvalues {self.power_hessian_eigs[0]:.3g}, "
            f"{self.power_hessian_eigs[1]:.3g} (indefinite -> a11 v F linearised); QP Hessian min eigenvalue "
            f"{self.qp_hessian_min_eig:.2g}",
            f"  {self.backend} settings " + ", ".join(f"{k}={v}" for k, v in self.settings.items() if k != "verbose"),
        ]
        if self.stages:
            st = self.stages["stages"]
            total = sum(x["mean_us"] for x in st.values())
            lines.append(f"  breakdown by stage (second pass of the same steps, every stage timed; step median "
                         f"{self.stages['step_median_ms']:.3f} ms instrumented), us per step:")
            lines.append(f"    {'stage':<38} {'mean':>7} {'median':>7} {'share':>6}")
            lines += [f"    {label:<38} {x['mean_us']:7.1f} {x['median_us']:7.1f} {x['mean_us'] / total:6.1%}"
                      for label, x in st.items()]
            lines.append(f"    {'total':<38} {total:7.1f}")
        return "\n".join(lines)


def bench_route():
    """The synthetic drive-like route: 6 km town (5 lights, a stop sign, two curves) + 7.2 km highway."""
    from pedas.route import Route, StopSign, TrafficLight

    plan = (("green", 25.0), ("yellow", 3.0), ("red", 22.0))
    lights = [TrafficLight(f"TL{i}", s, plan, offset=o) for i, (s, o) in
              enumerate(((600.0, 0.0), (1300.0, 17.0), (2300.0, 31.0), (3400.0, 9.0), (5200.0, 40.0)), start=1)]
    return Route.synthetic_mixed(lights=lights, stops=[StopSign("SS1", 2800.0)], name="bench")


def run_bench(steps: int = 5000, peer_steps: int = 300, seed: int = 0, osqp_settings: dict | None = None,
              backend: str | None = None, daqp_formulation: str | None = None) -> BenchResult:
    """Run the drive-like sequence for `steps` controller steps (restarting the route when it ends) with one QP
    backend (default: the controller's, ``CONTROLLER.qp_backend``) and, for DAQP, one formulation (default: the
    controller's, ``CONTROLLER.daqp.formulation``)."""
    import dataclasses

    from pedas.controller import PedasController
    from pedas.dp import dp_reference
    from pedas.mpc import power_hessian_eigs
    from pedas.params import CONTROLLER

    if steps < 1 or peer_steps < 0:
        raise ValueError("steps must be >= 1 and peer steps >= 0")
    if peer_steps:
        require("cvxpy", "bench", "the cvxpy peer of bench mpc")
        require("clarabel", "bench", "the cvxpy peer of bench mpc")
    backend = backend or CONTROLLER.qp_backend
    route = bench_route()
    dp = dp_reference(route)
    settings = dataclasses.replace(CONTROLLER, qp_backend=backend)
    if daqp_formulation:
        settings = dataclasses.replace(settings, daqp=dataclasses.replace(settings.daqp, formulation=daqp_formulation))
    label = f"{backend} ({settings.daqp.formulation})" if backend == "daqp" else backend
    ctrl = PedasController(route, v_dp=dp, settings=settings, osqp_settings=osqp_settings)
    step_t = np.empty(steps)
    solve_t = []
    statuses: dict[str, int] = {}
    peer_every = max(1, steps // max(peer_steps, 1)) if peer_steps else 0
    peer_qps = []   # the QPs of the peer steps, solved by the peer after the timed run
    counts = {"rt": 0, "cf": 0, "switches": 0}
    iters = []
    prev_ctrl = None

    def record(i, adv, elapsed):
        nonlocal prev_ctrl
        step_t[i] = elapsed
        mpc = ctrl.cf if adv.controller == "cf" else ctrl.rt
        solve_t.append(mpc.last_solve_time)
        iters.append(mpc.last_iter)
        statuses[adv.solve_status] = statuses.get(adv.solve_status, 0) + 1
        counts[adv.controller] += 1
        if adv.controller != prev_ctrl and prev_ctrl is not None:
            counts["switches"] += 1
        prev_ctrl = adv.controller
        if peer_every and i % peer_every == 0 and len(peer_qps) < peer_steps:
            x = None if adv.fallback or mpc.x_prev is None else mpc.x_prev.copy()
            peer_qps.append((mpc.qp_data(), x, int(mpc.ift[0]), int(mpc.ifb[0]), adv.solve_status))

    def restart():
        nonlocal prev_ctrl
        prev_ctrl = None

    _sequence(ctrl, route, steps, seed, record, restart)
    stages = stage_breakdown(PedasController(route, v_dp=dp, settings=settings, osqp_settings=osqp_settings),
                             route, steps, seed)
    peer_t, gaps, du0, over = _peer(peer_qps)
    ms = step_t * 1e3
    med = float(np.median(ms))
    peer_med = float(np.median(peer_t) * 1e3) if peer_t else float("nan")
    used = ctrl.settings.osqp.as_dict() if backend == "osqp" else dataclasses.asdict(ctrl.settings.daqp)
    return BenchResult(
        backend=label, steps=steps, median_ms=med, p95_ms=float(np.percentile(ms, 95)),
        p99_ms=float(np.percentile(ms, 99)), max_ms=float(ms.max()), solve_median_ms=float(np.median(solve_t)) * 1e3,
        solve_p99_ms=float(np.percentile(solve_t, 99)) * 1e3, peer_steps=len(peer_t), peer_median_ms=peer_med,
        ratio=peer_med / med if peer_t else float("nan"), obj_gap_max=float(max(gaps)) if gaps else float("nan"),
        obj_gap_over_1e3=over, du0_max_n=float(max(du0)) if du0 else float("nan"),
        iter_median=float(np.median(iters)), iter_p95=float(np.percentile(iters, 95)), iter_max=int(max(iters)),
        fallbacks=_count_prefix(statuses, "fallback"), corrections=int(statuses.get("speed_correction", 0)),
        switches=counts["switches"], controller_share={"rt": counts["rt"], "cf": counts["cf"]},
        statuses=statuses, settings=used,
        power_hessian_eigs=[float(e) for e in power_hessian_eigs(ctrl.model)],
        qp_hessian_min_eig=min(_min_eig(ctrl.rt.P), _min_eig(ctrl.cf.P)), stages=stages)


def run_bench_all(steps: int = 5000, peer_steps: int = 300, seed: int = 0) -> dict[str, BenchResult]:
    """:func:`run_bench` for every QP backend and DAQP formulation (same sequence seed), keyed by the result's label:
    DAQP condensed, DAQP regularised, OSQP."""
    runs = [("daqp", "condensed"), ("daqp", "regularised"), ("osqp", None)]
    out = {}
    for backend, form in runs:
        res = run_bench(steps=steps, peer_steps=peer_steps, seed=seed, backend=backend, daqp_formulation=form)
        out[res.backend] = res
    return out


def _peer(qps: list) -> tuple[list, list, list, dict]:
    """Each recorded QP rebuilt in cvxpy and solved by Clarabel at REF_TOL: (solve times s, relative objective gaps,
    |du0| N, gaps > 1e-3 by solve status). Run after the timed steps: a Clarabel solve between two controller
    steps evicts the controller's data from the caches and would be timed as part of the next steps."""
    from pedas.mpc import KN, solve_qp_cvxpy

    peer_t, gaps, du0 = [], [], []
    over: dict[str, int] = {}
    for (P, q, A, l, u, _), x, ift0, ifb0, solve_status in qps:
        t1 = time.perf_counter()
        status, _, x_ref = solve_qp_cvxpy(P, q, A, l, u, tol=REF_TOL)
        peer_t.append(time.perf_counter() - t1)
        if x is not None and status == "optimal":
            f, f_ref = _objective(P, q, x), _objective(P, q, x_ref)
            gaps.append(abs(f - f_ref) / max(1.0, abs(f_ref)))
            du0.append(KN * max(abs(x[ift0] - x_ref[ift0]), abs(x[ifb0] - x_ref[ifb0])))
            if gaps[-1] > 1e-3:
                over[solve_status] = over.get(solve_status, 0) + 1
    return peer_t, gaps, du0, over


def _objective(P, q, x) -> float:
    """1/2 x'Px + q'x with P given as its upper triangle (sparse products: no BLAS)."""
    Px = P @ x + P.T @ x - P.diagonal() * x
    return 0.5 * float((x * Px).sum()) + float((q * x).sum())


def _min_eig(P) -> float:
    P = P.toarray()
    return float(np.linalg.eigvalsh(P + P.T - np.diag(np.diag(P))).min())


def _count_prefix(statuses: dict, prefix: str) -> int:
    return int(sum(n for k, n in statuses.items() if k.startswith(prefix)))


def _sequence(ctrl, route, steps: int, seed: int, record, restart) -> None:
    """The drive-like sequence (module docstring): `steps` calls of ``ctrl.step``, each timed alone and handed to
    ``record(i, advisory, seconds)``; ``restart()`` when the route ends and the controller starts a new drive."""
    rng = np.random.default_rng(seed)
    t, s, v = 0.0, 0.0, 0.0
    lead_s, lead_v, lead_on = None, 0.0, False
    next_event = 20.0
    for i in range(steps):
        leader = (lead_s - s, lead_v) if lead_on else None
        t0 = time.perf_counter()
        adv = ctrl.step(t, s, v, leader)
        record(i, adv, time.perf_counter() - t0)
        # virtual driver: first-order lag towards the advice, plant = the advised speed trajectory
        v_new = max(0.0, v + DT / DRIVER_LAG * (adv.v_advice - v) + rng.normal(0.0, 0.05))
        s += DT * 0.5 * (v + v_new)
        v = v_new
        t += DT
        # leader: appears 60-95 m ahead, changes speed, vanishes after 25-60 s
        if t >= next_event:
            lead_on = not lead_on
            if lead_on:
                lead_s, lead_v = s + rng.uniform(60.0, 95.0), max(2.0, v + rng.uniform(-4.0, 1.0))
                next_event = t + rng.uniform(25.0, 60.0)
            else:
                next_event = t + rng.uniform(15.0, 40.0)
        if lead_on:
            lead_v = float(np.clip(lead_v + DT * rng.normal(0.0, 0.8), 0.0, 30.0))
            lead_s += DT * lead_v
            if lead_s - s < 2.0:   # the benchmark's driver never collides: the leader turns off
                lead_on = False
        if s >= route.length - 5.0:
            ctrl.reset()
            restart()
            t, s, v, lead_on = t + 1.0, 0.0, 0.0, False


# the stages of the breakdown, in the order of a step: (label, owner, attribute); owner "ctrl" is the controller,
# "mpc" each MPC (rt, cf), "qp" each MPC's QP backend, "solver" the backend's compiled solver object
STAGES = (
    ("measure", "ctrl", "_measure"),
    ("predict", "ctrl", "_predict"),
    ("objects ahead", "ctrl", "_objects_ahead"),
    ("green wave", "ctrl", "_green_wave"),
    ("reference", "ctrl", "_reference"),
    ("solve stage (choice, cf bounds)", "ctrl", "_solve"),
    ("QP fill: set_step", "mpc", "set_step"),
    ("QP fill: backend vectors", "qp", "_fill"),
    ("data check (finite q, l, u)", "module", "_finite_data"),
    ("QP prepare (condensed: compiled data check + vectors)", "qp", "_prepare"),
    ("solver C calls (update + solve)", "solver", None),
    ("QP check (condensed: compiled map back, residual, KKT)", "qp", "_check"),
    ("residual check", "qp", "_residual"),
    ("KKT check", "qp", "_kkt"),
    ("map back (x from the solver's z)", "qp", "_primal"),
    ("checked-solve glue (status, result)", "qp", "_solve_checked"),
    ("unpack (plan)", "mpc", "unpack"),
    ("advise", "ctrl", "_advise"),
    ("HUD", "ctrl", "_hud"),
    ("glue (step, MPC solve, Advisory)", "ctrl", "step"),
)


class _StageClock:
    """Exclusive time per stage: each timed call's own time minus that of the timed calls made inside it."""

    def __init__(self) -> None:
        self.acc: dict[str, float] = {}
        self._stack = [0.0]

    def wrap(self, label: str, fn):
        clock, stack, acc = time.perf_counter, self._stack, self.acc

        def timed(*args, **kw):
            stack.append(0.0)
            t0 = clock()
            try:
                return fn(*args, **kw)
            finally:
                dt = clock() - t0
                inner = stack.pop()
                stack[-1] += dt
                acc[label] = acc.get(label, 0.0) + dt - inner
        return timed


class _TimedSolver:
    """The backend's solver object with its per-step calls timed (DAQP's update and solve, OSQP's vector update and
    solve); everything else passed through."""

    def __init__(self, solver, clock: _StageClock, label: str) -> None:
        self._solver = solver
        for name in ("update", "solve", "update_data_vec"):
            if hasattr(solver, name):
                setattr(self, name, clock.wrap(label, getattr(solver, name)))

    def __getattr__(self, name):
        return getattr(self._solver, name)


def _direct_timed(clock: _StageClock, run, kernel, check_label: str, solver_label: str):
    """The condensed DAQP backend's ``_run`` when the kernel calls DAQP: timed as the check stage, then the
    kernel's own timing of DAQP's update + solve moved to the solver stage."""
    timed = clock.wrap(check_label, run)

    def run_direct(*args):
        out = timed(*args)
        clock.acc[check_label] -= kernel.solver_seconds
        clock.acc[solver_label] = clock.acc.get(solver_label, 0.0) + kernel.solver_seconds
        return out
    run_direct.timed = True
    return run_direct


def stage_breakdown(ctrl, route, steps: int, seed: int) -> dict:
    """Time per stage of the controller step on the benchmark's sequence (a second pass of the same steps on
    `ctrl`, a fresh controller): every stage of :data:`STAGES` timed exclusively (its own time without the timed
    stages it calls). Returns {'stages': {label: {'mean_us', 'median_us'}}, 'step_median_ms'} (the instrumented
    step; the timers' own cost, ~0.1 us per call, lands in the calling stage)."""
    import pedas.qp as qp_module

    clock = _StageClock()
    solver_label = next(label for label, owner, _ in STAGES if owner == "solver")
    for label, owner, attr in STAGES:
        if owner == "ctrl":
            setattr(ctrl, attr, clock.wrap(label, getattr(ctrl, attr)))
        elif owner in ("mpc", "qp"):
            for mpc in (ctrl.rt, ctrl.cf):
                obj = mpc if owner == "mpc" else mpc.qp
                if hasattr(obj, attr):
                    setattr(obj, attr, clock.wrap(label, getattr(obj, attr)))

    check_label = next(label for label, owner, attr in STAGES if (owner, attr) == ("qp", "_check"))

    def time_solvers() -> None:   # again after a restart: OSQP's cold start sets up a new solver object
        for mpc in (ctrl.rt, ctrl.cf):
            qp = mpc.qp
            if getattr(qp, "direct", False) and not hasattr(qp._run, "timed"):
                # DAQP called by the kernel: one call does DAQP's update + solve and the check; the kernel times
                # DAQP's part (solver_seconds), the rest of the call is the check's
                qp._run = _direct_timed(clock, qp._run, qp.kernel, check_label, solver_label)
            elif hasattr(qp, "model") and not isinstance(qp.model, _TimedSolver):
                qp.model = _TimedSolver(qp.model, clock, solver_label)
            elif getattr(qp, "_core", None) is not None and not isinstance(qp._core, _TimedSolver):
                qp._core = _TimedSolver(qp._core, clock, solver_label)

    time_solvers()
    finite = qp_module._finite_data
    qp_module._finite_data = clock.wrap("data check (finite q, l, u)", finite)
    per_step = {label: np.zeros(steps) for label, _, _ in STAGES}
    step_t = np.empty(steps)

    def record(i, adv, elapsed):
        step_t[i] = elapsed
        for label, sec in clock.acc.items():
            per_step[label][i] = sec
        clock.acc.clear()

    try:
        _sequence(ctrl, route, steps, seed, record, time_solvers)
    finally:
        qp_module._finite_data = finite
    return {"stages": {label: {"mean_us": float(t.mean() * 1e6), "median_us": float(np.median(t) * 1e6)}
                       for label, t in per_step.items()},
            "step_median_ms": float(np.median(step_t) * 1e3)}

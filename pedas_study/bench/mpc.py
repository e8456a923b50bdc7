"""Time of a controller step (`pedas-study bench mpc`) on a drive-like sequence, against cvxpy rebuilding the same QP.

The sequence: a synthetic urban + highway route (hills, two curves, four traffic lights, one stop sign), a
virtual driver that follows the advice with a first-order lag (so the state deviates from the plan as with a
human), and a leader that appears within sensor range, brakes and accelerates, and disappears again in cycles.
Each timed controller step is ``PedasController.step`` (vector update + OSQP solve + checks + HUD advisory). The
peer builds the very QP of the same step (``SparseMpc.qp_data``) from scratch in cvxpy and solves it with
Clarabel, on an evenly spread subset of the steps; both objectives are compared on those steps.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from pedas.constants import DT
from pedas_study.extras import require

DRIVER_LAG = 0.6  # s, first-order lag of the benchmark's virtual driver when tracking the advice


@dataclass
class BenchResult:
    """Timings in ms; ratio = peer median / controller median; obj_rel_max: largest relative objective gap."""

    steps: int
    median_ms: float
    p95_ms: float
    p99_ms: float
    max_ms: float
    solve_median_ms: float
    peer_steps: int
    peer_median_ms: float
    ratio: float
    obj_rel_max: float
    obj_rel_over_1e3: dict
    iter_median: float
    iter_p95: float
    fallbacks: int
    corrections: int
    switches: int
    power_hessian_eigs: list = field(default_factory=list)
    qp_hessian_min_eig: float = 0.0
    controller_share: dict = field(default_factory=dict)
    statuses: dict = field(default_factory=dict)
    osqp_settings: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """JSON-ready dict of the result."""
        return asdict(self)

    def to_text(self) -> str:
        lines = [
            f"controller step (update + solve + advisory) over {self.steps} steps:",
            f"  median {self.median_ms:.3f} ms   p95 {self.p95_ms:.3f} ms   p99 {self.p99_ms:.3f} ms   "
            f"max {self.max_ms:.3f} ms   (OSQP solve alone: median {self.solve_median_ms:.3f} ms; iterations median "
            f"{self.iter_median:.0f}, p95 {self.iter_p95:.0f})",
            f"cvxpy + Clarabel, same QP rebuilt per step, {self.peer_steps} steps: median {self.peer_median_ms:.3f} ms",
            f"ratio (cvxpy median / controller median): {self.ratio:.1f}x",
            f"objective agreement on the peer steps: max relative gap {self.obj_rel_max:.1e}; steps above 1e-3 by "
            f"OSQP status: {self.obj_rel_over_1e3 or 'none'}",
            f"controller share {self.controller_share}; fallbacks {self.fallbacks}, speed corrections "
            f"{self.corrections}, switches {self.switches}",
            f"solve status {self.statuses}",
            f"convexity: eq. (5) Hessian eigenvalues {self.power_hessian_eigs[0]:.3g}, {self.power_hessian_eigs[1]:.3g} "
            f"(indefinite -> a11 v F linearised); QP Hessian min eigenvalue {self.qp_hessian_min_eig:.2g}",
            "OSQP settings " + ", ".join(f"{k}={v}" for k, v in self.osqp_settings.items() if k != "verbose"),
        ]
        return "\n".join(lines)


def bench_route():
    """The synthetic drive-like route: 6 km town (5 lights, a stop sign, two curves) + 7.2 km highway."""
    from pedas.route import Route, StopSign, TrafficLight

    plan = (("green", 25.0), ("yellow", 3.0), ("red", 22.0))
    lights = [TrafficLight(f"TL{i}", s, plan, offset=o) for i, (s, o) in
              enumerate(((600.0, 0.0), (1300.0, 17.0), (2300.0, 31.0), (3400.0, 9.0), (5200.0, 40.0)), start=1)]
    return Route.synthetic_mixed(lights=lights, stops=[StopSign("SS1", 2800.0)], name="bench")


def run_bench(steps: int = 5000, peer_steps: int = 300, seed: int = 0, osqp_settings: dict | None = None) -> BenchResult:
    """Run the drive-like sequence for `steps` controller steps (restarting the route when it ends)."""
    from pedas.controller import PedasController
    from pedas.dp import dp_reference
    from pedas.mpc import power_hessian_eigs, solve_qp_cvxpy

    if steps < 1 or peer_steps < 0:
        raise ValueError("steps must be >= 1 and peer steps >= 0")
    if peer_steps:
        require("cvxpy", "bench", "the cvxpy peer of bench mpc")
        require("clarabel", "bench", "the cvxpy peer of bench mpc")
    rng = np.random.default_rng(seed)
    route = bench_route()
    dp = dp_reference(route)
    ctrl = PedasController(route, v_dp=dp, osqp_settings=osqp_settings)
    step_t = np.empty(steps)
    solve_t = []
    statuses: dict[str, int] = {}
    peer_every = max(1, steps // max(peer_steps, 1)) if peer_steps else 0
    peer_t, rels = [], []
    over: dict[str, int] = {}   # peer steps with a relative objective gap > 1e-3, by OSQP status
    t, s, v = 0.0, 0.0, 0.0
    lead_s, lead_v, lead_on = None, 0.0, False
    next_event = 20.0
    counts = {"rt": 0, "cf": 0, "switches": 0}
    iters = []
    prev_ctrl = None
    for i in range(steps):
        leader = (lead_s - s, lead_v) if lead_on else None
        t0 = time.perf_counter()
        adv = ctrl.step(t, s, v, leader)
        step_t[i] = time.perf_counter() - t0
        solver = ctrl.cf if adv.controller == "cf" else ctrl.rt
        solve_t.append(solver.last_solve_time)
        iters.append(solver.last_iter)
        statuses[adv.solve_status] = statuses.get(adv.solve_status, 0) + 1
        counts[adv.controller] += 1
        if adv.controller != prev_ctrl and prev_ctrl is not None:
            counts["switches"] += 1
        prev_ctrl = adv.controller
        if peer_every and i % peer_every == 0 and len(peer_t) < peer_steps:
            P, q, A, l, u, c = solver.qp_data()
            x_osqp = solver.x_prev
            t1 = time.perf_counter()
            status, obj, _ = solve_qp_cvxpy(P, q, A, l, u)
            peer_t.append(time.perf_counter() - t1)
            if not adv.fallback and x_osqp is not None and status == "optimal":
                f_osqp = 0.5 * float(x_osqp @ (P @ x_osqp + P.T @ x_osqp - P.diagonal() * x_osqp)) + float(q @ x_osqp)
                rels.append(abs(f_osqp - obj) / max(1.0, abs(obj)))
                if rels[-1] > 1e-3:
                    over[adv.solve_status] = over.get(adv.solve_status, 0) + 1
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
            t, s, v, lead_on, prev_ctrl = t + 1.0, 0.0, 0.0, False, None
    ms = step_t * 1e3
    med = float(np.median(ms))
    peer_med = float(np.median(peer_t) * 1e3) if peer_t else float("nan")
    return BenchResult(
        steps=steps, median_ms=med, p95_ms=float(np.percentile(ms, 95)), p99_ms=float(np.percentile(ms, 99)),
        max_ms=float(ms.max()), solve_median_ms=float(np.median(solve_t)) * 1e3, peer_steps=len(peer_t), peer_median_ms=peer_med,
        ratio=peer_med / med if peer_t else float("nan"), obj_rel_max=float(max(rels)) if rels else float("nan"),
        obj_rel_over_1e3=over,
        iter_median=float(np.median(iters)), iter_p95=float(np.percentile(iters, 95)),
        fallbacks=_count_prefix(statuses, "fallback"), corrections=int(statuses.get("speed_correction", 0)),
        switches=counts["switches"], controller_share={"rt": counts["rt"], "cf": counts["cf"]},
        statuses=statuses, osqp_settings=dict(ctrl.rt.settings),
        power_hessian_eigs=[float(e) for e in power_hessian_eigs(ctrl.model)],
        qp_hessian_min_eig=min(_min_eig(ctrl.rt.P), _min_eig(ctrl.cf.P)))


def _min_eig(P) -> float:
    P = P.toarray()
    return float(np.linalg.eigvalsh(P + P.T - np.diag(np.diag(P))).min())


def _count_prefix(statuses: dict, prefix: str) -> int:
    return int(sum(n for k, n in statuses.items() if k.startswith(prefix)))

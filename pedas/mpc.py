"""Shared building blocks of the two pEDAS MPCs (Sec. 3.5): one sparse QP, built once and solved by a QP backend
(:mod:`pedas.qp`: DAQP by default, OSQP as the cross-check).

The QP keeps the speed ``v_k``, the distance to the next stop sign / traffic light ``d_ITS,k`` and (car following)
the gap ``d_rel,k`` as explicit states tied together by equality rows (eq. 3a-3c), so that the sparsity pattern
*and* the values of ``P`` and ``A`` never change. Each control step only rewrites the vectors ``q``, ``l`` and
``u`` in place and hands them to the backend's vector update — no re-setup.

Decision vector (forces in kN and power in kW inside the QP so that all entries are O(1..100), which keeps
ADMM and the active-set factorisations well conditioned; the public plan is returned in SI units)::

    x = [ v_0..v_N | d_0..d_N | (r_0..r_N) | Ft_0..Ft_{N-1} | Fb_0.. | e1_0.. | e2_0.. | (e3_0..) ]

Cost (eq. 9a / 10a), ``k = 0..N-1``::

    P(v_k, Ft_k) + zeta1 (v_{k+1} - v_ref,k)^2      [rt]
                 or zeta1 e3_k^2 + zeta_v (v_{k+1} - v_p)^2   [cf; zeta_v is a regulariser beyond eq. (10)]
                 + zeta2 Fb_k^2 + zeta3 e1_k^2 + zeta4 e2_k^2

The tracking term uses ``v_{k+1}`` (``v_0`` is measured, so penalising it would only add a constant).

Convexity of the power term eq. (5): its Hessian in (v, Ft) is ``[[2 a20, a11], [a11, 2 a02]]``. When that block is
indefinite (the fitted BEV map always has a dominant ``a11 v Ft`` term, i.e. mechanical power ``v F``), the
bilinear term is replaced by its first-order Taylor expansion around the previous predicted trajectory (shifted by
one step): ``a11 v Ft ~ a11 (vbar Ft + Fbar v - vbar Fbar)``. This is a sequential (one-iteration-per-sample)
convexification; it is exact on the nominal trajectory and keeps ``P`` constant. Convex parts (``a20 v^2``,
``a02 Ft^2`` when non-negative) stay quadratic. :func:`power_hessian_eigs` reports the numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from pedas.constants import DT, N_HORIZON
from pedas.params import CONTROLLER, LEAF, DaqpSettings, MpcWeights, OsqpSettings
from pedas.power import PowerMap
from pedas.qp import BACKENDS, CsrProduct, DaqpBackend, DaqpCondensedBackend, OsqpBackend, residual

KN = 1000.0  # N per kN: forces inside the QP are in kN
LU = 1.0  # m per length unit of distances inside the QP (10 m and 0.1 m were tried: more iterations)
KW = 1000.0  # W per kW: the power cost inside the QP is in kW
INF = np.inf
_sum = np.add.reduce   # the reduction behind ndarray.sum (pairwise), without the method's dispatch
BIG = 1e30  # OSQP's infinity: the bound vectors hold +-BIG for unbounded rows (DAQP gets them as +-DaqpSettings.bound)


@dataclass(frozen=True)
class MpcModel:
    """The numbers of the vehicle/power model the QP needs (SI units).

    ``c_aero`` = 0.5 rho A_f c_w (N s^2/m^2); the linearised drag is ``c_aero (p1 v + p2)`` (Sec. 3.3, Fig. 5a).
    ``F_t,max ~ p3 v + p4`` (eq. 6a, N). ``power``: the fitted power map eq. (5), W with v in m/s and F in N.
    """

    m_eq: float
    m_v: float
    c_r: float
    c_aero: float
    p1: float
    p2: float
    p3: float
    p4: float
    power: PowerMap
    F_b_max: float
    g: float = 9.81


def power_hessian_eigs(m: MpcModel) -> np.ndarray:
    """Eigenvalues of the Hessian of eq. (5) in (v [m/s], F_t [N]); both >= 0 iff the power map is convex."""
    return np.linalg.eigvalsh(m.power.hessian)


@dataclass(slots=True)
class MpcPlan:
    """A solved (or fallback) plan over the horizon, SI units. ``v`` and the distances have N+1 entries (k=0..N).
    ``x``: the QP solution (QP units); its cost is :meth:`SparseMpc.objective`."""

    status: str
    ok: bool
    v: np.ndarray
    ft: np.ndarray
    fb: np.ndarray
    d_its: np.ndarray
    d_rel: np.ndarray | None
    eps1: np.ndarray
    eps2: np.ndarray
    eps3: np.ndarray | None
    iterations: int
    x: np.ndarray = field(repr=False, default=None)


class SparseMpc:
    """The sparse QP of eq. (9) (``follow=False``) or eq. (10) (``follow=True``), set up once in its QP backend.

    ``backend``: "daqp" or "osqp" (:mod:`pedas.qp`), with complete :class:`pedas.params.OsqpSettings` /
    :class:`pedas.params.DaqpSettings`. Per step call :meth:`set_step` with the measured state and the horizon
    profiles (q, l, u updated in place) and :meth:`solve`; the backend checks status, finiteness and primal
    feasibility, and only a checked solution becomes an :class:`MpcPlan` with ``ok=True``.
    """

    def __init__(self, model: MpcModel, weights: MpcWeights, follow: bool, n: int = N_HORIZON, dt: float = DT,
                 backend: str = CONTROLLER.qp_backend, osqp: OsqpSettings = CONTROLLER.osqp,
                 daqp: DaqpSettings = CONTROLLER.daqp) -> None:
        self.model, self.w, self.follow, self.n, self.dt = model, weights, follow, n, dt
        N = n
        # ---- variable layout -------------------------------------------------------------------------------
        o = 0
        self.iv = np.arange(o, o + N + 1); o += N + 1
        self.id = np.arange(o, o + N + 1); o += N + 1
        if follow:
            self.ir = np.arange(o, o + N + 1); o += N + 1
        self.ift = np.arange(o, o + N); o += N
        self.ifb = np.arange(o, o + N); o += N
        self.ie1 = np.arange(o, o + N); o += N
        self.ie2 = np.arange(o, o + N); o += N
        if follow:
            self.ie3 = np.arange(o, o + N); o += N
        self.nx = o

        # ---- model coefficients in QP units (eq. 3a) ---------------------------------------------------------
        mm = model
        self.a_v = 1.0 - dt * mm.c_aero * mm.p1 / mm.m_eq          # v_{k+1} = a_v v_k + b (Ft - Fb) + c_k
        self.b_f = dt * KN / mm.m_eq                                # per kN
        self.c_const = -dt * mm.c_aero * mm.p2 / mm.m_eq            # part of c_k independent of the grade
        # the 2x2 Hessian is PSD iff a20, a02 >= 0 and 4 a20 a02 >= a11^2: decided exactly, not by LAPACK's eigvalsh
        self.power_convex = mm.power.jointly_convex
        # power map in kW with F in kN: P = a00' + a10' v + a01' F + a11' v F + a20' v^2 + a02' F^2
        pm = mm.power
        self.pa00 = pm.a00 / KW
        self.pa10 = pm.a10 / KW
        self.pa01 = pm.a01 * KN / KW
        self.pa11 = pm.a11 * KN / KW
        self.pa20 = pm.a20 / KW
        self.pa02 = pm.a02 * KN * KN / KW
        self.lin_v2 = (not self.power_convex) and self.pa20 < 0   # linearise a negative curvature, keep a positive one
        self.lin_f2 = (not self.power_convex) and self.pa02 < 0

        # ---- constant Hessian P (upper triangle) -------------------------------------------------------------
        rows, cols, vals = [], [], []

        def add(i, j, val):
            rows.extend(np.atleast_1d(i)); cols.extend(np.atleast_1d(j))
            vals.extend(np.broadcast_to(val, np.atleast_1d(i).shape))

        w = weights
        if not self.lin_v2 and self.pa20 > 0:
            add(self.iv[:N], self.iv[:N], 2.0 * self.pa20)
        if not self.lin_f2 and self.pa02 > 0:
            add(self.ift, self.ift, 2.0 * self.pa02)
        if self.power_convex and self.pa11 != 0:
            add(self.iv[:N], self.ift, self.pa11)      # cross term stays exact when the map is convex
        if not follow:
            add(self.iv[1:], self.iv[1:], 2.0 * w.zeta1)
        else:
            add(self.ie3, self.ie3, 2.0 * w.zeta1 * LU * LU)
            if w.zeta_v > 0:
                add(self.iv[1:], self.iv[1:], 2.0 * w.zeta_v)
        add(self.ifb, self.ifb, 2.0 * w.zeta2)
        add(self.ie1, self.ie1, 2.0 * w.zeta3 * LU * LU)
        add(self.ie2, self.ie2, 2.0 * w.zeta4)
        P = sp.coo_matrix((vals, (rows, cols)), shape=(self.nx, self.nx)).tocsc()
        P.sum_duplicates()
        P = sp.triu(P, format="csc")
        self.P = P

        # ---- constant constraint matrix A -------------------------------------------------------------------
        A_rows: list[sp.spmatrix] = []
        self.rows: dict[str, np.ndarray] = {}
        nrow = 0

        def block(name: str, mat) -> None:
            nonlocal nrow
            mat = sp.csr_matrix(mat)
            A_rows.append(mat)
            self.rows[name] = np.arange(nrow, nrow + mat.shape[0])
            nrow += mat.shape[0]

        def sel(idx, coef=1.0):
            m = sp.lil_matrix((len(idx), self.nx))
            m[np.arange(len(idx)), idx] = coef
            return m

        # initial states
        block("init_v", sel([self.iv[0]]))
        block("init_d", sel([self.id[0]]))
        if follow:
            block("init_r", sel([self.ir[0]]))
        # eq. (3a): v_{k+1} - a_v v_k - b Ft_k + b Fb_k = c_k
        block("dyn_v", sel(self.iv[1:]) + sel(self.iv[:N], -self.a_v) + sel(self.ift, -self.b_f) + sel(self.ifb, self.b_f))
        # eq. (3b): d_{k+1} - d_k + dt/2 (v_k + v_{k+1}) = 0
        block("dyn_d", sel(self.id[1:]) + sel(self.id[:N], -1.0) + sel(self.iv[:N], dt / 2 / LU)
              + sel(self.iv[1:], dt / 2 / LU))
        if follow:
            # eq. (3c) with a frozen-time leader: r_{k+1} - r_k + dt/2 (v_k + v_{k+1}) = dt v_p
            block("dyn_r", sel(self.ir[1:]) + sel(self.ir[:N], -1.0) + sel(self.iv[:N], dt / 2 / LU)
                  + sel(self.iv[1:], dt / 2 / LU))
        # eq. (6c) speed limits on v_1..v_N
        block("v_lim", sel(self.iv[1:]))
        # eq. (6a) 0 <= Ft_k, Ft_k - p3 v_k <= p4 (kN)
        block("ft", sel(self.ift))
        block("ft_max", sel(self.ift) + sel(self.iv[:N], -mm.p3 / KN))
        # eq. (6b) 0 <= Fb_k <= Fb_max
        block("fb", sel(self.ifb))
        # slacks >= 0
        block("e1", sel(self.ie1))
        block("e2", sel(self.ie2))
        if follow:
            block("e3", sel(self.ie3))
        # eq. (8a/b) soft jerk limit: -dF <= Ft_k - Ft_{k-1} -/+ e2_k; k = 0 uses the previously applied force
        prev = sp.lil_matrix((N, self.nx))
        prev[np.arange(1, N), self.ift[:-1]] = -1.0
        block("jerk_up", sel(self.ift) + prev + sel(self.ie2, -1.0))     # <= dF (+ Ft_prev at k=0)
        block("jerk_dn", sel(self.ift) + prev + sel(self.ie2, 1.0))      # >= -dF (+ Ft_prev at k=0)
        # eq. (8c) d_ITS,k >= 0 (hard, only at a red light / stop sign) on d_1..d_N
        block("d_hard", sel(self.id[1:]))
        # eq. (8d) soft stop-line approach d_{k+1} - e1_k <= d_s,ITS
        block("d_soft", sel(self.id[1:]) + sel(self.ie1, -1.0))
        if follow:
            # eq. (7a) hard safe distance r_k - h_s v_k >= d_min on k=1..N
            block("safe", sel(self.ir[1:]) + sel(self.iv[1:], -w.h_s / LU))
            # eq. (7b) soft comfort distance r_{k+1} - h_c v_{k+1} - e3_k <= d_min
            block("comfort", sel(self.ir[1:]) + sel(self.iv[1:], -w.h_c / LU) + sel(self.ie3, -1.0))
        self.A = sp.vstack(A_rows, format="csc")
        self.m = nrow
        # contiguous slices of the blocks (assignment through slices is much cheaper than fancy indexing)
        self._rs = {k: slice(int(r[0]), int(r[-1]) + 1) for k, r in self.rows.items()}
        sl = lambda idx: slice(int(idx[0]), int(idx[-1]) + 1)  # noqa: E731
        self._sv, self._sv0, self._sv1 = sl(self.iv), sl(self.iv[:N]), sl(self.iv[1:])
        self._sd, self._sft, self._sfb, self._se1, self._se2 = (sl(self.id), sl(self.ift), sl(self.ifb),
                                                                 sl(self.ie1), sl(self.ie2))
        self._sr = sl(self.ir) if follow else None
        self._se3 = sl(self.ie3) if follow else None
        self._ivN = int(self.iv[N])
        self._c_grade = dt / model.m_eq * model.m_v * model.g
        # warm start shifted by one sample: element k of every horizon block takes the value of element k+1
        self._shift_x = np.arange(self.nx)
        for idx in [self.iv, self.id, self.ift, self.ifb, self.ie1, self.ie2] + (
                [self.ir, self.ie3] if follow else []):
            self._shift_x[idx[:-1]] = idx[1:]
        self._shift_y = np.arange(self.m)
        for rows_ in self.rows.values():
            if rows_.size > 1:
                self._shift_y[rows_[:-1]] = rows_[1:]

        # ---- vectors, updated in place each step ---------------------------------------------------------
        self.q = np.zeros(self.nx)
        self.l = np.full(self.m, -BIG)
        self.u = np.full(self.m, BIG)
        R = self.rows
        self.l[R["ft"]] = 0.0
        self.l[R["fb"]] = 0.0
        self.u[R["fb"]] = mm.F_b_max / KN
        self.u[R["ft_max"]] = mm.p4 / KN
        for name in ("e1", "e2") + (("e3",) if follow else ()):
            self.l[R[name]] = 0.0
        self.l[R["dyn_d"]] = 0.0
        self.u[R["dyn_d"]] = 0.0
        self.u[R["jerk_up"]] = w.dFt_max / KN
        self.l[R["jerk_dn"]] = -w.dFt_max / KN
        if follow:
            self.l[R["safe"]] = w.d_min / LU
            self.u[R["comfort"]] = w.d_min / LU
        self.dFt = w.dFt_max / KN
        # this step's linearisation point and reference, kept for the objective constant (:attr:`const`)
        self._v_lin, self._fb_lin, self._v_ref = np.empty(N), np.empty(N), np.empty(N)
        self._v_p = 0.0
        # set_step, compiled (pedas/_qpkernel.c): the blocks of q, l, u that change per step, written in place
        from pedas._qpkernel import Stepper

        rs = self._rs
        at = lambda name: rs[name].start if name in rs else -1  # noqa: E731
        self._stepper = Stepper(
            self.q, self.l, self.u, self._v_lin, self._fb_lin, self._v_ref,
            (at("init_v"), at("init_d"), at("dyn_v"), at("v_lim"), at("jerk_up"), at("jerk_dn"), at("d_hard"),
             at("d_soft"), at("init_r"), at("dyn_r"), at("safe"), self._sv0.start, self._sft.start, self._ivN),
            (follow, self.power_convex, self.lin_v2, self.lin_f2, w.zeta_v > 0),
            (model.c_r, self._c_grade, self.c_const, BIG, self.dFt, KN, LU, dt, w.d_min, self.pa10, self.pa01,
             self.pa11, 2.0 * self.pa20, 2.0 * self.pa02, 2.0 * w.zeta1, 2.0 * w.zeta_v))
        self._Pfull = CsrProduct(P + P.T - sp.diags(P.diagonal()))
        self._wx = np.empty(self.nx)
        # unpack: x times one scale vector (1 on speeds, KN on forces, LU on distances), the plan's arrays are views
        self._scale = np.ones(self.nx)
        for idx, k in ((self.id, LU), (self.ift, KN), (self.ifb, KN), (self.ie1, LU), (self.ie2, KN)) + (
                ((self.ir, LU), (self.ie3, LU)) if follow else ()):
            self._scale[idx] = k
        if backend not in BACKENDS:
            raise ValueError(f"unknown QP backend {backend!r}; one of {BACKENDS}")
        self.backend = backend
        self.settings = {k: v for k, v in osqp.as_dict().items() if k != "shift_warm_start"}  # OSQP's keywords
        self.shift_warm_start = bool(osqp.shift_warm_start) and backend == "osqp"
        if backend == "osqp":
            self.qp = OsqpBackend(self.P, self.A, self.q, self.l, self.u, osqp)
        else:
            eq = np.sort(np.concatenate([self.rows[k] for k in self.rows if k.startswith(("init_", "dyn_"))]))
            if daqp.formulation == "condensed":      # the states are what the initial and dynamics rows fix
                states = np.concatenate([self.iv, self.id] + ([self.ir] if follow else []))
                self.qp = DaqpCondensedBackend(self.P, self.A, self.l, self.u, eq, states, daqp)
            elif daqp.formulation == "regularised":
                self.qp = DaqpBackend(self.P, self.A, self.l, self.u, eq, daqp)
            else:
                raise ValueError(f"unknown DAQP formulation {daqp.formulation!r}; 'condensed' or 'regularised'")
        self.x_prev: np.ndarray | None = None
        self.last_solve_time = 0.0
        self.last_iter = 0

    # ------------------------------------------------------------------------------------------------------
    def set_step(self, v0: float, v_lo: np.ndarray, v_hi: np.ndarray, grade: np.ndarray,
                 v_ref: np.ndarray | None = None, d_its0: float = 0.0, d_hard_lo: np.ndarray | None = None,
                 d_s_its: float = INF, ft_prev: float | None = None, d_rel0: float = 0.0, v_p: float = 0.0,
                 v_lin: np.ndarray | None = None, ft_lin: np.ndarray | None = None,
                 safe_margin=0.0) -> None:
        """Write this step's data into q, l, u (in place). Arrays have N entries (k=0..N-1 for inputs/grade, and
        k=1..N for the state bounds v_lo, v_hi, d_hard_lo). ``d_hard_lo`` holds 0 where d_ITS >= 0 is enforced
        and -inf elsewhere. ``v_lin``/``ft_lin`` (N entries, SI) is the linearisation trajectory of the power term.
        ``safe_margin`` (m, scalar or N values for k=1..N, car following) shifts the hard safe-distance row to
        d_rel - h_s v >= d_min + margin: a positive back-off keeps solver-tolerance violations outside d_s, a
        negative value (psi < 0) relaxes it while the speed correction eq. (11) acts.

        What it writes: the initial states; eq. (3a)'s right-hand side ``c_k = c_const - c_grade (c_r cos theta_k +
        sin theta_k)``; the speed bounds (6c); the jerk rows' k = 0 with the previously applied force (8a/b); the
        d_ITS rows (8c, 8d); with a leader the gap's initial value, its dynamics ``dt v_p`` (3c) and the safe distance
        ``d_min + margin`` (7a); the linear cost, power eq. (5) with ``a11 v F ~ a11 (vbar F + Fbar v - vbar Fbar)``
        at the kept linearisation point and tracking eq. (9a) / speed matching (10a). One compiled call
        (:mod:`pedas._qpkernel`, ``Stepper``): the numbers numpy's elementwise operations gave,
        bit for bit (tests/pedas/test_qp_kernel.py keeps that formulation as the reference). Arrays are contiguous
        float64 with N entries, numbers are numbers: another length or dtype is a ValueError, None or a non-number a
        TypeError (arguments the MPC does not use are checked as well)."""
        self._stepper.set(v0, v_lo, v_hi, grade, v_ref, d_its0, d_hard_lo, d_s_its, ft_prev, d_rel0, v_p, v_lin,
                          ft_lin, safe_margin)
        self._v_p = v_p

    @property
    def const(self) -> float:
        """The constant of this step's cost (power offsets, linearisation, tracking), so that 1/2 x'Px + q'x + const
        is eq. (9a) / (10a) of x. Sums of products, not `@`: a BLAS dot product's last bits depend on the kernel."""
        N, w = self.n, self._wx[:self.n]
        const = N * self.pa00
        if not self.power_convex:
            vb, fb_ = self._v_lin, self._fb_lin
            const -= self.pa11 * float(_sum(np.multiply(vb, fb_, out=w)))
            if self.lin_v2:
                const -= self.pa20 * float(_sum(np.multiply(vb, vb, out=w)))
            if self.lin_f2:
                const -= self.pa02 * float(_sum(np.multiply(fb_, fb_, out=w)))
        if not self.follow:
            const += self.w.zeta1 * float(_sum(np.multiply(self._v_ref, self._v_ref, out=w)))
        elif self.w.zeta_v > 0:
            const += self.w.zeta_v * N * self._v_p * self._v_p
        return const

    def objective(self, x: np.ndarray) -> float:
        """The cost eq. (9a) / (10a) of x (QP units) for this step's data (valid until the next :meth:`set_step`):
        1/2 x'Px + q'x + :attr:`const`, sparse products (no BLAS). Not computed per solve: no check needs it."""
        w = self._wx
        px = self._Pfull.product(x)
        return (0.5 * float(_sum(np.multiply(x, px, out=w))) + float(_sum(np.multiply(self.q, x, out=w)))
                + self.const)

    def solve(self) -> MpcPlan:
        """Solve this step's QP with the backend; a plan only from a checked result (status, finite, feasible)."""
        if self.shift_warm_start and self.x_prev is not None and self.qp.y is not None:
            self.qp.warm_start(self.x_prev[self._shift_x], self.qp.y[self._shift_y])
        res = self.qp.solve(self.q, self.l, self.u)
        self.last_solve_time = res.run_time   # s, the solver's own timer
        self.last_iter = res.iterations
        if not res.ok:
            return MpcPlan(res.status, False, *([None] * 8), res.iterations, None)
        self.x_prev = res.x
        return self.unpack(res.x, res.status, res.iterations)

    def reset(self) -> None:
        """Forget the previous solution and start the backend cold (a new drive)."""
        self.x_prev = None
        self.qp.cold_start()

    def residual(self, x: np.ndarray) -> float:
        """Largest violation of l <= A x <= u (QP units)."""
        return residual(self.A, self.l, self.u, x)

    def unpack(self, x: np.ndarray, status: str, iters: int) -> MpcPlan:
        """The plan of a QP solution x (QP units): one product with the unit scale, the plan's arrays are views of
        it (the same numbers as scaling each block)."""
        y = x * self._scale
        return MpcPlan(
            status=status, ok=True, v=y[self._sv], ft=y[self._sft], fb=y[self._sfb], d_its=y[self._sd],
            d_rel=y[self._sr] if self.follow else None, eps1=y[self._se1], eps2=y[self._se2],
            eps3=y[self._se3] if self.follow else None, iterations=iters, x=x)

    def warm_start_from(self, v: np.ndarray, ft: np.ndarray, fb: np.ndarray) -> None:
        """Warm-start the primal variables from another controller's plan (SI), e.g. at a hand-over."""
        x = np.zeros(self.nx) if self.x_prev is None else self.x_prev.copy()
        x[self.iv] = v
        x[self.ift] = ft / KN
        x[self.ifb] = fb / KN
        self.qp.warm_start(x)

    def qp_data(self) -> tuple[sp.csc_matrix, np.ndarray, sp.csc_matrix, np.ndarray, np.ndarray, float]:
        """(P upper triangle, q, A, l, u, constant) of the current step — the exact QP the backend solves (DAQP:
        before its equality rows are folded into the Hessian), infinite bounds as +-inf, for peers."""
        l = np.where(self.l <= -BIG, -np.inf, self.l)
        u = np.where(self.u >= BIG, np.inf, self.u)
        return self.P, self.q.copy(), self.A, l, u, self.const


def vehicle_model(params=None) -> MpcModel:
    """The QP's numbers for a vehicle: linearised aero and traction limit (pedas.vehicle), power map eq. (5)
    (pedas.power), mass and rolling resistance (pedas.params). Defaults to the Nissan Leaf."""
    from pedas.power import power_map
    from pedas.vehicle import linear_model

    p = LEAF if params is None else params
    lm = linear_model(p)
    pm = power_map(p)
    return MpcModel(m_eq=p.m_eq, m_v=p.m_v, c_r=p.c_r, c_aero=lm.c_a, p1=lm.p1, p2=lm.p2, p3=lm.p3, p4=lm.p4,
                    power=pm, F_b_max=p.F_b_max, g=p.g)


def solve_qp_cvxpy(P: sp.spmatrix, q: np.ndarray, A: sp.spmatrix, l: np.ndarray, u: np.ndarray,
                   solver: str = "CLARABEL", tol: float | None = None) -> tuple[str, float, np.ndarray | None]:
    """The same QP (min 1/2 x'Px + q'x, l <= Ax <= u; P given as its upper triangle) built from scratch in cvxpy
    and solved by an independent interior-point solver (Clarabel). Returns (status, objective, x).

    ``tol``: Clarabel's gap and feasibility tolerances (e.g. 1e-10 for the reference of ``bench mpc`` and the
    accuracy tests; default: Clarabel's own, 1e-8). The peer of the MPC solutions in the tests and in
    ``pedas-study bench mpc``.
    """
    import cvxpy as cp

    P = sp.csc_matrix(P)
    Pfull = (P + P.T - sp.diags(P.diagonal())).tocsc()
    A = sp.csr_matrix(A)
    x = cp.Variable(A.shape[1])
    eq = np.isfinite(l) & np.isfinite(u) & (np.abs(u - l) <= 1e-12)
    lo = np.isfinite(l) & ~eq
    hi = np.isfinite(u) & ~eq
    cons = []
    if eq.any():
        cons.append(A[eq] @ x == l[eq])
    if lo.any():
        cons.append(A[lo] @ x >= l[lo])
    if hi.any():
        cons.append(A[hi] @ x <= u[hi])
    obj = cp.Minimize(0.5 * cp.quad_form(x, cp.psd_wrap(Pfull)) + q @ x)
    prob = cp.Problem(obj, cons)
    opts = {} if tol is None else dict(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, tol_ktratio=tol)
    prob.solve(solver=solver, **opts)
    return str(prob.status), float(prob.value) if prob.value is not None else float("nan"), x.value

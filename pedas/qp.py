"""The QP layer of the MPCs: one interface, two backends (OSQP, DAQP), every solution checked before use.

Both backends solve ``min 1/2 x'Px + q'x  s.t.  l <= A x <= u`` with constant ``P`` (upper triangle), ``A`` and
per-step vectors ``q``, ``l``, ``u`` (:class:`pedas.mpc.SparseMpc` keeps them and rewrites them in place).

* :class:`OsqpBackend` — ADMM (OSQP), the design's solver and the cross-check; tolerance ``eps_abs/eps_rel``.
* :class:`DaqpBackend` — a dual active-set method (DAQP), exact up to rounding, hot-started from the previous
  step's working set. DAQP needs a positive-definite Hessian, so the equality rows ``A_eq x = b_eq`` (initial
  states and dynamics, eq. 3a-3c) are folded into the cost, ``H = P + rho A_eq'A_eq``, ``f = q - rho A_eq'b_eq``:
  on the feasible set ``1/2 x'Hx + f'x = 1/2 x'Px + q'x - rho/2 |b_eq|^2``, so the minimiser is the same and the
  equality rows are still imposed exactly. Rows bounding one variable are passed as DAQP's simple bounds, and
  unbounded sides as ``+-bound`` (finite: a hot start on a row whose bound became infinite returned NaN).

Every solve returns a :class:`QpResult` whose ``ok`` is true only if the status is the solver's optimum ("solved";
OSQP's "solved inaccurate" and "maximum iterations reached" are failures), the solution is finite, it satisfies
``l <= A x <= u`` within the backend's residual tolerance (QP units) and it passes a KKT check with the solver's
own multipliers (:class:`_Kkt`): stationarity ``|Hz + f + M'lam|_inf <= KKT_STAT_TOL max(1, |f|_inf)`` and the
duality gap (primal minus dual objective) ``<= KKT_GAP_TOL max(1, |objective|)``. A solve whose data q, l, u are
not finite is refused before the solver sees it (status ``rejected:non-finite data``, solver state untouched), and
an OSQP whose iterate became non-finite is set up again (:meth:`OsqpBackend.rebuild`) and the solve repeated once.
:meth:`pedas.mpc.SparseMpc.objective` evaluates the objective of eq. (9a) / (10a) on demand.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from pedas.params import DaqpSettings, OsqpSettings

try:   # the clip ufunc itself (np.clip adds a Python-level dispatch per call); the same elementwise min/max
    from numpy._core.umath import clip as _clip
except ImportError:   # pragma: no cover - numpy < 2
    _clip = np.clip

BACKENDS = ("daqp", "osqp")

_OSQP_OK = {"solved"}   # only OSQP's optimum: "solved inaccurate" / "maximum iterations reached" are failures
OSQP_RESIDUAL_TOL = 1e-2    # QP units (m/s, m, kN): largest accepted violation of l <= Ax <= u for OSQP
OSQP_INFTY = 1e30           # OSQP's infinity: a bound at or beyond it is no bound (its multiplier: no certificate)
KKT_STAT_TOL = {"osqp": 1e-3, "daqp": 1e-6}   # stationarity, relative to max(1, |f|_inf)
KKT_GAP_TOL = {"osqp": 1e-2, "daqp": 1e-6}    # duality gap, relative to max(1, |objective|)
# DAQP exit flags (https://darnstrom.github.io/daqp/parameters): 1 optimal; the rest are failures
_DAQP_STATUS = {1: "solved", 2: "solved", -1: "primal infeasible", -2: "cycling", -3: "unbounded",
                -4: "maximum iterations reached", -5: "nonconvex", -6: "overdetermined initial active set"}
# DAQP releases whose C structures pedas/_daqp_abi.h declares: with one of them the condensed backend calls DAQP's C
# functions directly (pedas/_qpkernel.c, Kernel.open_daqp / solve); with any other, DAQP's Python interface
DAQP_DIRECT_VERSIONS = ("0.11.0",)


@functools.cache
def _daqp_direct_path() -> str | None:
    """The file of the loaded daqp module if its release is one of :data:`DAQP_DIRECT_VERSIONS`, else None."""
    from importlib.metadata import PackageNotFoundError, version

    import daqp

    try:
        release = version("daqp")
    except PackageNotFoundError:   # pragma: no cover - daqp imported from outside an installed distribution
        return None
    return daqp.__file__ if release in DAQP_DIRECT_VERSIONS else None


@dataclass(slots=True)
class QpResult:
    """One checked solve: status text, ok (status, finiteness and primal feasibility all passed), x (QP units;
    None when not ok), iterations, solver time (s)."""

    status: str
    ok: bool
    x: np.ndarray | None
    iterations: int
    run_time: float


def residual(A: sp.csc_matrix, l: np.ndarray, u: np.ndarray, x: np.ndarray) -> float:
    """Largest violation of l <= A x <= u (QP units). A sparse product: no BLAS, the same bits on every kernel."""
    Ax = A @ x
    return float(max(np.max(l - Ax, initial=0.0), np.max(Ax - u, initial=0.0)))


def _finite_data(*vectors: np.ndarray) -> bool:
    """All entries of the vectors are finite: a NaN or inf anywhere makes a sum of squares NaN or inf (quietly: no
    inf - inf), and the QP's vectors hold a few hundred entries of magnitude <= 1e30, so the sum of squares of
    finite entries (<= 1e63) cannot overflow."""
    total = 0.0
    for vec in vectors:
        total += float(vec @ vec)
    return total < np.inf


def _postcondition(status: str, x: np.ndarray | None, violation: float, tol: float) -> str:
    """The status of a solution the solver calls optimal, after the checks: unchanged if x is finite and its
    ``violation`` of l <= A x <= u (from :class:`_Residual`) is at most ``tol``, else 'rejected:<status>:non-finite'
    or 'rejected:<status>:residual' (not 'infeasible': that word is the solver's own verdict, on which the
    controller's fallback brakes).

    One comparison checks both: a non-finite x makes the violation NaN or +inf (every column of A has a nonzero,
    :class:`_Residual`), and NaN fails ``<=``. The elementwise finiteness test only names the reason of a rejection.
    """
    if violation <= tol:
        return status
    if x is None or not np.isfinite(x).all():
        return f"rejected:{status}:non-finite"
    return f"rejected:{status}:residual"


class CsrProduct:
    """A x for one constant A with a preallocated result vector (scipy's CSR product kernel directly, which skips the
    per-call checks of ``A @ x``; the same loop, the same bits: no BLAS)."""

    def __init__(self, A: sp.spmatrix) -> None:
        self.A = sp.csr_matrix(A)
        self.A.sort_indices()
        self._ax = np.empty(self.A.shape[0])
        try:
            from scipy.sparse._sparsetools import csr_matvec
        except ImportError:   # pragma: no cover - scipy moved its kernels
            csr_matvec = None
        self._kernel = csr_matvec
        self._args = (self.A.shape[0], self.A.shape[1], self.A.indptr, self.A.indices, self.A.data)
        self.product_vector = self._ax   # where :meth:`product` writes (views of it stay valid)

    def product(self, x: np.ndarray) -> np.ndarray:
        """A x into the work vector (valid until the next call)."""
        ax = self._ax
        if self._kernel is None:
            ax[:] = self.A @ x
        else:
            ax.fill(0.0)
            self._kernel(*self._args, x, ax)
        return ax


def _require_every_column(A: sp.spmatrix) -> None:
    """Every variable appears in a row of A (then a non-finite x makes A x, and the residual, non-finite)."""
    if not (abs(sp.csc_matrix(A)).sum(axis=0) > 0).all():
        raise ValueError("a variable of the QP appears in no row of A")


class _Residual:
    """:func:`residual` for one constant A, without the floor at 0: ``max(max(l - Ax), max(Ax - u))`` in one
    reduction over a preallocated ``[l - Ax | Ax - u]`` (which keeps a NaN). A non-finite entry of x makes
    the result NaN or +inf, because every column of A has a nonzero (checked here): the residual check is the
    finiteness check as well."""

    def __init__(self, A: sp.spmatrix) -> None:
        _require_every_column(A)
        self._Ax = CsrProduct(A)
        m = A.shape[0]
        self._t = np.empty(2 * m)
        self._lo, self._hi = self._t[:m], self._t[m:]

    def __call__(self, l: np.ndarray, u: np.ndarray, x: np.ndarray) -> float:
        ax = self._Ax.product(x)
        np.subtract(l, ax, self._lo)
        np.subtract(ax, u, self._hi)
        t = self._t
        return float(t[t.argmax()])   # the maximum (argmax returns the first NaN if there is one), cheaper than max


class _Kkt:
    """The KKT check of a QP ``min 1/2 z'Hz + f'z  s.t.  lo <= M z <= hi`` at a solver's (z, lam), lam > 0 pushing
    against hi, lam < 0 against lo (OSQP's y, DAQP's lambda). The first ``n_identity`` rows of M are the identity
    (DAQP's simple bounds, one per variable), ``M_rest`` the others.

    * stationarity: ``|Hz + f + M'lam|_inf / max(1, |f|_inf)``;
    * duality gap: primal objective ``1/2 z'Hz + f'z`` minus the dual objective of (z, lam),
      ``-1/2 z'Hz - sum_(lam_i > 0) lam_i hi_i - sum_(lam_i < 0) lam_i lo_i``, i.e.
      ``|z'Hz + f'z + lam+'hi + lam-'lo| / max(1, |1/2 z'Hz + f'z|)`` (with stationarity, the complementarity
      ``sum lam_i (b_i - (Mz)_i)`` of the bound b_i that lam_i pushes against).

    ``infinite``: a bound at or beyond it is no bound. With ``drop_infinite`` (OSQP, whose infinity 1e30 times a
    rounding-sized multiplier would swamp the gap) a multiplier on such a side is dropped and the stationarity
    residual shows it; otherwise (DAQP, bounds clipped to +-1e4) it stays and its product with the bound shows in
    the gap. Returns (stationarity, gap), NaN when z or lam is not finite (NaN fails every ``<=``). Dense products
    of small matrices: a check with margins of many orders of magnitude (docs/controller.md), whose last bits do
    not change its verdict.
    """

    def __init__(self, H: sp.spmatrix | np.ndarray, M_rest: sp.spmatrix | np.ndarray, n_identity: int,
                 infinite: float, drop_infinite: bool) -> None:
        dense = lambda a: np.ascontiguousarray(a.toarray() if sp.issparse(a) else a, dtype=float)  # noqa: E731
        self._H = dense(H)
        self._MrT = np.ascontiguousarray(dense(M_rest).T)
        self._n = n_identity
        self._inf, self._drop = infinite, drop_infinite
        self._hz, self._r = np.empty(self._H.shape[0]), np.empty(self._H.shape[0])
        self._b = np.empty(n_identity + self._MrT.shape[1])

    def __call__(self, f: np.ndarray, lo: np.ndarray, hi: np.ndarray, z: np.ndarray, lam: np.ndarray
                 ) -> tuple[float, float]:
        if self._drop:
            lam = np.where(((lam > 0.0) & (hi >= self._inf)) | ((lam < 0.0) & (lo <= -self._inf)), 0.0, lam)
        n, hz, r, b = self._n, self._hz, self._r, self._b
        np.matmul(self._H, z, hz)
        np.matmul(self._MrT, lam[n:], r)
        r += hz
        r += f
        if n:
            r += lam[:n]
        np.abs(r, r)
        # maxima by argmax (0.2 us against 0.9 us for .max(); the first NaN of r is its argmax, so NaN stays NaN)
        stat = float(r[r.argmax()]) / max(1.0, float(f[f.argmax()]), -float(f[f.argmin()]))   # |Hz| ~ |f + M'lam|
        zhz, fz = float(z @ hz), float(f @ z)
        np.copyto(b, lo)
        np.copyto(b, hi, where=lam > 0.0)     # the bound each multiplier pushes against
        gap = abs(zhz + fz + float(lam @ b)) / max(1.0, abs(0.5 * zhz + fz))
        return stat, gap


def _kkt_status(status: str, stat: float, gap: float, stat_tol: float, gap_tol: float) -> str:
    """``status`` if both KKT measures pass, else 'rejected:<status>:stationarity' or 'rejected:<status>:gap'."""
    if not stat <= stat_tol:
        return f"rejected:{status}:stationarity"
    if not gap <= gap_tol:
        return f"rejected:{status}:gap"
    return status


class OsqpBackend:
    """OSQP set up once; :meth:`solve` updates q, l, u (OSQP's vector update, no re-setup) and checks the result.

    Only ``solved`` is accepted, and only if finite, primal feasible within :data:`OSQP_RESIDUAL_TOL` and passing
    the KKT check (:class:`_Kkt` with OSQP's y, tolerances :data:`KKT_STAT_TOL`, :data:`KKT_GAP_TOL`). Non-finite
    data are refused without calling OSQP. If OSQP's iterate (x or y) is not finite after a solve, its state is
    poisoned (every later warm-started solve would start from NaN): OSQP is set up again and the solve repeated once.
    :meth:`cold_start` (a new drive) sets it up again as well.
    """

    name = "osqp"

    def __init__(self, P: sp.csc_matrix, A: sp.csc_matrix, q: np.ndarray, l: np.ndarray, u: np.ndarray,
                 settings: OsqpSettings) -> None:
        kw = settings.as_dict()
        self.shift_warm_start = bool(kw.pop("shift_warm_start"))
        self.settings = kw
        self._residual = _Residual(A)
        self._P, self._A = P, A
        self._kkt = _Kkt(P + P.T - sp.diags(P.diagonal()), A, 0, OSQP_INFTY, drop_infinite=True)
        self.rebuilds = 0
        self._data = (q.copy(), l.copy(), u.copy())   # finite vectors to set up with (each solve updates them)
        self._setup(*self._data)

    def _setup(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> None:
        """A new OSQP solver on (P, A) and these vectors: no iterate, no warm start, rho back to its initial value."""
        self.solver = osqp.OSQP()
        self.solver.setup(P=self._P, q=q, A=self._A, l=l, u=u, **self.settings)
        core = getattr(self.solver, "_solver", None)
        # the extension object behind OSQP.update/solve: same calls without the wrapper's per-call overhead
        self._core = core if core is not None and hasattr(core, "update_data_vec") and hasattr(core, "solution") \
            else None
        self.y: np.ndarray | None = None
        self._used = False

    def rebuild(self) -> None:
        """Set OSQP up again (the poisoned or stale solver is dropped; counted in :attr:`rebuilds`)."""
        self.rebuilds += 1
        self._setup(*self._data)

    def solve(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> QpResult:
        if not _finite_data(q, l, u):
            return QpResult("rejected:non-finite data", False, None, 0, 0.0)
        res, x, y = self._solve(q, l, u)
        if not (_finite_data(x) and _finite_data(y)):   # the iterate is poisoned: a new solver, one more try
            self.rebuild()
            again, x, y = self._solve(q, l, u)
            again.iterations += res.iterations
            again.run_time += res.run_time
            res = again
            if not (_finite_data(x) and _finite_data(y)):
                self.rebuild()
        return res

    def _solve(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> tuple[QpResult, np.ndarray, np.ndarray]:
        """One OSQP solve and its checks: (result, OSQP's x, OSQP's y)."""
        self._used = True
        if self._core is not None:
            core = self._core
            core.update_data_vec(q=q, l=l, u=u)
            core.solve()
            info = core.info
            status, iters, run_time = info.status, int(info.iter), float(info.run_time)
            sol = core.solution
            x, y = sol.x, sol.y
        else:
            self.solver.update(q=q, l=l, u=u)
            res = self.solver.solve(raise_error=False)
            status, iters, run_time = res.info.status, int(res.info.iter), float(res.info.run_time)
            x, y = res.x, res.y
        x = np.full(self._A.shape[1], np.nan) if x is None else x
        y = np.full(self._A.shape[0], np.nan) if y is None else y
        if status in _OSQP_OK:
            status = _postcondition(status, x, self._residual(l, u, x), OSQP_RESIDUAL_TOL)
        if status in _OSQP_OK:
            status = _kkt_status(status, *self._kkt(q, l, u, x, y), KKT_STAT_TOL["osqp"], KKT_GAP_TOL["osqp"])
        if status not in _OSQP_OK:
            return QpResult(status, False, None, iters, run_time), x, y
        self.y = y
        return QpResult(status, True, x, iters, run_time), x, y

    def warm_start(self, x: np.ndarray, y: np.ndarray | None = None) -> None:
        """Start the next solve's ADMM iterates from x (and y)."""
        if y is None:
            self.solver.warm_start(x=x)
        else:
            self.solver.warm_start(x=x, y=y)

    def cold_start(self) -> None:
        """Forget the previous iterate (a new drive, or after a failure the caller does not trust): OSQP is set up
        again if it has solved since its last setup."""
        if self._used:
            self.rebuild()


class _DaqpBase:
    """What both DAQP formulations share: the checked solve, the cold retry after a failure, the hot start.

    A subclass sets ``model`` (a set-up ``daqp.Model``), ``_sense0`` and ``settings``; it has ``_prepare`` (the data
    check and this step's DAQP vectors from q, l, u) and ``_check`` (x in the QP's variables from DAQP's solution, its
    residual and the KKT measures): the base's from ``_fill``, ``_primal``, ``_residual`` and ``_kkt`` in numpy, or
    the condensed backend's compiled kernel. ``_run`` is DAQP's update and solve and the check; the condensed backend
    replaces it with one kernel call that calls DAQP's C functions itself (no ``model`` then).
    After any failed solve the working set is cleared and the solve is repeated once from a cold start (a stale
    working set can make the active-set method fail on a feasible problem); a second failure is reported as such.
    Non-finite data are refused before DAQP sees them (working set untouched). A solution DAQP calls optimal passes
    the residual check and the KKT check (:class:`_Kkt`, or the condensed backend's compiled equivalent, on DAQP's
    own QP in z with DAQP's lambda: ``H``, the constraint rows ``[I; A_general]`` and the clipped bounds, ``+-bound``
    counting as no bound).
    """

    name = "daqp"

    def _setup(self, H: np.ndarray, Ag: np.ndarray) -> None:
        import daqp

        self.model = daqp.Model()
        self.model.setup(np.ascontiguousarray(H), self._f, np.ascontiguousarray(Ag), self._hi, self._lo,
                         self._sense0)
        s = self.model.settings
        s.update(primal_tol=self.settings.primal_tol, iter_limit=self.settings.iter_limit, eps_prox=0.0)
        self.model.settings = s
        self._cold = False

    def _bounds(self, A: sp.csr_matrix, eq_rows: np.ndarray, nx: int) -> tuple[np.ndarray, np.ndarray]:
        """Split the rows of A into DAQP simple bounds (a single coefficient 1: one row per variable) and general
        rows. Returns the indices of the general rows and DAQP's order of the rows, ``perm`` (constraint i is row
        perm[i]; the sentinel A.shape[0] for a variable without a simple bound)."""
        m = A.shape[0]
        self.bound = float(self.settings.bound)
        nnz = np.diff(A.indptr)
        single = (nnz == 1) & (A.data[np.minimum(A.indptr[:-1], A.data.size - 1)] == 1.0)
        # simple bound of variable j: the (only) single-variable row on it, else the sentinel row m (unbounded)
        simple = np.full(nx, m)
        for r in np.flatnonzero(single):
            j = A.indices[A.indptr[r]]
            if simple[j] != m:
                single[r] = False     # a second row on the same variable stays a general row
            else:
                simple[j] = r
        general = np.flatnonzero(~single)
        perm = np.concatenate([simple, general])       # DAQP constraint i <- row perm[i] of [l; -inf]
        is_eq = np.zeros(m + 1, dtype=bool)
        is_eq[eq_rows] = True
        self._sense0 = np.where(is_eq[perm], 5, 0).astype(np.int32)
        nb = perm.size
        self._lohi = np.empty(2 * nb)     # DAQP's [lower | upper] bounds, updated in place each solve
        self._lo, self._hi = self._lohi[:nb], self._lohi[nb:]
        return general, perm

    @staticmethod
    def _gather_index(rows: np.ndarray, m: int) -> np.ndarray:
        """DAQP's bounds are one gather from a work buffer ``[l (m rows) | -inf | u | +inf]``: constraint i takes
        row rows[i] (m: unbounded; the clip to +-bound makes the infinities +-bound). The indices of that gather."""
        return np.concatenate([rows, rows + m + 1]).astype(np.int64)

    def _prepare(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> bool:
        """The data check, then this step's DAQP vectors (``_fill``); False, with nothing written, if q, l or u is
        not finite."""
        if not _finite_data(q, l, u):
            return False
        self._fill(q, l, u)
        return True

    def _check(self, z: np.ndarray, lam: np.ndarray | None, l: np.ndarray, u: np.ndarray
               ) -> tuple[np.ndarray, float, float, float]:
        """(x, its violation of l <= A x <= u, KKT stationarity, KKT gap) of DAQP's (z, lam); the KKT measures are
        NaN without lam (no certificate)."""
        x = self._primal(z)   # a non-finite z gives a non-finite x (each y is one entry of x)
        stat, gap = (float("nan"), float("nan")) if lam is None else self._kkt(self._f, self._lo, self._hi, z, lam)
        return x, self._residual(l, u, x), stat, gap

    def solve(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> QpResult:
        if not self._prepare(q, l, u):
            return QpResult("rejected:non-finite data", False, None, 0, 0.0)
        res = self._solve_checked(l, u)
        if not res.ok:
            self.cold_start()
            again = self._solve_checked(l, u)
            again.iterations += res.iterations
            again.run_time += res.run_time
            res = again
            if not res.ok:
                self.cold_start()
        return res

    def _run(self, cold: bool, l: np.ndarray, u: np.ndarray) -> tuple:
        """DAQP's update (f and the bounds ``_prepare`` wrote; the constraint senses as well when `cold`) and solve,
        then, for an optimal exit, ``_check``: (exit flag, iterations, DAQP's solve time s, x, violation,
        stationarity, gap); for any other exit NaN measures, and x is not used (``_solve_checked`` reads it only
        when the exit is optimal)."""
        if cold:
            self.model.update(f=self._f, bupper=self._hi, blower=self._lo, sense=self._sense0)
        else:
            self.model.update(f=self._f, bupper=self._hi, blower=self._lo)
        z, _, flag, info = self.model.solve()
        x, violation, stat, gap = None, float("nan"), float("nan"), float("nan")
        if _DAQP_STATUS.get(flag) == "solved":
            x, violation, stat, gap = self._check(z, info.get("lam"), l, u)
        return flag, int(info["iterations"]), float(info["solve_time"]), x, violation, stat, gap

    def _solve_checked(self, l: np.ndarray, u: np.ndarray) -> QpResult:
        cold, self._cold = self._cold, False
        flag, iters, run_time, x, violation, stat, gap = self._run(cold, l, u)
        status = _DAQP_STATUS.get(flag) or f"daqp exit {flag}"
        if status == "solved":
            status = _postcondition(status, x, violation, self.settings.residual_tol)
            if status == "solved":
                status = _kkt_status(status, stat, gap, KKT_STAT_TOL["daqp"], KKT_GAP_TOL["daqp"])
        if status != "solved":
            return QpResult(status, False, None, iters, run_time)
        return QpResult(status, True, x, iters, run_time)

    def warm_start(self, x: np.ndarray, y: np.ndarray | None = None) -> None:
        """A primal guess is no working set: start the next solve cold (used at a hand-over between the MPCs)."""
        self.cold_start()

    def cold_start(self) -> None:
        """Clear the working set: the next solve starts from the equality rows only."""
        self._cold = True


class DaqpBackend(_DaqpBase):
    """DAQP on the regularised QP (module docstring): all variables kept, the equality rows folded into the Hessian.

    ``eq_rows``: rows of A that are equalities (l == u always); they stay DAQP equality rows as well.
    """

    def __init__(self, P: sp.csc_matrix, A: sp.csc_matrix, l: np.ndarray, u: np.ndarray, eq_rows: np.ndarray,
                 settings: DaqpSettings) -> None:
        self._residual = _Residual(A)
        self.settings = settings
        nx = A.shape[1]
        rho = float(settings.rho)
        Acsr = sp.csr_matrix(A)
        general, perm = self._bounds(Acsr, eq_rows, nx)
        self._bound_lo, self._bound_hi = np.array(-self.bound), np.array(self.bound)   # 0-d: cheap ufunc operands
        m = Acsr.shape[0]
        self._gather = self._gather_index(perm, m)
        self._src = np.empty(2 * (m + 1))
        self._src_l, self._src_u = self._src[:m], self._src[m + 1:2 * m + 1]
        self._src[m], self._src[2 * m + 1] = -np.inf, np.inf
        Aeq = sp.csr_matrix(Acsr[eq_rows])
        self._eq_rows = np.asarray(eq_rows)
        self._AeqT = CsrProduct(sp.csr_matrix(Aeq.T) * rho)   # its product kernel computes rho A_eq' b_eq
        self.P = (P + P.T - sp.diags(P.diagonal())).tocsc()
        self.H = (self.P + rho * (Aeq.T @ Aeq)).toarray()
        self._beq = np.empty(self._eq_rows.size)
        self._f = np.empty(nx)
        self._fill(np.zeros(nx), l, u)
        Ag = Acsr[general].toarray()
        self._setup(self.H, Ag)
        self._kkt = _Kkt(self.H, Ag, nx, self.bound, drop_infinite=False)

    def _fill(self, q: np.ndarray, l: np.ndarray, u: np.ndarray) -> None:
        """f = q - rho A_eq' b_eq and the DAQP bounds (simple bounds first, then general rows), clipped to +-bound."""
        self._src_l[...] = l
        self._src_u[...] = u
        self._src.take(self._gather, None, self._lohi)
        _clip(self._lohi, self._bound_lo, self._bound_hi, self._lohi)
        l.take(self._eq_rows, None, self._beq)
        np.subtract(q, self._AeqT.product(self._beq), self._f)

    def _primal(self, z: np.ndarray) -> np.ndarray:
        return z


class DaqpCondensedBackend(_DaqpBase):
    """DAQP on the condensed QP: the states are eliminated through the equality rows, DAQP sees the inputs only.

    ``basic``: the variables the equality rows ``eq_rows`` determine (as many as rows; for the MPCs the states v,
    d_ITS, d_rel). Taken in the right order each row fixes one more basic variable (initial state, then the
    dynamics step by step), so ``x_B = T b_eq + S x_N`` by substitution and every x that meets the equality rows is
    ``x = E b_eq + Z y`` with ``y = x_N``. The QP in y has the positive-definite Hessian ``Z'PZ`` (no
    regularisation), ``f = Z'q + Z'PE b_eq`` and the rows ``l - K b_eq <= A_in Z y <= u - K b_eq`` with
    ``K = A_in E``. ``Z'PZ``, ``Z'PE``, ``A_in Z`` and ``K`` are constant: built once, by elementwise substitution
    and sparse products (no BLAS: the same bits on every kernel); per step only b_eq, q and the bounds change. The
    solution is mapped back to x and checked against the full ``l <= A x <= u``, equality rows included.

    The per-step work around DAQP's calls is compiled (:mod:`pedas._qpkernel`, ``Kernel``): ``fill`` (data check, f,
    the bounds) and ``check`` (x, its residual, the KKT measures), each one call. They compute f, the bounds and x as
    scipy's CSR product and numpy's elementwise operations did, bit for bit (tests/pedas/test_qp_kernel.py).
    """

    def __init__(self, P: sp.csc_matrix, A: sp.csc_matrix, l: np.ndarray, u: np.ndarray, eq_rows: np.ndarray,
                 basic: np.ndarray, settings: DaqpSettings) -> None:
        _require_every_column(A)   # the residual check is the finiteness check as well
        self.settings = settings
        Acsr = sp.csr_matrix(A)
        m, nx = Acsr.shape
        eq_rows, basic = np.asarray(eq_rows), np.asarray(basic)
        free = np.setdiff1d(np.arange(nx), basic)
        ineq = np.setdiff1d(np.arange(m), eq_rows)
        Aeq = sp.csr_matrix(Acsr[eq_rows])
        T, S = _substitute(sp.csr_matrix(Aeq[:, basic]), sp.csr_matrix(Aeq[:, free]))
        Zd = np.zeros((nx, free.size))
        Zd[basic] = S
        Zd[free, np.arange(free.size)] = 1.0
        Ed = np.zeros((nx, eq_rows.size))
        Ed[basic] = T
        Z, E = sp.csr_matrix(Zd), sp.csr_matrix(Ed)
        self.P = sp.csr_matrix(P + P.T - sp.diags(P.diagonal()))
        ZT = sp.csr_matrix(Z.T)
        H = (ZT @ self.P @ Z).toarray()
        self.H = 0.5 * (H + H.T)            # exactly symmetric (the two triangles may differ in the last bit)
        A_in = sp.csr_matrix(Acsr[ineq] @ Z)
        A_in.eliminate_zeros()
        A_in.sort_indices()
        nf, neq = free.size, eq_rows.size
        general, perm = self._bounds(A_in, np.zeros(0, dtype=int), nf)
        # DAQP constraint i is inequality row perm[i] (ineq.size: none), i.e. row rows[i] of l, u (m: none)
        gather = self._gather_index(np.append(ineq, m)[perm], m)
        # K's rows in DAQP's order (an empty row for none), so that the shift of the gathered bounds needs no gather
        K = sp.vstack([Acsr[ineq] @ E, sp.csr_matrix((1, neq))], format="csr")[perm]
        # the per-step products, each set in one block-diagonal product (every row is the row of its block, summed in
        # the same order: the same bits as separate products):
        # [Z'q | Z'PE b_eq | K b_eq] from [q | b_eq], and [E b_eq | Z y] from [b_eq | y]
        self.vec = _block_diag_csr(ZT, sp.vstack([ZT @ self.P @ E, K], format="csr"))
        self.map = _block_diag_csr(E, Z)
        self._eq_rows, self._gather = eq_rows.astype(np.int64), gather
        Hs, self.G = sp.csr_matrix(self.H), sp.csr_matrix(A_in[general])   # G: DAQP's general rows
        Hs.sort_indices()
        self.G.sort_indices()
        self._f = np.empty(nf)
        # fill and the checks in one compiled kernel each (pedas/_qpkernel.c): ~5 us a step against ~40 us in numpy
        from pedas._qpkernel import Kernel

        csr = lambda c: (c.indptr.astype(np.int64), c.indices.astype(np.int64), c.data, *c.shape)  # noqa: E731
        self.kernel = Kernel(nx, m, self.bound, self._eq_rows, gather, csr(self.vec), csr(self.map),
                             csr(Acsr if Acsr.has_sorted_indices else Acsr.sorted_indices()), csr(Hs), csr(self.G),
                             self._f, self._lohi)
        self._prepare = self.kernel.fill   # fill(q, l, u) -> bool: the data check, f and the bounds
        self._nx = nx
        if not self._prepare(np.zeros(nx), l, u):
            raise ValueError("the QP's initial bounds are not finite")
        path = _daqp_direct_path()
        self.direct = path is not None   # DAQP's C functions called by the kernel (else its Python interface)
        if path is None:   # a DAQP build whose C layout the kernel does not know: its Python interface
            self._setup(self.H, self.G.toarray())
        else:   # DAQP's update, solve and the check in one call, without the Python interface's ~7-10 us a step
            self.kernel.open_daqp(path, self.H, self.G.toarray(), self._sense0.astype(np.int64),
                                  float(settings.primal_tol), int(settings.iter_limit))
            self._run = self._run_direct
            self._cold = False

    def _run_direct(self, cold: bool, l: np.ndarray, u: np.ndarray) -> tuple:
        """``_run`` as one kernel call: DAQP's own C update and solve, called as ``daqp.Model`` calls them (the same
        exit flag, iterations, solution and multipliers), then the kernel's check."""
        x = np.empty(self._nx)
        flag, iters, run_time, violation, stat, gap = self.kernel.solve(cold, x)
        return flag, iters, run_time, x, violation, stat, gap   # x is written (and read) for an optimal exit only

    def _check(self, z: np.ndarray, lam: np.ndarray | None, l: np.ndarray, u: np.ndarray
               ) -> tuple[np.ndarray, float, float, float]:
        """x = E b_eq + Z y (a new array: the plan keeps it), its violation of the full l <= A x <= u (the kernel's
        copy of this step's l, u) and the KKT measures, in one kernel call."""
        x = np.empty(self._nx)
        violation, stat, gap = self.kernel.check(z, lam, x)
        return x, violation, stat, gap


def _block_diag_csr(*blocks: sp.spmatrix) -> sp.csr_matrix:
    """The block-diagonal CSR matrix of ``blocks``, built from their sorted CSR arrays (every stored entry kept, each
    row's entries in the order of its block's row)."""
    mats = [sp.csr_matrix(b) for b in blocks]
    for b in mats:
        b.sort_indices()
    indptr, indices, data = [np.zeros(1, dtype=np.int64)], [], []
    r0 = c0 = nnz = 0
    for b in mats:
        indptr.append(b.indptr[1:].astype(np.int64) + nnz)
        indices.append(b.indices.astype(np.int64) + c0)
        data.append(b.data)
        nnz += b.nnz
        r0 += b.shape[0]
        c0 += b.shape[1]
    return sp.csr_matrix((np.concatenate(data), np.concatenate(indices), np.concatenate(indptr)), shape=(r0, c0))


def _substitute(AB: sp.csr_matrix, AN: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """``T = AB^-1`` and ``S = -AB^-1 AN`` for a square AB that is triangular up to a permutation (taken in some
    order, each row has exactly one column not yet solved). Forward substitution on the rows of ``[I | -AN]``,
    elementwise operations only. Raises ValueError for any other AB."""
    n = AB.shape[0]
    rhs = np.hstack([np.eye(n), -AN.toarray()])
    X = np.zeros_like(rhs)             # row c: basic variable c as a linear function of [b_eq | x_N]
    known = np.zeros(n, dtype=bool)
    pending = list(range(n))
    while pending:
        rest = []
        for r in pending:
            cols = AB.indices[AB.indptr[r]:AB.indptr[r + 1]]
            vals = AB.data[AB.indptr[r]:AB.indptr[r + 1]]
            unknown = [k for k, c in enumerate(cols) if not known[c]]
            if len(unknown) != 1:
                rest.append(r)
                continue
            k = unknown[0]
            row = rhs[r].copy()
            for c, a in zip(cols, vals):
                if known[c]:
                    row -= a * X[c]
            X[cols[k]] = row / vals[k]
            known[cols[k]] = True
        if len(rest) == len(pending):
            raise ValueError("the equality rows are not triangular in the basic variables")
        pending = rest
    return X[:, :n], X[:, n:]

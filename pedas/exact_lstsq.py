"""Least squares in exact rational arithmetic: the same bits on every machine.

Floating-point least squares (LAPACK's ``lstsq``, an SLSQP run) depends on the BLAS/LAPACK kernel numpy picks at
run time: dot products are summed in a kernel-specific order, so the last bits differ between kernels, and an
optimiser whose result is not checked may even stop at its start point. The vehicle model's fits are tiny (two or
six unknowns over a few thousand points), so they are solved here exactly: every float is a dyadic rational, the
normal equations A^T A x = A^T y are formed in integers and solved with :class:`fractions.Fraction`, and each
unknown is rounded once, to the nearest float. Same data, same result, on any machine and any kernel.

- :func:`lstsq` — the ordinary least-squares solution (A must have full column rank).
- :func:`line_below` — the least-squares line a v + b through points (v_k, f_k) subject to a v_k + b <= f_k for
  every k (a two-variable convex QP), found by enumerating active sets in floating point and *proven* optimal in
  exact arithmetic by its KKT conditions (primal feasibility at every point, non-negative multipliers).
"""
from __future__ import annotations

import operator
from fractions import Fraction
from itertools import combinations

import numpy as np


class FitError(ArithmeticError):
    """An exact fit is not defined (rank-deficient data) or no candidate passed its optimality check."""


def _scaled_ints(col: np.ndarray) -> tuple[list[int], int]:
    """The column as integers n_k with col_k = n_k / den (den a power of two), exactly."""
    ratios = [float(x).as_integer_ratio() for x in col]
    den = max(d for _, d in ratios)
    return [n * (den // d) for n, d in ratios], den


def _dot(a: tuple[list[int], int], b: tuple[list[int], int]) -> Fraction:
    return Fraction(sum(map(operator.mul, a[0], b[0])), a[1] * b[1])


def _solve(M: list[list[Fraction]], r: list[Fraction]) -> list[Fraction]:
    """Gauss-Jordan elimination with exact pivots; FitError if M is singular."""
    n = len(r)
    M = [row[:] + [r[i]] for i, row in enumerate(M)]
    for c in range(n):
        piv = next((i for i in range(c, n) if M[i][c] != 0), None)
        if piv is None:
            raise FitError("the least-squares problem is rank-deficient")
        M[c], M[piv] = M[piv], M[c]
        inv = 1 / M[c][c]
        M[c] = [x * inv for x in M[c]]
        for i in range(n):
            if i != c and M[i][c] != 0:
                f = M[i][c]
                M[i] = [x - f * y for x, y in zip(M[i], M[c])]
    return [M[i][n] for i in range(n)]


def lstsq_fractions(A: np.ndarray, y: np.ndarray) -> list[Fraction]:
    """The exact least-squares solution of A x ~ y as fractions (A: m x n float array, full column rank)."""
    A = np.asarray(A, dtype=float)
    y = np.asarray(y, dtype=float)
    if A.ndim != 2 or y.shape != (A.shape[0],) or not (np.isfinite(A).all() and np.isfinite(y).all()):
        raise ValueError("lstsq: A must be a finite m x n array and y a finite vector of length m")
    cols = [_scaled_ints(A[:, j]) for j in range(A.shape[1])]
    yi = _scaled_ints(y)
    n = len(cols)
    M = [[_dot(cols[i], cols[j]) for j in range(n)] for i in range(n)]
    return _solve(M, [_dot(cols[i], yi) for i in range(n)])


def lstsq(A: np.ndarray, y: np.ndarray) -> tuple[float, ...]:
    """The least-squares solution of A x ~ y, each entry the float nearest to the exact solution."""
    return tuple(float(x) for x in lstsq_fractions(A, y))


def _kkt_line(v: list[Fraction], f: list[Fraction], active: tuple[int, ...]):
    """Exact (a, b) and multipliers of min sum (a v_k + b - f_k)^2 with the constraints in `active` as equalities.

    Lagrangian: sum (a v_k + b - f_k)^2 + sum_i lam_i (a v_i + b - f_i); returns None if the system is singular.
    """
    svv = sum(x * x for x in v)
    sv = sum(v)
    m = len(v)
    svf = sum(x * y for x, y in zip(v, f))
    sf = sum(f)
    # stationarity: 2 [svv sv; sv m] z + sum lam_i [v_i; 1] = 2 [svf; sf]; primal: v_i a + b = f_i (i active)
    k = len(active)
    M = [[2 * svv, 2 * sv] + [v[i] for i in active],
         [2 * sv, Fraction(2 * m)] + [Fraction(1)] * k]
    r = [2 * svf, 2 * sf]
    for i in active:
        M.append([v[i], Fraction(1)] + [Fraction(0)] * k)
        r.append(f[i])
    try:
        sol = _solve(M, r)
    except FitError:
        return None
    return sol[0], sol[1], sol[2:]


def line_below(v: np.ndarray, f: np.ndarray, max_checks: int = 50) -> tuple[float, float]:
    """(a, b) of the least-squares line a v + b <= f_k at every point (v_k, f_k), proven optimal exactly.

    Candidates (no constraint active, one, or two: the line through two points) are ranked by their
    floating-point objective among the float-feasible ones; the best ones are then checked in exact arithmetic
    (feasible at every point, multipliers >= 0: the KKT conditions of this convex QP, which has a unique
    minimiser when the v_k are not all equal). The first that passes is the optimum; rounding it to floats can put
    the line above a point by an ulp, so the intercept is lowered by that excess. FitError if none passes.
    """
    v = np.asarray(v, dtype=float)
    f = np.asarray(f, dtype=float)
    if v.ndim != 1 or v.shape != f.shape or v.size < 2 or np.ptp(v) == 0:
        raise ValueError("line_below: need at least two distinct speeds")
    vq = [Fraction(x) for x in v.tolist()]
    fq = [Fraction(x) for x in f.tolist()]
    n = v.size
    cands: list[tuple[int, ...]] = [()] + [(i,) for i in range(n)]
    cands += list(combinations(range(n), 2))
    # float screening, elementwise only (no BLAS): the line of each candidate, its feasibility and objective
    sums = (float(np.sum(v * v)), float(np.sum(v)), float(np.sum(v * f)), float(np.sum(f)))
    scored = []
    for act in cands:
        ab = _float_line(v, f, act, sums)
        if ab is None:
            continue
        res = ab[0] * v + ab[1] - f
        if np.max(res) > 1e-6 * max(1.0, float(np.max(np.abs(f)))):
            continue
        scored.append((float(np.sum(res * res)), act))
    scored.sort(key=lambda t: (t[0], t[1]))
    for _, act in scored[:max_checks]:
        sol = _kkt_line(vq, fq, act)
        if sol is None:
            continue
        a, b, lam = sol
        if any(x < 0 for x in lam) or any(a * x + b > y for x, y in zip(vq, fq)):
            continue
        af, bf = float(a), float(b)
        excess = float(np.max(af * v + bf - f))
        return af, (bf - excess if excess > 0 else bf)
    raise FitError("no candidate line passed the exact KKT check")


def _float_line(v, f, act, sums):
    """Float (a, b) of a candidate active set (screening only)."""
    svv, sv, svf, sf = sums
    m = float(v.size)
    if len(act) == 2:
        i, j = act
        if v[i] == v[j]:
            return None
        a = (f[j] - f[i]) / (v[j] - v[i])
        return a, f[i] - a * v[i]
    if len(act) == 1:
        i = act[0]
        # b = f_i - a v_i; minimise over a: sum (a (v_k - v_i) - (f_k - f_i))^2
        dv = v - v[i]
        den = float(np.sum(dv * dv))
        if den == 0:
            return None
        a = float(np.sum(dv * (f - f[i]))) / den
        return a, f[i] - a * v[i]
    det = svv * m - sv * sv
    return (svf * m - sv * sf) / det, (svv * sf - sv * svf) / det

"""Many bounded scalar minimisations run in lockstep, so that each round's trial points of all of them are evaluated in
one vectorised call (e.g. the polychoric correlations of every item pair, :func:`analysis.survey.ordinal.polychoric`).

Each search is Brent's bounded method exactly as ``scipy.optimize.minimize_scalar(method="bounded")`` performs it
(golden-section steps and parabolic interpolation, Forsythe, Malcolm & Moler 1977): the same trial points, the same
arithmetic, the same stopping rule (|x - midpoint| <= 2 tol - (b - a)/2 with tol = sqrt(2.2e-16) |x| + xatol/3) and
the same result, so a search here returns bit for bit what scipy returns for that function alone
(tests/analysis/test_lockstep.py compares them).
"""
from __future__ import annotations

from dataclasses import dataclass
from math import sqrt

import numpy as np


@dataclass(frozen=True)
class BoundedResult:
    """x: the minimiser found; fun: f(x); nfev: evaluations; success: converged within maxiter and no NaN;
    message: scipy's message of the same outcome."""

    x: float
    fun: float
    nfev: int
    success: bool
    message: str


def bounded_search(bounds: tuple[float, float], xatol: float = 1e-5, maxiter: int = 500):
    """Brent's bounded search as a generator: it yields each trial point x and is sent f(x); it returns (as
    StopIteration.value) the :class:`BoundedResult`. The steps are those of scipy's ``_minimize_scalar_bounded``."""
    x1, x2 = bounds
    if not (np.isfinite(x1) and np.isfinite(x2)) or x1 > x2:
        raise ValueError(f"bounds must be finite with lower <= upper, not {bounds}")
    maxfun = maxiter
    flag = 0
    sqrt_eps = sqrt(2.2e-16)
    golden_mean = 0.5 * (3.0 - sqrt(5.0))
    a, b = x1, x2
    fulc = a + golden_mean * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    x = xf
    fx = yield x
    num = 1
    fu = np.inf
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while np.abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = 1
        if np.abs(e) > tol1:  # parabolic fit through the three best points
            golden = 0
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = np.abs(q)
            r = e
            e = rat
            if (np.abs(p) < np.abs(0.5 * q * r)) and (p > q * (a - xf)) and (p < q * (b - xf)):
                rat = (p + 0.0) / q
                x = xf + rat
                if ((x - a) < tol2) or ((b - x) < tol2):
                    si = np.sign(xm - xf) + ((xm - xf) == 0)
                    rat = tol1 * si
            else:
                golden = 1
        if golden:
            e = a - xf if xf >= xm else b - xf
            rat = golden_mean * e
        si = np.sign(rat) + (rat == 0)
        x = xf + si * np.maximum(np.abs(rat), tol1)
        fu = yield x
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if (fu <= fnfc) or (nfc == xf):
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif (fu <= ffulc) or (fulc == xf) or (fulc == nfc):
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxfun:
            flag = 1
            break
    if np.isnan(xf) or np.isnan(fx) or np.isnan(fu):
        flag = 2
    message = {0: "Solution found.", 1: "Maximum number of function calls reached.",
               2: "NaN result encountered."}[flag]
    return BoundedResult(x=float(xf), fun=float(fx), nfev=num, success=flag == 0, message=message)


def minimize_bounded_many(evaluate, n: int, bounds: tuple[float, float], xatol: float = 1e-5,
                          maxiter: int = 500) -> list[BoundedResult]:
    """Minimise n scalar functions on `bounds`, each by :func:`bounded_search`, in lockstep.

    ``evaluate(indices, xs)`` returns f_i(x) for each search index i in `indices` at its trial point in `xs` (a
    float array), all in one call. Returns the n results in index order."""
    searches = [bounded_search(bounds, xatol, maxiter) for _ in range(n)]
    pending = {i: next(s) for i, s in enumerate(searches)}
    results: list[BoundedResult | None] = [None] * n
    while pending:
        idx = list(pending)
        values = evaluate(idx, np.array([pending[i] for i in idx], dtype=float))
        for i, v in zip(idx, values):
            try:
                pending[i] = searches[i].send(v)
            except StopIteration as stop:
                results[i] = stop.value
                del pending[i]
    return results

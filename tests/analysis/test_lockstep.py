"""Brent's bounded search run in lockstep (analysis.survey.lockstep) against scipy's own minimize_scalar(bounded):
the same trial points and results bit for bit; and the polychoric correlations and their asymptotic variances of
every item pair computed together equal those of each pair on its own (polychoric_pair, _avar)."""
from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
import pytest
from scipy import optimize

from analysis.survey import ordinal as O
from analysis.survey.lockstep import bounded_search, minimize_bounded_many


def _bits(x) -> np.ndarray:
    return np.asarray(x, dtype=float).view(np.int64)


FUNCTIONS = [lambda x: (x - 0.3) ** 2, lambda x: np.cos(3 * x) + 0.1 * x, lambda x: abs(x + 0.5),
             lambda x: -np.exp(-(x - 0.999) ** 2), lambda x: np.sin(40 * x), lambda x: 1.0]


@pytest.mark.parametrize("k", range(len(FUNCTIONS)))
def test_search_takes_scipys_steps(k):
    f = FUNCTIONS[k]
    seen = []

    def logged(x):
        seen.append(float(x))
        return float(f(x))

    ref = optimize.minimize_scalar(logged, bounds=(-1.0, 1.0), method="bounded",
                                   options={"xatol": 1e-10, "maxiter": 500})
    mine, search, x = [], bounded_search((-1.0, 1.0), xatol=1e-10, maxiter=500), None
    x = next(search)
    try:
        while True:
            mine.append(float(x))
            x = search.send(float(f(x)))
    except StopIteration as stop:
        res = stop.value
    assert mine == seen
    assert _bits(res.x) == _bits(float(ref.x)) and res.fun == float(ref.fun)
    assert (res.nfev, res.success, res.message) == (ref.nfev, ref.success, ref.message)


def test_iteration_limit_is_scipys():
    ref = optimize.minimize_scalar(lambda x: np.sin(40 * x), bounds=(-1, 1), method="bounded",
                                   options={"xatol": 1e-14, "maxiter": 5})
    res = minimize_bounded_many(lambda idx, xs: [float(np.sin(40 * x)) for x in xs], 1, (-1, 1), 1e-14, 5)[0]
    assert (res.success, res.message, res.nfev) == (False, ref.message, 5) and ref.success is False
    assert res.x == float(ref.x)


def test_many_searches_in_lockstep_equal_each_alone():
    centres = np.linspace(-0.9, 0.9, 7)
    calls = []

    def evaluate(idx, xs):
        calls.append(len(idx))
        return [float((x - centres[i]) ** 2 + 0.01 * np.cos(9 * x)) for i, x in zip(idx, xs)]

    many = minimize_bounded_many(evaluate, len(centres), (-1.0, 1.0), xatol=1e-10)
    for i, c in enumerate(centres):
        alone = optimize.minimize_scalar(lambda x: float((x - c) ** 2 + 0.01 * np.cos(9 * x)), bounds=(-1.0, 1.0),
                                         method="bounded", options={"xatol": 1e-10})
        assert many[i].x == float(alone.x) and many[i].nfev == alone.nfev
    # all searches share the rounds: the first round evaluates all of them in one call
    assert calls[0] == len(centres) and len(calls) == max(r.nfev for r in many)


def _answers(seed: int, n: int = 50, p: int = 6) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, 1)) @ np.full((1, p), 0.7) + rng.normal(scale=0.7, size=(n, p))
    cuts = np.sort(rng.normal(size=(p, 4)), axis=1)
    x = np.column_stack([np.searchsorted(cuts[j], z[:, j]) + 1 for j in range(p)]).astype(float)
    x[:, -1] = 6 - x[:, 0]   # a negative correlation: the other branch of the bivariate normal
    return pd.DataFrame(x, columns=[f"i{j}" for j in range(p)])


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_polychoric_together_equals_each_pair_alone(seed):
    data = _answers(seed)
    items = list(data.columns)
    poly = O.polychoric(data, items)
    for a, b in combinations(items, 2):
        ca, ta = O.codes(data[a])
        cb, tb = O.codes(data[b])
        r = O.polychoric_pair(ca, cb, ta, tb)
        assert _bits(poly.R.loc[a, b]) == _bits(r)
        assert _bits(poly.avar.loc[a, b]) == _bits(O._avar(ca, cb, ta, tb, r))

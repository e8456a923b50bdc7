"""The controller's compiled prediction stage (pedas/_qpkernel.c, Horizon) against the numpy formulation it replaces:
numpy's interp and the predicted vectors bit for bit (they reach the MPCs), and bad input refused."""
from __future__ import annotations

import numpy as np
import pytest

from pedas._qpkernel import Horizon, interp

try:   # the same interp the numpy formulation called
    from numpy._core.multiarray import interp as np_interp
except ImportError:   # pragma: no cover - numpy < 2
    from numpy.core.multiarray import interp as np_interp

N = 20


def _same(a, b) -> bool:
    return np.asarray(a, float).tobytes() == np.asarray(b, float).tobytes()


@pytest.mark.parametrize("size", [1, 2, 3, 4, 5, 9, 40, 700])
def test_interp_is_numpys(size):
    """On random sorted tables (repeated points among them) and keys below, inside, on and above the grid, NaN
    included, every value is numpy's, bit for bit."""
    rng = np.random.default_rng(size)
    for trial in range(40):
        xp = np.sort(rng.uniform(-50.0, 500.0, size))
        if size > 3 and trial % 3 == 0:
            xp[size // 2] = xp[size // 2 - 1]                     # a repeated grid point
        fp = rng.normal(0.0, 10.0, size)
        if trial % 5 == 1:
            fp[rng.integers(0, size)] = np.inf                    # an infinite value: numpy's NaN fix-ups
        keys = np.concatenate([rng.uniform(-100.0, 600.0, 30), xp[rng.integers(0, size, 5)],
                               [xp[0], xp[-1], np.nextafter(xp[-1], np.inf), np.nan, -0.0]])
        for x in (keys, np.sort(keys[:-3]), np.sort(keys[:-3])[::-1].copy()):
            out = np.empty_like(x)
            interp(x, xp, fp, out)
            assert _same(out, np_interp(x, xp, fp, None, None)), (size, trial)


def _route_tables(rng):
    """A random route grid and profiles; some speeds are 0.0 or -0.0 (a stop: numpy's maximum and minimum return
    the second of two equal zeros, which decides the sign of a zero)."""
    xs = np.cumsum(rng.uniform(0.5, 5.0, 600))
    dp_s = np.cumsum(rng.uniform(1.0, 8.0, 300))
    tables = (xs, rng.normal(0.0, 0.03, xs.size), rng.uniform(5.0, 30.0, xs.size), rng.uniform(5.0, 30.0, xs.size),
              rng.uniform(0.0, 12.0, xs.size), rng.choice([13.9, 22.2, 27.8], xs.size), dp_s,
              rng.uniform(0.0, 30.0, dp_s.size))
    for t in (tables[3], tables[4], tables[7]):
        t[rng.random(t.size) < 0.1] = 0.0
        t[rng.random(t.size) < 0.1] = -0.0
    return tables


def _numpy_predict(tables, dt, s, v, prev_v, prev_ft):
    """PedasController._predict as numpy computed it."""
    xs, grade, vmax, venv, _, limit, dp_s, dp_v = tables
    if prev_v is not None:
        v_lin = np.concatenate([[v], prev_v[2:]])
        ft_lin = np.concatenate([prev_ft[1:], [prev_ft[-1]]])
    else:
        v_lin, ft_lin = np.full(N, v), np.zeros(N)
    s_pred = np.add.accumulate(np.maximum(v_lin, np.array(0.0)))
    s_pred = np.add(np.multiply(s_pred, np.array(dt)), s)
    s_grade = np.concatenate([[s], s_pred[:-1]])
    return (v_lin, ft_lin, s_pred, s_grade, np_interp(s_grade, xs, grade, None, None),
            np_interp(s_pred, xs, vmax, None, None), np_interp(s_pred, dp_s, dp_v, None, None),
            np_interp(s_pred, xs, venv, None, None), float(np_interp(s, xs, limit, None, None)))


def test_predict_is_the_numpy_formulation():
    """v_lin, ft_lin, s_pred, s_grade, grade, v_max, v_DP, v_env and the limit, bit for bit, with and without a
    previous plan, for speeds and plans with zeros, negatives (a plan's -0.0 or a rounding below zero) and the route's
    ends."""
    rng = np.random.default_rng(3)
    tables = _route_tables(rng)
    outs = tuple(np.empty(N) for _ in range(15))
    dt = 0.2
    h = _horizon(tables, dt, outs)
    for trial in range(300):
        s = float(rng.choice([rng.uniform(-10.0, tables[0][-1] + 50.0), tables[0][rng.integers(0, 600)], 0.0]))
        v = float(rng.choice([rng.uniform(0.0, 35.0), 0.0]))
        prev_v = prev_ft = None
        if trial % 4:
            prev_v = rng.uniform(-0.5, 35.0, N + 1)
            prev_v[rng.random(N + 1) < 0.2] = -0.0
            prev_ft = rng.normal(0.0, 2000.0, N)
        limit = h.predict(s, v, prev_v, prev_ft)
        want = _numpy_predict(tables, dt, s, v, prev_v, prev_ft)
        for got, ref in zip((*outs[:8], limit), want):
            assert _same(got, ref), trial


def _horizon(tables, dt, outs, ramps=None):
    k = np.arange(1, N + 1)
    return Horizon(tables, dt, ramps or (dt * k, 3.0 * dt * k, 0.5 * k), (2.0, 100.0, 1.5), outs)


def test_horizon_refuses_bad_input():
    rng = np.random.default_rng(1)
    tables = _route_tables(rng)
    outs = tuple(np.empty(N) for _ in range(15))
    h = _horizon(tables, 0.2, outs)
    with pytest.raises(TypeError):
        h.predict(0.0, 1.0, np.zeros(N + 1), None)              # both or neither
    with pytest.raises(ValueError, match="prev_v"):
        h.predict(0.0, 1.0, np.zeros(N), np.zeros(N))
    with pytest.raises(ValueError, match="prev_ft"):
        h.predict(0.0, 1.0, np.zeros(N + 1), np.zeros(N + 1))
    with pytest.raises(TypeError):
        h.predict(None, 1.0, None, None)
    with pytest.raises(TypeError):
        h.reference(0.0, 1.0, "fast", None, False, True)
    with pytest.raises(TypeError):
        h.reference(0.0, 1.0, None, None, False)
    with pytest.raises(ValueError, match="frac"):
        h.line_min(0.0, 10.0, np.zeros(65))
    with pytest.raises(ValueError, match="grade"):
        _horizon((tables[0], tables[1][:-1], *tables[2:]), 0.2, outs)
    with pytest.raises(ValueError, match="dp_v"):
        _horizon((*tables[:7], tables[7][:-1]), 0.2, outs)
    with pytest.raises(TypeError):
        _horizon(tables[:-1], 0.2, outs)
    with pytest.raises(TypeError):
        _horizon(tables, 0.2, outs[:-1])
    with pytest.raises(ValueError, match="v_dp"):
        _horizon(tables, 0.2, (*outs[:6], np.empty(N - 1), *outs[7:]))
    with pytest.raises(ValueError, match="depart"):
        _horizon(tables, 0.2, outs, ramps=(np.zeros(N - 1), np.zeros(N), np.zeros(N)))
    with pytest.raises(ValueError, match="recover"):
        _horizon(tables, 0.2, outs, ramps=(np.zeros(N), np.zeros(N), np.zeros(N + 1)))
    with pytest.raises(TypeError):
        _horizon(tables, 0.2, outs, ramps=(np.zeros(N), np.zeros(N)))
    with pytest.raises(TypeError):
        h.follow(1.0)
    with pytest.raises(TypeError):
        h.follow(1.0, None)
    with pytest.raises(ValueError, match="v_lin"):
        _horizon(tables, 0.2, tuple(np.empty(0) for _ in outs))
    with pytest.raises(RuntimeError, match="not set up"):
        Horizon.__new__(Horizon).predict(0.0, 1.0, None, None)
    with pytest.raises(RuntimeError, match="set up once"):
        h.__init__(tables, 0.2, (np.zeros(N), np.zeros(N), np.zeros(N)), (2.0, 100.0, 1.5), outs)
    with pytest.raises(ValueError, match="out"):
        interp(np.zeros(3), tables[0], tables[1], np.zeros(2))
    with pytest.raises(ValueError, match="at least one"):
        interp(np.zeros(3), np.zeros(0), np.zeros(0), np.zeros(3))


def _numpy_reference(tables, ramps, two_a_stop, cruise_look, pred, s, v, v_gw, target, stop_expected, free):
    """PedasController._reference's vectors as numpy computed them: (mode, max v_hi, v_ref, v_lo, v_hi, reach)."""
    from bisect import bisect_left

    xs, vmin, dp_s, dp_v = tables[0], tables[4], tables[6], tables[7]
    depart, reach_ramp = ramps[:2]
    _, _, s_pred, _, _, vmax, vdp, venv = pred
    if v_gw is not None:
        v_ref, mode = np.minimum(venv, v_gw), "green_wave"
    else:
        j0, j1 = bisect_left(dp_s.tolist(), s), bisect_left(dp_s.tolist(), s + cruise_look)
        cruise = float(np.maximum.reduce(dp_v[j0:max(j1, j0 + 1)])) if j0 < dp_v.size else float(dp_v[-1])
        v_ref = np.minimum(np.add(depart, v), cruise)
        v_ref = np.minimum(np.maximum(vdp, v_ref), venv)
        mode = "dp"
    if target is not None:
        env = np.sqrt(np.multiply(np.maximum(np.subtract(target, np.subtract(s_pred, s)), np.array(0.0)),
                                  np.array(two_a_stop)))
        if env[-1] < v_ref[-1] or stop_expected:
            mode = "stop"
        v_ref = np.minimum(v_ref, env)
    reach = np.subtract(v, reach_ramp)
    v_hi = np.maximum(vmax, reach)
    if mode in ("green_wave", "dp") and free:
        v_lo = np.minimum(np_interp(s_pred, xs, vmin, None, None), v)
    else:
        v_lo = np.zeros_like(v_hi)
    v_lo = np.minimum(v_lo, v_hi)
    return ("green_wave", "dp", "stop").index(mode), float(v_hi[v_hi.argmax()]), v_ref, v_lo, v_hi, reach


def _numpy_follow(ramps, safe_backoff, pred, v_hi, reach, v, psi):
    """PedasController._solve's car-following bounds as numpy computed them: (v_hi_cf, margin)."""
    depart, _, recover = ramps
    vmax, vdp = pred[5], pred[6]
    v_hi_cf = np.minimum(np.add(depart, v), vmax)
    v_hi_cf = np.maximum(vdp, v_hi_cf)
    v_hi_cf = np.maximum(v_hi_cf, reach)
    v_hi_cf = np.minimum(v_hi, v_hi_cf)
    return v_hi_cf, np.minimum(np.array(safe_backoff), np.add(recover, psi))


def test_reference_and_the_green_wave_lookups_are_the_numpy_formulation():
    """v_ref, v_lo, v_hi, reach, the mode and the largest v_hi after predict, bit for bit, in every branch (green-wave
    band or the DP reference, a stop target or none, a stop expected, a leader or none, positions before, on and
    beyond the DP reference); the green wave's lowest v_max up to the line, v_min at s and the car-following bounds
    (follow: v_hi and the safe margin, psi of either sign) as well."""
    rng = np.random.default_rng(7)
    tables = _route_tables(rng)
    dt, two_a_stop, cruise_look = 0.2, 2.0, 100.0
    k = np.arange(1, N + 1)
    ramps = (1.0 * dt * k, 3.0 * dt * k, 0.5 * k)
    safe_backoff = 1.5
    outs = tuple(np.empty(N) for _ in range(15))
    h = Horizon(tables, dt, ramps, (two_a_stop, cruise_look, safe_backoff), outs)
    frac8 = np.linspace(0.0, 1.0, 8)
    modes = set()
    for trial in range(400):
        s = float(rng.choice([rng.uniform(-10.0, tables[6][-1] + 50.0), tables[6][rng.integers(0, 300)], 0.0]))
        v = float(rng.choice([rng.uniform(0.0, 35.0), 0.0, -0.0]))
        prev_v = rng.uniform(-0.5, 35.0, N + 1) if trial % 3 else None
        prev_ft = rng.normal(0.0, 2000.0, N) if prev_v is not None else None
        h.predict(s, v, prev_v, prev_ft)
        pred = tuple(o.copy() for o in outs[:8])
        v_gw = float(rng.choice([rng.uniform(3.0, 20.0), 0.0, -0.0])) if rng.random() < 0.4 else None
        target = float(rng.uniform(-20.0, 150.0)) if rng.random() < 0.5 else None
        stop_expected, free = bool(rng.random() < 0.2), bool(rng.random() < 0.7)
        got = h.reference(s, v, v_gw, target, stop_expected, free)
        want = _numpy_reference(tables, ramps, two_a_stop, cruise_look, pred, s, v, v_gw, target, stop_expected,
                                free)
        assert got[0] == want[0] and _same(got[1], want[1]), trial
        for out, ref in zip(outs[8:12], want[2:]):
            assert _same(out, ref), trial
        modes.add(got[0])
        psi = float(rng.choice([rng.uniform(-10.0, 30.0), 0.0, -0.0]))
        h.follow(v, psi)
        for out, ref in zip(outs[13:], _numpy_follow(ramps, safe_backoff, pred, outs[10], outs[11], v, psi)):
            assert _same(out, ref), trial
        d = max(float(rng.uniform(-5.0, 150.0)), 0.0)
        line = np_interp(s + d * frac8, tables[0], tables[2], None, None)
        assert _same(h.line_min(s, d, frac8), line[line.argmin()])
        assert _same(h.v_min(s), np_interp(s, tables[0], tables[4], None, None))
    assert modes == {0, 1, 2}

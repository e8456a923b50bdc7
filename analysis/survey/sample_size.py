"""A priori power for the next study: the power and required N of each hypothesis, analytic (Cohen's f² with the
noncentral F) or by Monte-Carlo simulation, and the RMSEA-based N of the measurement model (docs/power.md).

* **Effect size** (:func:`effect_sizes`). The population is multivariate normal over the composites (and numeric
  covariate columns) of the study's regressions, with the mean and covariance of the study's data
  (:func:`population_from_data`) or of a user-given covariance matrix (:func:`population_from_csv`). A hypothesis
  reads its predictor in its model at its step (k predictors); its effect is Cohen's
  ``f² = R²_change / (1 − R²_full)`` with ``u = 1``: R²_full of the step's regression in the population, R²_change
  what the hypothesis's predictor adds to the other k − 1.
* **Analytic** (:func:`analytic_power`): the power of the F test of that one coefficient,
  ``1 − F_ncf(F_crit; u, v, λ = f² (u + v + 1))`` with ``v = N − k − 1`` (:func:`f2_power`: Cohen 1988, the formula of
  G*Power and R's ``pwr.f2.test``), and the smallest integer N whose power reaches the target, by bisection on N
  (:func:`analytic_n`; the power rises with N).
* **Simulation** (:func:`simulated_power`, :func:`mc_power`): for a sample size N, ``reps`` samples of N are drawn at
  once (one numpy array per block of samples); each hypothesis's regression step is fitted by OLS in every sample
  together (:func:`batch_t`) and judged by the study's own rule (β of the expected sign and two-sided p < α, as
  :func:`analysis.survey.hypotheses.supported`); power = the share of samples that support it. The required N is
  found by doubling N until the power reaches the target, then by bisection between the last two sizes.
  The samples of size N come from ``SeedSequence(seed, spawn_key=(N,))``: every hypothesis sees the same samples at
  the same N, however the hypotheses are split among worker processes.
* **RMSEA** (:func:`rmsea_power`, :func:`rmsea_n`): MacCallum, Browne & Sugawara (1996). With ``df`` degrees of
  freedom and noncentrality ``lambda = (N - 1) df eps^2``, the test of close fit (H0 eps = .05 against eps = .08)
  rejects above the ``1 - alpha`` quantile of the noncentral chi-square under H0; the test of not-close fit (H0 eps
  = .05 against eps = .01) below its ``alpha`` quantile.

Sampling multiplies standard normals by the Cholesky factor column by column with elementwise ufuncs, the
regressions use elementwise sums and an elementwise Cholesky factorisation over the sample axis (no BLAS or LAPACK
call), and the population's Cholesky factor is computed in plain Python, so the draws and verdicts are the same bits
under every BLAS kernel.
"""
from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd
from scipy import stats

from analysis.survey.mvn import cholesky
from analysis.survey.regression import ModelSpec

METHODS = ("analytic", "simulation")
POWER_COLUMNS = ["hypothesis", "path", "sign", "n", "reps", "supported", "power", "ci_low", "ci_high", "method"]
N_COLUMNS = ["hypothesis", "path", "sign", "target_power", "alpha", "n_required", "power_at_n", "method", "k",
             "beta", "f2", "n_current", "power_current", "note"]
#: standard normals drawn per block of samples (8 bytes each): bounds the memory of a simulation at large N
BLOCK = 2_000_000
#: the note of a directional hypothesis whose population effect has the other sign (or is zero)
WRONG_SIGN = "the population effect has the other sign: the hypothesis is not supported at any N"


@dataclass(frozen=True)
class Population:
    """A multivariate normal population: variable `names`, `mean` (len k) and covariance `cov` (k x k); `n` the
    number of complete rows it was fitted to (None for a given matrix)."""

    names: tuple[str, ...]
    mean: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]
    n: int | None = None

    def frame(self) -> pd.DataFrame:
        """The covariance matrix as a DataFrame (names as index and columns)."""
        return pd.DataFrame(self.cov, index=list(self.names), columns=list(self.names))


@dataclass(frozen=True)
class Target:
    """One hypothesis: the regression (dv on `predictors`) of its step, the coefficient it reads."""

    hypothesis: str
    dv: str
    predictors: tuple[str, ...]
    predictor: str
    sign: str

    @property
    def path(self) -> str:
        return f"{self.predictor} -> {self.dv}"

    @property
    def order(self) -> tuple[str, ...]:
        """The step's predictors with the hypothesis's predictor last (the order the effect size and the batched
        regression read it in)."""
        return tuple(p for p in self.predictors if p != self.predictor) + (self.predictor,)


@dataclass(frozen=True)
class Effect:
    """The population effect of one target: k predictors, the standardized coefficient `beta` of its predictor,
    R² of the step with and without it, and Cohen's f² = (r2_full − r2_reduced)/(1 − r2_full)."""

    k: int
    beta: float
    r2_full: float
    r2_reduced: float
    f2: float

    def hopeless(self, sign: str) -> bool:
        """True when the study's rule cannot be met for large N: a directional hypothesis whose population
        coefficient has the other sign or is zero, or a zero effect."""
        return self.f2 == 0.0 or (sign == ">" and not self.beta > 0) or (sign == "<" and not self.beta < 0)


def population_from_data(data: pd.DataFrame) -> Population:
    """The normal population with the mean and covariance (n - 1 denominator) of the complete rows of `data`."""
    d = data.dropna()
    if len(d) < 3:
        raise ValueError(f"a population needs at least 3 complete rows, not {len(d)}")
    x = d.to_numpy(dtype=float)
    centred = x - x.mean(axis=0)
    k = x.shape[1]
    # elementwise sums instead of a BLAS product keep the bits independent of the kernel
    cov = [[math.fsum(centred[:, i] * centred[:, j]) / (len(d) - 1) for j in range(k)] for i in range(k)]
    return Population(tuple(d.columns), tuple(float(m) for m in x.mean(axis=0)), tuple(tuple(r) for r in cov),
                      n=len(d))


def population_from_csv(path: str | Path) -> Population:
    """A user-given population: a square CSV covariance (or correlation) matrix with the variable names as header
    and first column; means are 0 (they do not change a regression coefficient's test)."""
    try:
        df = pd.read_csv(path, index_col=0)
    except FileNotFoundError:
        raise FileNotFoundError(f"population file not found: {path}") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a CSV matrix ({' '.join(str(exc).split())})") from None
    names = [str(c) for c in df.columns]
    if [str(i) for i in df.index] != names:
        raise ValueError(f"{path}: the first column must name the same variables as the header, in the same order")
    try:
        m = df.to_numpy(dtype=float)
    except ValueError:
        raise ValueError(f"{path}: the matrix has non-numeric cells") from None
    if not np.isfinite(m).all():
        raise ValueError(f"{path}: the matrix has empty or non-numeric cells")
    if not np.array_equal(m, m.T):
        raise ValueError(f"{path}: the matrix is not symmetric")
    pop = Population(tuple(names), tuple(0.0 for _ in names), tuple(tuple(float(v) for v in r) for r in m))
    try:
        cholesky(pop.cov)
    except ValueError:
        raise ValueError(f"{path}: the matrix is not positive definite") from None
    return pop


def targets(study_models: Sequence[ModelSpec], hypotheses, names: Sequence[str]) -> list[Target]:
    """The hypotheses as :class:`Target` s: each reads its predictor in its model at its step (covariate columns
    expanded as in the analysis's model specs). ValueError if a variable is not in the population."""
    specs = {m.name: m for m in study_models}
    out = []
    for h in hypotheses:
        m = specs.get(h.model)
        if m is None:
            raise ValueError(f"{h.hypothesis}: model {h.model} is not among the study's regressions")
        preds = tuple(m.predictors(h.step))
        missing = [v for v in (m.dv, *preds) if v not in names]
        if missing:
            raise ValueError(f"{h.hypothesis}: the population has no variable {missing[0]!r} "
                             f"(it has {', '.join(names)})")
        out.append(Target(h.hypothesis, m.dv, preds, h.predictor, h.sign))
    return out


def effect(pop: Population, t: Target) -> Effect:
    """The population effect of `t` (:class:`Effect`), from the covariance matrix in plain Python.

    With the step's predictors ordered so that the hypothesis's predictor is last, S = L L' (Cholesky) and
    L w = c (c = cov(predictors, dv)): R²_full = w'w / var(dv), R²_reduced the same sum without the last term
    (the leading block of L is the Cholesky factor of the other predictors), f² = w_k² / (var(dv) − w'w), and the
    coefficient b_k = w_k / L_kk, standardized beta = b_k sd(x_k) / sd(dv).

    Examples
    --------
    One predictor with a standardized coefficient of .3: R² = .09, f² = .09 / .91.

    >>> from analysis.survey.sample_size import Population, Target, effect
    >>> pop = Population(("X", "Y"), (0.0, 0.0), ((1.0, 0.3), (0.3, 1.0)))
    >>> e = effect(pop, Target("H1", "Y", ("X",), "X", ">"))
    >>> round(e.f2, 6), round(e.beta, 6), e.k
    (0.098901, 0.3, 1)
    """
    col = {name: i for i, name in enumerate(pop.names)}
    order = t.order
    k = len(order)
    s = [[pop.cov[col[a]][col[b]] for b in order] for a in order]
    c = [pop.cov[col[a]][col[t.dv]] for a in order]
    vy = pop.cov[col[t.dv]][col[t.dv]]
    if not vy > 0:
        raise ValueError(f"{t.hypothesis}: {t.dv} has no variance in the population")
    try:
        L = cholesky(s)
    except ValueError:
        raise ValueError(f"{t.hypothesis}: the predictors {', '.join(order)} of {t.dv} are collinear in the "
                         f"population (their covariance matrix is not positive definite)") from None
    w: list[float] = []
    for i in range(k):
        w.append((c[i] - math.fsum(L[i][j] * w[j] for j in range(i))) / L[i][i])
    sq = [v * v for v in w]
    resid = vy - math.fsum(sq)
    if not resid > 1e-12 * vy:
        raise ValueError(f"{t.hypothesis}: the predictors explain all of {t.dv} in the population (R² = 1)")
    b = w[-1] / L[-1][-1]
    return Effect(k=k, beta=b * math.sqrt(s[-1][-1] / vy), r2_full=math.fsum(sq) / vy,
                  r2_reduced=math.fsum(sq[:-1]) / vy, f2=sq[-1] / resid)


def effect_sizes(pop: Population, tgts: Sequence[Target]) -> pd.DataFrame:
    """One row per target: hypothesis, path, sign, k, beta, r2_full, r2_reduced, f2 (:func:`effect`)."""
    rows = []
    for t in tgts:
        e = effect(pop, t)
        rows.append({"hypothesis": t.hypothesis, "path": t.path, "sign": t.sign, "k": e.k, "beta": e.beta,
                     "r2_full": e.r2_full, "r2_reduced": e.r2_reduced, "f2": e.f2})
    return pd.DataFrame(rows, columns=["hypothesis", "path", "sign", "k", "beta", "r2_full", "r2_reduced", "f2"])


def f2_power(f2: float, n: int, u: int = 1, k: int = 1, alpha: float = 0.05) -> float:
    """Exact power of the F test of `u` coefficients in a regression with `k` predictors and N = `n`: effect size
    f^2 = R^2_change / (1 - R^2_full), v = n - k - 1, lambda = f^2 (u + v + 1) (Cohen 1988; R pwr.f2.test).

    Examples
    --------
    One standardized beta of .3 (f^2 = .09 / .91) with N = 50:

    >>> from analysis.survey.sample_size import f2_power
    >>> round(f2_power(0.09 / 0.91, 50), 4)
    0.5868
    """
    v = n - k - 1
    if v < 1:
        raise ValueError(f"n = {n} leaves no residual degrees of freedom for {k} predictor(s)")
    crit = stats.f.ppf(1 - alpha, u, v)
    return float(stats.ncf.sf(crit, u, v, f2 * (u + v + 1)))


def analytic_n(f2: float, k: int = 1, power: float = 0.8, alpha: float = 0.05, n_max: int = 10_000) -> int | None:
    """The smallest integer N (>= k + 2) with :func:`f2_power` (u = 1) >= `power`, by bisection on N (the power
    rises with N); None when N = `n_max` does not reach it.

    Examples
    --------
    One standardized beta of .3: R's ``pwr.f2.test(u = 1, f2 = .09/.91, power = .8)`` gives v = 79.33, so
    N = ceiling(v) + k + 1 = 82.

    >>> from analysis.survey.sample_size import analytic_n
    >>> analytic_n(0.09 / 0.91)
    82
    """
    if not 0 < power < 1:
        raise ValueError(f"power must be between 0 and 1, not {power}")
    lo, hi = k + 2, int(n_max)
    if hi < lo:
        raise ValueError(f"n_max = {n_max} is below the smallest N of a regression with {k} predictor(s) ({lo})")
    if not f2 > 0 or f2_power(f2, hi, 1, k, alpha) < power:
        return None
    if f2_power(f2, lo, 1, k, alpha) >= power:
        return lo
    while hi - lo > 1:  # power(lo) < power <= power(hi)
        mid = (lo + hi) // 2
        if f2_power(f2, mid, 1, k, alpha) >= power:
            hi = mid
        else:
            lo = mid
    return hi


def _note(e: Effect, sign: str, reached: bool, target: float, n_max: int) -> str:
    if e.hopeless(sign):
        return "no effect in the population" if e.f2 == 0.0 else WRONG_SIGN
    return "" if reached else f"power {target} is not reached below N = {n_max}"


def _check_n(n: int, k: int, what: str) -> int:
    if n < k + 2:
        raise ValueError(f"{what} {n} is too small for a regression with {k} predictor(s) (at least {k + 2})")
    return int(n)


def _n_frame(rows: list[dict]) -> pd.DataFrame:
    out = pd.DataFrame(rows, columns=N_COLUMNS)
    for c in ("n_required", "n_current", "k"):
        out[c] = out[c].astype("Int64")
    return out


def _power_frame(rows: list[dict]) -> pd.DataFrame:
    out = pd.DataFrame(rows, columns=POWER_COLUMNS)
    for c in ("n", "reps", "supported"):
        out[c] = out[c].astype("Int64")
    return out.sort_values(["hypothesis", "n"], kind="stable", key=_hypothesis_key).reset_index(drop=True)


def _hypothesis_key(s: pd.Series) -> pd.Series:
    # keep the model file's order of the hypotheses (the rows come in it), sort by n within each
    return s.map({h: i for i, h in enumerate(dict.fromkeys(s))}) if s.name == "hypothesis" else s


def analytic_power(pop: Population, tgts: Sequence[Target], *, target: float = 0.8, alpha: float = 0.05,
                   n_current: int | None = None, sizes: Sequence[int] = (), n_max: int = 10_000
                   ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Analytic power of every target (module docstring): (power per N, columns POWER_COLUMNS; the required N per
    target, columns N_COLUMNS).

    The power table holds the power at each of `sizes` (the curve), at `n_current` (default: the N the population
    was fitted to, ``pop.n``) and at the required N. A directional hypothesis whose population effect has the
    other sign has no required N and no power (the F test's power counts significant effects of either sign; the
    study's rule supports only the expected one), and its note says so.
    """
    if not 0 < target < 1:
        raise ValueError(f"the target power must be between 0 and 1, not {target}")
    n_current = pop.n if n_current is None else n_current
    power_rows, n_rows = [], []
    for t in tgts:
        e = effect(pop, t)
        base = {"hypothesis": t.hypothesis, "path": t.path, "sign": t.sign}
        ns = {_check_n(n, e.k, "sample size") for n in sizes}
        cur = _check_n(n_current, e.k, "the current N") if n_current is not None else None
        hopeless = e.hopeless(t.sign)
        n_req = None if hopeless else analytic_n(e.f2, e.k, target, alpha, n_max)

        def pw(n: int) -> float:
            return float("nan") if hopeless else f2_power(e.f2, n, 1, e.k, alpha)

        n_rows.append({**base, "target_power": target, "alpha": alpha, "n_required": n_req,
                       "power_at_n": pw(n_req) if n_req is not None else float("nan"), "method": "analytic",
                       "k": e.k, "beta": e.beta, "f2": e.f2, "n_current": cur,
                       "power_current": pw(cur) if cur is not None else float("nan"),
                       "note": _note(e, t.sign, n_req is not None, target, n_max)})
        ns |= {n for n in (cur, n_req) if n is not None}
        for n in sorted(ns):
            power_rows.append({**base, "n": n, "reps": None, "supported": None, "power": pw(n),
                               "ci_low": float("nan"), "ci_high": float("nan"), "method": "analytic"})
    return _power_frame(power_rows), _n_frame(n_rows)


def batch_t(y: np.ndarray, xs: Sequence[np.ndarray]) -> tuple[np.ndarray, int]:
    """t statistic of the last predictor of the OLS regression (with intercept) of y on xs, in many samples at once.

    `y` and each of `xs` are (samples, N) arrays. Cross-products of the centred columns, an elementwise Cholesky
    factorisation of the predictors' cross-product matrix S = L L' and L w = c over the sample axis give
    SSE = s_yy − w'w and t_k = w_k / sqrt(SSE / df) (b_k = w_k / L_kk, Var(b_k) = σ² / L_kk²), df = N − k − 1;
    the same t as :func:`analysis.survey.regression.ols`. A sample whose predictors are collinear, or which the
    predictors fit exactly, gets NaN. Returns (t, df).
    """
    k = len(xs)
    n = y.shape[1]
    df = n - k - 1
    if df < 1:
        raise ValueError(f"N = {n} leaves no residual degrees of freedom for {k} predictor(s)")
    yc = y - y.mean(axis=1, keepdims=True)
    xc = [x - x.mean(axis=1, keepdims=True) for x in xs]
    c = [(x * yc).sum(axis=1) for x in xc]
    syy = (yc * yc).sum(axis=1)
    ok = np.ones(y.shape[0], dtype=bool)
    L: list[list[np.ndarray]] = [[] for _ in range(k)]
    for i in range(k):
        for j in range(i + 1):
            s = (xc[i] * xc[j]).sum(axis=1) - sum((L[i][m] * L[j][m] for m in range(j)), np.zeros(len(ok)))
            if i == j:
                ok &= s > 1e-12 * (xc[i] * xc[i]).sum(axis=1)
                L[i].append(np.sqrt(np.where(ok, s, 1.0)))
            else:
                L[i].append(s / L[j][j])
    w: list[np.ndarray] = []
    for i in range(k):
        w.append((c[i] - sum((L[i][j] * w[j] for j in range(i)), np.zeros(len(ok)))) / L[i][i])
    sse = syy - sum((v * v for v in w), np.zeros(len(ok)))
    ok &= sse > 1e-12 * syy
    t = w[-1] / np.sqrt(np.where(ok, sse, 1.0) / df)
    return np.where(ok, t, np.nan), df


def _supported(t: np.ndarray, df: int, sign: str, alpha: float) -> np.ndarray:
    """The rule of analysis.survey.hypotheses.supported for arrays of t (NaN: not supported)."""
    p = 2.0 * stats.t.sf(np.abs(t), df)
    significant = p < alpha
    if sign == ">":
        return significant & (t > 0)
    if sign == "<":
        return significant & (t < 0)
    return significant


def _counts(pop: Population, tgts: Sequence[Target], n: int, reps: int, seed: int, alpha: float) -> list[int]:
    """Supported counts per target among `reps` samples of size n from SeedSequence(seed, spawn_key=(n,)), drawn
    in blocks of whole samples (the block size depends on n and the number of variables only)."""
    L = cholesky(pop.cov)
    col = {name: i for i, name in enumerate(pop.names)}
    kv = len(pop.names)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(n),)))
    block = max(1, BLOCK // (n * kv))
    hits = [0] * len(tgts)
    done = 0
    while done < reps:
        r = min(block, reps - done)
        z = rng.standard_normal((r, n, kv))
        cache: dict[int, np.ndarray] = {}

        def var(i: int) -> np.ndarray:
            # x_i = mean_i + sum_j L_ij z_j, elementwise (no BLAS product)
            if i not in cache:
                x = np.full((r, n), float(pop.mean[i]))
                for j in range(i + 1):
                    x += z[:, :, j] * L[i][j]
                cache[i] = x
            return cache[i]

        for t_i, t in enumerate(tgts):
            tt, df = batch_t(var(col[t.dv]), [var(col[p]) for p in t.order])
            hits[t_i] += int(_supported(tt, df, t.sign, alpha).sum())
        done += r
    return hits


def _mc_row(t: Target, n: int, k: int, reps: int) -> dict:
    lo, hi = stats.binomtest(int(k), reps).proportion_ci(0.95, method="exact")
    return {"hypothesis": t.hypothesis, "path": t.path, "sign": t.sign, "n": int(n), "reps": reps,
            "supported": int(k), "power": int(k) / reps, "ci_low": lo, "ci_high": hi, "method": "simulation"}


def _check_mc(reps: int, workers: int) -> None:
    if reps < 1:
        raise ValueError(f"reps must be >= 1, not {reps}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, not {workers}")


def _map(fn, jobs: list, workers: int, progress: bool, desc: str) -> list:
    """fn over jobs, in `workers` local processes when > 1; results in the order of `jobs`."""
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="job", desc=desc)
    out = []
    if workers == 1 or len(jobs) == 1:
        for job in jobs:
            out.append(fn(job))
            if bar is not None:
                bar.update()
    else:
        with ProcessPoolExecutor(max_workers=min(workers, len(jobs))) as ex:
            for res in ex.map(fn, jobs):
                out.append(res)
                if bar is not None:
                    bar.update()
    if bar is not None:
        bar.close()
    return out


def _counts_job(job: tuple) -> list[int]:
    return _counts(*job)


def mc_power(pop: Population, tgts: Sequence[Target], sizes: Sequence[int], *, reps: int = 1000, alpha: float = 0.05,
             seed: int = 20240101, workers: int = 1, progress: bool = False) -> pd.DataFrame:
    """Monte-Carlo power of each target at each sample size (columns POWER_COLUMNS; ci = Clopper-Pearson 95 %).

    The same seed gives the same table for any number of `workers` (local processes, one size each)."""
    _check_mc(reps, workers)
    need = max(len(t.predictors) for t in tgts) + 2
    for n in sizes:
        if n < need:
            raise ValueError(f"sample size {n} is too small for the regressions (at least {need})")
    counts = _map(_counts_job, [(pop, tuple(tgts), int(n), reps, seed, alpha) for n in sizes], workers, progress,
                  "power")
    return _power_frame([_mc_row(t, n, k, reps) for n, c in zip(sizes, counts) for t, k in zip(tgts, c)])


def _search(job: tuple) -> tuple[list[dict], dict]:
    """One target's simulation (simulated_power): its power rows and its required-N row."""
    pop, t, target, reps, alpha, seed, n_current, sizes, n_max = job
    e = effect(pop, t)
    seen: dict[int, int] = {}

    def power(n: int) -> float:
        if n not in seen:
            seen[n] = _counts(pop, [t], n, reps, seed, alpha)[0]
        return seen[n] / reps

    n_req = None
    if not e.hopeless(t.sign):
        # double N until the power reaches the target, then bisect between the last two sizes
        lo, hi = None, e.k + 2
        while power(hi) < target and hi < n_max:
            lo, hi = hi, min(2 * hi, n_max)
        if power(hi) >= target:
            if lo is not None:
                while hi - lo > 1:  # power(lo) < target <= power(hi)
                    mid = (lo + hi) // 2
                    if power(mid) >= target:
                        hi = mid
                    else:
                        lo = mid
            n_req = hi
    for n in (*sizes, *([n_current] if n_current is not None else [])):
        power(n)
    row = {"hypothesis": t.hypothesis, "path": t.path, "sign": t.sign, "target_power": target, "alpha": alpha,
           "n_required": n_req, "power_at_n": power(n_req) if n_req is not None else float("nan"),
           "method": "simulation", "k": e.k, "beta": e.beta, "f2": e.f2, "n_current": n_current,
           "power_current": power(n_current) if n_current is not None else float("nan"),
           "note": _note(e, t.sign, n_req is not None, target, n_max)}
    return [_mc_row(t, n, seen[n], reps) for n in sorted(seen)], row


def simulated_power(pop: Population, tgts: Sequence[Target], *, target: float = 0.8, reps: int = 1000,
                    alpha: float = 0.05, seed: int = 20240101, n_current: int | None = None,
                    sizes: Sequence[int] = (), n_max: int = 10_000, workers: int = 1, progress: bool = False
                    ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Monte-Carlo power and required N of every target (module docstring): (power at every N simulated, columns
    POWER_COLUMNS; the required N per target, columns N_COLUMNS).

    Per target, N is doubled from k + 2 until the simulated power reaches `target` (at most `n_max`), then bisected
    between the last two sizes: the required N is the smallest N of that search whose power reaches the target (the
    simulated power is not exactly monotone in N; a size that falls short by chance after a larger one reached it
    is not searched for). The power is also simulated at `sizes` and at `n_current` (default ``pop.n``). A
    directional hypothesis whose population effect has the other sign is not searched (its power falls to 0 as N
    grows). The same seed gives the same tables for any number of `workers` (local processes, one target each).
    """
    if not 0 < target < 1:
        raise ValueError(f"the target power must be between 0 and 1, not {target}")
    _check_mc(reps, workers)
    n_current = pop.n if n_current is None else n_current
    for t in tgts:
        k = len(t.predictors)
        for n in sizes:
            _check_n(n, k, "sample size")
        if n_current is not None:
            _check_n(n_current, k, "the current N")
        if n_max < k + 2:
            raise ValueError(f"n_max = {n_max} is below the smallest N of a regression with {k} predictor(s)")
        effect(pop, t)  # a degenerate population fails before any simulation
    jobs = [(pop, t, target, reps, alpha, seed, n_current, tuple(int(n) for n in sizes), int(n_max)) for t in tgts]
    res = _map(_search, jobs, workers, progress, "power")
    return _power_frame([r for rows, _ in res for r in rows]), _n_frame([row for _, row in res])


def required_n(power: pd.DataFrame, target: float, alpha: float) -> pd.DataFrame:
    """Per hypothesis of a power curve (mc_power), the smallest N whose power reaches `target` and stays there
    for every larger N of the curve (NaN when none does). Columns hypothesis, path, sign, target_power, alpha,
    n_required, power_at_n."""
    rows = []
    for (h, path, sign), g in power.groupby(["hypothesis", "path", "sign"], sort=False):
        g = g.sort_values("n")
        ok = (g["power"] >= target).to_numpy()
        n_req, p_at = float("nan"), float("nan")
        for i in range(len(g)):
            if ok[i:].all():
                n_req, p_at = int(g["n"].iloc[i]), float(g["power"].iloc[i])
                break
        rows.append({"hypothesis": h, "path": path, "sign": sign, "target_power": target, "alpha": alpha,
                     "n_required": n_req, "power_at_n": p_at})
    return pd.DataFrame(rows, columns=N_COLUMNS[:7])


def _ncx2_sf(x: float, df: int, nc: float) -> float:
    return float(stats.chi2.sf(x, df) if nc == 0 else stats.ncx2.sf(x, df, nc))


def _ncx2_ppf(q: float, df: int, nc: float) -> float:
    return float(stats.chi2.ppf(q, df) if nc == 0 else stats.ncx2.ppf(q, df, nc))


def rmsea_power(n: int, df: int, eps0: float = 0.05, eps_a: float = 0.08, alpha: float = 0.05) -> float:
    """Power of the RMSEA test of H0 eps = eps0 against eps = eps_a with N = n (MacCallum et al. 1996): close fit
    when eps_a > eps0 (reject above the 1 - alpha quantile), not-close fit when eps_a < eps0 (reject below alpha).

    Examples
    --------
    >>> from analysis.survey.sample_size import rmsea_power
    >>> round(rmsea_power(200, 50), 4)
    0.7691
    """
    if df < 1:
        raise ValueError(f"the model has {df} degrees of freedom; RMSEA power needs df >= 1")
    if n < 2:
        raise ValueError(f"n must be >= 2, not {n}")
    nc0, nca = (n - 1) * df * eps0 ** 2, (n - 1) * df * eps_a ** 2
    if eps_a > eps0:
        return _ncx2_sf(_ncx2_ppf(1 - alpha, df, nc0), df, nca)
    if eps_a < eps0:
        return 1.0 - _ncx2_sf(_ncx2_ppf(alpha, df, nc0), df, nca)
    raise ValueError("eps0 and eps_a must differ")


def rmsea_n(df: int, power: float = 0.8, eps0: float = 0.05, eps_a: float = 0.08, alpha: float = 0.05,
            n_max: int = 100_000) -> int:
    """Smallest N with :func:`rmsea_power` >= `power` (power rises with N; bisection on integers)."""
    if not 0 < power < 1:
        raise ValueError(f"power must be between 0 and 1, not {power}")
    if rmsea_power(n_max, df, eps0, eps_a, alpha) < power:
        raise ValueError(f"power {power} is not reached below N = {n_max}")
    lo, hi = 2, n_max
    while lo < hi:
        mid = (lo + hi) // 2
        if rmsea_power(mid, df, eps0, eps_a, alpha) >= power:
            hi = mid
        else:
            lo = mid + 1
    return lo


def measurement_df(retained: dict[str, Sequence[str]]) -> int:
    """Degrees of freedom of the CFA with correlated factors: p(p+1)/2 moments minus 2p - k + k(k+1)/2 parameters
    (p - k free loadings with one marker per factor, p residual variances, the factor (co)variances)."""
    p = sum(len(v) for v in retained.values())
    k = len(retained)
    return p * (p + 1) // 2 - (2 * p - k + k * (k + 1) // 2)


def power_figure(power: pd.DataFrame, target: float, out_dir: str | Path, stem: str = "power_curve") -> list[Path]:
    """Power against N per hypothesis (a 95 % band where the power is simulated), with the target line (PNG and
    PDF via analysis.render.save_figure). Hypotheses without a power (other sign) are left out."""
    from analysis.render import bare_figure, save_figure

    fig = bare_figure((6.5, 4))
    ax = fig.subplots()
    methods = set(power["method"]) if "method" in power.columns else {"simulation"}
    for h, g in power.groupby("hypothesis", sort=False):
        g = g[g["power"].notna()].sort_values("n")
        if g.empty:
            continue
        n = g["n"].to_numpy(dtype=float)
        ax.plot(n, g["power"].to_numpy(dtype=float), marker="o", ms=3, label=f"{h} ({g['path'].iloc[0]})")
        if g["ci_low"].notna().any():
            ax.fill_between(n, g["ci_low"].to_numpy(dtype=float), g["ci_high"].to_numpy(dtype=float), alpha=0.15)
    ax.axhline(target, color="black", lw=0.8, ls="--")
    ax.set_xlabel("sample size N")
    ax.set_ylabel("power (" + ", ".join("Monte-Carlo" if m == "simulation" else "noncentral F"
                                         for m in sorted(methods)) + ")")
    ax.set_ylim(0, 1)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    return save_figure(fig, out_dir, stem)


@dataclass(frozen=True)
class StudyPlan:
    """What power analysis needs from a study: its regressions (covariate columns expanded), its hypotheses,
    alpha, the measurement model's degrees of freedom, and the variables of the regressions."""

    models: tuple[ModelSpec, ...]
    hypotheses: tuple
    alpha: float
    measurement_df: int
    variables: tuple[str, ...]


def study_plan(study, instrument=None, attributes: pd.DataFrame | None = None,
               index: pd.Index | None = None) -> tuple[StudyPlan, pd.DataFrame]:
    """The :class:`StudyPlan` of `study` and its covariate columns for the participants of `index` (an empty frame
    when the study's regressions have no covariates)."""
    from analysis.survey.acceptance import covariate_frame, resolve_instrument, survey_plan

    plan = survey_plan(study, resolve_instrument(study, instrument), study.model)
    if not plan.hypotheses:
        raise ValueError("the study's model declares no hypotheses (label a regression path, e.g. Y ~ H1*X)")
    idx = index if index is not None else pd.Index([], name="participant_id")
    covars, cov_cols = covariate_frame(attributes, study, plan.covariates, idx)
    models = tuple(ModelSpec(m.name, m.dv, tuple(tuple(c for p in b for c in cov_cols.get(p, [p])) for b in m.steps),
                             m.label) for m in plan.models)
    variables = []
    for m in models:
        for v in (m.dv, *m.predictors(len(m.steps))):
            if v not in variables:
                variables.append(v)
    return StudyPlan(models, tuple(plan.hypotheses), plan.alpha, measurement_df(plan.retained),
                     tuple(variables)), covars


def population_of_responses(responses: pd.DataFrame, study, attributes: pd.DataFrame | None = None,
                            instrument=None) -> tuple[Population, StudyPlan]:
    """The population fitted to a study's data: composites of the retained items (as the analysis scores them)
    and the covariate columns of its regressions."""
    from analysis.survey.acceptance import resolve_instrument
    from analysis.survey.scoring import composites, score_responses

    ins = resolve_instrument(study, instrument)
    sample = score_responses(responses, ins, listwise=True)
    plan, covars = study_plan(study, ins, attributes, sample.scored.index)
    comp = composites(sample.scored, {c: list(v) for c, v in study.model.measurement.items()})
    data = comp.join(covars) if len(covars.columns) else comp
    return population_from_data(data[list(plan.variables)]), plan

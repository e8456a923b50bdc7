"""A priori power for the next study: Monte-Carlo power of each hypothesis, and the RMSEA-based N of the
measurement model (docs/power.md).

* **Hypotheses.** The population is multivariate normal over the composites (and numeric covariate columns) of the
  study's regressions, with the mean and covariance of the study's data (:func:`population_from_analysis`) or of a
  user-given covariance matrix (:func:`population_from_csv`). For each candidate N, ``reps`` samples of N are drawn;
  each hypothesis's regression step is fitted by OLS (:func:`analysis.survey.regression.ols`) and judged by the same
  rule as the study's own test (:func:`analysis.survey.hypotheses.supported`); power = the share of samples that support
  it. Replicate r at size N draws from ``SeedSequence(seed, spawn_key=(N, r))``: the estimate does not depend on how the
  replicates are split among worker processes.
* **Analytic case** (:func:`f2_power`): one regression coefficient, whose exact power is the noncentral F,
  ``1 - F_ncf(F_crit; u, v, lambda = f^2 (u + v + 1))`` (Cohen 1988, the formula of R's ``pwr.f2.test``).
* **RMSEA** (:func:`rmsea_power`, :func:`rmsea_n`): MacCallum, Browne & Sugawara (1996). With ``df`` degrees of
  freedom and noncentrality ``lambda = (N - 1) df eps^2``, the test of close fit (H0 eps = .05 against eps = .08)
  rejects above the ``1 - alpha`` quantile of the noncentral chi-square under H0; the test of not-close fit (H0 eps
  = .05 against eps = .01) below its ``alpha`` quantile.

Sampling multiplies standard normals by the Cholesky factor column by column with elementwise ufuncs (no BLAS
product), and the Cholesky factor is computed in plain Python, so the draws are the same bits under every BLAS
kernel.
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

from analysis.survey.hypotheses import supported
from analysis.survey.mvn import cholesky, draw
from analysis.survey.regression import ModelSpec, ols

POWER_COLUMNS = ["hypothesis", "path", "sign", "n", "reps", "supported", "power", "ci_low", "ci_high"]
N_COLUMNS = ["hypothesis", "path", "sign", "target_power", "alpha", "n_required", "power_at_n"]


@dataclass(frozen=True)
class Population:
    """A multivariate normal population: variable `names`, `mean` (len k) and covariance `cov` (k x k)."""

    names: tuple[str, ...]
    mean: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]

    def frame(self) -> pd.DataFrame:
        """The covariance matrix as a DataFrame (names as index and columns)."""
        return pd.DataFrame(self.cov, index=list(self.names), columns=list(self.names))


@dataclass(frozen=True)
class Target:
    """One hypothesis to simulate: the regression (dv on `predictors`) of its step, the coefficient it reads."""

    hypothesis: str
    dv: str
    predictors: tuple[str, ...]
    predictor: str
    sign: str

    @property
    def path(self) -> str:
        return f"{self.predictor} -> {self.dv}"


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
    return Population(tuple(d.columns), tuple(float(m) for m in x.mean(axis=0)), tuple(tuple(r) for r in cov))


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
    m = df.to_numpy(dtype=float)
    if not np.isfinite(m).all():
        raise ValueError(f"{path}: the matrix has empty or non-numeric cells")
    if not np.array_equal(m, m.T):
        raise ValueError(f"{path}: the matrix is not symmetric")
    pop = Population(tuple(names), tuple(0.0 for _ in names), tuple(tuple(float(v) for v in r) for r in m))
    cholesky(pop.cov)  # refuses a matrix that is not positive definite
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


def _count(job: tuple) -> list[int]:
    """Supported counts per target for replicates `reps` (a range) at size n (one worker's share)."""
    pop, tgts, n, reps, seed, alpha = job
    L = cholesky(pop.cov)
    col = {name: i for i, name in enumerate(pop.names)}
    hits = [0] * len(tgts)
    for r in reps:
        x = draw(L, pop.mean, n, np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(n, r))))
        for t_i, t in enumerate(tgts):
            try:
                fit = ols(x[:, col[t.dv]], x[:, [col[p] for p in t.predictors]])
            except ValueError:  # a singular sample supports nothing
                continue
            k = t.predictors.index(t.predictor) + 1
            hits[t_i] += supported(float(fit["b"][k]), float(fit["p"][k]), t.sign, alpha)
    return hits


def mc_power(pop: Population, tgts: Sequence[Target], sizes: Sequence[int], *, reps: int = 1000, alpha: float = 0.05,
             seed: int = 20240101, workers: int = 1, progress: bool = False) -> pd.DataFrame:
    """Monte-Carlo power of each target at each sample size (columns POWER_COLUMNS; ci = Clopper-Pearson 95 %).

    The same seed gives the same table for any number of `workers` (local processes)."""
    if reps < 1:
        raise ValueError(f"reps must be >= 1, not {reps}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, not {workers}")
    for n in sizes:
        need = max(len(t.predictors) for t in tgts) + 2
        if n < need:
            raise ValueError(f"sample size {n} is too small for the regressions (at least {need})")
    chunks = max(1, workers)
    jobs = [(pop, tuple(tgts), int(n), range(c, reps, chunks), seed, alpha) for n in sizes for c in range(chunks)]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="chunk", desc="power")
    results = []
    if workers == 1:
        for job in jobs:
            results.append(_count(job))
            if bar is not None:
                bar.update()
    else:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            for res in ex.map(_count, jobs):
                results.append(res)
                if bar is not None:
                    bar.update()
    if bar is not None:
        bar.close()
    rows = []
    for s_i, n in enumerate(sizes):
        counts = np.sum(results[s_i * chunks:(s_i + 1) * chunks], axis=0)
        for t, k in zip(tgts, counts):
            lo, hi = stats.binomtest(int(k), reps).proportion_ci(0.95, method="exact")
            rows.append({"hypothesis": t.hypothesis, "path": t.path, "sign": t.sign, "n": int(n), "reps": reps,
                         "supported": int(k), "power": int(k) / reps, "ci_low": lo, "ci_high": hi})
    return pd.DataFrame(rows, columns=POWER_COLUMNS)


def required_n(power: pd.DataFrame, target: float, alpha: float) -> pd.DataFrame:
    """Per hypothesis, the smallest simulated N whose power reaches `target` and stays there for every larger N
    simulated (NaN when none does). Columns N_COLUMNS."""
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
    return pd.DataFrame(rows, columns=N_COLUMNS)


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
    """Power against N per hypothesis, with the target line (PNG and PDF via analysis.render.save_figure)."""
    from analysis.render import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for h, g in power.groupby("hypothesis", sort=False):
        g = g.sort_values("n")
        ax.plot(g["n"], g["power"], marker="o", ms=3, label=f"{h} ({g['path'].iloc[0]})")
        ax.fill_between(g["n"], g["ci_low"], g["ci_high"], alpha=0.15)
    ax.axhline(target, color="black", lw=0.8, ls="--")
    ax.set_xlabel("sample size N")
    ax.set_ylabel("power (Monte-Carlo)")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    paths = save_figure(fig, out_dir, stem)
    plt.close(fig)
    return paths


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

"""Measurement invariance across groups: multi-group CFA, configural -> metric -> scalar (Meredith 1993;
Vandenberg & Lance 2000).

Model per group g (lavaan's defaults for ``cfa(group=, group.equal=)``): Sigma_g = Lambda_g Psi_g Lambda_g' +
Theta_g, mu_g = nu_g + Lambda_g alpha_g; the first loading of each factor fixed to 1.

* configural: every parameter free per group, alpha_g = 0 (intercepts absorb the means);
* metric: Lambda equal across groups;
* scalar: Lambda and nu equal across groups, alpha_1 = 0 and alpha_g free for g >= 2.

ML on the biased group covariances S_g and means m_g (lavaan ``likelihood = "normal"``):
F = sum_g (N_g/N) [log|Sigma_g| + tr(S_g Sigma_g^-1) - log|S_g| - p + (m_g - mu_g)' Sigma_g^-1 (m_g - mu_g)],
chi2 = N F, df = G (p(p+1)/2 + p) - free parameters. Baseline: independence per group,
chi2_b = sum_g N_g (sum log s_ii - log|S_g|) on G p(p-1)/2 df. CFI, TLI as :func:`analysis.survey.cfa.fit_indices`;
RMSEA = sqrt(G) sqrt(max(chi2 - df, 0) / (df N)) (lavaan's multi-group RMSEA).

Decisions (``holds``, with the reason in ``reason``):

* configural: the model fits each group acceptably, CFI >= 0.90 and RMSEA <= 0.08 (the "acceptable fit" bounds
  of Hu & Bentler 1999 and Browne & Cudeck 1993 that invariance studies use, Putnick & Bornstein 2016); a poorly
  fitting configural model is a warning, and the later steps are not judged (nothing is invariant whose form does
  not fit);
* metric and scalar: the previous step holds and the restriction costs little fit, Delta CFI = CFI_restricted -
  CFI_free >= -0.01 (Cheung & Rensvold 2002) and Delta RMSEA = RMSEA_restricted - RMSEA_free <= 0.015 (Chen 2007);
  either criterion failing rejects the step. Delta chi2 = chi2_restricted - chi2_free on Delta df, with its p from
  chi2(Delta df), is reported beside them (it is sensitive to N).

Every step's solution is checked per group for admissibility (:mod:`analysis.survey.admissibility`; the residual
and latent variances are bounded below at 1e-8, so a variance there is at its bound): each problem is a warning.

A group must have more participants than the model has items (else S_g is singular and the step undefined):
smaller groups are refused with a one-line error naming them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import optimize, stats

from analysis.survey.admissibility import improper, singular_sample

STEPS = ("configural", "metric", "scalar")
DELTA_CFI = -0.01       # Cheung & Rensvold 2002
DELTA_RMSEA = 0.015     # Chen 2007
CONFIGURAL_CFI = 0.90   # acceptable configural fit: CFI >= .90 and RMSEA <= .08
CONFIGURAL_RMSEA = 0.08


@dataclass
class _Layout:
    n_par: int
    lam: list  # per group: (G_item_idx, factor_idx, param_idx) for free loadings
    theta: list  # per group: param idx per item
    psi: list  # per group: list of (a, b, param_idx), a >= b
    nu: list  # per group: param idx per item
    alpha: list  # per group: list of (factor, param_idx)


def _layout(step: str, G: int, p: int, fac: np.ndarray, markers: set[int], k: int) -> _Layout:
    n = 0

    def new():
        nonlocal n
        n += 1
        return n - 1

    shared_lam = {i: new() for i in range(p) if i not in markers} if step in ("metric", "scalar") else None
    shared_nu = [new() for _ in range(p)] if step == "scalar" else None
    L = _Layout(0, [], [], [], [], [])
    for g in range(G):
        L.lam.append([(i, fac[i], shared_lam[i] if shared_lam is not None else new())
                      for i in range(p) if i not in markers])
        L.theta.append([new() for _ in range(p)])
        L.psi.append([(a, b, new()) for a in range(k) for b in range(a + 1)])
        L.nu.append(shared_nu if shared_nu is not None else [new() for _ in range(p)])
        L.alpha.append([(f, new()) for f in range(k)] if step == "scalar" and g > 0 else [])
    L.n_par = n
    return L


def _matrices(x, L, g, p, k, fac, markers):
    lam = np.zeros((p, k))
    for i in markers:
        lam[i, fac[i]] = 1.0
    for i, f, j in L.lam[g]:
        lam[i, f] = x[j]
    psi = np.zeros((k, k))
    for a, b, j in L.psi[g]:
        psi[a, b] = psi[b, a] = x[j]
    theta = np.diag(x[L.theta[g]])
    nu = x[L.nu[g]]
    alpha = np.zeros(k)
    for f, j in L.alpha[g]:
        alpha[f] = x[j]
    return lam, psi, theta, nu, alpha


def _objective(x, L, groups, p, k, fac, markers, N):
    f = 0.0
    grad = np.zeros_like(x)
    for g, (S, m, ng, logdet_s) in enumerate(groups):
        lam, psi, theta, nu, alpha = _matrices(x, L, g, p, k, fac, markers)
        sigma = lam @ psi @ lam.T + theta
        sign, logdet = np.linalg.slogdet(sigma)
        if sign <= 0:
            return 1e10, np.zeros_like(x)
        si = np.linalg.inv(sigma)
        d = m - (nu + lam @ alpha)
        w = ng / N
        f += w * (logdet + np.trace(S @ si) - logdet_s - p + d @ si @ d)
        Gm = si - si @ (S + np.outer(d, d)) @ si
        dmu = -2.0 * si @ d
        dlam = 2.0 * Gm @ lam @ psi + np.outer(dmu, alpha)
        dpsi = lam.T @ Gm @ lam
        for i, fct, j in L.lam[g]:
            grad[j] += w * dlam[i, fct]
        for a, b, j in L.psi[g]:
            grad[j] += w * (dpsi[a, b] if a == b else 2.0 * dpsi[a, b])
        np.add.at(grad, L.theta[g], w * np.diag(Gm))
        np.add.at(grad, L.nu[g], w * dmu)
        dal = lam.T @ dmu
        for fct, j in L.alpha[g]:
            grad[j] += w * dal[fct]
    return f, grad


@dataclass
class InvarianceResult:
    """steps: step, chi2, df, p, cfi, tli, rmsea, n_params, converged, delta_chi2, delta_df, p_delta, delta_cfi,
    holds, delta_rmsea, reason (why a step does not hold; empty when it holds); groups: group, n."""

    group_var: str
    steps: pd.DataFrame
    groups: pd.DataFrame
    warnings: list[str] = field(default_factory=list)


def _fit_step(step, stats_g, p, k, fac, markers, N):
    G = len(stats_g)
    L = _layout(step, G, p, fac, markers, k)
    x0 = np.zeros(L.n_par)
    for g, (S, m, ng, _) in enumerate(stats_g):
        for i, f, j in L.lam[g]:
            x0[j] = 1.0
        x0[L.theta[g]] = 0.5 * np.diag(S)
        for a, b, j in L.psi[g]:
            if a == b:
                mk = [i for i in markers if fac[i] == a][0]
                x0[j] = 0.5 * S[mk, mk]
        x0[L.nu[g]] = m
    bounds = [(None, None)] * L.n_par
    for g in range(G):
        for j in L.theta[g]:
            bounds[j] = (1e-8, None)
        for a, b, j in L.psi[g]:
            if a == b:
                bounds[j] = (1e-8, None)
    res = optimize.minimize(_objective, x0, jac=True, method="L-BFGS-B", bounds=bounds,
                            args=(L, stats_g, p, k, fac, markers, N),
                            options={"maxiter": 50000, "maxfun": 100000, "ftol": 1e-15, "gtol": 1e-9})
    fval, grad = _objective(res.x, L, stats_g, p, k, fac, markers, N)
    # postcondition: a stationary point (projected gradient ~ 0 away from the bounds)
    free = np.array([not (b[0] is not None and x - b[0] < 1e-6) for x, b in zip(res.x, bounds)])
    converged = bool(res.success and np.isfinite(fval) and np.max(np.abs(grad[free])) < 1e-4)
    return fval, L, converged, res


def _admissibility(step, x, L, stats_g, levels, items, names, p, k, fac, markers) -> list[str]:
    """Improper estimates of one step, group by group (:func:`analysis.survey.admissibility.improper`)."""
    out = []
    for g, (S, _, _, _) in enumerate(stats_g):
        lam, psi, theta, _, _ = _matrices(x, L, g, p, k, fac, markers)
        sigma = lam @ psi @ lam.T + theta
        std = [lam[i, fac[i]] * np.sqrt(psi[fac[i], fac[i]]) / np.sqrt(sigma[i, i]) if psi[fac[i], fac[i]] > 0
               else np.nan for i in range(p)]
        out += improper(f"invariance {step}, group {levels[g]}: ",
                        std_loadings=pd.DataFrame({"item": items, "loading": std}),
                        error_var=pd.Series(np.diag(theta), index=items), item_var=pd.Series(np.diag(S), index=items),
                        latent_cov=pd.DataFrame(psi, index=names, columns=names))
    return out


def _decisions(steps: pd.DataFrame) -> tuple[list[bool], list[str]]:
    """holds and reason of each step (module docstring: configural fit, then Delta CFI and Delta RMSEA).

    Examples
    --------
    A configural CFI of .813 is poor fit, so nothing holds:

    >>> import pandas as pd
    >>> from analysis.survey.invariance import _decisions
    >>> st = pd.DataFrame({"cfi": [0.813, 0.810, 0.790], "rmsea": [0.07, 0.07, 0.08],
    ...                    "delta_cfi": [float("nan"), -0.003, -0.020], "delta_rmsea": [float("nan"), 0.0, 0.01]})
    >>> _decisions(st)
    ([False, False, False], ['CFI 0.813 < 0.90', 'the configural step does not hold', 'the metric step does not hold'])
    >>> st["cfi"] = [0.953, 0.950, 0.930]
    >>> _decisions(st)
    ([True, True, False], ['', '', 'Delta CFI -0.020 < -0.01'])
    """
    holds, reasons = [], []
    for k, r in enumerate(steps.itertuples()):
        why = []
        if k == 0:
            if not r.cfi >= CONFIGURAL_CFI:
                why.append(f"CFI {r.cfi:.3f} < {CONFIGURAL_CFI:.2f}")
            if np.isfinite(r.rmsea) and r.rmsea > CONFIGURAL_RMSEA:
                why.append(f"RMSEA {r.rmsea:.3f} > {CONFIGURAL_RMSEA:.2f}")
        elif not holds[-1]:
            why.append(f"the {STEPS[k - 1]} step does not hold")
        else:
            if not r.delta_cfi >= DELTA_CFI:
                why.append(f"Delta CFI {r.delta_cfi:.3f} < {DELTA_CFI:g}")
            if np.isfinite(r.delta_rmsea) and r.delta_rmsea > DELTA_RMSEA:
                why.append(f"Delta RMSEA {r.delta_rmsea:.3f} > {DELTA_RMSEA:g}")
        holds.append(not why)
        reasons.append("; ".join(why))
    return holds, reasons


def invariance(scored: pd.DataFrame, constructs: dict[str, list[str]], groups: pd.Series, *,
               group_var: str = "group") -> InvarianceResult:
    """Configural, metric and scalar multi-group CFA of `constructs` across the levels of `groups` (a Series indexed
    like `scored`; participants without a group are left out).

    Raises ValueError (one line) when fewer than two groups remain or a group has no more participants than the
    model has items.
    """
    items = [i for its in constructs.values() for i in its]
    g = groups.reindex(scored.index)
    data = scored[items].assign(_g=g).dropna()
    levels = [lv for lv in pd.unique(data["_g"])]
    levels = sorted(levels, key=lambda v: str(v))
    p, k = len(items), len(constructs)
    if len(levels) < 2:
        raise ValueError(f"invariance: {group_var} has {len(levels)} group(s) among the participants; at least 2 "
                         f"are needed")
    sizes = {lv: int((data["_g"] == lv).sum()) for lv in levels}
    small = [f"{lv} ({n})" for lv, n in sizes.items() if n <= p]
    if small:
        raise ValueError(f"invariance by {group_var}: group(s) {', '.join(small)} too small; the model has {p} items, "
                         f"so every group needs at least {p + 1} participants")
    names = list(constructs)
    fac = np.array([names.index(c) for c, its in constructs.items() for _ in its])
    markers = {items.index(its[0]) for its in constructs.values()}
    stats_g, near = [], []
    for lv in levels:
        x = data.loc[data["_g"] == lv, items].to_numpy(float)
        S = np.cov(x, rowvar=False, bias=True)
        sign, ld = np.linalg.slogdet(S)
        said = singular_sample(f"invariance by {group_var}, group {lv}: ", pd.DataFrame(S, index=items, columns=items))
        if sign <= 0:
            why = f" ({said[0].split(': ', 1)[1]})" if said else ""
            raise ValueError(f"invariance by {group_var}: the item covariance matrix of group {lv} is singular{why}")
        near += said
        stats_g.append((S, x.mean(axis=0), len(x), ld))
    N = sum(s[2] for s in stats_g)
    G = len(stats_g)
    chi2_b = sum(ng * (np.sum(np.log(np.diag(S))) - ld) for S, _, ng, ld in stats_g)
    df_b = G * p * (p - 1) // 2
    rows, warn = [], list(near)
    for step in STEPS:
        fval, L, ok, res = _fit_step(step, stats_g, p, k, fac, markers, N)
        n_par = L.n_par
        if not ok:
            warn.append(f"invariance {step}: the optimiser did not reach a stationary point ({res.message})")
        warn += _admissibility(step, res.x, L, stats_g, levels, items, names, p, k, fac, markers)
        chi2 = max(N * fval, 0.0)
        df = G * (p * (p + 1) // 2 + p) - n_par
        d_m, d_b = max(chi2 - df, 0.0), max(chi2_b - df_b, 0.0)
        cfi = 1.0 - d_m / max(d_m, d_b) if max(d_m, d_b) > 0 else 1.0
        tli = (chi2_b / df_b - chi2 / df) / (chi2_b / df_b - 1.0) if df > 0 else float("nan")
        rmsea = float(np.sqrt(G) * np.sqrt(d_m / (df * N))) if df > 0 else float("nan")
        rows.append({"step": step, "chi2": float(chi2), "df": int(df),
                     "p": float(stats.chi2.sf(chi2, df)) if df > 0 else float("nan"), "cfi": float(cfi),
                     "tli": float(tli), "rmsea": rmsea, "n_params": n_par, "converged": ok})
    out = pd.DataFrame(rows)
    dchi = out["chi2"].diff()
    ddf = out["df"].diff()
    out["delta_chi2"] = dchi
    out["delta_df"] = ddf
    out["p_delta"] = [float(stats.chi2.sf(c, d)) if np.isfinite(c) and d > 0 else float("nan")
                      for c, d in zip(dchi, ddf)]
    out["delta_cfi"] = out["cfi"].diff()
    out["delta_rmsea"] = out["rmsea"].diff()
    holds, reasons = _decisions(out)
    out["holds"] = holds
    out["reason"] = reasons
    if not holds[0]:
        warn.append(f"invariance configural: the configural model fits poorly ({reasons[0]}); metric and scalar "
                    f"invariance are not judged")
    out = out[["step", "chi2", "df", "p", "cfi", "tli", "rmsea", "n_params", "converged", "delta_chi2", "delta_df",
               "p_delta", "delta_cfi", "holds", "delta_rmsea", "reason"]]
    return InvarianceResult(group_var=group_var, steps=out,
                            groups=pd.DataFrame({"group": [str(lv) for lv in levels],
                                                 "n": [sizes[lv] for lv in levels]}), warnings=warn)

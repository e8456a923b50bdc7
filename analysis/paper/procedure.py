"""Which extraction produced Table 3's "standardized factor loadings"? A feasibility test per construct.

For a construct with k items, the printed λ, Cα, CR, AVE and item SDs are *consistent with* an extraction when some
correlation matrix R of the k items (unit diagonal, positive semi-definite) yields exactly the printed λ under that
extraction and, with the printed item SDs, exactly the printed Cα. CR and AVE are Hair's functions of λ
(:func:`analysis.paper.audit.cr_ave`), so they are checked on the printed λ.

The key fact: for each extraction of :mod:`analysis.survey.extraction`, "λ is the solution for R" is a set of k *linear*
equations in the k(k-1)/2 off-diagonal correlations (plus "the eigenvalue is the largest"):

* pca: R v = μ v with v = λ/√μ, μ = Σλ²:           Σ_{j≠i} r_ij λ_j = λ_i (μ - 1)
* paf (fixed point, communalities h² = λ²):         Σ_{j≠i} r_ij λ_j = λ_i (μ - λ_i²)
* ml (one factor, ψ_i = 1 - λ_i², γ = 1 + Σλ²/ψ):    Σ_{j≠i} r_ij λ_j/ψ_j = λ_i (γ - 1/ψ_i)
  (Jöreskog's stationarity condition R Ψ⁻¹λ = γ λ; it is also a one-construct CFA)

and Cα is a monotone function of the one linear form q = Σ_{i<j} s_i s_j r_ij. Hence:

* k = 2 and k = 3: the equations fix R (2 items under PCA also need λ₁ = λ₂). Cα is then *determined* by the
  printed λ and SDs; over the rounding box of the printed digits (λ ± half a unit of the last digit, SDs in their
  truncation interval [printed, printed + unit)) it spans an interval. Disjoint from the printed Cα's interval: the
  extraction is *rejected* - a proof. Overlapping: the extraction is consistent, and with 1 (k = 3) or 1-2 (k = 2)
  more printed numbers than unknowns this is a test the numbers could have failed.
* k >= 4: the solutions form an affine family of dimension k(k-1)/2 - k; a matrix of it that is a correlation matrix,
  has the printed Cα and for which λ belongs to the largest eigenvalue is searched with SLSQP (from the family's
  least-squares point; further starts, if asked for, are seeded).
  A matrix found is a *witness*: the extraction is consistent (proven constructively, but not singled out: other
  extractions may fit too). None found is evidence, not proof.

Reversing an item multiplies its row and column of R by -1: its loading changes sign, nothing else (other λ, Cα of
the retained items, CR, AVE). So the printed numbers cannot tell whether PEoU3 was reversed before the extraction;
its sign only says that the item *as analysed* ran against the others.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pandas as pd
from scipy import optimize

from analysis.paper import grim
from analysis.paper import published as P
from analysis.survey import extraction as X
from analysis.survey.reliability import alpha_from_cov

METHODS = ("pca", "paf", "ml")
METHOD_NAMES = {"pca": "principal components (SPSS FACTOR default)", "paf": "principal axis factoring",
                "ml": "ML factor analysis / one-construct CFA"}
N_STARTS = 1
SEED = 20240


@dataclass
class Feasibility:
    """One construct x extraction x item set: status fits | rejected | not found, the numbers that decide it."""

    construct: str
    method: str
    item_set: str                  # retained | all
    items: list[str]
    k: int
    unknowns: int
    equations: int                 # k loading equations + 1 for Cα
    alpha_printed: float
    alpha_low: float               # the Cα range the printed λ allow (determined case) or the witness' Cα
    alpha_high: float
    status: str
    how: str                       # closed form | witness | search
    witness: np.ndarray | None = None


def system(lam: np.ndarray, method: str) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """The linear equations M r = b in the off-diagonal correlations r (pairs i < j) of the module docstring."""
    lam = np.asarray(lam, float)
    k = len(lam)
    pairs = list(itertools.combinations(range(k), 2))
    mu = float((lam ** 2).sum())
    if method == "ml":
        psi = 1.0 - lam ** 2
        w = lam / psi
        b = lam * (1.0 + (lam ** 2 / psi).sum() - 1.0 / psi)
    elif method in ("pca", "paf"):
        w = lam
        b = lam * (mu - 1.0) if method == "pca" else lam * (mu - lam ** 2)
    else:
        raise ValueError(f"unknown extraction {method!r} (one of {', '.join(METHODS)})")
    M = np.zeros((k, len(pairs)))
    for p, (i, j) in enumerate(pairs):
        M[i, p], M[j, p] = w[j], w[i]
    return M, b, pairs


def to_matrix(r: np.ndarray, pairs: list[tuple[int, int]], k: int) -> np.ndarray:
    R = np.eye(k)
    for p, (i, j) in enumerate(pairs):
        R[i, j] = R[j, i] = r[p]
    return R


def top_gap(R: np.ndarray, lam: np.ndarray, method: str) -> float:
    """How far the eigenvalue λ belongs to lies above every other eigenvalue of the matrix the extraction
    decomposes (> 0 needed): μ minus the largest eigenvalue on the complement of λ's direction."""
    return float(top_gaps(np.asarray(R, float)[None], lam, method)[0])


def top_gaps(Rs: np.ndarray, lam: np.ndarray, method: str) -> np.ndarray:
    """:func:`top_gap` of each matrix of the stack ``Rs`` (n x k x k), in one batched eigen-decomposition."""
    lam = np.asarray(lam, float)
    if method == "ml":
        psi = 1.0 - lam ** 2
        d = 1.0 / np.sqrt(psi)
        m, v, mu = Rs * np.outer(d, d), lam * d, 1.0 + (lam ** 2 / psi).sum()
    else:
        m, v, mu = Rs.copy(), lam.copy(), (lam ** 2).sum()
        if method == "paf":
            idx = np.arange(len(lam))
            m[:, idx, idx] = lam ** 2
    v = v / np.linalg.norm(v)
    proj = np.eye(len(v)) - np.outer(v, v)
    others = np.linalg.eigvalsh(proj @ m @ proj)
    # the complement's eigenvalues plus the 0 that v contributes; drop that one 0
    zero = np.argmin(np.abs(others), axis=1)
    others[np.arange(len(others)), zero] = -np.inf
    return mu - others.max(axis=1)


def is_solution(R: np.ndarray, lam: np.ndarray, method: str, tol: float = 1e-6) -> bool:
    """Postcondition of a witness: a correlation matrix (PSD) whose extraction by ``method`` gives ``lam``."""
    if np.linalg.eigvalsh(R)[0] < -1e-9 or np.max(np.abs(R)) > 1 + 1e-12:
        return False
    if method == "paf":  # iterate to the fixed point, not SPSS's stopping rule, to check the solution itself
        ex = X.paf_loadings(R, max_iter=20000, tol=1e-13)
    else:
        ex = X.extract(R, method)
    return bool(np.max(np.abs(ex.loadings - lam)) < tol)


def _alpha(R: np.ndarray, sd: np.ndarray, sub: list[int]) -> float:
    return alpha_from_cov((np.outer(sd, sd) * R)[np.ix_(sub, sub)])


def _boxes(values: np.ndarray, decimals: np.ndarray, mode: str) -> list[tuple[float, float]]:
    return [grim.interval(v, int(d), mode) for v, d in zip(values, decimals)]


def determined_alpha_range(lam, lam_dec, sd, sd_dec, sub: list[int], method: str) -> tuple[float, float] | None:
    """Cα over the corners of the rounding box when the equations fix R (k <= 3); None if no corner solves them.

    The box is tiny (half-widths <= 0.005) and Cα smooth in λ and the SDs, so its extremes are at corners."""
    lb, sb = _boxes(lam, lam_dec, "round"), _boxes(sd, sd_dec, "truncate")
    k = len(lam)
    if k == 2 and method == "pca":
        # both loadings equal √((1 + r)/2): only the common part of the two boxes can be a solution
        lo, hi = max(lb[0][0], lb[1][0]), min(lb[0][1], lb[1][1])
        if lo > hi:
            return None
        lb = [(lo, hi), (lo, hi)]
        corners = [((a, a), s) for a in (lo, hi) for s in itertools.product(*sb)]
    else:
        corners = [(l_, s) for l_ in itertools.product(*lb) for s in itertools.product(*sb)]
    vals = []
    for l_, s in corners:
        M, b, pairs = system(np.array(l_), method)
        r, *_ = np.linalg.lstsq(M, b, rcond=None)
        if np.max(np.abs(M @ r - b)) > 1e-9:
            continue
        vals.append(_alpha(to_matrix(r, pairs, k), np.array(s), sub))
    return (min(vals), max(vals)) if vals else None


def family_members(lam, sd, sub: list[int], method: str, half_width: float = 2.5, steps: int = 251,
                   refine: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Scan a 1- or 2-dimensional solution family (k = 4: 6 correlations, 4 equations) on a grid of its
    coordinates (orthonormal directions, ±``half_width``, ``steps`` per axis), then on a 100x finer grid around
    the members with the smallest and the largest Cα (the extremes lie on the region's boundary, which the
    coarse grid only approaches; ``refine=False`` skips this). Returns the members that are correlation matrices
    with λ on the largest eigenvalue (m x k x k) and their Cα over the items ``sub``."""
    lam, sd = np.asarray(lam, float), np.asarray(sd, float)
    M, b, pairs = system(lam, method)
    r0, *_ = np.linalg.lstsq(M, b, rcond=None)
    # r0 is the minimum-norm solution (orthogonal to the family's directions), so a member r has coordinates
    # t = nullᵀr with |t| <= |r| <= √6 (|r_ij| <= 1): ±2.5 covers every member
    null = np.linalg.svd(M)[2][np.linalg.matrix_rank(M):].T
    step = 2 * half_width / (steps - 1)
    T, Rs, alphas = _members(lam, sd, sub, method, r0, null, pairs, np.zeros(null.shape[1]), half_width, steps)
    if refine and len(alphas):
        for t in (T[np.argmin(alphas)], T[np.argmax(alphas)]):
            T2, R2, a2 = _members(lam, sd, sub, method, r0, null, pairs, t, step, 201)
            T, Rs, alphas = np.vstack([T, T2]), np.concatenate([Rs, R2]), np.concatenate([alphas, a2])
    return Rs, alphas


def _members(lam, sd, sub, method, r0, null, pairs, centre, half_width, steps):
    k = len(lam)
    axes = [np.linspace(c - half_width, c + half_width, steps) for c in centre]
    T = np.array(np.meshgrid(*axes, indexing="ij")).reshape(null.shape[1], -1).T
    r = r0[None, :] + T @ null.T
    keep = np.all(np.abs(r) <= 1.0, axis=1)
    T, r = T[keep], r[keep]
    Rs = np.repeat(np.eye(k)[None], len(r), axis=0)
    for p, (i, j) in enumerate(pairs):
        Rs[:, i, j] = Rs[:, j, i] = r[:, p]
    ok = np.linalg.eigvalsh(Rs)[:, 0] >= 0
    ok[ok] = top_gaps(Rs[ok], lam, method) > 0
    T, Rs = T[ok], Rs[ok]
    cov = np.einsum("nij,i,j->nij", Rs, sd, sd)[:, sub][:, :, sub]
    kk = len(sub)
    alphas = kk / (kk - 1) * (1 - np.trace(cov, axis1=1, axis2=2) / cov.sum(axis=(1, 2)))
    return T, Rs, alphas


def family_alpha_range(lam, sd, sub: list[int], method: str) -> tuple[float, float]:
    """The Cα range over the members of :func:`family_members` ((nan, nan) when none qualifies)."""
    _, alphas = family_members(lam, sd, sub, method)
    return (float(alphas.min()), float(alphas.max())) if len(alphas) else (float("nan"), float("nan"))


def search_witness(lam, sd, sub: list[int], alpha: float, method: str, r_pref: np.ndarray | None = None,
                   starts: int = N_STARTS, seed: int = SEED) -> np.ndarray | None:
    """A correlation matrix solving the equations with Cα(sub) = alpha and λ on the largest eigenvalue, nearest
    ``r_pref`` (default: the one-factor pattern λ_iλ_j); None when no start succeeds. Seeded, deterministic."""
    lam, sd = np.asarray(lam, float), np.asarray(sd, float)
    k = len(lam)
    M, b, pairs = system(lam, method)
    r0, *_ = np.linalg.lstsq(M, b, rcond=None)
    if np.max(np.abs(M @ r0 - b)) > 1e-9:
        return None
    null = np.linalg.svd(M)[2][np.linalg.matrix_rank(M):].T            # basis of the family's directions
    pref = r_pref if r_pref is not None else np.array([lam[i] * lam[j] for i, j in pairs])
    R_of = lambda t: to_matrix(r0 + null @ t, pairs, k)  # noqa: E731
    cons = [{"type": "eq", "fun": lambda t: _alpha(R_of(t), sd, sub) - alpha},
            {"type": "ineq", "fun": lambda t: np.linalg.eigvalsh(R_of(t))[0] - 1e-6},
            {"type": "ineq", "fun": lambda t: top_gap(R_of(t), lam, method) - 1e-6}]
    # (a positive semi-definite matrix with unit diagonal has |r_ij| <= 1: no bound needed)
    rng = np.random.default_rng(seed)
    best = None
    for s in range(starts):
        t0 = np.zeros(null.shape[1]) if s == 0 else rng.normal(0, 0.3, null.shape[1])
        res = optimize.minimize(lambda t: float(((r0 + null @ t - pref) ** 2).sum()), t0, method="SLSQP",
                                constraints=cons, options={"maxiter": 100, "ftol": 1e-12})
        if not res.success:
            continue
        R = R_of(res.x)
        if abs(_alpha(R, sd, sub) - alpha) < 1e-7 and is_solution(R, lam, method) and (
                best is None or res.fun < best[0]):
            best = (res.fun, R)
    return None if best is None else best[1]


@lru_cache(maxsize=1)
def _default_feasibility() -> tuple[Feasibility, ...]:
    return tuple(feasibility(P.load_published()))


def feasibility(published: pd.DataFrame | None = None, methods=METHODS, starts: int = N_STARTS) -> list[Feasibility]:
    """Every construct x extraction x item set (retained; all items where some were omitted).

    Without ``published`` the shipped values are used and the result is cached (the witness search takes ~10 s)."""
    if published is None:
        return list(_default_feasibility())
    pub = published
    t3, tc = P.table3(pub), P.table3_constructs(pub).set_index("construct")
    dec = pub[pub["table"] == "table3"].set_index(["quantity", "row"])["decimals"].astype(int)
    out = []
    for c in P.TABLE4_ORDER:
        g_all = t3[t3["construct"] == c]
        sets = [("retained", g_all[~g_all["omitted"]])]
        if g_all["omitted"].any():
            sets.append(("all", g_all))
        for name, g in sets:
            items = g["item"].tolist()
            sub = [i for i, it in enumerate(items) if not g.set_index("item").loc[it, "omitted"]]
            lam, sd = g["loading"].values.astype(float), g["sd"].values.astype(float)
            lam_dec = np.array([dec[("loading", i)] for i in items])
            sd_dec = np.array([dec[("sd", i)] for i in items])
            alpha = float(tc.loc[c, "alpha"])
            a_lo, a_hi = grim.interval(alpha, int(dec[("alpha", c)]))
            k = len(items)
            for m in methods:
                M, _, _ = system(lam, m)
                unknowns = k * (k - 1) // 2
                rank = np.linalg.matrix_rank(M)
                if unknowns - rank <= 0 or k <= 3:
                    rng_ = determined_alpha_range(lam, lam_dec, sd, sd_dec, sub, m)
                    if rng_ is None:
                        status, lo, hi = "rejected", np.nan, np.nan
                    else:
                        lo, hi = rng_
                        status = "fits" if (lo <= a_hi and hi >= a_lo) else "rejected"
                    out.append(Feasibility(c, m, name, items, k, unknowns, k + 1, alpha, lo, hi, status,
                                           "closed form"))
                elif unknowns - rank <= 2:
                    lo, hi = family_alpha_range(lam, sd, sub, m)
                    status = "fits" if (lo <= a_hi and hi >= a_lo) else "rejected"
                    out.append(Feasibility(c, m, name, items, k, unknowns, k + 1, alpha, lo, hi, status,
                                           "family scan"))
                else:
                    wit = search_witness(lam, sd, sub, alpha, m, starts=starts)
                    a = _alpha(wit, sd, sub) if wit is not None else np.nan
                    out.append(Feasibility(c, m, name, items, k, unknowns, k + 1, alpha, a, a,
                                           "fits" if wit is not None else "not found",
                                           "witness" if wit is not None else "search", wit))
    return out


def feasibility_table(results: list[Feasibility]) -> pd.DataFrame:
    """Tidy: construct, method, item_set, k, unknowns, equations, alpha_printed, alpha_low, alpha_high, status, how."""
    cols = ["construct", "method", "item_set", "k", "unknowns", "equations", "alpha_printed", "alpha_low",
            "alpha_high", "status", "how"]
    return pd.DataFrame([{c: getattr(r, c) for c in cols} for r in results], columns=cols)


def target_blocks(published: pd.DataFrame | None = None, method: str = "pca"
                  ) -> dict[str, tuple[list[str], np.ndarray, str]]:
    """Per construct, a correlation matrix of its items under which ``method`` reproduces the printed λ - the
    within-construct target of the reconstruction: construct -> (items, R, how).

    Preference: an item set on which the method fits (all items before retained ones, so that the omitted items'
    λ are met too); the matrix is the closed-form solution at the printed λ (2-3 items), else a witness with the
    printed Cα. Where the method fits no item set (PEoU), a well-conditioned member of the all-items family
    whose Cα is within 0.01 of the reachable value nearest the printed one."""
    pub = published if published is not None else P.load_published()
    t3, tc = P.table3(pub), P.table3_constructs(pub).set_index("construct")
    res = [r for r in feasibility(published) if r.method == method]
    out = {}
    for c in P.TABLE4_ORDER:
        rows = sorted((r for r in res if r.construct == c), key=lambda r: (r.status != "fits", r.item_set != "all"))
        r = rows[0]
        g = t3.set_index("item").loc[r.items]
        lam, sd = g["loading"].to_numpy(float), g["sd"].to_numpy(float)
        sub = [i for i, it in enumerate(r.items) if not g.loc[it, "omitted"]]
        alpha = float(tc.loc[c, "alpha"])
        if r.status == "fits" and r.how == "closed form":
            M, b, pairs = system(lam, method)
            R, how = to_matrix(np.linalg.lstsq(M, b, rcond=None)[0], pairs, len(lam)), "closed form"
        elif r.status == "fits":
            R = r.witness if r.witness is not None else search_witness(lam, sd, sub, alpha, method)
            how = f"witness with Cα {alpha:g}"
        else:
            # the most interior member (largest smallest eigenvalue) among those within 0.01 of the reachable Cα
            # nearest the printed one: an edge member is nearly singular, which integer data cannot approach
            Rs, alphas = family_members(lam, sd, sub, method, refine=False)  # interior members are wanted
            gap = np.abs(alphas - alpha)
            near = Rs[gap <= gap.min() + 0.01]
            R = near[int(np.argmax(np.linalg.eigvalsh(near)[:, 0]))]
            how = f"Cα {_alpha(R, sd, sub):.4f} (printed {alpha:g} not reachable)"
        if R is None or not is_solution(R, lam, method):
            raise ValueError(f"{c}: no {method} target matrix reproduces the printed loadings")
        out[c] = (list(r.items), R, how)
    return out

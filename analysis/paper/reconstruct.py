"""A reconstructed survey dataset that reproduces the paper's published statistics.

The study's raw answers are not public. This module builds a deterministic integer 1-5 dataset for the N the tables
imply (40, see the audit) such that

1. every item's answer distribution (its *marginal*) reproduces the printed mean exactly and the printed SD under the
   paper's convention (SDs are truncated, audit finding "sd_truncated"); the one GRIM-impossible mean (PBC2 4.208)
   is replaced by the nearest possible one (4.200). Among the count vectors that fit (GRIMMER candidates) the one
   whose SD is nearest the middle of the printed interval is chosen, ties broken by the flattest shape.
2. values are then *arranged within columns* - the marginals never change - by swap search (in the spirit of
   LikertMakeR's ``lcor``) so that the item correlation matrix approaches a target built from the consistent parts
   of the paper:
   - composite correlations: Table 4, with the two PEoU correlations that Table 5 fixes (r = β of the one-predictor
     steps) in place of Table 4's (audit finding "t4_t5"); every other Table 5 number agrees with this matrix;
   - composite SDs: implied by the printed Cα and item SDs (these reproduce Table 5's B/β ratios; the printed λ do
     not, audit finding "loadings_vs_alpha");
   - within a construct: a correlation matrix under which the paper's procedure, the first principal component
     (audit finding "extraction"), gives exactly the printed loadings, with the printed Cα where that is reachable
     (:func:`analysis.paper.procedure.target_blocks`); across constructs r_ij = a_i a_j Φ_AB with a_i = √c_k λ_i
     (c_k scales λ_iλ_j so that the composite SD, hence Cα, is met) and Φ_AB chosen so that the composite
     correlation is met.
3. The swap search evaluates all n(n-1)/2 swaps of one column at once with numpy: a swap of rows a, b in column c
   changes only row/column c of the centred cross-product matrix, by d·(x_a - x_b) with d = x_bc - x_ac.

Everything runs on the *scored* scale (PEoU3 reversed, Table 3's convention); the written CSV holds raw answers.
"""
from __future__ import annotations

import copy
import functools
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.paper import audit as A
from analysis.paper import grim, procedure
from analysis.paper import published as P
from analysis.survey.reliability import alpha_from_cov

N_IMPLIED = 40
DEFAULT_SEED = 20240
CONSTRUCTS = P.TABLE4_ORDER

# Loss weights: composite correlations and SDs decide Table 5, so they dominate; the item-level structure
# (loadings, the dropped items) is met as far as it can be without disturbing them.
W_COMPOSITE_R = 1.0e5
W_COMPOSITE_SD = 1.0e5
W_ITEM_WITHIN = 400.0
W_ITEM_ACROSS = 1.0


@dataclass
class Targets:
    """What the reconstruction aims at (all on the scored scale)."""

    n: int
    items: list[str]                       # instrument order
    construct_of: dict[str, str]
    retained: dict[str, list[str]]         # construct -> items kept in the final model
    counts: dict[str, np.ndarray]          # item -> counts of answers 1..5
    mean_printed: dict[str, float]
    sd_printed: dict[str, float]
    sd_decimals: dict[str, int]
    composite_r: pd.DataFrame              # 6x6
    composite_sd: dict[str, float]
    loading_scale: dict[str, float]        # c_k
    item_r: np.ndarray                     # p x p target correlations
    notes: list[str] = field(default_factory=list)

    @property
    def weights_matrix(self) -> np.ndarray:
        """p x 6 composite weights (1/k for the construct's retained items)."""
        w = np.zeros((len(self.items), len(CONSTRUCTS)))
        for j, c in enumerate(CONSTRUCTS):
            for it in self.retained[c]:
                w[self.items.index(it), j] = 1.0 / len(self.retained[c])
        return w


def choose_counts(mean: float, sd: float, n: int, sd_decimals: int, sd_mode: str = "truncate") -> np.ndarray:
    """The count vector (answers 1..5) for a printed mean/SD: GRIMMER candidates, SD nearest the middle of the
    printed interval, then the flattest (largest entropy) shape. Raises ValueError if none exists."""
    cands = grim.grimmer_candidates(mean, sd, n, 3, sd_decimals, sd_mode=sd_mode)
    lo, hi = grim.interval(sd, sd_decimals, sd_mode)
    vals = np.arange(1, 6)
    if not len(cands):
        # no exact fit (GRIMMER-inconsistent pair): keep the mean, take the achievable SD nearest the printed one
        allc, s_all, q_all = grim.count_vectors(n)
        same_mean = np.abs(s_all / n - mean) <= grim.half_unit(3)
        if not same_mean.any():
            raise ValueError(f"no 1-5 distribution of {n} answers has mean {mean}")
        sds_all = grim.sd_from_sums(s_all, q_all, n)
        best = np.min(np.abs(sds_all[same_mean] - (lo + hi) / 2))
        cands = allc[same_mean & (np.abs(np.abs(sds_all - (lo + hi) / 2) - best) < 1e-12)]
    s, q = cands @ vals, cands @ vals ** 2
    sds = grim.sd_from_sums(s, q, n)
    p = cands / n
    entropy = -(np.where(p > 0, p * np.log(np.where(p > 0, p, 1)), 0)).sum(axis=1)
    order = np.lexsort((-entropy, np.round(np.abs(sds - (lo + hi) / 2), 9)))
    return cands[order[0]]


def counts_candidates(mean: float, sd: float, n: int, sd_decimals: int) -> np.ndarray:
    """All GRIMMER candidates (truncated SDs), best first by the rule of :func:`choose_counts`."""
    first = choose_counts(mean, sd, n, sd_decimals)
    cands = grim.grimmer_candidates(mean, sd, n, 3, sd_decimals, sd_mode="truncate")
    rest = [c for c in cands if not np.array_equal(c, first)]
    return np.array([first] + rest)


def choose_pair_counts(c1: np.ndarray, c2: np.ndarray, alpha: float, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """For a 2-item scale: the candidate pair whose reachable α (integer Σxy) is nearest ``alpha``.

    α = 4·cov / (v1 + v2 + 2·cov) with cov = (Σxy - S1·S2/n)/(n - 1); solving for cov and rounding Σxy gives the
    nearest reachable α of each pair. Ties keep the earlier (better by the single-item rule) candidates."""
    vals = np.arange(1, 6)
    best = None
    for i, a in enumerate(c1):
        s1, q1 = a @ vals, a @ vals ** 2
        v1 = (q1 - s1 ** 2 / n) / (n - 1)
        for j, b in enumerate(c2):
            s2, q2 = b @ vals, b @ vals ** 2
            v2 = (q2 - s2 ** 2 / n) / (n - 1)
            cov = alpha * (v1 + v2) / (4 - 2 * alpha)
            sxy = np.round(cov * (n - 1) + s1 * s2 / n)
            cov_r = (sxy - s1 * s2 / n) / (n - 1)
            a_r = 4 * cov_r / (v1 + v2 + 2 * cov_r)
            key = (round(abs(a_r - alpha), 9), i + j)
            if best is None or key < best[0]:
                best = (key, a, b, float(a_r))
    return best[1], best[2], best[3]


def build_targets(published: pd.DataFrame | None = None, n: int = N_IMPLIED) -> Targets:
    """Derive the reconstruction targets from the published values (see the module docstring); those of the
    shipped published values are derived once per process (a copy each call: callers may change theirs)."""
    if published is None:
        return copy.deepcopy(_shipped_targets(n))
    return _build_targets(published, n)


@functools.lru_cache(maxsize=None)
def _shipped_targets(n: int) -> Targets:
    return _build_targets(P.load_published(), n)


def _build_targets(pub: pd.DataFrame, n: int) -> Targets:
    inst = P.paper_study().instrument()
    t3 = P.table3(pub).set_index("item")
    tc = P.table3_constructs(pub).set_index("construct")
    items = [i for i in inst.scaled_items if i in t3.index]
    construct_of = {i: t3.loc[i, "construct"] for i in items}
    retained = {c: [i for i in items if construct_of[i] == c and not t3.loc[i, "omitted"]] for c in CONSTRUCTS}
    dec = pub[(pub["table"] == "table3") & (pub["quantity"] == "sd")].set_index("row")["decimals"].astype(int)
    notes = []
    counts, mean_p, sd_p = {}, {}, {}
    for it in items:
        m, sd = float(t3.loc[it, "mean"]), float(t3.loc[it, "sd"])
        mean_p[it], sd_p[it] = m, sd
        if not grim.grim_consistent(m, n, 3):
            near = round(m * n) / n
            m = near
            c = choose_counts(m, sd, n, int(dec[it]))
            x = np.repeat(np.arange(1, 6), c)
            notes.append(f"{it}: printed M = {mean_p[it]:g}, SD = {sd:g} impossible for N = {n} (GRIM); using the "
                         f"nearest possible mean {m:.3f} and the nearest achievable SD {x.std(ddof=1):.4f}")
        counts[it] = choose_counts(m, sd, n, int(dec[it]))
    for c in CONSTRUCTS:
        if len(retained[c]) == 2:
            i1, i2 = retained[c]
            counts[i1], counts[i2], a_hit = choose_pair_counts(
                counts_candidates(mean_p[i1], sd_p[i1], n, int(dec[i1])),
                counts_candidates(mean_p[i2], sd_p[i2], n, int(dec[i2])), float(tc.loc[c, "alpha"]), n)
            notes.append(f"{c}: {i1}/{i2} distributions chosen jointly so that a reachable Cα ({a_hit:.4f}) is "
                         f"nearest the printed {tc.loc[c, 'alpha']:.3f} (a 2-item α moves in steps of one unit of Σxy)")
    # item SDs as realised by the chosen counts (exact; the printed ones are truncated)
    vals = np.arange(1, 6)
    sd_real = {it: float(np.repeat(vals, counts[it]).std(ddof=1)) for it in items}
    # composite targets: correlations Table 5 fixes, SDs that give the printed Cα with the realised item SDs
    comp_r = A.table5_consistent_correlations(pub).loc[list(CONSTRUCTS), list(CONSTRUCTS)]
    comp_sd = {c: A.composite_sd_from_alpha(np.array([sd_real[i] for i in retained[c]]), tc.loc[c, "alpha"])
               for c in CONSTRUCTS}
    # c_k: scale of r_ij = c λ_i λ_j so that Var(mean of retained items) = comp_sd²
    scale, a = {}, {}
    for c in CONSTRUCTS:
        its = retained[c]
        s = np.array([sd_real[i] for i in its])
        lam = t3.loc[its, "loading"].values.astype(float)
        k = len(its)
        off = np.outer(s * lam, s * lam)
        np.fill_diagonal(off, 0.0)
        scale[c] = float((k ** 2 * comp_sd[c] ** 2 - (s ** 2).sum()) / off.sum())
    for it in items:
        a[it] = np.sqrt(max(scale[construct_of[it]], 0.0)) * float(t3.loc[it, "loading"])
    # Φ_AB so that the composite correlations are met: r_C = Φ w_A w_B, w_A = Σ s_i a_i / (k SD_A)
    w = {c: sum(sd_real[i] * a[i] for i in retained[c]) / (len(retained[c]) * comp_sd[c]) for c in CONSTRUCTS}
    p = len(items)
    T = np.eye(p)
    for i, ii in enumerate(items):
        for j, jj in enumerate(items):
            if i == j:
                continue
            ci, cj = construct_of[ii], construct_of[jj]
            phi = 1.0 if ci == cj else comp_r.loc[ci, cj] / (w[ci] * w[cj])
            T[i, j] = a[ii] * a[jj] * phi
    # within a construct: a matrix under which the paper's procedure (first principal component, audit finding
    # "extraction") gives exactly the printed loadings with the printed Cα (procedure.target_blocks)
    for c, (its, block, how) in procedure.target_blocks(pub).items():
        idx = [items.index(i) for i in its]
        T[np.ix_(idx, idx)] = block
        notes.append(f"{c}: within-construct target under principal components: {how} ({len(its)} items)")
    # a target that no data set can have (not positive semi-definite) is pulled to the nearest correlation matrix
    ev, V = np.linalg.eigh(T)
    if ev.min() < 1e-3:
        notes.append(f"item-level target not positive definite (min eigenvalue {ev.min():.3f}); clipped")
        T = V @ np.diag(np.maximum(ev, 1e-3)) @ V.T
        d = np.sqrt(np.diag(T))
        T = T / np.outer(d, d)
    for c in CONSTRUCTS:
        notes.append(f"{c}: r_ij = {scale[c]:.3f}·λ_iλ_j (composite SD {comp_sd[c]:.4f} from Cα "
                     f"{tc.loc[c, 'alpha']:.3f}); Φ-weight {w[c]:.3f}")
    return Targets(n=n, items=items, construct_of=construct_of, retained=retained, counts=counts,
                   mean_printed=mean_p, sd_printed=sd_p, sd_decimals={k: int(v) for k, v in dec.items()},
                   composite_r=comp_r, composite_sd=comp_sd, loading_scale=scale, item_r=T, notes=notes)


# ----------------------------------------------------------------------------------------------------------------
# The swap search
# ----------------------------------------------------------------------------------------------------------------

class _Objective:
    """Loss of an arrangement, computed from cross-products only, so every swap of a column can be scored at once.

    Terms: Table 5 (every printed R², adj R², ΔR², β, B, SE B, scaled by its tolerance), composite correlations
    and SDs (Table 4 / Cα), and item-level correlations (loading pattern, deleted items)."""

    def __init__(self, targets: Targets, w_r: float = W_COMPOSITE_R, w_sd: float = W_COMPOSITE_SD,
                 w_within: float = W_ITEM_WITHIN, w_across: float = W_ITEM_ACROSS, w_t5: float = 0.0,
                 published: pd.DataFrame | None = None) -> None:
        self.t = targets
        self.w_r, self.w_sd, self.w_t5 = w_r, w_sd, w_t5
        self.n = targets.n
        self.W = targets.weights_matrix
        self.R = targets.composite_r.values
        self.sd_c = np.array([targets.composite_sd[c] for c in CONSTRUCTS])
        p = len(targets.items)
        same = np.array([[targets.construct_of[a] == targets.construct_of[b] for b in targets.items]
                         for a in targets.items])
        m = np.where(same, w_within, w_across)
        np.fill_diagonal(m, 0.0)
        self.M = m
        self.T = targets.item_r
        self.iu = np.triu_indices(len(CONSTRUCTS), 1)
        self.p = p
        self.steps = _table5_steps(published)

    def table5_loss(self, S: np.ndarray) -> np.ndarray:
        """Σ ((value - printed)/tolerance)² over Table 5, for composite covariance(s) S (..., 6, 6)."""
        sd = np.sqrt(np.diagonal(S, axis1=-2, axis2=-1))
        R = S / (sd[..., :, None] * sd[..., None, :])
        n = self.n
        loss = np.zeros(S.shape[:-2])
        r2_of = {}
        for st in self.steps:
            x, y = st["x"], st["y"]
            k = len(x)
            rxx = R[..., x, :][..., :, x]
            rxy = R[..., x, y]
            inv = np.linalg.inv(rxx)
            beta = np.einsum("...ij,...j->...i", inv, rxy)
            r2 = (beta * rxy).sum(-1)
            r2_of[st["key"]] = r2
            ratio = sd[..., y][..., None] / sd[..., x]
            se_b = ratio * np.sqrt(np.maximum(1 - r2, 1e-12)[..., None] / (n - k - 1)
                                   * np.diagonal(inv, axis1=-2, axis2=-1))
            adj = 1 - (1 - r2) * (n - 1) / (n - k - 1)
            d_r2 = r2 - (r2_of[st["prev"]] if st["prev"] else 0.0)
            loss = loss + ((r2 - st["r2"]) / TOL_R2) ** 2 + ((adj - st["adj_r2"]) / TOL_R2) ** 2 \
                + ((d_r2 - st["delta_r2"]) / TOL_R2) ** 2
            loss = loss + (((beta - st["beta"]) / TOL_BETA) ** 2).sum(-1) \
                + (((beta * ratio - st["b"]) / TOL_B) ** 2).sum(-1) + (((se_b - st["se_b"]) / TOL_B) ** 2).sum(-1)
        return loss

    def composite_loss(self, S: np.ndarray) -> np.ndarray:
        """S: (..., 6, 6) composite covariance -> loss (...)."""
        d = np.sqrt(np.diagonal(S, axis1=-2, axis2=-1))
        r = S / (d[..., :, None] * d[..., None, :])
        lr = ((r[..., self.iu[0], self.iu[1]] - self.R[self.iu]) ** 2).sum(-1)
        ls = ((d / self.sd_c - 1.0) ** 2).sum(-1)
        out = self.w_r * lr + self.w_sd * ls
        if self.w_t5:
            out = out + self.w_t5 * self.table5_loss(S)
        return out

    def item_loss(self, C: np.ndarray, sd: np.ndarray) -> float:
        r = C / ((self.n - 1) * np.outer(sd, sd))
        return float(0.5 * (self.M * (r - self.T) ** 2).sum())

    def total(self, C: np.ndarray, sd: np.ndarray) -> float:
        S = self.W.T @ C @ self.W / (self.n - 1)
        return float(self.composite_loss(S)) + self.item_loss(C, sd)


# Table 5 tolerances (docs/contracts.md): ±0.01 for R², adj R², ΔR², β; ±0.02 for B and SE B
TOL_R2, TOL_BETA, TOL_B = 0.01, 0.01, 0.02


def _table5_steps(published: pd.DataFrame | None = None) -> list[dict]:
    """Table 5 as index lists into CONSTRUCTS with the printed values (step order; ΔR² refers to 'prev')."""
    st, co = P.table5_steps(published), P.table5_coefficients(published)
    out = []
    for model, (dv, steps) in P.TABLE5_MODELS.items():
        prev = None
        for step in range(1, len(steps) + 1):
            preds = [p for s in steps[:step] for p in s]
            row = st[(st["model"] == model) & (st["step"] == step)]
            key = f"m{model}s{step}"
            if row.empty:  # model 4 step 1 is printed as "same as model 3 step 1"
                prev = "m3s1"
                continue
            c = co[(co["model"] == model) & (co["step"] == step)].set_index("predictor").loc[preds]
            out.append({"key": key, "prev": prev, "y": CONSTRUCTS.index(dv),
                        "x": [CONSTRUCTS.index(p) for p in preds],
                        "r2": float(row["r2"].iloc[0]), "adj_r2": float(row["adj_r2"].iloc[0]),
                        "delta_r2": float(row["delta_r2"].iloc[0]), "beta": c["beta"].values,
                        "b": c["b"].values, "se_b": c["se_b"].values})
            prev = key
    return out


def _start(targets: Targets, rng: np.random.Generator) -> np.ndarray:
    """Starting arrangement: ranks of a draw from N(0, target) decide which row gets which value (Iman-Conover
    style), so the search begins near the target correlation structure."""
    p, n = len(targets.items), targets.n
    vals = np.arange(1, 6)
    L = np.linalg.cholesky(targets.item_r + 1e-9 * np.eye(p))
    Z = rng.standard_normal((n, p)) @ L.T
    X = np.empty((n, p))
    for j, it in enumerate(targets.items):
        X[np.argsort(Z[:, j], kind="stable"), j] = np.repeat(vals, targets.counts[it]).astype(float)
    return X


def _sweeps(X: np.ndarray, obj: _Objective, rng: np.random.Generator, max_sweeps: int, temp0: float,
            max_pairs: int = 0) -> tuple[np.ndarray, int]:
    """Column-wise best-improvement swaps (all n(n-1)/2 swaps of a column evaluated at once) with a Metropolis
    temperature falling linearly to zero over the first 60 % of the sweeps. Returns (X, sweeps done)."""
    n, p = X.shape
    Xc = X - X.mean(axis=0)
    C = Xc.T @ Xc
    sd = np.sqrt(np.diag(C) / (n - 1))
    W = obj.W
    S = W.T @ C @ W / (n - 1)
    ia, ib = np.triu_indices(n, 1)
    denom = (n - 1) * np.outer(sd, sd)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        temp = temp0 * max(0.0, 1 - sweeps / (0.6 * max_sweeps))
        improved = 0
        for c in rng.permutation(p):
            d = Xc[ib, c] - Xc[ia, c]                       # new x_ac - old x_ac
            live = d != 0
            if not live.any():
                continue
            a_, b_, d = ia[live], ib[live], d[live]
            if max_pairs and len(d) > max_pairs:  # a random subset keeps the expensive Table 5 term affordable
                pick = np.sort(rng.choice(len(d), max_pairs, replace=False))
                a_, b_, d = a_[pick], b_[pick], d[pick]
            delta = d[:, None] * (Xc[a_] - Xc[b_])          # change of C[c, :]
            delta[:, c] = 0.0
            # item part: only row c of the correlation matrix changes
            r_old = C[c] / denom[c]
            r_new = (C[c][None, :] + delta) / denom[c][None, :]
            m, tt = obj.M[c], obj.T[c]
            d_item = ((r_new - tt) ** 2 - (r_old - tt) ** 2) @ m
            # composite part: ΔS = (v uᵀ + u vᵀ)/(n-1), u = Wᵀδ, v = W[c]
            v = W[c]
            if v.any():
                u = delta @ W / (n - 1)
                S_new = S[None] + v[None, :, None] * u[:, None, :] + u[:, :, None] * v[None, None, :]
                d_comp = obj.composite_loss(S_new) - obj.composite_loss(S)
            else:  # an item outside every composite (a deleted item) cannot move them
                S_new, d_comp = None, 0.0
            dl = d_item + d_comp
            k = int(np.argmin(dl))
            accept = dl[k] < -1e-12 or (temp > 0 and rng.random() < np.exp(-dl[k] / temp))
            if not accept:
                continue
            a, b = a_[k], b_[k]
            X[[a, b], c] = X[[b, a], c]
            Xc[[a, b], c] = Xc[[b, a], c]
            C[c, :] += delta[k]
            C[:, c] += delta[k]
            if S_new is not None:
                S = S_new[k]
            improved += 1
        # stop only on the search's own state, never on the clock: the output must not depend on machine load
        if improved == 0 and temp == 0:
            break
    return X, sweeps


# Search phases. 1: the whole structure (composites, loading pattern, deleted items) from the copula start, with a
# Metropolis temperature in loss units. 2: every term in units of its tolerance - Table 5 (±0.01 / ±0.02), composite
# r (±0.01 -> weight 1e4), composite SD (±1 % -> 1e4) - with the item structure as a light tie-breaker; a random
# subset of 150 swaps per column keeps the Table 5 term affordable.
PHASES = (
    dict(w_r=1.0e5, w_sd=1.0e5, w_within=W_ITEM_WITHIN, w_across=W_ITEM_ACROSS, sweeps=300, temp0=3.0),
    dict(w_r=1.0e4, w_sd=1.0e5, w_within=30.0, w_across=0.05, w_t5=1.0, sweeps=150, temp0=0.1, max_pairs=150),
)


def _arrange(targets: Targets, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Arrange the fixed marginals into columns; returns (scored data n x p, info)."""
    t0 = time.perf_counter()
    X = _start(targets, rng)
    ref = _Objective(targets)
    info = {"loss_start": ref.total(*_cross(X)), "sweeps": []}
    for ph in PHASES:
        obj = _Objective(targets, ph["w_r"], ph["w_sd"], ph["w_within"], ph["w_across"], ph.get("w_t5", 0.0))
        X, k = _sweeps(X, obj, rng, ph["sweeps"], ph["temp0"], ph.get("max_pairs", 0))
        info["sweeps"].append(k)
    info["loss"] = ref.total(*_cross(X))
    info["seconds"] = time.perf_counter() - t0
    return X.astype(int), info


def _cross(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    Xc = X - X.mean(axis=0)
    C = Xc.T @ Xc
    return C, np.sqrt(np.diag(C) / (len(X) - 1))


# ----------------------------------------------------------------------------------------------------------------
# Result
# ----------------------------------------------------------------------------------------------------------------

def composite_scores(scored: pd.DataFrame, retained: dict[str, list[str]]) -> pd.DataFrame:
    """Composites = mean of each construct's retained (scored) items."""
    return pd.DataFrame({c: scored[its].mean(axis=1) for c, its in retained.items()})


def regression_table(comp: pd.DataFrame) -> pd.DataFrame:
    """Table 5's models by OLS on the composites: model, step, dv, predictor, r2, adj_r2, delta_r2, b, se_b, beta."""
    rows = []
    n = len(comp)
    for model, (dv, steps) in P.TABLE5_MODELS.items():
        prev_r2 = 0.0
        y = comp[dv].values
        for step in range(1, len(steps) + 1):
            preds = [p for s in steps[:step] for p in s]
            Xm = np.column_stack([np.ones(n)] + [comp[p].values for p in preds])
            coef, *_ = np.linalg.lstsq(Xm, y, rcond=None)
            resid = y - Xm @ coef
            k = len(preds)
            sse = float(resid @ resid)
            sst = float(((y - y.mean()) ** 2).sum())
            r2 = 1 - sse / sst
            cov = sse / (n - k - 1) * np.linalg.inv(Xm.T @ Xm)
            for j, pname in enumerate(preds):
                rows.append({"model": model, "step": step, "dv": dv, "predictor": pname, "r2": r2,
                             "adj_r2": 1 - (1 - r2) * (n - 1) / (n - k - 1), "delta_r2": r2 - prev_r2,
                             "b": coef[j + 1], "se_b": float(np.sqrt(cov[j + 1, j + 1])),
                             "beta": coef[j + 1] * comp[pname].std(ddof=1) / comp[dv].std(ddof=1)})
            prev_r2 = r2
    return pd.DataFrame(rows)


@dataclass
class Reconstruction:
    """The generated data (raw answers, survey CSV of docs/contracts.md), its targets and how close it came."""

    data: pd.DataFrame
    targets: Targets
    seed: int
    info: dict

    def scored(self) -> pd.DataFrame:
        return P.paper_study().instrument().reverse(self.data[self.targets.items])

    def write(self, path: str | Path) -> Path:
        """Write the survey CSV (byte-identical for the same seed)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.data.to_csv(path, index=False, lineterminator="\n")
        return path

    def deltas(self) -> pd.DataFrame:
        """Achieved vs published: quantity, key, published, achieved, delta (on the scored scale)."""
        t = self.targets
        sc = self.scored()
        pub = P.load_published()
        rows = []
        for it in t.items:
            rows.append(("mean", it, t.mean_printed[it], float(sc[it].mean())))
            # SDs are printed truncated: compare the truncated value
            sd = float(sc[it].std(ddof=1))
            unit = 10.0 ** -t.sd_decimals[it]
            rows.append(("sd (truncated)", it, t.sd_printed[it], np.floor(sd / unit + 1e-9) * unit))
        comp = composite_scores(sc, t.retained)
        cr = comp.corr()
        t4 = P.table4_matrix(pub)
        for i, a in enumerate(CONSTRUCTS):
            for b in CONSTRUCTS[i + 1:]:
                rows.append(("composite r (Table 4)", f"{a}-{b}", float(t4.loc[a, b]), float(cr.loc[a, b])))
        tc = P.table3_constructs(pub).set_index("construct")
        for c in CONSTRUCTS:
            cov = sc[t.retained[c]].cov().values
            rows.append(("alpha", c, float(tc.loc[c, "alpha"]), alpha_from_cov(cov)))
        reg = regression_table(comp)
        co = P.table5_coefficients(pub)
        st = P.table5_steps(pub)
        for r in st.itertuples():
            g = reg[(reg["model"] == r.model) & (reg["step"] == r.step)].iloc[0]
            for q in ("r2", "adj_r2", "delta_r2"):
                rows.append((q, f"m{r.model}s{r.step}", getattr(r, q), float(g[q])))
        for r in co.itertuples():
            g = reg[(reg["model"] == r.model) & (reg["step"] == r.step) & (reg["predictor"] == r.predictor)].iloc[0]
            for q in ("b", "se_b", "beta"):
                rows.append((q, f"m{r.model}s{r.step} {r.predictor}", getattr(r, q), float(g[q])))
        df = pd.DataFrame(rows, columns=["quantity", "key", "published", "achieved"])
        df["delta"] = df["achieved"] - df["published"]
        return df

    def summary_text(self) -> str:
        d = self.deltas()
        lines = [f"swap search: {'+'.join(map(str, self.info['sweeps']))} sweeps, loss {self.info['loss_start']:.4g} -> "
                 f"{self.info['loss']:.4g} in {self.info['seconds']:.1f} s"]
        for q, g in d.groupby("quantity", sort=False):
            k = g["delta"].abs().idxmax()
            lines.append(f"  {q:24s} max |delta| {abs(d.loc[k, 'delta']):.4f} ({d.loc[k, 'key']})")
        return "\n".join(lines)


def reconstruct(seed: int = DEFAULT_SEED, published: pd.DataFrame | None = None, n: int = N_IMPLIED,
                participant_ids: list[str] | None = None) -> Reconstruction:
    """Generate the reconstructed survey (raw answers; PEoU3 not reversed) for ``seed``.

    ``participant_ids`` default to the survey respondents of the reference cohort with the same seed."""
    targets = build_targets(published, n)
    rng = np.random.default_rng(seed)
    X, info = _arrange(targets, rng)
    if participant_ids is None:
        from analysis.paper.reference_cohort import make_cohort

        participant_ids = make_cohort(seed=seed).survey_ids()
    if len(participant_ids) != n:
        raise ValueError(f"{len(participant_ids)} participant ids for {n} respondents")
    scored = pd.DataFrame(X, columns=targets.items)
    raw = P.paper_study().instrument().reverse(scored)          # reversing twice = raw answers
    data = pd.concat([pd.DataFrame({"participant_id": list(participant_ids)}), raw.astype(int)], axis=1)
    return Reconstruction(data=data, targets=targets, seed=seed, info=info)

"""Synthetic survey data for the tests and the benchmarks.

- :func:`simulate_study_responses` / :func:`simulate_study_participants`: seeded synthetic survey answers and
  participant attributes for any study: one factor per construct of the study's instrument, loadings ~0.8,
  discretised to each item's scale, reverse-scored items generated negatively keyed (raw, as a participant ticks
  them). Test fixtures, not a model of any real survey.
"""
from __future__ import annotations

import re

import numpy as np
import pandas as pd

from analysis.survey.mvn import cholesky, draw


def participant_ids(study, n: int) -> list[str]:
    """`n` ids in the study's own format: the number at the end of ``id_example`` counted up with its width
    (``LK-01`` -> LK-01, LK-02, ...; ``P001`` -> P001, P002, ...); each is checked against the id pattern.

    Examples
    --------
    >>> from analysis.survey.testing import participant_ids
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> participant_ids(load(REPO_ROOT / "studies" / "lane_keeping"), 3)
    ['LK-01', 'LK-02', 'LK-03']
    """
    m = re.fullmatch(r"(.*?)(\d+)(\D*)", study.id_example)
    if m is None:
        raise ValueError(f"id example {study.id_example!r} ends in no number to count up")
    head, digits, tail = m.groups()
    return [study.validate_id(f"{head}{i:0{len(digits)}d}{tail}") for i in range(1, n + 1)]


def _thresholds(k: int) -> np.ndarray:
    """k - 1 cut points on the latent (standard normal) scale for a k-point item: answers lean towards agreement,
    as acceptance answers usually do (the middle category sits at about -0.3 SD)."""
    return np.linspace(-2.0, 1.4, k + 1)[1:-1]


def simulate_study_responses(study, n: int = 40, seed: int = 1, *, instrument=None, loading: float = 0.8,
                             phi=0.4, signals: dict[str, dict[str, float]] | None = None,
                             thresholds=None, latent: str = "cholesky") -> pd.DataFrame:
    """Wide survey frame (participant_id + every scaled item of the study's instrument, raw answers as ticked) of
    `n` synthetic participants with a clean factor structure.

    One latent factor per construct of the instrument (standard normal, correlation `phi`: one number for every
    pair, or a construct x construct matrix/DataFrame in the instrument's construct order); an item is
    ``loading * signal + sqrt(1 - loading^2) * noise``, where the signal is its construct's factor or, for an item
    in `signals`, the weighted sum {construct: weight} of factors; a reverse-scored item is generated negatively
    keyed (as a participant ticks it). The continuous value is cut into the item's scale_min..scale_max by
    `thresholds` (default: evenly spaced cut points leaning towards agreement, :func:`_thresholds`).
    Deterministic for (study, n, seed, options) on every machine: the factors are drawn with :mod:`analysis.survey.mvn`
    (no BLAS). ``latent="numpy-svd"`` draws them with numpy's ``multivariate_normal`` instead, as the generator did
    before; its bits depend on the OpenBLAS kernel (the committed test data of tests/data were drawn that way under
    ``OPENBLAS_CORETYPE=Haswell``). A test fixture, not a model of any real survey.

    Examples
    --------
    >>> from analysis.survey.testing import simulate_study_responses
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> data = simulate_study_responses(load(REPO_ROOT / "studies" / "lane_keeping"), 24, seed=7)
    >>> data.shape, data["participant_id"].iloc[-1], int(data["PE1"].min()) >= 1, int(data["PE1"].max()) <= 7
    ((24, 13), 'LK-24', True, True)
    """
    from analysis.survey.scoring import resolve_instrument

    inst = resolve_instrument(study, instrument)
    factors = list(inst.constructs)
    if np.isscalar(phi):
        corr = np.full((len(factors), len(factors)), float(phi))
        np.fill_diagonal(corr, 1.0)
    else:
        corr = np.asarray(phi.loc[factors, factors] if isinstance(phi, pd.DataFrame) else phi, dtype=float)
    rng = np.random.default_rng(seed)
    if latent == "cholesky":
        eta = draw(cholesky(corr.tolist()), [0.0] * len(factors), n, rng)
    elif latent == "numpy-svd":
        eta = rng.multivariate_normal(np.zeros(len(factors)), corr, size=n)
    else:
        raise ValueError(f"latent must be 'cholesky' or 'numpy-svd', not {latent!r}")
    col = {f: k for k, f in enumerate(factors)}
    out = {"participant_id": participant_ids(study, n)}
    for c, items in inst.constructs.items():
        for item in items:
            weights = (signals or {}).get(item, {c: 1.0})
            signal = sum(w * eta[:, col[f]] for f, w in weights.items())
            x = loading * signal + np.sqrt(1 - loading ** 2) * rng.standard_normal(n)
            if item in inst.reverse_items:
                x = -x
            lo, hi = inst.scale(item)
            cuts = _thresholds(hi - lo + 1) if thresholds is None else np.asarray(thresholds, float)
            out[item] = np.clip(np.digitize(x, cuts) + lo, lo, hi).astype(int)
    return pd.DataFrame(out)


def simulate_study_participants(study, n: int = 40, seed: int = 1) -> pd.DataFrame:
    """participant_id + one column per declared attribute for `n` synthetic participants (the ids of
    :func:`simulate_study_responses`): a number within min..max drawn around min + 30 % of the range (SD a sixth of
    it; whole numbers for an integer attribute), a choice drawn uniformly, a text attribute left empty. Seeded by
    `seed` (its own stream: the answers of the same seed do not change when attributes are added).

    Examples
    --------
    >>> from analysis.survey.testing import simulate_study_participants
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> p = simulate_study_participants(load(REPO_ROOT / "studies" / "lane_keeping"), 24, seed=7)
    >>> list(p.columns), bool(p["age"].between(18, 90).all())
    (['participant_id', 'age', 'gender', 'km_per_year'], True)
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1]))
    out: dict[str, list] = {"participant_id": participant_ids(study, n)}
    for a in study.attributes:
        if a.type in ("integer", "number"):
            lo = 0.0 if a.min is None else float(a.min)
            hi = lo + 100.0 if a.max is None else float(a.max)
            x = np.clip(rng.normal(lo + 0.3 * (hi - lo), (hi - lo) / 6.0, n), lo, hi)
            out[a.name] = [int(v) for v in np.round(x)] if a.type == "integer" else [float(v) for v in np.round(x, 1)]
        elif a.type == "choice":
            out[a.name] = [str(v) for v in rng.choice(list(a.choices), n)]
        else:
            out[a.name] = [None] * n
    return pd.DataFrame(out)

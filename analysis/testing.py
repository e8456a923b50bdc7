"""Independent reference implementations and synthetic data for the tests and the benchmarks.

- :func:`kpis_pandas`: the KPIs of :mod:`analysis.kpis` computed again in pandas (vectorised group shifts; same
  definitions, same output columns), independently of the SQL: the cross-check of the SQL in the tests and the
  peer of ``pedas-study bench kpi``.
- :func:`simulate_study_responses` / :func:`simulate_study_participants`: seeded synthetic survey answers and
  participant attributes for any study: one factor per construct of the study's instrument, loadings ~0.8,
  discretised to each item's scale, reverse-scored items generated negatively keyed (raw, as a participant ticks
  them). Test fixtures, not a model of any real survey.
"""
from __future__ import annotations

import re

import numpy as np
import pandas as pd

from analysis.kpis import KPI_FIELDS, ROUTE_SEGMENTS, SEGMENTS, KpiParams
from analysis.mvn import cholesky, draw


def kpis_pandas(samples: pd.DataFrame, params: KpiParams | None = None) -> pd.DataFrame:
    """The KPIs of :mod:`analysis.kpis` computed with pandas (vectorised; same definitions, same output columns).
    ``samples`` has the :data:`analysis.kpis.KPI_COLUMNS`."""
    p = params or KpiParams()
    df = samples.sort_values(["drive_id", "idx"], kind="stable").reset_index(drop=True)
    g = df.groupby("drive_id", sort=False)
    t, v, s, lim = df["t"], df["v"], df["s"], df["speed_limit"]
    dt = g["t"].shift(-1) - t
    ds = g["s"].shift(-1) - s
    p_mid = (df["p_batt"] + g["p_batt"].shift(-1)) / 2.0
    a0 = df["a"].astype(float)  # the caller fills a missing `a` (analysis.kpis.fill_acceleration)
    a1 = g["a"].shift(-1).astype(float)
    viol = (v > lim + np.maximum(p.tol_abs, p.tol_rel * lim))
    first = ~df["drive_id"].duplicated()
    viol_chg = first | (viol != viol.shift(1))
    st = pd.Series(np.where(v < p.v_stop, "S", np.where(v > p.v_moving, "M", None)), index=df.index)
    st_prev = st.shift(1).where(~first, None)
    st_chg = st.notna() & ((st != st_prev) | st_prev.isna())
    tl_prev = g["tl_id"].shift(1)
    tl_chg = ~((df["tl_id"] == tl_prev) | (df["tl_id"].isna() & tl_prev.isna()))
    red_cand = (v < p.v_stop) & (df["tl_state"] == "red") & (df["d_tl"] < p.red_stop_dist) & df["tl_id"].notna()

    has = dt.notna()
    jerk_ok = has & a0.notna() & a1.notna() & (dt > 0)
    jerk2 = (((a1 - a0) / dt) ** 2 * dt).where(jerk_ok, 0.0)
    work = pd.DataFrame({
        "drive_id": df["drive_id"], "segment": df["segment"], "n_intervals": has.astype(int),
        "energy_wh": (p_mid * dt) / 3600.0, "distance_m": ds, "trip_time_s": dt,
        "violation_distance_m": ds.where(viol, 0.0), "jerk2_dt": jerk2, "jerk_time": dt.where(jerk_ok, 0.0),
        "abs_a_dt": (a0.abs() * dt), "a_time": dt.where(a0.notna()),
    })
    keys = ["drive_id", "segment"]
    seg = work.groupby(keys, sort=False).sum(min_count=1).reset_index()

    # violation episodes: from a change point to the next change point of the drive (or the drive's end)
    t_end = g["t"].transform("max")
    vc = df.loc[viol_chg, ["drive_id", "segment", "t"]].assign(viol=viol[viol_chg], t_end=t_end[viol_chg])
    nxt = vc.groupby("drive_id", sort=False)["t"].shift(-1).fillna(vc["t_end"])
    ev = vc[vc["viol"] & ((nxt - vc["t"]) >= p.min_event_s)]
    viol_ev = ev.groupby(keys, sort=False).size().rename("violation_events")
    # stops (hysteresis): an S change point whose previous change point is M
    sc = df.loc[st_chg, ["drive_id", "segment"]].assign(st=st[st_chg])
    before = sc.groupby("drive_id", sort=False)["st"].shift(1)
    stops = sc[(sc["st"] == "S") & (before == "M")].groupby(keys, sort=False).size().rename("stops")
    # crossings: tl_id changes away from a light; state and segment of the sample before
    cr_mask = tl_chg & tl_prev.notna()
    appr = tl_chg.astype(int).groupby(df["drive_id"], sort=False).cumsum()   # approach number per sample
    appr_before = appr.groupby(df["drive_id"], sort=False).shift(1)     # a crossing belongs to the approach it ends
    cr = pd.DataFrame({"drive_id": df["drive_id"][cr_mask], "segment": g["segment"].shift(1)[cr_mask],
                       "state": g["tl_state"].shift(1)[cr_mask], "appr": appr_before[cr_mask].astype("int64")})
    cross = cr.groupby(keys, sort=False)["state"].agg(
        tl_crossed="size", tl_crossed_green=lambda x: (x == "green").sum(),
        tl_crossed_yellow=lambda x: (x == "yellow").sum(), tl_crossed_red=lambda x: (x == "red").sum())
    # red stops: once per approach (run of one tl_id)
    rc = pd.DataFrame({"drive_id": df["drive_id"], "appr": appr, "segment": df["segment"]})[red_cand]
    red = rc.groupby(["drive_id", "appr"], sort=False)["segment"].first().reset_index()
    red_ev = red.groupby(keys, sort=False).size().rename("red_stops")
    # green passes: crossings in green whose approach had no red stop
    stopped = pd.MultiIndex.from_frame(red[["drive_id", "appr"]])
    gp = cr[(cr["state"] == "green") & ~pd.MultiIndex.from_frame(cr[["drive_id", "appr"]]).isin(stopped)]
    green_ev = gp.groupby(keys, sort=False).size().rename("tl_green_passes")

    for part in (viol_ev, stops, cross, red_ev, green_ev):
        seg = seg.merge(part.reset_index(), on=keys, how="left")
    counts = ["violation_events", "stops", "tl_crossed", "tl_crossed_green", "tl_crossed_yellow",
              "tl_crossed_red", "red_stops", "tl_green_passes"]
    seg[counts] = seg[counts].fillna(0).astype("int64")
    seg = seg[seg["segment"].isin(ROUTE_SEGMENTS)]
    overall = seg.drop(columns="segment").groupby("drive_id", sort=False).sum(min_count=1).reset_index()
    overall["segment"] = "overall"
    out = pd.concat([seg, overall], ignore_index=True)
    out["mean_speed_mps"] = out["distance_m"] / out["trip_time_s"].replace(0, np.nan)
    out["wh_per_km"] = out["energy_wh"] / (out["distance_m"] / 1000.0).replace(0, np.nan)
    out["violation_share"] = out["violation_distance_m"] / out["distance_m"].replace(0, np.nan)
    out["rms_jerk"] = np.sqrt(out["jerk2_dt"] / out["jerk_time"].replace(0, np.nan))
    out["mean_abs_a"] = out["abs_a_dt"] / out["a_time"].replace(0, np.nan)
    order = {s: i for i, s in enumerate(SEGMENTS)}
    out = out.sort_values(["drive_id", "segment"], key=lambda c: c.map(order) if c.name == "segment" else c)
    return out[list(KPI_FIELDS)].reset_index(drop=True)


def participant_ids(study, n: int) -> list[str]:
    """`n` ids in the study's own format: the number at the end of ``id_example`` counted up with its width
    (``LK-01`` -> LK-01, LK-02, ...; ``P001`` -> P001, P002, ...); each is checked against the id pattern.

    Examples
    --------
    >>> from analysis.testing import participant_ids
    >>> from pedas.paths import REPO_ROOT
    >>> from study.definition import load
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
    Deterministic for (study, n, seed, options) on every machine: the factors are drawn with :mod:`analysis.mvn`
    (no BLAS). ``latent="numpy-svd"`` draws them with numpy's ``multivariate_normal`` instead, as the generator did
    before; its bits depend on the OpenBLAS kernel (the committed test data of tests/data were drawn that way under
    ``OPENBLAS_CORETYPE=Haswell``). A test fixture, not a model of any real survey.

    Examples
    --------
    >>> from analysis.testing import simulate_study_responses
    >>> from pedas.paths import REPO_ROOT
    >>> from study.definition import load
    >>> data = simulate_study_responses(load(REPO_ROOT / "studies" / "lane_keeping"), 24, seed=7)
    >>> data.shape, data["participant_id"].iloc[-1], int(data["PE1"].min()) >= 1, int(data["PE1"].max()) <= 7
    ((24, 13), 'LK-24', True, True)
    """
    from analysis.scoring import resolve_instrument

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
    >>> from analysis.testing import simulate_study_participants
    >>> from pedas.paths import REPO_ROOT
    >>> from study.definition import load
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

"""An independent reference implementation of the drive KPIs, for the tests and the benchmarks.

:func:`kpis_pandas`: the KPIs of :mod:`analysis.drives.kpis` computed again in pandas (vectorised group shifts; same
definitions, same output columns), independently of the SQL: the cross-check of the SQL in the tests and the peer of
``pedas-study bench kpi``.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.drives.kpis import KPI_FIELDS, ROUTE_SEGMENTS, SEGMENTS, KpiParams


def kpis_pandas(samples: pd.DataFrame, params: KpiParams | None = None) -> pd.DataFrame:
    """The KPIs of :mod:`analysis.drives.kpis` computed with pandas (vectorised; same definitions, same output columns).
    ``samples`` has the :data:`analysis.drives.kpis.KPI_COLUMNS`."""
    p = params or KpiParams()
    df = samples.sort_values(["drive_id", "idx"], kind="stable").reset_index(drop=True)
    g = df.groupby("drive_id", sort=False)
    t, v, s, lim = df["t"], df["v"], df["s"], df["speed_limit"]
    dt = g["t"].shift(-1) - t
    ds = g["s"].shift(-1) - s
    p_mid = (df["p_batt"] + g["p_batt"].shift(-1)) / 2.0
    a0 = df["a"].astype(float)  # the caller fills a missing `a` (analysis.drives.kpis.fill_acceleration)
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

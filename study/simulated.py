"""Simulated drives in the store: who is simulated, how a simulated drive is stored and its one-line summary.

Virtual participants drive the study route in SUMO traffic (:mod:`pedas.cohort`); their logs go through the
drive import (:func:`study.drives.import_drive_frame`, source 'simulation') like a lab's logs.
"""
from __future__ import annotations

import pandas as pd

ROUTE_NAME = "study-13.2km"


def participants_to_simulate(st, ids: list[str] | None = None) -> pd.DataFrame:
    """participant_id and style of the given participants (all when `ids` is None), sorted by ID; UserError for
    an unknown ID."""
    from study.participants import require

    if ids is not None:
        for pid in ids:
            require(st, pid)
    df = st.df("SELECT participant_id, style FROM participants ORDER BY participant_id")
    if ids is not None:
        df = df[df["participant_id"].isin(ids)]
    return df.reset_index(drop=True)


def drive_settings(df: pd.DataFrame, task) -> dict:
    """The settings stored with a simulated drive: the drive loop's own (without its machine-dependent wall time),
    the participant seed, the style and the route."""
    info = dict(df.attrs.get("drive", {}))
    info.pop("wall_s", None)
    info.update({"participant_seed": task.seed, "style": task.style, "route": ROUTE_NAME})
    return info


def store_simulated(st, tasks, results: dict, replace: bool = False) -> list[tuple]:
    """Import the simulated drive of every task (`results`: {(participant_id, condition): log}) in task order;
    [(task, log, import result)]."""
    from study.drives import import_drive_frame

    out = []
    for task in tasks:
        df = results[(task.participant_id, task.condition)]
        r = import_drive_frame(st, task.participant_id, task.condition, df, source="simulation", route=ROUTE_NAME,
                               replace=replace, seed=task.seed, meta=drive_settings(df, task))
        out.append((task, df, r))
    return out


def summary_line(task, df: pd.DataFrame, r) -> str:
    """One line per simulated drive: participant, condition, style, import status, samples, duration, energy and
    the traffic lights passed in green without a stop."""
    from pedas.drive import green_crossings

    g = green_crossings(df)
    e_wh = float((df["p_batt"] * df["t"].diff().fillna(0.0)).sum()) / 3600.0
    return (f"{task.participant_id} {task.condition:<8} {task.style:<8} {r.status:<9} {r.n_samples:>5} samples "
            f"{df['t'].iloc[-1]:7.1f} s {e_wh:7.1f} Wh  lights passed in green without a stop "
            f"{int(g['green_pass'].sum())}/{len(g)}")

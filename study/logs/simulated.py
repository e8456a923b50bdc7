"""Simulated drives in the store: who is simulated, how a simulated drive is stored and its one-line summary.

Virtual participants drive the study route in SUMO traffic (:mod:`pedas.cohort`); their logs go through the
drive import (:func:`study.logs.importing.import_drive_frame`, source 'simulation') like a lab's logs. The simulator drives
its own conditions and driving styles (:mod:`pedas.vocabulary`): a study can be simulated when it declares those
conditions; a participant's ``style`` attribute (when the study declares one) chooses the virtual driver.
"""
from __future__ import annotations

import pandas as pd

from study.common.errors import UserError

#: the route every simulated drive is stored with (the simulator's 13.2 km study route; its route file's name)
ROUTE_NAME = "study-13.2km"


def check_simulable(study) -> None:
    """UserError unless `study` declares every condition the simulator drives (pedas.vocabulary.CONDITIONS)."""
    from pedas.vocabulary import CONDITIONS

    missing = [c for c in CONDITIONS if c not in study.condition_names]
    if missing:
        raise UserError(f"study {study.study_id} cannot be simulated: the simulator drives the conditions "
                        f"{', '.join(CONDITIONS)}; the study declares {', '.join(study.condition_names)}")


def participants_to_simulate(st, ids: list[str] | None = None) -> pd.DataFrame:
    """participant_id and style of the given participants (all when `ids` is None), sorted by ID.

    The style is the participant attribute ``style`` (study.people.participants.participant_attributes); None when the
    study declares no such attribute or the participant has no value (simulated as 'normal'). An unknown ID, a
    study whose conditions the simulator does not drive, or a style the simulator does not know -> UserError.
    """
    from pedas.vocabulary import STYLES
    from study.people.participants import participant_attributes, require
    from study.store.studies import definition

    check_simulable(definition(st))
    if ids is not None:
        for pid in ids:
            require(st, pid)
    attrs = participant_attributes(st, ids)
    styles = attrs["style"] if "style" in attrs.columns else pd.Series([None] * len(attrs), dtype=object)
    styles = [s if isinstance(s, str) and s else None for s in styles]
    for pid, style in zip(attrs["participant_id"], styles):
        if style is not None and style not in STYLES:
            raise UserError(f"{pid}: the simulator has no driving style {style!r} ({'|'.join(STYLES)})")
    return pd.DataFrame({"participant_id": pd.Series(list(attrs["participant_id"]), dtype=object),
                         "style": pd.Series(styles, dtype=object)})


def drive_settings(df: pd.DataFrame, task) -> dict:
    """The settings stored with a simulated drive: the drive loop's own (without its machine-dependent wall time),
    the participant seed, the style, the route, and where its battery power comes from (the simulator's vehicle
    model, pedas.params.LEAF)."""
    from study.logs.importing import ENERGY_MODELS

    info = dict(df.attrs.get("drive", {}))
    info.pop("wall_s", None)
    info.update({"participant_seed": task.seed, "style": task.style, "route": ROUTE_NAME,
                 "energy_source": f"modelled ({ENERGY_MODELS['nissan_leaf']})"})
    return info


def store_simulated(st, tasks, results: dict, replace: bool = False) -> list[tuple]:
    """Import the simulated drive of every task (`results`: {(participant_id, condition): log}) in task order;
    [(task, log, import result)]. What the HUD of a pEDAS drive showed (its columns
    :data:`pedas.drive.HUD_LOG_COLUMNS`) is stored as the drive's HUD channels (:mod:`study.logs.hud_channels`), so that
    its replay shows exactly that."""
    from study.logs.importing import import_drive_frame

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

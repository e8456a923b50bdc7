"""SUMO floating-car data (FCD XML, ``sumo --fcd-output``) as a drive log of one vehicle.

The file is read as a stream (xml.etree.ElementTree.iterparse): one ``<timestep time=...>`` per simulation step
with one ``<vehicle id=... x= y= speed= pos= lane= .../>`` per vehicle. :func:`read_fcd` returns one row per step
in which the vehicle appears: ``time`` and every attribute of its element (numbers as float64, ``lane``, ``type``
and other text as text), plus two positions along its trip (m) for a log mapping's ``s``:

* ``start_lane_distance`` — the vehicle's position on its first lane plus the distance travelled since
  (``odometer``, recorded with ``--fcd-output.attributes odometer``; without it the x/y path length): the route
  position when the route starts at the start of that lane;
* ``xy_distance`` — the length of the x/y path from the first sample.

SUMO's own units: time s, x/y/pos/odometer m, speed m/s, acceleration m/s², slope and angle in degrees.
"""
from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from study.errors import UserError

TEXT_ATTRIBUTES = ("id", "lane", "edge", "type", "signals")


def _open(path: Path):
    return gzip.open(path, "rb") if path.name.lower().endswith(".gz") else open(path, "rb")


def read_fcd(path: str | Path, vehicle: str | None = None) -> pd.DataFrame:
    """The FCD rows of `vehicle` (None: the file's only vehicle) as a DataFrame (see the module docstring).

    A missing file, a file that is not FCD XML, an unknown vehicle or an ambiguous choice -> UserError.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    rows: list[dict] = []
    seen: dict[str, None] = {}
    t = root = None
    try:
        with _open(path) as f:
            for event, el in ET.iterparse(f, events=("start", "end")):
                if event == "start":
                    if root is None:
                        root = el.tag
                        if root != "fcd-export":
                            raise UserError(f"{path.name}: not SUMO FCD output (element <{el.tag}>, "
                                            f"expected <fcd-export>)")
                    if el.tag == "timestep":
                        t = el.get("time")
                    continue
                if el.tag == "vehicle":
                    vid = el.get("id")
                    seen.setdefault(vid, None)
                    if vehicle is None or vid == vehicle:
                        rows.append(dict(el.attrib, time=t))
                elif el.tag == "timestep":
                    el.clear()  # streaming: a long run's file is never held in memory
    except ET.ParseError as exc:
        raise UserError(f"{path.name}: not readable XML: {exc}") from None
    if vehicle is None and len(seen) > 1:
        ids = list(seen)
        raise UserError(f"{path.name} holds {len(ids)} vehicles ({', '.join(ids[:5])}{', ...' if len(ids) > 5 else ''}): "
                        f"name one with --vehicle (or [log] vehicle in the mapping)")
    if not rows:
        raise UserError(f"{path.name}: no vehicle {vehicle!r} in this FCD file"
                        f"{' (vehicles: ' + ', '.join(list(seen)[:5]) + ')' if seen else ' (no vehicles)'}")
    return _frame(rows)


def _frame(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    for col in df.columns:
        if col not in TEXT_ATTRIBUTES:
            conv = pd.to_numeric(df[col], errors="coerce")
            if conv.notna().sum() == df[col].notna().sum():  # numeric attribute (text ones stay text)
                df[col] = conv.astype("float64")
    x, y = df.get("x"), df.get("y")
    if x is not None and y is not None:
        xy = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x.to_numpy()), np.diff(y.to_numpy())))])
        df["xy_distance"] = xy
    else:
        xy = None
    if "pos" in df.columns:
        travelled = df["odometer"].to_numpy() - df["odometer"].iloc[0] if "odometer" in df.columns else xy
        if travelled is not None:
            df["start_lane_distance"] = float(df["pos"].iloc[0]) + travelled
    front = ["time"] + [c for c in df.columns if c != "time"]
    return df[front]

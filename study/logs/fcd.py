"""SUMO floating-car data (FCD XML, ``sumo --fcd-output``) as a drive log of one vehicle.

The file is read as a stream (xml.etree.ElementTree.iterparse): one ``<timestep time=...>`` per simulation step
with one ``<vehicle id=... x= y= speed= pos= lane= .../>`` per vehicle. :func:`read_fcd` returns one row per step
in which the vehicle appears: ``time`` and every attribute of its element (numbers as float64, ``lane``, ``type``
and other text as text), and:

* ``time`` — s since the vehicle's first sample (SUMO's clock minus that sample's time: a vehicle that departs at
  SUMO time 300 s starts its drive at 0); ``sumo_time`` — SUMO's clock (s), by which traffic-light programs run;
* ``acceleration`` — SUMO's value when the file has it (``--fcd-output.acceleration``, off by default), else
  derived from the speed as SUMO defines it, the backward difference over the step that ends at the sample:
  a[i] = (v[i] − v[i−1]) / (t[i] − t[i−1]) for i ≥ 1 and a[0] = 0 (SUMO reports 0 at a vehicle's insertion);
  ``DataFrame.attrs["derived"]`` then names it;
* two positions along its trip (m) for a log mapping's ``s``: ``start_lane_distance`` — the vehicle's position on
  its first lane plus the distance travelled since (``odometer``, recorded with ``--fcd-output.attributes
  odometer``; without it the x/y path length): the route position when the route starts at the start of that lane;
  ``xy_distance`` — the length of the x/y path from the first sample.

SUMO's own units: time s, x/y/pos/odometer m, speed m/s, acceleration m/s², slope and angle in degrees.
"""
from __future__ import annotations

import gzip
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from study.common.errors import UserError, shown

TEXT_ATTRIBUTES = ("id", "lane", "edge", "type", "signals")
LISTED_IDS = 20   # vehicle ids a message lists (sorted); a longer list ends in "..."


def _open(path: Path):
    return gzip.open(path, "rb") if path.name.lower().endswith(".gz") else open(path, "rb")


def _natural(vid: str) -> list:
    """Sort key: digits as numbers (car2 before car10)."""
    return [(0, int(p), "") if p.isdigit() else (1, 0, p) for p in re.split(r"(\d+)", vid) if p]


def likely_ego(samples: dict[str, int]) -> str | None:
    """The vehicle most likely to be the driven one: the id ``ego`` (any case), else the only id containing
    ``ego``, else the vehicle with the most samples (the longest in the file; ties: the first id sorted)."""
    if not samples:
        return None
    named = [v for v in samples if v.lower() == "ego"] or [v for v in samples if "ego" in v.lower()]
    if len(named) == 1:
        return named[0]
    return min(samples, key=lambda v: (-samples[v], _natural(v)))


def vehicles_text(samples: dict[str, int]) -> str:
    """``N vehicles (id, id, ...)`` sorted (the first :data:`LISTED_IDS`), naming the likely ego."""
    ids = sorted(samples, key=_natural)
    shown = ", ".join(ids[:LISTED_IDS]) + (f", ... ({len(ids) - LISTED_IDS} more)" if len(ids) > LISTED_IDS else "")
    return f"{len(ids)} vehicle{'s' if len(ids) != 1 else ''} ({shown}; likely the ego: {likely_ego(samples)})"


def read_fcd(path: str | Path, vehicle: str | None = None) -> pd.DataFrame:
    """The FCD rows of `vehicle` (None: the file's only vehicle) as a DataFrame (see the module docstring).

    A missing file, a file that is not FCD XML, an unknown vehicle or an ambiguous choice -> UserError.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    rows: list[dict] = []
    seen: dict[str, int] = {}
    t = root = None
    try:
        with _open(path) as f:
            for event, el in ET.iterparse(f, events=("start", "end")):
                if event == "start":
                    if root is None:
                        root = el.tag
                        if root != "fcd-export":
                            raise UserError(f"{shown(path)}: not SUMO FCD output (element <{el.tag}>, "
                                            f"expected <fcd-export>)")
                    if el.tag == "timestep":
                        t = el.get("time")
                    continue
                if el.tag == "vehicle":
                    vid = el.get("id")
                    seen[vid] = seen.get(vid, 0) + 1
                    if vehicle is None or vid == vehicle:
                        rows.append(dict(el.attrib, time=t))
                elif el.tag == "timestep":
                    el.clear()  # streaming: a long run's file is never held in memory
    except ET.ParseError as exc:
        raise UserError(f"{shown(path)}: not readable XML: {exc}") from None
    if vehicle is None and len(seen) > 1:
        ids = sorted(seen, key=_natural)
        listed = ", ".join(ids[:LISTED_IDS]) + (", ..." if len(ids) > LISTED_IDS else "")
        raise UserError(f"{shown(path)} holds {len(ids)} vehicles ({listed}): name one with --vehicle (or [log] vehicle "
                        f"in the mapping); likely the ego: {likely_ego(seen)}")
    if not rows:
        raise UserError(f"{shown(path)}: no vehicle {vehicle!r} in this FCD file; it holds "
                        f"{vehicles_text(seen) if seen else 'no vehicles'}")
    return _frame(rows)


def derived_acceleration(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """SUMO's acceleration (m/s²) from speed `v` (m/s) at times `t` (s): the backward difference
    a[i] = (v[i] − v[i−1]) / (t[i] − t[i−1]) over the step that ends at sample i, and a[0] = 0."""
    a = np.zeros(v.size)
    if v.size > 1:
        a[1:] = np.diff(v) / np.diff(t)
    return a


def _frame(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    for col in df.columns:
        if col not in TEXT_ATTRIBUTES:
            conv = pd.to_numeric(df[col], errors="coerce")
            if conv.notna().sum() == df[col].notna().sum():  # numeric attribute (text ones stay text)
                df[col] = conv.astype("float64")
    derived = []
    if pd.api.types.is_float_dtype(df["time"]):
        df["sumo_time"] = df["time"]
        df["time"] = df["time"] - df["time"].iloc[0]  # the drive starts at the vehicle's first sample
        if "acceleration" not in df.columns and "speed" in df.columns and pd.api.types.is_float_dtype(df["speed"]):
            # SUMO writes acceleration only with --fcd-output.acceleration (off by default)
            df["acceleration"] = derived_acceleration(df["time"].to_numpy(), df["speed"].to_numpy())
            derived.append("acceleration")
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
    out = df[front]
    out.attrs["derived"] = derived
    return out

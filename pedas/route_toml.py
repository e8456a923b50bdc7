"""The route file's records and its writer: traffic lights and stop signs by position, and the TOML text of a route
(the format of docs/drive_logs.md, "Route file"; :mod:`study.folder.route_file` reads and checks it).

The writer lives in the simulation core because :mod:`pedas.route_study` writes the paper's route file from the SUMO
network with it, and the core imports nothing of the study layer.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Light:
    """A traffic light: id, stop-line position s (m), optional fixed-time phases ((state, s), ...) and offset (s)."""

    id: str
    s: float
    phases: tuple[tuple[str, float], ...] = ()
    offset: float = 0.0


@dataclass(frozen=True)
class Stop:
    """A stop sign: id and stop-line position s (m)."""

    id: str
    s: float


def _fmt(x: float) -> str:
    """A number as TOML: whole numbers without a fraction, others in their shortest exact form."""
    x = float(x)
    return str(int(x)) if x.is_integer() else repr(x)


def _str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def dump_route(name: str, sections: list[tuple[float, float, float, str]], lights: list[Light] = (),
               stops: list[Stop] = (), speed_unit: str = "m/s", header: str = "", description: str = "") -> str:
    """The TOML text of a route: `sections` as (s_from m, s_to m, speed_limit in `speed_unit`, segment)."""
    out = [f"# {ln}" if ln else "#" for ln in header.splitlines()]
    out += ["", "[route]", f"name = {_str(name)}"]
    if description:
        out.append(f"description = {_str(description)}")
    out += [f"speed_unit = {_str(speed_unit)}", 'position_unit = "m"']
    for a, b, lim, seg in sections:
        out += ["", "[[sections]]", f"s_from = {_fmt(a)}", f"s_to = {_fmt(b)}", f"speed_limit = {_fmt(lim)}",
                f"segment = {_str(seg)}"]
    for tl in lights:
        out += ["", "[[lights]]", f"id = {_str(tl.id)}", f"s = {_fmt(tl.s)}"]
        if tl.phases:
            out.append("phases = [" + ", ".join(f"[{_str(st)}, {_fmt(d)}]" for st, d in tl.phases) + "]")
            out.append(f"offset = {_fmt(tl.offset)}")
    for ss in stops:
        out += ["", "[[stops]]", f"id = {_str(ss.id)}", f"s = {_fmt(ss.s)}"]
    return "\n".join(out).lstrip("\n") + "\n"

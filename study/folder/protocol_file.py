"""A protocol file of a study folder as data: its phases in order, its condition orders (counterbalancing) and
their planned minutes.

A protocol is a JSON file of a study folder (declared in its ``study.toml``, docs/study_folder.md) with an ordered
list of ``phases`` (each a ``name``, ``planned_minutes``, whether it is a ``drive`` and for which ``condition`` of
the study; a questionnaire phase names its ``instrument`` and optionally the condition it ``rates``, see
:mod:`study.folder.occasions`) and optionally ``orders`` (order name -> the phases in that order). Extra keys are kept in
:attr:`Phase.extra` / :attr:`Protocol.extra` so that newer files load in older code. Recording a participant's way
through a protocol is :mod:`study.people.protocol`; assigning an order, :mod:`study.people.orders`.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import Any

from study.common.errors import UserError


@dataclass(frozen=True)
class Phase:
    name: str
    planned_minutes: float | None = None
    drive: bool = False
    condition: str | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)
    instrument: str | None = None   # a questionnaire phase: the instrument answered in it (its name, no version)
    rates: str | None = None        # the condition a questionnaire phase after a drive rates

    @property
    def questionnaire(self) -> bool:
        return self.instrument is not None


@dataclass(frozen=True)
class Protocol:
    """An ordered list of phases. ``.phases`` are the names in order, ``.steps`` the Phase objects."""

    name: str
    steps: tuple[Phase, ...]
    version: int | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def phases(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.steps)

    def phase(self, name: str) -> Phase:
        for p in self.steps:
            if p.name == name:
                return p
        raise UserError(f"unknown phase {name!r} (protocol {self.name}: {', '.join(self.phases)})")

    def index(self, name: str) -> int:
        """0-based position of a phase; unknown phase -> UserError."""
        return self.phases.index(self.phase(name).name)


def parse_protocol(text: str, rel: str = "protocol.json") -> Protocol:
    """Parse a protocol file's JSON text (unknown keys are kept, not refused); a problem -> UserError naming `rel`."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(f"{rel}:{exc.lineno}: not valid JSON: {exc.msg}") from None
    if not isinstance(data, dict) or not isinstance(data.get("name"), str):
        raise UserError(f"{rel}: a protocol is a JSON object with a name and phases")
    name = data["name"]
    steps = []
    for raw in data.get("phases", []):
        raw = {"name": raw} if isinstance(raw, str) else dict(raw)
        known = {k: raw.pop(k) for k in ("name", "planned_minutes", "drive", "condition", "instrument", "rates")
                 if k in raw}
        if not isinstance(known.get("name"), str):
            raise UserError(f"{rel}: every phase needs a name")
        pm = known.get("planned_minutes")
        if pm is not None and (isinstance(pm, bool) or not isinstance(pm, (int, float)) or pm < 0):
            raise UserError(f"{rel}: phase {known['name']}: planned_minutes must be a number >= 0")
        for k in ("instrument", "rates"):
            if known.get(k) is not None and not isinstance(known[k], str):
                raise UserError(f"{rel}: phase {known['name']}: {k} must be a name")
        steps.append(Phase(extra=raw, **known))
    names = [s.name for s in steps]
    if not names or len(set(names)) != len(names):
        raise UserError(f"{rel}: phases must be a non-empty list of distinct names")
    extra = {k: v for k, v in data.items() if k not in ("name", "version", "phases")}
    proto = Protocol(name=name, steps=tuple(steps), version=data.get("version"), extra=extra)
    try:
        protocol_orders(proto)  # checks that every order lists each phase once
    except UserError as exc:
        raise UserError(f"{rel}: {exc}") from None
    return proto


def protocol_orders(proto: Protocol) -> dict[str, tuple[str, ...]]:
    """Order name -> phase sequence. A protocol without ``orders`` has the single order ``default``."""
    orders = proto.extra.get("orders")
    if not orders:
        return {"default": proto.phases}
    out: dict[str, tuple[str, ...]] = {}
    for name, seq in orders.items():
        if sorted(seq) != sorted(proto.phases):
            raise UserError(f"protocol {proto.name}: order {name!r} must list each phase exactly once")
        out[name] = tuple(seq)
    return out


def ordered_protocol(proto: Protocol, order_name: str) -> Protocol:
    """The protocol with its steps in the sequence of `order_name`."""
    orders = protocol_orders(proto)
    if order_name not in orders:
        raise UserError(f"protocol {proto.name} has no order {order_name!r} (orders: {', '.join(orders)})")
    by_name = {p.name: p for p in proto.steps}
    return replace(proto, steps=tuple(by_name[n] for n in orders[order_name]))


def planned_minutes(proto: Protocol) -> float:
    """Planned duration of the whole protocol (minutes); phases without a plan count 0."""
    return float(sum(p.planned_minutes or 0.0 for p in proto.steps))

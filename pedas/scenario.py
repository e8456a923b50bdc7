"""Traffic scenarios of the study route: which SUMO sources a simulated drive uses.

A scenario names the netconvert configuration (and every file it reads), the routes, the vehicle types and the
seeded demand. The urban part is the same in every scenario; they differ on the highway:

* ``single-lane``: the first reproduction's highway, one lane per direction, ramps joining at priority junctions,
  traffic that cannot overtake (``data/network/study.*``, docs/route_and_traffic.md);
* ``motorway``: the highway as a German motorway, two lanes per direction with acceleration and deceleration
  lanes at the ramps and main-carriageway traffic from upstream that overtakes the ego; the ego keeps the right
  lane apart from leaving the acceleration lane (``data/network/motorway/``, sources in docs/route_and_traffic.md,
  "Motorway scenario").

Decisions and sources of every setting are in the docs; nothing here is tuned to the paper's results.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from pedas.paths import NETWORK_DIR

SINGLE_LANE = "single-lane"
MOTORWAY = "motorway"
DEFAULT_SCENARIO = MOTORWAY


@dataclass(frozen=True)
class Scenario:
    """The SUMO inputs of one scenario (absolute paths) and whether the ego may change lanes at all."""

    name: str
    netccfg: Path
    routes: Path
    vtypes: Path
    demand: Path
    ego_merges: bool  # the ego leaves an acceleration lane by a lane change (SUMO's strategic lane change)
    description: str

    @property
    def sources(self) -> tuple[Path, ...]:
        """The netconvert configuration and every input file it names (in its order)."""
        text = self.netccfg.read_text(encoding="utf-8")
        names = [n for v in re.findall(r'<[a-z-]+-files value="([^"]+)"', text) for n in v.split(",")]
        return (self.netccfg, *(self.netccfg.parent / n for n in names))

    @property
    def files(self) -> tuple[Path, ...]:
        """Everything a drive in this scenario reads from the data folder (network sources and traffic)."""
        return (*self.sources, self.routes, self.vtypes, self.demand)


def _scenarios() -> dict[str, Scenario]:
    mw = NETWORK_DIR / MOTORWAY
    return {
        SINGLE_LANE: Scenario(SINGLE_LANE, NETWORK_DIR / "study.netccfg", NETWORK_DIR / "study.rou.xml",
                              NETWORK_DIR / "vtypes.add.xml", NETWORK_DIR / "demand.json", False,
                              "single-lane highway, no overtaking, ramps at priority junctions"),
        MOTORWAY: Scenario(MOTORWAY, mw / "motorway.netccfg", mw / "motorway.rou.xml", mw / "vtypes.add.xml",
                           mw / "demand.json", True,
                           "motorway: 2 lanes per direction, acceleration/deceleration lanes, traffic overtakes"),
    }


SCENARIOS: dict[str, Scenario] = _scenarios()


def get_scenario(name: str | Scenario | None = None) -> Scenario:
    """The scenario called `name` (default :data:`DEFAULT_SCENARIO`); ValueError naming the known ones."""
    if isinstance(name, Scenario):
        return name
    key = name or DEFAULT_SCENARIO
    if key not in SCENARIOS:
        raise ValueError(f"unknown scenario {key!r} (expected {'|'.join(SCENARIOS)})")
    return SCENARIOS[key]

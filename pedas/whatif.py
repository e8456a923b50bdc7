"""What-if settings of a simulated drive: the unpublished settings the sensitivity sweep varies.

The paper does not print its traffic volumes, its lorry share, how closely its participants followed the advice,
how fast they liked to drive, or the DP's time weight; the HUD band is printed (+-2 km/h) but its effect is of
interest too. :class:`WhatIf` moves each of them away from the documented scenario; ``WhatIf()`` (every field at
its default) is the scenario as documented, and a drive with it is the same drive, bit for bit, as one without.

* ``urban_density``: x the rate of every urban flow of the scenario's demand (the flows without ``"part":
  "highway"``; timetabled buses keep their timetable);
* ``highway_density``: x the rate of every highway flow (on-ramps and main carriageway);
* ``lorry_share``: the share of heavy vehicles (``lorry``/``truck``) in every highway flow that has a vehicle
  mix (None: the scenario's own, 15 % on the motorway);
* ``compliance_shift``: added to each participant's compliance with the advice (clipped to [0, 1]);
* ``hud_band_kmh``: half-width of the HUD's coast band (km/h), for the HUD and the assisted driver alike;
* ``dp_time_weight``: x the DP's time weight w_time (J/s, Sec. 3.2);
* ``speeding_shift``: added to each participant's desired-speed factors (town and highway): +0.05 = every
  participant wishes to drive 5 % of the limit faster, which raises the prevalence of speeding.

The same participant seed and traffic seed are used at every setting (common random numbers): a change in a
result is the setting's, not another draw of people. Changing a flow's rate changes how many random numbers that
flow draws, so the flows after it in the demand file see other draws (urban flows come first: the highway's
density does not change the urban traffic, the urban density does change the highway's realisation).

:data:`FACTORS` holds the sweep's default range of each setting with its reason (docs/sweep.md).
"""
from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, fields

from pedas.constants import HUD_BAND, KMH

HIGHWAY = "highway"  # a flow's "part" in demand.json; every other flow is urban
HEAVY_TYPES = ("lorry", "truck")


@dataclass(frozen=True)
class WhatIf:
    """Unpublished settings of a drive, each at the documented scenario's value by default (module docstring)."""

    urban_density: float = 1.0
    highway_density: float = 1.0
    lorry_share: float | None = None
    compliance_shift: float = 0.0
    hud_band_kmh: float = HUD_BAND / KMH
    dp_time_weight: float = 1.0
    speeding_shift: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is not None and not isinstance(v, (int, float)):
                raise ValueError(f"what-if setting {f.name} must be a number, not {v!r}")
        if self.urban_density < 0 or self.highway_density < 0:
            raise ValueError("what-if densities must be >= 0")
        if self.lorry_share is not None and not 0.0 <= self.lorry_share <= 1.0:
            raise ValueError(f"what-if lorry_share must be within [0, 1], not {self.lorry_share}")
        if self.hud_band_kmh <= 0:
            raise ValueError(f"what-if hud_band_kmh must be > 0, not {self.hud_band_kmh}")
        if self.dp_time_weight < 0:
            raise ValueError(f"what-if dp_time_weight must be >= 0, not {self.dp_time_weight}")

    def items(self) -> tuple[tuple[str, float], ...]:
        """The settings that differ from the default, sorted by name (hashable: part of a drive task's key)."""
        default = WhatIf()
        return tuple(sorted((f.name, float(getattr(self, f.name))) for f in fields(self)
                            if getattr(self, f.name) != getattr(default, f.name)))

    @classmethod
    def from_items(cls, items) -> "WhatIf":
        """The settings of :meth:`items` (or any iterable of (name, value) pairs); ValueError on an unknown name."""
        known = {f.name for f in fields(cls)}
        pairs = dict(items)
        unknown = sorted(set(pairs) - known)
        if unknown:
            raise ValueError(f"unknown what-if setting {unknown[0]!r} (expected one of {', '.join(sorted(known))})")
        return cls(**pairs)

    def is_default(self) -> bool:
        return not self.items()

    # ---------------------------------------------------------------------------------------- applied to a drive
    @property
    def hud_band(self) -> float:
        """The HUD band in m/s."""
        return HUD_BAND if self.hud_band_kmh == HUD_BAND / KMH else self.hud_band_kmh * KMH

    def demand(self, demand: dict) -> dict:
        """A copy of a scenario's demand (pedas.traffic.load_demand) with the densities and lorry share applied;
        the demand itself when nothing changes."""
        if self.urban_density == 1.0 and self.highway_density == 1.0 and self.lorry_share is None:
            return demand
        out = copy.deepcopy(demand)
        for f in out["flows"]:
            highway = f.get("part") == HIGHWAY
            if "rate" in f:
                f["rate"] = float(f["rate"]) * (self.highway_density if highway else self.urban_density)
            if highway and self.lorry_share is not None and f.get("mix"):
                heavy = [k for k in f["mix"] if k in HEAVY_TYPES]
                for k in heavy:
                    f["mix"][k] = self.lorry_share / len(heavy)
        # a flow with rate 0 departs nobody
        out["flows"] = [f for f in out["flows"] if "period" in f or float(f["rate"]) > 0.0]
        return out

    def driver(self, params):
        """A participant (:class:`pedas.drivers.DriverParams`) with the compliance and speeding shifts applied."""
        if self.compliance_shift == 0.0 and self.speeding_shift == 0.0:
            return params
        return dataclasses.replace(
            params, compliance=min(max(params.compliance + self.compliance_shift, 0.0), 1.0),
            speed_factor=params.speed_factor + self.speeding_shift,
            speed_factor_hw=params.speed_factor_hw + self.speeding_shift)

    def controller(self, settings):
        """Controller settings (:class:`pedas.params.ControllerParams`) with the HUD band applied; `settings`
        themselves (their own band) when this setting is at its default."""
        if self.hud_band_kmh == WhatIf.hud_band_kmh or self.hud_band == settings.hud_band:
            return settings
        return dataclasses.replace(settings, hud_band=self.hud_band)


@dataclass(frozen=True)
class Factor:
    """One setting of the sweep: name (a :class:`WhatIf` field), range [lo, hi], unit, what it is, and the reason
    for the range."""

    name: str
    lo: float
    hi: float
    unit: str
    doc: str
    source: str


FACTORS: dict[str, Factor] = {f.name: f for f in (
    Factor("urban_density", 0.5, 1.5, "x", "urban traffic volume, x the documented flows",
           "the paper calls the urban traffic dense but prints no volume; +-50 % around the documented flows "
           "(docs/route_and_traffic.md) spans light to near-saturated junctions"),
    Factor("highway_density", 0.5, 1.5, "x", "highway traffic volume, x the documented flows",
           "1 500 veh/h per direction is a daytime hour of an average German motorway (BASt counts); x 0.5-1.5 "
           "spans 750-2 250 veh/h on two lanes, a degree of saturation of 0.2-0.6 (capacity 3 600-4 000 veh/h, "
           "HBS 2015): free flow, as the paper implies"),
    Factor("lorry_share", 0.05, 0.25, "share", "share of heavy vehicles in the highway traffic",
           "the average heavy-vehicle share on German motorways is ~15 % (BASt counts); single sites range from "
           "below 10 % to above 25 %"),
    Factor("compliance_shift", -0.3, 0.15, "+", "added to each participant's compliance with the advice",
           "the documented compliance (0.65-0.85 by style) is an assumption; studies of in-vehicle speed advice "
           "report partial, drifting compliance (docs/drivers.md): from a third less to full compliance"),
    Factor("hud_band_kmh", 1.0, 4.0, "km/h", "half-width of the HUD coast band",
           "the paper prints +-2 km/h (Sec. 3.8); 1-4 km/h spans the resolution of a speedometer reading to a "
           "band a driver notices without a glance"),
    Factor("dp_time_weight", 0.5, 2.0, "x", "the DP's time weight, x w_time",
           "the paper weighs trip time against energy without printing the weight; w_time = 4 000 W is chosen "
           "(docs/vehicle_and_references.md), whose weight sweep shows 2 000-8 000 W changing the town's mean "
           "reference speed by ~1 km/h and the trip by ~0.3 min: x 0.5-2 tests how much that choice matters"),
    Factor("speeding_shift", -0.05, 0.10, "+", "added to each participant's desired-speed factors",
           "the documented free speeds (docs/drivers.md) put 8 of 34 baseline drivers above a limit; driving-"
           "simulator studies report from a few to most drivers speeding: -5 % to +10 % of the limit"),
)}

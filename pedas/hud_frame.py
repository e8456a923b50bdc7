"""The HUD frame: what the head-up display draws at one instant (Sec. 3.8, Fig. 7), as a small JSON-ready record.

:func:`hud_frame` turns a measured speed and the controller's advice (:class:`pedas.hud.HudAdvice` or
:class:`pedas.controller.Advisory`) into a :class:`HudFrame`; the web component ``pedas/web/hud.js`` draws it
(``<pedas-hud>``), :mod:`pedas.hud_png` renders it to PNG, the live server sends it, the replay page shows it.

Display rules (the paper shows integers on the HUD): speeds and the limit in whole km/h (rounded half up), the
countdown in whole seconds rounded up (a light that changes in 2.3 s shows 3, never 2 — the driver must not be told
there is less time than there is).

:data:`FIG7` are the nine situations of Fig. 7 (a-i), each produced by :func:`pedas.hud.advisory` from a state,
a plan and a route context — never written as frames by hand.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from pedas.constants import KMH
from pedas.hud import HudContext, HudState, advisory
from pedas.params import CONTROLLER


def display_kmh(v_ms: float | None) -> int | None:
    """m/s -> whole km/h as the HUD shows them, rounded half up (None stays None)."""
    return None if v_ms is None else int(math.floor(v_ms / KMH + 0.5))


@dataclass(frozen=True)
class HudFrame:
    """One HUD frame. speed, advice, limit: km/h (integers as displayed; advice None = no advice, as in a baseline
    drive; limit None = no sign); arrow -1|0|1;
    arrow_len 0..1 (fraction of the full arrow); color 'black'|'green'|'red' (the digits and the arrow);
    in_band: inside the +-2 km/h band (coast); countdown: whole s until the next light changes, or None;
    icon 'green_wave'|'stop_sign'|'curve'|None; warning: the tone sounds."""

    speed: int
    advice: int | None
    limit: int | None
    arrow: int
    arrow_len: float
    color: str
    in_band: bool
    countdown: int | None
    icon: str | None
    warning: bool

    def as_dict(self) -> dict:
        return asdict(self)


def hud_frame(v: float, advice) -> HudFrame:
    """The frame for measured speed v (m/s) and an advice with the fields of :class:`pedas.hud.HudAdvice`
    (v_opt or v_advice, hud_arrow, arrow_len, hud_in_band, warning, tl_countdown, icon, speed_limit)."""
    v_opt = advice.v_opt if hasattr(advice, "v_opt") else advice.v_advice
    color = "black" if advice.hud_in_band else ("green" if advice.hud_arrow > 0 else "red")
    cd = advice.tl_countdown
    return HudFrame(speed=display_kmh(max(v, 0.0)), advice=display_kmh(v_opt),
                    limit=display_kmh(getattr(advice, "speed_limit", None)),
                    arrow=int(advice.hud_arrow), arrow_len=round(float(advice.arrow_len), 3), color=color,
                    in_band=bool(advice.hud_in_band), countdown=None if cd is None else int(math.ceil(cd - 1e-9)),
                    icon=advice.icon, warning=bool(advice.warning))


@dataclass(frozen=True)
class Situation:
    """One panel of Fig. 7: letter, caption, and the inputs of :func:`pedas.hud.advisory` that produce it."""

    key: str
    caption: str
    state: HudState
    plan: tuple[float, ...]
    context: HudContext

    def frame(self) -> HudFrame:
        return hud_frame(self.state.v, advisory(self.state, self.plan, self.context))


_URBAN = 50 * KMH
_HWY = 100 * KMH
FIG7: tuple[Situation, ...] = (
    Situation("a", "speed up: optimal speed 8 km/h above (green arrow up)",
              HudState(v=40 * KMH), (48 * KMH,), HudContext(speed_limit=_URBAN)),
    Situation("b", "slow down: optimal speed 12 km/h below (red arrow down)",
              HudState(v=50 * KMH), (38 * KMH,), HudContext(speed_limit=_URBAN)),
    Situation("c", "inside the +-2 km/h band: black digits, coast",
              HudState(v=45 * KMH), (46 * KMH,), HudContext(speed_limit=_URBAN)),
    Situation("d", "traffic light changes in 6.4 s (countdown), slow down to stop",
              HudState(v=45 * KMH), (36 * KMH,),
              HudContext(speed_limit=_URBAN, tl_distance=70.0, tl_remaining=6.4)),
    Situation("e", "green wave: speed up to pass the next light in green",
              HudState(v=38 * KMH), (44 * KMH,),
              HudContext(mode="green_wave", speed_limit=_URBAN, tl_distance=120.0, tl_remaining=14.0)),
    Situation("f", "stop sign ahead: slow down",
              HudState(v=30 * KMH), (20 * KMH,), HudContext(speed_limit=_URBAN, stop_distance=60.0)),
    Situation("g", "curve ahead: slow down to its speed",
              HudState(v=95 * KMH), (80 * KMH,), HudContext(speed_limit=_HWY, curve_distance=110.0)),
    Situation("h", "safe distance violated: warning tone",
              HudState(v=50 * KMH), (42 * KMH,), HudContext(speed_limit=_URBAN, psi=-3.0)),
    Situation("i", "slow-down advice ignored for warn_delay s: warning tone",
              HudState(v=50 * KMH, slow_unfollowed=CONTROLLER.warn_delay), (44 * KMH,),
              HudContext(speed_limit=_URBAN)),
)


def fig7_frames() -> dict[str, HudFrame]:
    """Letter -> frame of the nine Fig. 7 situations."""
    return {s.key: s.frame() for s in FIG7}

"""The HUD frame: what the head-up display draws at one instant (Sec. 3.8, Fig. 7), as a small JSON-ready record.

:func:`hud_frame` turns a measured speed and the controller's advice (:class:`pedas.hud.HudAdvice` or
:class:`pedas.controller.Advisory`) into a :class:`HudFrame`; the web component ``pedas/web/hud.js`` draws it
(``<pedas-hud>``), :mod:`pedas.hud_png` renders it to PNG, the live server sends it, the replay page shows it.

Display rules (the paper shows integers on the HUD): speeds and the limit in whole km/h (rounded half up); the
countdown in whole seconds rounded down (the paper shows "the remaining time (less than 10 s)": every remaining
time below 10 s is shown, as 0..9, and 9.0-9.99 s shows 9, never 10; the digit is the number of whole seconds
still left, like a signal's countdown timer, and in a green phase it never promises more green than there is).

:data:`FIG7` are the nine panels of Fig. 7 (a-i) as the paper's text describes them, each produced by
:func:`pedas.hud.advisory` from the state, plan and route context the controller had at one step of a simulated
drive of the reference cohort (``hud_fig7.json``, found by :mod:`pedas.hud_search`) — never written by hand.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

from pedas.constants import HUD_BAND, KMH
from pedas.hud import HudContext, HudState, advisory
from pedas.params import CONTROLLER
from pedas.records import fast_init

#: m/s^2, a deceleration most drivers find comfortable: AASHTO, A Policy on Geometric Design of Highways and
#: Streets (2011), Sec. 3.2.6: 3.4 m/s^2 (11.2 ft/s^2), the deceleration of its stopping-sight-distance rule
B_COMF = 3.4


def display_kmh(v_ms: float | None) -> int | None:
    """m/s -> whole km/h as the HUD shows them, rounded half up (None stays None)."""
    return None if v_ms is None else int(math.floor(v_ms / KMH + 0.5))


@fast_init
@dataclass(frozen=True)
class HudFrame:
    """One HUD frame. speed, advice, limit: km/h (integers as displayed; advice None = no advice, as in a baseline
    drive; limit None = no sign); arrow -1|0|1;
    arrow_len 0..1 (fraction of the full arrow); color 'black'|'green'|'red' (the digits and the arrow);
    in_band: inside the +-2 km/h band (coast); countdown: whole s left in the next light's phase (0..9), or None;
    light: that phase ('green'|'yellow'|'red', lit in the light glyph; None without countdown);
    icon 'green_wave'|'stop_sign'|'yield_sign'|'curve'|None; warning: the warning tone sounds (a slow-down advice
    not followed, :func:`pedas.hud.advisory`'s ``tone``); brake: the explicit brake state (:func:`cut_in_advice`:
    the gap closes faster than a comfortable deceleration can handle), drawn as "BRAKE" with the full red arrow."""

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
    light: str | None = None
    brake: bool = False

    def as_dict(self) -> dict:
        return asdict(self)


def display_countdown(remaining: float | None) -> int | None:
    """Seconds left (s) -> the whole seconds the HUD shows: rounded down (9.99 -> 9, 0.4 -> 0); None stays None.
    The 1e-9 keeps a remaining time computed as 6.999999999 for 7.0 at 7."""
    return None if remaining is None else max(int(math.floor(remaining + 1e-9)), 0)


def cut_in_advice(v: float, v_opt: float, leader: tuple[float, float] | None, alert: bool, *,
                  b_comf: float = B_COMF) -> tuple[float, bool]:
    """The advice the HUD shows inside a too-short gap, and whether it shows the brake state: (m/s, bool).

    Only while the controller's alert is on (psi < 0, the speed correction of eq. 11 in force) and its advice
    v_opt asks for a slow-down, with a leader (gap m, its speed v_p m/s). The correction can ask for 0 km/h when a
    car cuts in a few metres ahead, even when that car is faster and the gap already opens. What the situation
    needs is the constant deceleration that keeps the gap from closing, DRAC = (v - v_p)^2 / (2 gap) when
    v > v_p (0 otherwise):
    - DRAC > b_comf: the brake state (no number can say "brake now" better);
    - otherwise the advice is bounded below by min(v, v_p): matching the leader's speed keeps the gap, a faster
      leader opens it while the driver coasts. The controller's own advice (v_opt) is unchanged."""
    if leader is None or not alert or v_opt >= v - HUD_BAND:
        return v_opt, False
    gap, v_p = leader
    if v > v_p and (v - v_p) ** 2 / (2.0 * max(gap, 0.1)) > b_comf:
        return v_opt, True
    return max(v_opt, min(v, v_p)), False


#: when the HUD sounds its tone: "unfollowed" = a slow-down advice not followed for warn_delay s (any situation);
#: "margin" = that, and the safe distance violated (psi = d_rel - d_s < 0, eq. 11): "unsafe driving situations"
TONE_RULES = ("unfollowed", "margin")


def margin_violated(v: float, leader: tuple[float, float] | None) -> bool:
    """psi = gap - (d_min + h_s v) < 0 with the car-following MPC's d_min (m) and h_s (s) (eq. 11's psi)."""
    cf = CONTROLLER.cf_weights
    return leader is not None and leader[0] - (cf.d_min + cf.h_s * v) < 0.0


def hud_frame(v: float, advice, leader: tuple[float, float] | None = None, tone_rule: str = "unfollowed") -> HudFrame:
    """The frame for measured speed v (m/s), an advice with the fields of :class:`pedas.hud.HudAdvice` (v_opt or
    v_advice, hud_arrow, arrow_len, hud_in_band, warning, tl_countdown, icon, speed_limit, tl_phase, tone) and the
    leader (gap m, speed m/s) or None; inside a too-short gap the shown advice is :func:`cut_in_advice`'s; the tone
    follows `tone_rule` (:data:`TONE_RULES`)."""
    v_opt = advice.v_opt if hasattr(advice, "v_opt") else advice.v_advice
    arrow, arrow_len, in_band = int(advice.hud_arrow), float(advice.arrow_len), bool(advice.hud_in_band)
    shown, brake = cut_in_advice(v, v_opt, leader, bool(getattr(advice, "warning", False)))
    if brake:
        arrow, arrow_len, in_band = -1, 1.0, False
    elif shown != v_opt:   # bounded: the arrow and band follow the shown advice (pedas.hud.advisory's rule)
        dv = shown - v
        arrow = 0 if abs(dv) <= HUD_BAND else (1 if dv > 0 else -1)
        arrow_len, in_band = (0.0 if arrow == 0 else min(abs(dv) / CONTROLLER.arrow_full_scale, 1.0)), arrow == 0
    color = "black" if in_band else ("green" if arrow > 0 else "red")
    cd = display_countdown(advice.tl_countdown)
    return HudFrame(speed=display_kmh(max(v, 0.0)), advice=display_kmh(shown),
                    limit=display_kmh(getattr(advice, "speed_limit", None)),
                    arrow=arrow, arrow_len=round(arrow_len, 3), color=color,
                    in_band=in_band, countdown=cd, icon=advice.icon,
                    warning=bool(getattr(advice, "tone", False)) and (tone_rule == "unfollowed"
                                                                      or margin_violated(v, leader)),
                    light=None if cd is None else getattr(advice, "tl_phase", None), brake=brake)


@dataclass(frozen=True)
class Situation:
    """One panel of Fig. 7: letter, the paper's caption, the sentence of its text the panel follows, where we chose,
    the drive and time it comes from, and the inputs of :func:`pedas.hud.advisory` that produce it."""

    key: str
    caption: str
    sentence: str
    choice: str
    drive: str
    t: float
    s: float
    state: HudState
    plan: tuple[float, ...]
    context: HudContext

    def frame(self) -> HudFrame:
        return hud_frame(self.state.v, advisory(self.state, self.plan, self.context))

    def source(self) -> str:
        """Where the state comes from, one line."""
        c = self.context
        parts = [f"{self.drive} pedas drive, t = {self.t:.1f} s (SUMO time), s = {self.s:.0f} m",
                 f"v = {self.state.v / KMH:.1f} km/h, v_opt = {self.plan[0] / KMH:.1f} km/h, mode {c.mode}"]
        if c.tl_remaining is not None:
            parts.append(f"light {c.tl_state} {c.tl_remaining:.2f} s left at {c.tl_distance:.0f} m")
        if c.stop_distance is not None and c.stop_distance <= 150:
            parts.append(f"stop line at {c.stop_distance:.0f} m")
        if c.curve_distance is not None:
            parts.append(f"curve at {c.curve_distance:.0f} m")
        if c.psi is not None:
            parts.append(f"psi = d_rel - d_s = {c.psi:.1f} m")
        return "; ".join(parts)


FIG7_FILE = Path(__file__).resolve().parent / "hud_fig7.json"


def _load_fig7() -> tuple[Situation, ...]:
    out = []
    for r in json.loads(FIG7_FILE.read_text(encoding="utf-8")):
        out.append(Situation(r["key"], r["caption"], r["sentence"], r["choice"], r["drive"], float(r["t"]),
                             float(r["s"]), HudState(**r["state"]), tuple(r["plan"]), HudContext(**r["context"])))
    return tuple(out)


#: the nine panels, a-i (written by ``pedas-study hud search``)
FIG7: tuple[Situation, ...] = _load_fig7()


def fig7_frames() -> dict[str, HudFrame]:
    """Letter -> frame of the nine Fig. 7 panels."""
    return {s.key: s.frame() for s in FIG7}

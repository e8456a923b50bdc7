"""HUD advisory of the eco-driving feedback system (Sec. 3.8), a pure function of (state, plan, route context).

Labs can drive a real head-up display from :func:`advisory`; the controller calls it once per step.

- optimal speed v_opt = the first planned speed of the MPC plan;
- arrow up (green) when v < v_opt - HUD_BAND, down (red) when v > v_opt + HUD_BAND, none inside the +-2 km/h band,
  where the digits turn black and the driver is advised to coast (no pedal);
- at standstill (v < STANDSTILL) the band does not apply: a standing car cannot coast, so an optimal speed more
  than START_MIN above v shows the arrow up ("drive off"). Without this, a plan that leaves standstill gently
  (v_opt = v_1, one sample ahead, rises by F_t,max/m_eq x 0.2 s, which can be < 2 km/h) would show black digits,
  and a driver who coasts as instructed would stand at a green light forever;
- arrow length proportional to |v - v_opt|, full length at ARROW_FULL_SCALE, capped at 1;
- the remaining time of the next traffic light's phase when it is below HUD_TL_COUNTDOWN and the light is within
  ICON_RANGE;
- one icon: stop sign > curve > green wave (the most safety-relevant first);
- warning tone when the safe distance is violated (psi < 0) or a slow-down advice has not been followed for
  WARN_DELAY s (the driver kept a >= -NOT_DECEL m/s^2 while the arrow pointed down).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from pedas.constants import HUD_BAND, HUD_TL_COUNTDOWN, KMH

ARROW_FULL_SCALE = 10.0 * KMH  # m/s, |v - v_opt| at which the arrow has full length (design choice)
ICON_RANGE = 150.0  # m, look-ahead for TL countdown / stop-sign / curve icons (design choice)
WARN_DELAY = 2.0  # s, a slow-down advice ignored this long triggers the warning tone (design choice)
NOT_DECEL = 0.3  # m/s^2, a deceleration weaker than this does not count as following a slow-down advice
STANDSTILL = 0.1  # m/s, below this the car stands (the drive loop's halt threshold)
START_MIN = 0.3 * KMH  # m/s, v_opt this far above a standing car's speed means "drive off" (design choice)


def wants_start(v: float, v_target: float) -> bool:
    """A standing car (v < STANDSTILL m/s) is advised to drive off: v_target exceeds v by more than START_MIN."""
    return v < STANDSTILL and v_target - v > START_MIN


@dataclass(frozen=True)
class HudState:
    """Measured host state: speed v (m/s), acceleration a (m/s^2) and how long a slow-down advice has gone
    unfollowed so far, slow_unfollowed (s; see :func:`update_unfollowed`)."""

    v: float
    a: float = 0.0
    slow_unfollowed: float = 0.0


@dataclass(frozen=True)
class HudContext:
    """Route context at the current position.

    mode: controller mode ('green_wave'|'dp'|'stop'|'follow'); tl_distance (m to the next light's stop line or
    None), tl_remaining (s left in its current phase or None); stop_distance (m to the next stop line or None);
    curve_distance (m to the next curve whose limit is below the current speed, or None); psi = d_rel - d_s (m,
    None without a leader); speed_limit (m/s, shown under the speed).
    """

    mode: str = "dp"
    tl_distance: float | None = None
    tl_remaining: float | None = None
    stop_distance: float | None = None
    curve_distance: float | None = None
    psi: float | None = None
    speed_limit: float | None = None


@dataclass(frozen=True)
class HudAdvice:
    """What the HUD shows: v_opt (m/s), hud_arrow -1|0|1, arrow_len 0..1, hud_in_band (black digits, coast),
    color ('black'|'green'|'red'), warning tone, tl_countdown (s or None), icon ('green_wave'|'stop_sign'|'curve'|
    None), speed_limit (m/s or None)."""

    v_opt: float
    hud_arrow: int
    arrow_len: float
    hud_in_band: bool
    color: str
    warning: bool
    tl_countdown: float | None
    icon: str | None
    speed_limit: float | None


def update_unfollowed(prev: float, arrow: int, a: float, dt: float) -> float:
    """Seconds a slow-down advice (arrow -1) has gone unfollowed: grows by dt while the arrow points down and the
    driver decelerates less than NOT_DECEL m/s^2, resets to 0 otherwise."""
    if arrow < 0 and a > -NOT_DECEL:
        return prev + dt
    return 0.0


def advisory(state: HudState, plan: Sequence[float], context: HudContext) -> HudAdvice:
    """The HUD record for a measured state, a plan of predicted speeds v_1..v_N (m/s) and the route context."""
    v_opt = float(plan[0])
    dv = v_opt - state.v
    if dv > HUD_BAND or wants_start(state.v, v_opt):
        arrow, color = 1, "green"
    elif dv < -HUD_BAND:
        arrow, color = -1, "red"
    else:
        arrow, color = 0, "black"
    arrow_len = 0.0 if arrow == 0 else min(abs(dv) / ARROW_FULL_SCALE, 1.0)
    countdown = None
    if (context.tl_distance is not None and context.tl_remaining is not None
            and 0.0 <= context.tl_distance <= ICON_RANGE and context.tl_remaining < HUD_TL_COUNTDOWN):
        countdown = float(context.tl_remaining)
    if context.stop_distance is not None and 0.0 <= context.stop_distance <= ICON_RANGE:
        icon = "stop_sign"
    elif context.curve_distance is not None and 0.0 <= context.curve_distance <= ICON_RANGE:
        icon = "curve"
    elif context.mode == "green_wave" and context.tl_distance is not None and context.tl_distance <= ICON_RANGE:
        icon = "green_wave"
    else:
        icon = None
    warning = (context.psi is not None and context.psi < 0.0) or state.slow_unfollowed >= WARN_DELAY
    return HudAdvice(v_opt=v_opt, hud_arrow=arrow, arrow_len=float(arrow_len), hud_in_band=arrow == 0,
                     color=color, warning=bool(warning), tl_countdown=countdown, icon=icon,
                     speed_limit=context.speed_limit)

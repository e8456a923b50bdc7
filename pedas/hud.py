"""HUD advisory of the eco-driving feedback system (Sec. 3.8), a pure function of (state, plan, route context).

Labs can drive a real head-up display from :func:`advisory`; the controller calls it once per step.

- optimal speed v_opt = the first planned speed of the MPC plan;
- arrow up (green) when v < v_opt - band, down (red) when v > v_opt + band, none inside the band (the paper's
  +-2 km/h, HUD_BAND, the default of ``ControllerParams.hud_band``), where the digits turn black and the driver is
  advised to coast (no pedal);
- at standstill (v < standstill) the band does not apply: a standing car cannot coast, so an optimal speed more
  than start_min above v shows the arrow up ("drive off"). Without this, a plan that leaves standstill gently
  (v_opt = v_1, one sample ahead, rises by F_t,max/m_eq x 0.2 s, which can be < 2 km/h) would show black digits,
  and a driver who coasts as instructed would stand at a green light forever;
- arrow length proportional to |v - v_opt|, full length at arrow_full_scale, capped at 1;
- the remaining time of the next traffic light's phase when it is below HUD_TL_COUNTDOWN and the light is within
  icon_range;
- the phase of that light (tl_phase, 'green'|'yellow'|'red'), lit in the HUD's light glyph beside the countdown
  (Fig. 7h green, 7i red);
- one icon: stop or yield sign > curve > green wave (the most safety-relevant first);
- tone: the warning tone the HUD sounds, the paper's rule "if the suggestion to slow down is not followed": the
  arrow has pointed down for warn_delay s while the driver kept a >= -not_decel m/s^2 (slow_unfollowed >=
  warn_delay). 2 s is above a driver's brake reaction time to an expected signal (about 0.7-1.5 s), so a driver
  about to follow the advice is not alarmed, and short enough that the tone comes while braking still helps;
- warning: the controller's alert, tone or the safe distance violated (psi < 0). The virtual drivers of the
  simulated cohort react to it (pedas.drivers), so it stays as it was; the HUD sounds only the tone.

HUD_BAND and HUD_TL_COUNTDOWN are printed in the paper (pedas.constants); the lower-case thresholds are design
choices, fields of :class:`pedas.params.ControllerParams`, taken as keyword arguments defaulting to
:data:`pedas.params.CONTROLLER`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from pedas.constants import HUD_TL_COUNTDOWN
from pedas.params import CONTROLLER
from pedas.records import fast_init


def wants_start(v: float, v_target: float, *, standstill: float = CONTROLLER.standstill,
                start_min: float = CONTROLLER.start_min) -> bool:
    """A standing car (v < standstill m/s) is advised to drive off: v_target exceeds v by more than start_min m/s."""
    return v < standstill and v_target - v > start_min


@fast_init
@dataclass(frozen=True)
class HudState:
    """Measured host state: speed v (m/s), acceleration a (m/s^2) and how long a slow-down advice has gone
    unfollowed so far, slow_unfollowed (s; see :func:`update_unfollowed`)."""

    v: float
    a: float = 0.0
    slow_unfollowed: float = 0.0


@fast_init
@dataclass(frozen=True)
class HudContext:
    """Route context at the current position.

    mode: controller mode ('green_wave'|'dp'|'stop'|'follow'); tl_distance (m to the next light's stop line or
    None), tl_remaining (s left in its current phase or None); stop_distance (m to the next stop line or None);
    curve_distance (m to the next curve whose limit is below the current speed, or None); psi = d_rel - d_s (m,
    None without a leader); speed_limit (m/s, shown under the speed); tl_state: the light's current phase
    ('green'|'yellow'|'red' or None); stop_kind: 'stop'|'yield', the kind of sign at stop_distance.
    """

    mode: str = "dp"
    tl_distance: float | None = None
    tl_remaining: float | None = None
    stop_distance: float | None = None
    curve_distance: float | None = None
    psi: float | None = None
    speed_limit: float | None = None
    tl_state: str | None = None
    stop_kind: str = "stop"


ICONS = ("green_wave", "stop_sign", "yield_sign", "curve")


@fast_init
@dataclass(frozen=True)
class HudAdvice:
    """What the HUD shows: v_opt (m/s), hud_arrow -1|0|1, arrow_len 0..1, hud_in_band (black digits, coast),
    color ('black'|'green'|'red'), warning (the controller's alert: tone or psi < 0), tl_countdown (s or None),
    icon (one of ICONS or None), speed_limit (m/s or None), tl_phase (the phase whose remaining time tl_countdown
    is, or None), tone (the HUD's warning tone: a slow-down advice not followed for warn_delay s)."""

    v_opt: float
    hud_arrow: int
    arrow_len: float
    hud_in_band: bool
    color: str
    warning: bool
    tl_countdown: float | None
    icon: str | None
    speed_limit: float | None
    tl_phase: str | None = None
    tone: bool = False


def update_unfollowed(prev: float, arrow: int, a: float, dt: float, *,
                      not_decel: float = CONTROLLER.not_decel) -> float:
    """Seconds a slow-down advice (arrow -1) has gone unfollowed: grows by dt while the arrow points down and the
    driver decelerates less than not_decel m/s^2, resets to 0 otherwise."""
    if arrow < 0 and a > -not_decel:
        return prev + dt
    return 0.0


def advisory(state: HudState, plan: Sequence[float], context: HudContext, *,
             arrow_full_scale: float = CONTROLLER.arrow_full_scale, icon_range: float = CONTROLLER.icon_range,
             warn_delay: float = CONTROLLER.warn_delay, standstill: float = CONTROLLER.standstill,
             start_min: float = CONTROLLER.start_min, band: float = CONTROLLER.hud_band) -> HudAdvice:
    """The HUD record for a measured state, a plan of predicted speeds v_1..v_N (m/s) and the route context.

    Keyword arguments: the HUD fields of :class:`pedas.params.ControllerParams` (m/s, m, s, m/s, m/s, and
    ``band`` = ``hud_band``, m/s)."""
    v_opt = float(plan[0])
    dv = v_opt - state.v
    if dv > band or wants_start(state.v, v_opt, standstill=standstill, start_min=start_min):
        arrow, color = 1, "green"
    elif dv < -band:
        arrow, color = -1, "red"
    else:
        arrow, color = 0, "black"
    arrow_len = 0.0 if arrow == 0 else min(abs(dv) / arrow_full_scale, 1.0)
    countdown, phase = None, None
    if (context.tl_distance is not None and context.tl_remaining is not None
            and 0.0 <= context.tl_distance <= icon_range and context.tl_remaining < HUD_TL_COUNTDOWN):
        countdown, phase = float(context.tl_remaining), context.tl_state
    if context.stop_distance is not None and 0.0 <= context.stop_distance <= icon_range:
        icon = "yield_sign" if context.stop_kind == "yield" else "stop_sign"
    elif context.curve_distance is not None and 0.0 <= context.curve_distance <= icon_range:
        icon = "curve"
    elif context.mode == "green_wave" and context.tl_distance is not None and context.tl_distance <= icon_range:
        icon = "green_wave"
    else:
        icon = None
    tone = state.slow_unfollowed >= warn_delay
    warning = (context.psi is not None and context.psi < 0.0) or tone
    return HudAdvice(v_opt=v_opt, hud_arrow=arrow, arrow_len=float(arrow_len), hud_in_band=arrow == 0,
                     color=color, warning=bool(warning), tl_countdown=countdown, icon=icon,
                     speed_limit=context.speed_limit, tl_phase=phase, tone=bool(tone))

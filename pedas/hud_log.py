"""What the driver saw, per sample: the HUD frame as drive-log channels, and the tone rebuilt from a drive log.

The drive log (docs/contracts.md) keeps the arrow and the band (``hud_arrow``, ``hud_in_band``) and the
controller's warning; what else the HUD displayed is kept in the optional channels :data:`HUD_CHANNELS` (numbers,
so that they fit the store's DOUBLE extra channels): :func:`channel_values` turns a :class:`pedas.hud_frame.HudFrame`
into them and :func:`frame_from_channels` back. A live server calls :func:`channel_values` on the frame it sends
and logs the values with the sample.

For a log without them, :func:`unfollowed_series` rebuilds the seconds a slow-down advice went unfollowed from the
logged t, v and hud_arrow with the controller's own rule (:func:`pedas.hud.update_unfollowed`: the measured
acceleration a = (v_k - v_k-1) / (t_k - t_k-1), the previous sample's arrow), so the tone
(:func:`pedas.hud.advisory`) is what the driver heard.
"""
from __future__ import annotations

import math
from typing import Sequence

from pedas.hud_frame import HudFrame
from pedas.params import CONTROLLER
from pedas.hud import update_unfollowed

#: the optional channels: name, unit, description
HUD_CHANNELS: tuple[tuple[str, str, str], ...] = (
    ("hud_speed", "km/h", "speed digits shown (whole km/h)"),
    ("hud_limit", "km/h", "speed limit shown below the speed (empty: none)"),
    ("hud_arrow_len", "1", "arrow length shown, 0..1 of the full arrow"),
    ("hud_countdown", "s", "traffic-light countdown shown, whole s 0..9 (empty: none)"),
    ("hud_light", "1", "phase of the counted-down light: 1 green, 2 yellow, 3 red (empty: none)"),
    ("hud_icon", "1", "icon shown: 0 none, 1 green wave (G), 2 stop sign, 3 yield sign, 4 curve"),
    ("hud_tone", "1", "warning tone sounding: 1 yes, 0 no"),
    ("hud_arrow_shown", "1", "arrow shown: 1 up, 0 none (coast), -1 down, -2 the brake state (empty: hud_arrow)"),
)
LIGHT_CODES = {"green": 1.0, "yellow": 2.0, "red": 3.0}
ICON_CODES = {None: 0.0, "green_wave": 1.0, "stop_sign": 2.0, "yield_sign": 3.0, "curve": 4.0}


def _num(x) -> float:
    return math.nan if x is None else float(x)


def channel_values(frame: HudFrame) -> dict[str, float]:
    """The HUD channels of one frame (NaN where nothing is shown)."""
    return {"hud_speed": float(frame.speed), "hud_limit": _num(frame.limit), "hud_arrow_len": float(frame.arrow_len),
            "hud_countdown": _num(frame.countdown), "hud_light": _num(LIGHT_CODES.get(frame.light)),
            "hud_icon": ICON_CODES[frame.icon], "hud_tone": 1.0 if frame.warning else 0.0,
            "hud_arrow_shown": -2.0 if frame.brake else float(frame.arrow)}


def frame_from_channels(ch: dict, advice_kmh: float | None, arrow: int, in_band: bool) -> HudFrame:
    """The frame a sample's channels say was shown; advice_kmh, arrow and in_band are the log's v_advice (km/h),
    hud_arrow and hud_in_band."""
    def whole(x):
        return None if x is None or x != x else int(round(x))

    shown = ch.get("hud_arrow_shown")
    brake = shown == -2.0
    if shown is not None and shown == shown:   # the arrow the frame showed (cut_in_advice may differ from the log's)
        arrow, in_band = (-1, False) if brake else (int(shown), shown == 0.0)
    lights = {v: k for k, v in LIGHT_CODES.items()}
    icons = {v: k for k, v in ICON_CODES.items()}
    color = "black" if in_band or arrow == 0 else ("green" if arrow > 0 else "red")
    cd = whole(ch.get("hud_countdown"))
    return HudFrame(speed=whole(ch["hud_speed"]), advice=whole(advice_kmh), limit=whole(ch.get("hud_limit")),
                    arrow=int(arrow), arrow_len=float(ch.get("hud_arrow_len") or 0.0), color=color,
                    in_band=bool(in_band), countdown=cd, icon=icons.get(ch.get("hud_icon"), None),
                    warning=ch.get("hud_tone") == 1.0,
                    light=None if cd is None else lights.get(ch.get("hud_light")), brake=brake)


def unfollowed_series(t: Sequence[float], v: Sequence[float], arrow: Sequence[int | None], *,
                      dt: float = 0.2, not_decel: float = CONTROLLER.not_decel) -> list[float]:
    """Per sample, the seconds a slow-down advice had gone unfollowed (s), as the controller counted them: at
    sample k the acceleration since k-1 and the arrow shown at k-1 (a missing arrow counts as none); dt is the
    step assumed before the first sample (the controller's DT)."""
    out, unf, prev_arrow = [], 0.0, 0
    for k in range(len(t)):
        if k == 0:
            a, step = 0.0, dt
        else:
            step = t[k] - t[k - 1]
            a = (max(v[k], 0.0) - max(v[k - 1], 0.0)) / step if step > 0 else 0.0
            step = step if step > 0 else dt
        unf = update_unfollowed(unf, prev_arrow, a, step, not_decel=not_decel)
        out.append(unf)
        prev_arrow = 0 if arrow[k] is None or arrow[k] != arrow[k] else int(arrow[k])
    return out

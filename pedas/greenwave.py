"""Green-wave reference speed, eq. (1) (Sec. 3.2).

For the next traffic light m at distance d_TL and its green windows [g_mn, r_mn) (absolute SPaT times), arriving
within window n at constant speed requires d_TL / (r_mn - t) <= v <= d_TL / (g_mn - t):

    [v_ref,min, v_ref,max] = [d_TL / r_mn, d_TL / g_mn] ∩ [v_min, v_max]          (1)

(with r_mn, g_mn counted from now). The earliest window n with a non-empty band is used and v_ref,min is the
reference, since lower speeds are more energy-efficient. An empty band for every window within the horizon means
a stop at red is unavoidable: the reference falls back to v_DP (the MPC's d_TL >= 0 constraint stops the car).
Stop signs are exempt from eq. (1): approaching a stop sign the reference is v_DP, which the DP forces to 0 at
the stop line (compulsory halt, STOP_DWELL s).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pedas.params import CONTROLLER
from pedas.route import Route, TrafficLight

__all__ = ["GreenWave", "green_wave_band", "green_wave_reference"]


def green_wave_band(d_tl: float, t: float, light: TrafficLight, v_min: float, v_max: float,
                    horizon: float = CONTROLLER.gw_horizon, margin: float = CONTROLLER.gw_margin, *,
                    v_floor: float = CONTROLLER.gw_v_floor) -> tuple[float, float] | None:
    """Eq. (1): the speed band (m/s) to reach the stop line `d_tl` m ahead within a green window, or None.

    Windows up to `horizon` s ahead are scanned from the earliest; the first one whose band intersects
    [max(v_min, v_floor), v_max] is returned (a band below `v_floor` m/s is "crawl": stop unavoidable). A window
    open now (g <= t) has no upper bound from the SPaT (v_ref,max = v_max). Each window is shrunk by `margin` s at
    both ends (a future start only) so the arrival is not on the edge of red. At the stop line (d_tl <= 0) the band
    is [v_min, v_max] if the light is green now, else None. Defaults: the gw_* fields of
    :data:`pedas.params.CONTROLLER`.
    """
    lo_road = max(v_min, v_floor)
    if v_max < lo_road:
        return None
    if d_tl <= 0:
        return (float(v_min), float(v_max)) if light.state_at(t) == "green" else None
    for g, r in light.green_windows(t, t + horizon):
        if g > t + horizon:
            break
        g = g + margin if g > t else g
        r = r - margin
        if r <= max(g, t):
            continue
        v_lo = d_tl / (r - t) if math.isfinite(r) else 0.0  # d_TL / r_mn
        v_hi = d_tl / (g - t) if g > t else math.inf  # d_TL / g_mn
        lo, hi = max(v_lo, lo_road), min(v_hi, v_max)
        if lo <= hi:
            return (float(lo), float(hi))
    return None


@dataclass(frozen=True)
class GreenWave:
    """Reference speed v_ref (m/s) and why: mode 'green_wave' (eq. 1 band, v_ref = v_ref,min), 'dp' (no light in
    range, or stop at red unavoidable: v_ref = v_DP) or 'stop' (stop sign ahead: v_ref = v_DP which halts at it).
    tl_id: the light (or stop sign) concerned, None if none; band: (v_ref,min, v_ref,max) or None."""

    v_ref: float
    mode: str
    tl_id: str | None
    band: tuple[float, float] | None


def green_wave_reference(route: Route, s: float, t: float, v_dp_at_s: float,
                         spat_range: float = CONTROLLER.spat_range, horizon: float = CONTROLLER.gw_horizon,
                         margin: float = CONTROLLER.gw_margin, *, v_floor: float = CONTROLLER.gw_v_floor) -> GreenWave:
    """The reference speed at route position s (m) and time t (s) given the DP speed v_DP(s) (m/s).

    The next traffic light within `spat_range` m gets eq. (1) with v_min at s and v_max the smallest allowed
    speed up to its stop line (curves and limits on the way). A stop sign before that light takes precedence
    (mode 'stop'). No band -> v_DP (mode 'dp', tl_id set: stop at red unavoidable).
    """
    tl = route.next_light(s)
    ss = route.next_stop(s)
    if ss is not None and (tl is None or ss.s < tl.s) and ss.s - s <= spat_range:
        return GreenWave(float(v_dp_at_s), "stop", ss.ss_id, None)
    if tl is None or tl.s - s > spat_range:
        return GreenWave(float(v_dp_at_s), "dp", None, None)
    d_tl = tl.s - s
    v_min = route.at(s, "v_min")
    v_max = route.min_over(s, tl.s, "v_max")
    band = green_wave_band(d_tl, t, tl, v_min, v_max, horizon, margin, v_floor=v_floor)
    if band is None:
        return GreenWave(float(v_dp_at_s), "dp", tl.tl_id, None)
    return GreenWave(float(band[0]), "green_wave", tl.tl_id, band)

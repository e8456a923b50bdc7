"""HUD advisory (Sec. 3.8) as a pure function of state, plan and context."""
from __future__ import annotations

import pytest

from pedas.constants import HUD_BAND, KMH
from pedas.hud import HudContext, HudState, advisory, update_unfollowed, wants_start
from pedas.params import CONTROLLER


def test_band_arrow_and_length():
    ctx = HudContext()
    inside = advisory(HudState(v=10.0), [10.0 + 0.9 * HUD_BAND], ctx)
    assert (inside.hud_arrow, inside.hud_in_band, inside.color, inside.arrow_len) == (0, True, "black", 0.0)
    up = advisory(HudState(v=10.0), [10.0 + 1.0], ctx)
    assert (up.hud_arrow, up.hud_in_band, up.color) == (1, False, "green")
    assert up.arrow_len == pytest.approx(1.0 / CONTROLLER.arrow_full_scale)
    down = advisory(HudState(v=10.0), [10.0 - 20 * KMH, 5.0], ctx)
    assert (down.hud_arrow, down.color, down.arrow_len) == (-1, "red", 1.0)     # capped
    assert down.v_opt == pytest.approx(10.0 - 20 * KMH)                         # first planned speed
    assert HUD_BAND == pytest.approx(2.0 / 3.6)


def test_tl_countdown_only_below_10_s_and_in_range():
    st = HudState(v=10.0)
    assert advisory(st, [10.0], HudContext(tl_distance=80.0, tl_remaining=7.5)).tl_countdown == 7.5
    assert advisory(st, [10.0], HudContext(tl_distance=80.0, tl_remaining=12.0)).tl_countdown is None
    assert advisory(st, [10.0], HudContext(tl_distance=CONTROLLER.icon_range + 1, tl_remaining=5.0)).tl_countdown is None
    assert advisory(st, [10.0], HudContext()).tl_countdown is None


def test_icons_priority():
    st = HudState(v=10.0)
    gw = HudContext(mode="green_wave", tl_distance=120.0)
    assert advisory(st, [10.0], gw).icon == "green_wave"
    assert advisory(st, [10.0], HudContext(mode="dp", tl_distance=120.0)).icon is None
    assert advisory(st, [10.0], HudContext(mode="green_wave", tl_distance=120.0, curve_distance=60.0)).icon == "curve"
    assert advisory(st, [10.0], HudContext(stop_distance=90.0, curve_distance=60.0)).icon == "stop_sign"
    assert advisory(st, [10.0], HudContext(stop_distance=CONTROLLER.icon_range + 5)).icon is None


def test_warning_on_safe_distance_violation_or_ignored_slow_down():
    ctx = HudContext(psi=-0.5)
    assert advisory(HudState(v=10.0), [10.0], ctx).warning
    assert not advisory(HudState(v=10.0), [10.0], HudContext(psi=0.5)).warning
    assert advisory(HudState(v=10.0, slow_unfollowed=CONTROLLER.warn_delay), [8.0], HudContext()).warning
    assert not advisory(HudState(v=10.0, slow_unfollowed=CONTROLLER.warn_delay - 0.2), [8.0], HudContext()).warning


def test_update_unfollowed():
    t = 0.0
    for _ in range(10):                       # arrow down, driver keeps speed: accumulates
        t = update_unfollowed(t, -1, 0.0, 0.2)
    assert t == pytest.approx(2.0)
    assert update_unfollowed(t, -1, -CONTROLLER.not_decel - 0.1, 0.2) == 0.0    # decelerates: reset
    assert update_unfollowed(t, 0, 0.0, 0.2) == 0.0                  # no slow-down advice: reset


def test_thresholds_are_keyword_arguments():
    """The design thresholds are keyword arguments (defaults: pedas.params.CONTROLLER), not module constants."""
    st, ctx = HudState(v=10.0), HudContext(stop_distance=120.0)
    assert advisory(st, [10.0], ctx).icon == "stop_sign"
    assert advisory(st, [10.0], ctx, icon_range=100.0).icon is None
    assert advisory(st, [11.0], HudContext()).arrow_len == pytest.approx(1.0 / CONTROLLER.arrow_full_scale)
    assert advisory(st, [11.0], HudContext(), arrow_full_scale=2.0).arrow_len == pytest.approx(0.5)
    slow = HudState(v=10.0, slow_unfollowed=1.0)
    assert not advisory(slow, [8.0], HudContext()).warning
    assert advisory(slow, [8.0], HudContext(), warn_delay=1.0).warning
    assert update_unfollowed(0.0, -1, -0.2, 0.2) == pytest.approx(0.2)
    assert update_unfollowed(0.0, -1, -0.2, 0.2, not_decel=0.1) == 0.0
    # the drive-off rule keeps its two-argument form for the driver model (pedas.drivers)
    assert wants_start(0.0, 0.26) and not wants_start(0.0, 0.26, start_min=0.5)
    standing = advisory(HudState(v=0.0), [0.26], HudContext())
    assert standing.hud_arrow == 1
    assert advisory(HudState(v=0.0), [0.26], HudContext(), start_min=0.5).hud_arrow == 0


def test_tone_only_when_slow_down_advice_not_followed():
    """The HUD's tone is the paper's rule (slow-down advice not followed for warn_delay s); a violated safe
    distance alone raises the controller's warning (the virtual driver's cue) but no tone."""
    violated = advisory(HudState(v=10.0), [10.0], HudContext(psi=-0.5))
    assert violated.warning and not violated.tone
    ignored = advisory(HudState(v=10.0, slow_unfollowed=2.0), [8.0], HudContext())
    assert CONTROLLER.warn_delay == 2.0 and ignored.tone and ignored.warning
    assert not advisory(HudState(v=10.0, slow_unfollowed=1.8), [8.0], HudContext()).tone
    # at 5 Hz the timer sums 0.2 s steps in floating point: after ten it holds 1.9999999999999998 s (< 2.0), so
    # the tone sounds on the eleventh sample, 2.2 s after the arrow turned down (the controller's warning alike)
    unf = 0.0
    for _ in range(10):
        unf = update_unfollowed(unf, -1, -0.1, 0.2)
    assert unf == 1.9999999999999998
    assert not advisory(HudState(v=10.0, slow_unfollowed=unf), [8.0], HudContext()).tone
    unf = update_unfollowed(unf, -1, -0.1, 0.2)
    assert advisory(HudState(v=10.0, slow_unfollowed=unf), [8.0], HudContext()).tone


def test_counted_down_phase_and_yield_sign():
    ctx = HudContext(tl_distance=80.0, tl_remaining=4.2, tl_state="red")
    red = advisory(HudState(v=10.0), [10.0], ctx)
    assert (red.tl_countdown, red.tl_phase) == (4.2, "red")
    # no countdown (more than 10 s left): no phase either
    assert advisory(HudState(v=10.0), [10.0], HudContext(tl_distance=80.0, tl_remaining=12.0,
                                                        tl_state="green")).tl_phase is None
    assert advisory(HudState(v=10.0), [10.0], HudContext(stop_distance=60.0, stop_kind="yield")).icon == "yield_sign"
    assert advisory(HudState(v=10.0), [10.0], HudContext(stop_distance=60.0)).icon == "stop_sign"

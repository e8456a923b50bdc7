"""The HUD frame (pedas.hud_frame): display rounding with hand-worked numbers, and the nine Fig. 7 situations."""
from __future__ import annotations

import json

import pytest

from pedas.constants import KMH
from pedas.hud import HudAdvice
from pedas.hud_frame import FIG7, HudFrame, fig7_frames, hud_frame


def _advice(**kw) -> HudAdvice:
    base = dict(v_opt=10.0, hud_arrow=0, arrow_len=0.0, hud_in_band=True, color="black", warning=False,
                tl_countdown=None, icon=None, speed_limit=None)
    return HudAdvice(**{**base, **kw})


def test_rounding_to_displayed_integers():
    # 12.5 m/s = 45.0 km/h; 12.64 m/s = 45.504 km/h -> 46 (half up); 13.8889 m/s = 50.0 km/h
    f = hud_frame(12.64, _advice(v_opt=12.5, speed_limit=50 * KMH))
    assert (f.speed, f.advice, f.limit) == (46, 45, 50)
    assert hud_frame(-0.01, _advice()).speed == 0            # a negative speed reading shows 0
    # the countdown is rounded up: 2.3 s left shows 3, exactly 4 s shows 4
    assert hud_frame(10.0, _advice(tl_countdown=2.3)).countdown == 3
    assert hud_frame(10.0, _advice(tl_countdown=4.0)).countdown == 4
    assert hud_frame(10.0, _advice()).countdown is None and hud_frame(10.0, _advice()).limit is None


def test_colour_follows_arrow_and_band():
    assert hud_frame(10.0, _advice(hud_arrow=1, hud_in_band=False, arrow_len=0.25)).color == "green"
    assert hud_frame(10.0, _advice(hud_arrow=-1, hud_in_band=False, arrow_len=1.0)).color == "red"
    # the drive-off advice at standstill: arrow up although inside the km/h band of the digits
    assert hud_frame(0.0, _advice(v_opt=0.2, hud_arrow=1, hud_in_band=False)).color == "green"


def test_frame_from_controller_advisory_fields():
    """An Advisory (v_advice instead of v_opt) gives the same frame as the HudAdvice it was built from."""
    from pedas.controller import Advisory

    adv = Advisory(v_advice=11.0, controller="rt", mode="dp", ft=0.0, fb=0.0, hud_arrow=1, arrow_len=0.4,
                   hud_in_band=False, warning=True, tl_countdown=5.5, icon="curve", solve_status="solved",
                   fallback=False, plan_v=(11.0,), speed_limit=50 * KMH)
    hud = _advice(v_opt=11.0, hud_arrow=1, arrow_len=0.4, hud_in_band=False, color="green", warning=True,
                  tl_countdown=5.5, icon="curve", speed_limit=50 * KMH)
    assert hud_frame(9.0, adv) == hud_frame(9.0, hud)
    assert json.loads(json.dumps(hud_frame(9.0, adv).as_dict()))["countdown"] == 6


def test_fig7_situations_show_what_their_captions_say():
    frames = fig7_frames()
    assert list(frames) == list("abcdefghi")
    a, b, c, d, e, f, g, h, i = (frames[k] for k in "abcdefghi")
    assert (a.arrow, a.color) == (1, "green") and (b.arrow, b.color) == (-1, "red")
    assert (c.arrow, c.color, c.in_band) == (0, "black", True)
    assert d.countdown == 7 and d.icon is None          # 6.4 s left -> 7
    assert (e.icon, e.arrow) == ("green_wave", 1)
    assert f.icon == "stop_sign" and g.icon == "curve" and g.limit == 100
    assert h.warning and i.warning and not any(frames[k].warning for k in "abcdefg")
    # only the situation that shows a countdown has one, only e-g show an icon
    assert [k for k, fr in frames.items() if fr.countdown is not None] == ["d"]
    assert [k for k, fr in frames.items() if fr.icon] == ["e", "f", "g"]
    assert len({s.caption for s in FIG7}) == 9


@pytest.mark.parametrize("v_opt,expected", [(10.0 + 5 * KMH, 0.5), (10.0 + 20 * KMH, 1.0)])
def test_arrow_length_carried_through(v_opt, expected):
    from pedas.hud import HudContext, HudState, advisory

    frame = hud_frame(10.0, advisory(HudState(v=10.0), [v_opt], HudContext()))
    assert isinstance(frame, HudFrame) and frame.arrow_len == pytest.approx(expected)

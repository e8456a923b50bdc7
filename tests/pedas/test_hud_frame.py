"""The HUD frame (pedas.hud_frame): display rounding with hand-worked numbers, and the nine Fig. 7 situations."""
from __future__ import annotations

import json

import pytest

from pedas.constants import KMH
from pedas.hud import HudAdvice
from pedas.hud import advisory
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
    # the countdown is rounded down (the paper shows times under 10 s): 2.3 s left shows 2, exactly 4 s shows 4,
    # 9.99 s shows 9 (never 10), the last second shows 0; a float 6.9999999999 for 7 s shows 7
    assert hud_frame(10.0, _advice(tl_countdown=2.3)).countdown == 2
    assert hud_frame(10.0, _advice(tl_countdown=4.0)).countdown == 4
    assert hud_frame(10.0, _advice(tl_countdown=9.99)).countdown == 9
    assert hud_frame(10.0, _advice(tl_countdown=0.4)).countdown == 0
    assert hud_frame(10.0, _advice(tl_countdown=7.0 - 1e-10)).countdown == 7
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
                   fallback=False, plan_v=(11.0,), speed_limit=50 * KMH, tl_phase="green", tone=False)
    hud = _advice(v_opt=11.0, hud_arrow=1, arrow_len=0.4, hud_in_band=False, color="green", warning=True,
                  tl_countdown=5.5, icon="curve", speed_limit=50 * KMH, tl_phase="green")
    assert hud_frame(9.0, adv) == hud_frame(9.0, hud)
    shown = json.loads(json.dumps(hud_frame(9.0, adv).as_dict()))
    assert (shown["countdown"], shown["light"]) == (5, "green")
    # the frame's warning is the tone: the controller's warning without a tone (safe distance) sounds nothing
    assert shown["warning"] is False
    assert hud_frame(9.0, _advice(hud_arrow=-1, hud_in_band=False, warning=True, tone=True)).warning is True


def test_fig7_panels_show_what_the_papers_text_says():
    """Each panel, produced by advisory from a recorded controller state of a reference drive, shows what the
    paper's text describes for it (the paper, Fig. 7 and Sec. 3.8)."""
    frames = fig7_frames()
    assert list(frames) == list("abcdefghi")
    a, b, c, d, e, f, g, h, i = (frames[k] for k in "abcdefghi")
    assert a.arrow != 0 and a.countdown is not None                      # all three regions shown
    assert b.icon == "green_wave"                                        # the "G" icon
    assert (c.icon, c.arrow) == ("stop_sign", -1)                        # stop sign, slow down
    assert (d.color, d.in_band, d.arrow) == ("black", True, 0) and d.limit >= 100   # band, freeway
    assert (e.arrow, e.icon, e.countdown) == (1, None, None)             # speed up to the comfort distance
    assert (f.arrow, f.icon, f.countdown) == (-1, None, None)            # slow down before d_s is violated
    assert (g.icon, g.arrow) == ("curve", -1)
    assert (h.light, i.light) == ("green", "red") and h.countdown < 10 and i.countdown < 10
    assert not any(fr.warning for fr in frames.values())
    by = {s.key: s for s in FIG7}
    assert by["d"].context.mode == "dp" and by["b"].context.mode == "green_wave"
    assert by["e"].context.psi > 0 and 0.0 <= by["f"].context.psi <= 5.0         # psi = d_rel - d_s, m
    assert len({s.sentence for s in FIG7}) == 9 and all(s.drive.startswith("P") for s in FIG7)


def test_each_stored_state_passes_its_panels_test():
    """The stored states (pedas/hud_fig7.json) pass the test of the panel they are stored for (pedas.hud_search)."""
    from pedas.hud_search import PANELS, pick
    from pedas.params import CONTROLLER

    w = CONTROLLER.cf_weights
    records = [{"advice": advisory(s.state, s.plan, s.context), "context": s.context, "v": s.state.v,
                "plan0": s.plan[0], "controller": "cf" if s.context.mode == "follow" else "rt",
                "leader": (s.context.psi + w.h_s * s.state.v + w.d_min, 8.0) if s.context.psi is not None else None,
                "d_c": w.h_c * s.state.v + w.d_min} for s in FIG7]
    for p, r in zip(PANELS, records):
        assert p.test(r), p.key      # every stored panel passes its own panel's test
        assert pick(records, p) is not None


@pytest.mark.parametrize("v_opt,expected", [(10.0 + 5 * KMH, 0.5), (10.0 + 20 * KMH, 1.0)])
def test_arrow_length_carried_through(v_opt, expected):
    from pedas.hud import HudContext, HudState, advisory

    frame = hud_frame(10.0, advisory(HudState(v=10.0), [v_opt], HudContext()))
    assert isinstance(frame, HudFrame) and frame.arrow_len == pytest.approx(expected)


def test_cut_in_advice_hand_worked():
    """P006 of the reference cohort at t = 767.2 s: 82.10 km/h, a car cut in 4.54 m ahead at 119.59 km/h, the
    speed correction advised 0 km/h. The leader is faster: DRAC = 0, the shown advice is bounded by
    min(v, v_p) = v: coast, no arrow. A leader at 60 km/h 10 m ahead: DRAC = (22.81 - 16.67)^2 / 20 = 1.88 m/s^2
    <= 3.4, the advice is bounded by 60 km/h; 5 m ahead at 40 km/h: DRAC = (22.81 - 11.11)^2 / 10 =
    13.7 m/s^2 > 3.4: the brake state."""
    from types import SimpleNamespace

    from pedas.constants import KMH
    from pedas.hud_frame import cut_in_advice, hud_frame

    v = 82.10 * KMH
    adv = SimpleNamespace(v_advice=0.0, hud_arrow=-1, arrow_len=1.0, hud_in_band=False, warning=True,
                          tl_countdown=None, icon=None, speed_limit=120 * KMH, tl_phase=None, tone=False)
    assert cut_in_advice(v, 0.0, (4.54, 119.59 * KMH), True) == (v, False)
    f = hud_frame(v, adv, (4.54, 119.59 * KMH))
    assert (f.advice, f.arrow, f.color, f.in_band, f.brake) == (82, 0, "black", True, False)
    assert cut_in_advice(v, 0.0, (10.0, 60 * KMH), True) == (pytest.approx(60 * KMH), False)
    f = hud_frame(v, adv, (10.0, 60 * KMH))
    assert (f.advice, f.arrow, f.color, f.brake) == (60, -1, "red", False)
    f = hud_frame(v, adv, (5.0, 40 * KMH))
    assert (f.advice, f.arrow, f.arrow_len, f.brake) == (0, -1, 1.0, True)
    # no alert (psi >= 0) or no leader: the controller's advice as it is
    assert cut_in_advice(v, 0.0, (4.54, 119.59 * KMH), False) == (0.0, False)
    assert hud_frame(v, adv).advice == 0 and hud_frame(v, adv).arrow == -1


def test_tone_rules():
    """"unfollowed": the controller's tone as it is; "margin": only while psi = gap - (d_min + h_s v) < 0."""
    from types import SimpleNamespace

    from pedas.hud_frame import hud_frame
    from pedas.params import CONTROLLER

    cf = CONTROLLER.cf_weights
    v = 20.0
    d_s = cf.d_min + cf.h_s * v
    adv = SimpleNamespace(v_advice=18.0, hud_arrow=-1, arrow_len=0.5, hud_in_band=False, warning=True,
                          tl_countdown=None, icon=None, speed_limit=None, tl_phase=None, tone=True)
    assert hud_frame(v, adv).warning and not hud_frame(v, adv, None, "margin").warning
    assert not hud_frame(v, adv, (d_s + 0.1, 20.0), "margin").warning
    assert hud_frame(v, adv, (d_s - 0.1, 20.0), "margin").warning
    assert not hud_frame(v, SimpleNamespace(**{**vars(adv), "tone": False}), (1.0, 20.0), "margin").warning

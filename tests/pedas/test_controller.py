"""PedasController in closed loop with an ideal driver (the next speed is the advised speed)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pedas.constants import DT, N_HORIZON, SENSOR_RANGE, STOP_DWELL
from pedas.controller import Advisory, PedasController
from pedas.params import CONTROLLER, ControllerParams, MpcWeights, OsqpSettings
from pedas.route import Route, StopSign, TrafficLight
from pedas.speed_correction import corrected_speed

PLAN = (("green", 20.0), ("yellow", 3.0), ("red", 20.0))


def drive(ctrl, s=0.0, v=10.0, t=0.0, s_end=None, t_end=300.0, leader=None):
    """Ideal driver: v_{k+1} = v_advice. leader(t, s) -> (gap, v_p) | None. Returns a list of rows."""
    rows = []
    s_end = ctrl.route.length - 5.0 if s_end is None else s_end
    while s < s_end and t < t_end:
        lead = leader(t, s) if leader else None
        adv = ctrl.step(t, s, v, lead)
        v_new = adv.v_advice
        rows.append(dict(t=t, s=s, v=v, adv=adv, lead=lead, s_next=s + 0.5 * DT * (v + v_new)))
        s, v, t = s + 0.5 * DT * (v + v_new), v_new, t + DT
    return rows


def test_advisory_record():
    route = Route.synthetic(length=600.0)
    adv = PedasController(route).step(0.0, 0.0, 8.0, None)
    assert isinstance(adv, Advisory)
    with pytest.raises(dataclasses.FrozenInstanceError):
        adv.v_advice = 1.0
    assert adv.controller == "rt" and adv.mode in ("dp", "green_wave")
    assert len(adv.plan_v) == N_HORIZON and adv.plan_v[0] == adv.v_advice
    assert adv.solve_status == "solved" and not adv.fallback
    assert adv.hud_arrow in (-1, 0, 1) and 0.0 <= adv.arrow_len <= 1.0


def test_stop_sign_stop_in_band_and_dwell():
    route = Route.synthetic(length=700.0, stops=[StopSign("SS1", 300.0)])
    ctrl = PedasController(route)
    rows = drive(ctrl, s=0.0, v=12.0)
    stopped = [r for r in rows if r["v"] < 0.3 and 250.0 < r["s"] < 301.0]
    assert stopped, "the vehicle never stopped at the stop sign"
    s_stop = stopped[0]["s"]
    assert 300.0 - route.d_stopline - 0.05 <= s_stop <= 300.0 + 0.05        # within the stop-line band
    t_stop = stopped[0]["t"]
    t_leave = min(r["t"] for r in rows if r["s"] > 300.05)
    assert t_leave - t_stop >= STOP_DWELL - 1e-9                            # 3 s compulsory halt
    assert rows[-1]["s"] > 600.0                                             # and it drives on
    assert ctrl.stats["stops_served"] == 1 and ctrl.stats["stops_missed"] == 0
    assert any(r["adv"].icon == "stop_sign" for r in rows)
    assert not any(r["adv"].fallback for r in rows)


def test_standstill_just_past_the_stop_sign_serves_the_stop():
    """A driver who crept 0.8 m past the sign and stopped there: after the dwell the advice lets them go on."""
    route = Route.synthetic(length=700.0, stops=[StopSign("SS1", 300.0)])
    ctrl = PedasController(route)
    t, advice = 0.0, []
    while t < STOP_DWELL + 1.0:
        advice.append(ctrl.step(t, 300.8, 0.0, None).v_advice)
        t += DT
    assert ctrl.stats["stops_served"] == 1 and ctrl.stats["stops_missed"] == 0
    assert advice[-1] > 0.0


def test_red_light_is_never_crossed():
    # red from 0 to 40 s at 300 m: a 12 m/s vehicle would arrive at 25 s
    tl = TrafficLight("TL1", 300.0, (("red", 40.0), ("green", 30.0), ("yellow", 3.0)))
    route = Route.synthetic(length=600.0, lights=[tl])
    ctrl = PedasController(route)
    rows = drive(ctrl, s=0.0, v=12.0)
    crossing = [r for r in rows if r["s"] < 300.0 <= r["s_next"]]
    assert len(crossing) == 1
    assert tl.state_at(crossing[0]["t"] + DT) == "green"
    waiting = [r for r in rows if r["v"] < 0.3 and r["s"] < 300.0]
    assert waiting and 300.0 - route.d_stopline - 0.05 <= waiting[0]["s"] <= 300.0
    assert any(r["adv"].mode == "stop" for r in rows)
    assert any(r["adv"].tl_countdown is not None for r in rows)


def test_green_wave_crosses_two_lights_in_green_without_stopping():
    lights = [TrafficLight("TL1", 500.0, PLAN), TrafficLight("TL2", 1100.0, PLAN, offset=10.0)]
    route = Route.synthetic(length=1400.0, lights=lights)
    rows = drive(PedasController(route), s=0.0, v=10.0)
    for tl in lights:
        cross = [r for r in rows if r["s"] < tl.s <= r["s_next"]]
        assert len(cross) == 1
        assert tl.state_at(cross[0]["t"] + DT) == "green", tl.tl_id
    assert min(r["v"] for r in rows if r["s"] < 1200.0) > 5.0              # no stop (the DP ends at 0)
    assert any(r["adv"].mode == "green_wave" and r["adv"].icon == "green_wave" for r in rows)


def leader_escaping():
    """leader(t, s): drives 8 m/s for 40 s from 150 m ahead, then 20 m/s (it escapes the sensor range)."""
    lead = {"s": 150.0, "t": 0.0}

    def leader(t, s):
        v_p = 8.0 if t < 40.0 else 20.0
        lead["s"] += v_p * (t - lead["t"])
        lead["t"] = t
        gap = lead["s"] - s
        return (gap, v_p) if gap <= 150.0 else None

    return leader


def test_switching_at_sensor_range_with_bounded_advice_jump():
    route = Route.synthetic(length=2500.0)
    ctrl = PedasController(route)
    rows = drive(ctrl, s=0.0, v=13.0, t_end=120.0, leader=leader_escaping())
    ctrls = [r["adv"].controller for r in rows]
    for r in rows:   # cf exactly when the leader is within the sensor range
        assert (r["adv"].controller == "cf") == (r["lead"] is not None and r["lead"][0] <= SENSOR_RANGE)
    switches = [i for i in range(1, len(rows)) if ctrls[i] != ctrls[i - 1]]
    assert len(switches) == 2 and ctrls[switches[0]] == "cf" and ctrls[switches[1]] == "rt"
    for i in switches:
        for j in range(i, min(i + CONTROLLER.blend_steps, len(rows))):
            jump = abs(rows[j]["adv"].v_advice - rows[j - 1]["adv"].v_advice)
            assert jump <= CONTROLLER.blend_max_step + 1e-9, (i, j, jump)
    assert not any(r["adv"].fallback for r in rows)
    assert ctrl.stats["switches"] == 2
    # car following never advises a state inside the safe distance here (psi stays >= 0)
    assert all(r["lead"][0] - (3.0 + 1.0 * r["v"]) >= -1e-6 for r in rows if r["adv"].controller == "cf")


def test_speed_correction_when_inside_the_safe_distance():
    route = Route.synthetic(length=800.0)
    ctrl = PedasController(route)
    v = 12.0
    psi = -6.0                                   # v_corr = -1.21 m/s: outside the +-2 km/h band
    adv = ctrl.step(0.0, 100.0, v, (3.0 + 1.0 * v + psi, 12.0))
    assert adv.controller == "cf" and adv.mode == "follow"
    assert adv.v_advice <= corrected_speed(v, psi) + 1e-9
    assert adv.warning and adv.hud_arrow == -1
    assert ctrl.stats["corrections"] == 1


def test_infeasible_solve_falls_back_to_a_flagged_braking_plan():
    tl = TrafficLight("TL1", 300.0, (("red", 60.0), ("green", 30.0)))
    route = Route.synthetic(length=600.0, speed_limit=25.0, lights=[tl])
    ctrl = PedasController(route)
    adv = ctrl.step(0.0, 296.0, 20.0, None)     # 4 m before a red light at 20 m/s: no feasible stop
    assert adv.fallback and adv.solve_status.startswith("fallback:")
    assert "infeasible" in adv.solve_status
    assert np.allclose(np.diff((20.0,) + adv.plan_v), -CONTROLLER.fallback_decel * DT)
    assert adv.fb > 0 and adv.ft == 0.0
    assert ctrl.stats["fallbacks"] == 1


def test_same_inputs_same_outputs():
    lights = [TrafficLight("TL1", 400.0, PLAN)]
    route = Route.synthetic(length=900.0, lights=lights, stops=[StopSign("SS1", 700.0)])
    a = [r["adv"] for r in drive(PedasController(route), v=9.0, t_end=60.0)]
    b = [r["adv"] for r in drive(PedasController(route), v=9.0, t_end=60.0)]
    assert a == b


def test_curve_is_taken_at_its_safe_speed_with_early_advice():
    kappa = np.zeros(101)
    kappa[50:60] = 1.0 / 40.0                       # 500-590 m: radius 40 m -> sqrt(2.0 * 40) = 8.9 m/s
    route = Route.synthetic(length=1000.0, curvature=kappa)
    rows = drive(PedasController(route), s=0.0, v=13.0)
    in_curve = [r["v"] for r in rows if 500.0 <= r["s"] <= 590.0]
    assert max(in_curve) <= np.sqrt(2.0 * 40.0) + 0.05
    slowing = [r for r in rows if r["s"] < 500.0 and r["adv"].icon == "curve" and r["adv"].v_advice < r["v"] - 0.1]
    assert slowing and min(r["s"] for r in slowing) < 470.0       # slow-down advice well before the curve


def test_settings_are_frozen_and_hashable():
    assert isinstance(CONTROLLER, ControllerParams) and CONTROLLER == ControllerParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        CONTROLLER.blend_max_step = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        CONTROLLER.osqp.eps_abs = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        CONTROLLER.rt_weights.zeta1 = 1.0
    tuned = dataclasses.replace(CONTROLLER, blend_max_step=0.1)
    assert len({CONTROLLER: 0, tuned: 1, ControllerParams(): 2}) == 2
    assert hash(tuned) == hash(dataclasses.replace(CONTROLLER, blend_max_step=0.1))


def test_settings_reach_both_mpcs_and_osqp():
    rt_w = MpcWeights(zeta1=4.0)
    cf_w = dataclasses.replace(CONTROLLER.cf_weights, h_s=1.5, d_min=4.0)
    settings = dataclasses.replace(CONTROLLER, rt_weights=rt_w, cf_weights=cf_w,
                                   osqp=OsqpSettings(eps_abs=1e-4, max_iter=2000))
    ctrl = PedasController(Route.synthetic(length=600.0), settings=settings)
    assert ctrl.rt.w is rt_w and ctrl.cf.w is cf_w and (ctrl.h_s, ctrl.d_min) == (1.5, 4.0)
    for mpc in (ctrl.rt, ctrl.cf):
        assert (mpc.settings["eps_abs"], mpc.settings["max_iter"], mpc.settings["eps_rel"]) == (1e-4, 2000, 2e-5)
        assert "shift_warm_start" not in mpc.settings and not mpc.shift_warm_start
    # OSQP overrides for solver experiments (bench mpc) go on top of settings.osqp
    ctrl = PedasController(Route.synthetic(length=600.0), settings=settings, osqp_settings={"eps_rel": 1e-4})
    assert (ctrl.rt.settings["eps_abs"], ctrl.rt.settings["eps_rel"]) == (1e-4, 1e-4)


def test_tuning_the_hand_over_rate_limit_without_monkeypatching():
    """blend_max_step bounds the advice change after a switch; the default bound is not binding that tightly."""
    route = Route.synthetic(length=2500.0)

    def jumps_after_switches(settings):
        rows = drive(PedasController(route, settings=settings), s=0.0, v=13.0, t_end=120.0,
                     leader=leader_escaping())
        ctrls = [r["adv"].controller for r in rows]
        switches = [i for i in range(1, len(rows)) if ctrls[i] != ctrls[i - 1]]
        assert len(switches) == 2
        return [abs(rows[j]["adv"].v_advice - rows[j - 1]["adv"].v_advice)
                for i in switches for j in range(i, min(i + settings.blend_steps, len(rows)))]

    slow = dataclasses.replace(CONTROLLER, blend_max_step=0.05)
    assert max(jumps_after_switches(slow)) <= 0.05 + 1e-9
    assert max(jumps_after_switches(CONTROLLER)) > 0.05


def test_tuning_the_fallback_and_the_hud_without_monkeypatching():
    tl = TrafficLight("TL1", 300.0, (("red", 60.0), ("green", 30.0)))
    route = Route.synthetic(length=600.0, speed_limit=25.0, lights=[tl])
    settings = dataclasses.replace(CONTROLLER, fallback_decel=2.0)
    adv = PedasController(route, settings=settings).step(0.0, 296.0, 20.0, None)   # infeasible: fallback
    assert adv.fallback and np.allclose(np.diff((20.0,) + adv.plan_v), -2.0 * DT)
    # the stop-sign icon appears within icon_range of the sign
    route = Route.synthetic(length=700.0, stops=[StopSign("SS1", 300.0)])
    assert PedasController(route).step(0.0, 180.0, 10.0, None).icon == "stop_sign"          # 120 m < 150 m
    near = dataclasses.replace(CONTROLLER, icon_range=100.0)
    assert PedasController(route, settings=near).step(0.0, 180.0, 10.0, None).icon is None


def test_hud_limit_is_the_legal_limit_in_force_never_interpolated():
    """A limit change 50 -> 100 km/h between grid points 300 and 310 m: between them the HUD shows 50 (the sign
    passed), from 310 m on 100; the old linear interpolation showed 75 km/h at 305 m."""
    import dataclasses as dc

    from pedas.constants import KMH

    base = Route.synthetic(length=800.0)
    limit = np.where(base.s < 310.0, 50 * KMH, 100 * KMH)
    route = dc.replace(base, speed_limit=limit)
    shown = [PedasController(route).step(0.0, s, 13.0, None).speed_limit / KMH for s in (300.0, 305.0, 309.9, 310.0)]
    assert shown == pytest.approx([50.0, 50.0, 50.0, 100.0])

"""Liveness of the drive loop: an unheld standstill is an error that names the drive, and the real driver model
has no such fixed point (the advice/driver deadlock a flat traction line used to cause)."""
from __future__ import annotations

import pickle

import pytest

import pedas.drivers
import pedas.hud
import pedas.vehicle
from pedas.drive import (STANDSTILL_LIMIT, DriveError, DriveTimeout, LivenessGuard, LivenessViolation,
                         SafetyViolation, drive)
from pedas.hud import HudContext, HudState, advisory, wants_start


def _stand(guard: LivenessGuard, seconds: float, **kw) -> None:
    t = 0.0
    while t <= seconds:
        guard.check(t, 100.0, 0.0, kw.get("gap"), kw.get("tl_state"), kw.get("d_tl"))
        t += 0.2


def test_standing_at_green_with_a_free_road_is_a_violation():
    with pytest.raises(LivenessViolation, match=r"standing still for 20\.\d s at t=20\.\d s, s=100\.0 m"):
        _stand(LivenessGuard(), STANDSTILL_LIMIT + 1.0, tl_state="green", d_tl=5.0)
    with pytest.raises(LivenessViolation, match="no light ahead"):
        _stand(LivenessGuard(), STANDSTILL_LIMIT + 1.0)


@pytest.mark.parametrize("held", [dict(tl_state="red", d_tl=3.0), dict(tl_state="yellow", d_tl=30.0),
                                  dict(gap=8.0, tl_state="green", d_tl=20.0)])
def test_a_light_or_a_vehicle_holds_the_car_legitimately(held):
    _stand(LivenessGuard(), 10 * STANDSTILL_LIMIT, **held)


def test_moving_resets_the_clock():
    g = LivenessGuard()
    _stand(g, STANDSTILL_LIMIT - 1.0)
    g.check(STANDSTILL_LIMIT, 100.0, 1.0, None, None, None)  # drove off
    _stand(g, STANDSTILL_LIMIT - 1.0)


def test_drive_errors_keep_kind_and_name_across_processes():
    err = SafetyViolation("red light T1 crossed", "red_light").named("pEDAS drive of participant seed 7")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is SafetyViolation and back.kind == "red_light"
    assert str(back) == "pEDAS drive of participant seed 7: red light T1 crossed"
    assert LivenessViolation("x").kind == "standstill" and DriveTimeout("x").kind == "timeout"
    assert issubclass(LivenessViolation, DriveError) and DriveError("x").kind == "error"


def test_hud_says_drive_off_at_standstill_inside_the_band():
    """A plan leaving standstill by less than the 2 km/h band shows the arrow up, not black digits."""
    ctx = HudContext()
    standing = advisory(HudState(v=0.0), [0.26], ctx)
    assert standing.hud_arrow == 1 and not standing.hud_in_band
    moving = advisory(HudState(v=10.0), [10.26], ctx)  # the band applies while moving
    assert moving.hud_arrow == 0 and moving.hud_in_band
    assert not wants_start(0.0, 0.05) and wants_start(0.0, 0.26) and not wants_start(1.0, 2.0)


@pytest.fixture
def flat_traction_line(monkeypatch):
    """The vehicle model one BLAS kernel used to produce: F_t,max flat at 2148.9 N (p3 = 0)."""
    real = pedas.vehicle.linear_model()
    flat = pedas.vehicle.LinearModel(real.p1, real.p2, 0.0, 2148.9, real.c_a, real.v_lo, real.v_hi)
    monkeypatch.setattr(pedas.vehicle, "linear_model", lambda *a, **k: flat)


@pytest.mark.sumo
@pytest.mark.slow
def test_a_stalled_driver_model_is_caught_and_the_real_one_drives_on(flat_traction_line, monkeypatch):
    # the stalled model: coasting inside the band even when standing (the behaviour before wants_start)
    with monkeypatch.context() as m:
        m.setattr(pedas.drivers, "wants_start", lambda v, target: False)
        m.setattr(pedas.hud, "wants_start", lambda v, target, **kw: False)
        with pytest.raises(LivenessViolation) as info:
            drive(1005, "cautious", "pedas")
    msg = str(info.value)
    assert msg.startswith("pEDAS drive of participant seed 1005 (cautious, traffic seed 1005): standing still")
    assert " t=" in msg and " s=" in msg
    # the real model with the same weak traction limit reaches the end of the route
    df = drive(1005, "cautious", "pedas")
    assert df["s"].iloc[-1] > 13_000


def test_a_cohort_drive_error_names_the_participant(monkeypatch, tmp_path):
    import pedas.drive
    from pedas.cohort import DriveTask, run_task

    def stalled(seed, style, condition, traffic_seed=None, scenario=None, whatif=None):
        raise LivenessViolation(f"pEDAS drive of participant seed {seed} ({style}): standing still at t=1 s")

    monkeypatch.setattr(pedas.drive, "drive", stalled)
    with pytest.raises(LivenessViolation, match=r"^P003: pEDAS drive of participant seed 42 \(sporty\)"):
        run_task(DriveTask("P003", 42, "sporty", "pedas"), str(tmp_path))

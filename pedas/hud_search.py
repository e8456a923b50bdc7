"""Fig. 7 from real drives: record the controller's HUD inputs at every step of a simulated pEDAS drive and find,
for each panel of Fig. 7, a step that shows the situation the paper's text describes.

:class:`RecordingController` is a :class:`pedas.controller.PedasController` that also keeps, per step, what
:func:`pedas.hud.advisory` was given (HudState, the first planned speed, HudContext) and what it returned; the drive
is the same drive (the recorder only reads). :data:`PANELS` are the paper's sentences with the test a recorded step
must pass and the score that picks one step among those that pass (the clearest instance: lowest score, earliest
on ties). :func:`search` drives the given people in order until every panel is found.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

from pedas.constants import KMH
from pedas.controller import PedasController
from pedas.hud import HudState, advisory, update_unfollowed


class RecordingController(PedasController):
    """A PedasController that records the HUD's inputs and output of every step in ``records`` (dicts: t, s, v,
    leader gap and speed, controller, state, plan0, context, advice)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.records: list[dict] = []
        self._leader = None

    def step(self, t, s, v, leader=None):
        self._leader = leader
        self._t_now, self._s_now = float(t), float(s)
        return super().step(t, s, v, leader)

    def _hud(self, s, v, a_meas, dt_real, pred, obj, sol, plan_v):
        cfg = self.settings
        unfollowed = update_unfollowed(self._unfollowed, self._last_arrow, a_meas, dt_real, not_decel=cfg.not_decel)
        hud = super()._hud(s, v, a_meas, dt_real, pred, obj, sol, plan_v)
        ctx = self._hud_context(s, v, pred, obj, sol)
        state = HudState(v=float(v), a=float(a_meas), slow_unfollowed=float(unfollowed))
        again = advisory(state, plan_v[:1], ctx, **self._hud_kw)
        if again != hud:   # postcondition: the recorded inputs give exactly what the controller showed
            raise RuntimeError(f"recorded HUD inputs at s={s:.1f} m do not reproduce the HUD: {again} != {hud}")
        self.records.append({"t": self._t_now, "s": float(s), "v": float(v), "leader": self._leader,
                             "controller": sol.ctrl, "state": state, "plan0": float(plan_v[0]), "context": ctx,
                             "advice": hud, "d_s": None if self._leader is None else
                             cfg.cf_weights.h_s * v + cfg.cf_weights.d_min,
                             "d_c": None if self._leader is None else cfg.cf_weights.h_c * v + cfg.cf_weights.d_min})
        return hud


@dataclass(frozen=True)
class Panel:
    """One panel of Fig. 7: letter, the paper's caption and the sentence of its text the panel follows, the test a
    recorded step must pass, the score that picks the clearest one (lower is better) and where we chose."""

    key: str
    caption: str
    sentence: str
    test: Callable[[dict], bool]
    score: Callable[[dict], float]
    choice: str


def _a(r):
    return r["advice"]


def _c(r):
    return r["context"]


def _plain(r):   # nothing else on the HUD's third region
    return _a(r).icon is None and _a(r).tl_countdown is None and not _a(r).tone


def _countdown_test(phase: str) -> Callable[[dict], bool]:
    """Test of panels h and i: the countdown alone on the HUD's third region while approaching (v > 10 km/h) a
    light in `phase` ("green" or "red")."""
    return lambda r: (_a(r).tl_phase == phase and _a(r).tl_countdown is not None and _a(r).icon is None
                      and r["v"] > 10 * KMH and not _a(r).tone)


def _countdown_score(r):   # panels h and i: about 6.5 s left
    return abs(_a(r).tl_countdown - 6.5)


PANELS: tuple[Panel, ...] = (
    Panel("a", "1. Current speed of the host vehicle, 2. Speed advisory using arrow visualization, 3. Additional "
               "useful information",
          "An example of the speed advisory system is shown in Figure a with information being displayed at three "
          "regions on the HUD.",
          lambda r: _a(r).hud_arrow == 1 and _a(r).tl_countdown is not None and _a(r).icon is None and not _a(r).tone,
          lambda r: abs(_a(r).arrow_len - 0.5) + abs(_a(r).tl_countdown - 5.0) / 10,
          "all three regions filled: an arrow up (region 2) and a countdown (region 3); the arrow as near half "
          "length as the drives offer (0.25 of full length in this step)"),
    Panel("b", "Green-wave speed advisory to cross the immediate TL signal at green phase",
          "An icon with a letter 'G' on a green background appears to indicate the driver that a green-wave is "
          "possible.",
          lambda r: (_a(r).icon == "green_wave" and _a(r).tl_countdown is None and r["v"] > 20 * KMH
                     and 40.0 <= _c(r).tl_distance <= 150.0 and not _a(r).tone),
          lambda r: abs(_c(r).tl_distance - 100.0) / 50 + (_c(r).tl_state != "green"),
          "the G icon while driving (v > 20 km/h) 40-150 m before a light in green; the paper does not say "
          "which arrow: in the drives the green-wave speed is mostly held (digits black, no arrow)"),
    Panel("c", "Speed advisory to slow down while approaching a stop sign",
          "pEDAS alerts the driver of a stop or yield sign ahead by displaying a visual icon on the HUD [...] "
          "it suggests the driver to gradually slow down while approaching the stop/yield sign.",
          lambda r: _a(r).icon == "stop_sign" and _a(r).hud_arrow == -1 and r["v"] > 20 * KMH and not _a(r).tone,
          lambda r: abs(_c(r).stop_distance - 80.0) / 40 + abs(_a(r).arrow_len - 0.5),
          "a stop sign (the study route has no yield sign), slow-down arrow, about 80 m before the line"),
    Panel("d", "Black digits indicate that current velocity is within the optimal speed band",
          "in a freeway scenario pEDAS recommends the driver to track a DP optimal speed [...] the color of the "
          "speed digit remains black when the driver reaches this optimal band",
          lambda r: (_a(r).hud_in_band and _c(r).mode == "dp" and r["controller"] == "rt" and _plain(r)
                     and (_c(r).speed_limit or 0) >= 100 * KMH and r["v"] > 80 * KMH),
          lambda r: abs(r["v"] - r["plan0"]),
          "freeway = a road with a limit of 100 km/h or more; DP reference tracked (rt controller, mode dp)"),
    Panel("e", "Indication to speed up to maintain a desired inter-vehicle distance to a preceding vehicle",
          "pEDAS suggests the driver to maintain a desired inter-vehicle distance to the preceding vehicle by "
          "suggesting to speed-up if the host vehicle violates the comfort distance",
          lambda r: (r["controller"] == "cf" and r["leader"] is not None and _a(r).hud_arrow == 1 and _plain(r)
                     and r["leader"][0] > r["d_c"] and r["v"] > 30 * KMH and r["leader"][1] > 5.0),
          lambda r: abs(_a(r).arrow_len - 0.5),
          "car following a moving leader, the gap larger than the comfort distance d_c = h_c v + d_min, arrow up"),
    Panel("f", "Advisory to slow down to maintain a safe distance to a preceding vehicle",
          "suggests the driver to slow down if the safe distance to the preceding vehicle is about to be violated",
          lambda r: (r["controller"] == "cf" and r["leader"] is not None and _a(r).hud_arrow == -1 and _plain(r)
                     and _c(r).psi is not None and 0.0 <= _c(r).psi <= 5.0 and r["v"] > 30 * KMH
                     and r["leader"][1] > 5.0),
          lambda r: _c(r).psi / 5 + abs(_a(r).arrow_len - 0.5),
          "'about to be violated' = the gap at most 5 m above the safe distance d_s = h_s v + d_min, behind a "
          "moving leader; no tone yet"),
    Panel("g", "Speed advisory to decelerate and travel at a safe speed while approaching a curved road",
          "pEDAS with the help of road curvature information alerts the driver to slow down well ahead of a sharp "
          "curve and suggests to take the turn at a safe speed.",
          lambda r: _a(r).icon == "curve" and _a(r).hud_arrow == -1 and _a(r).tl_countdown is None and not _a(r).tone,
          lambda r: abs(_c(r).curve_distance - 80.0) / 40 + abs(_a(r).arrow_len - 0.5) + (r["controller"] != "rt"),
          "the curve icon with a slow-down arrow, about 80 m before the curve, no leader ahead (rt controller)"),
    Panel("h", "Indication of the remaining time of green traffic light phase",
          "The next feature displays the remaining time (less than 10 s) of the immediate TL signal phase on the "
          "HUD when the host vehicle is approaching a signalized intersection [...] at TL green phase",
          _countdown_test("green"), _countdown_score,
          "approaching (v > 10 km/h) a light in green; about 6.5 s left"),
    Panel("i", "Indication of the remaining time of red traffic light phase",
          "The next feature displays the remaining time (less than 10 s) of the immediate TL signal phase [...] "
          "at TL red phase",
          _countdown_test("red"), _countdown_score,
          "approaching (v > 10 km/h) a light in red; about 6.5 s left"),
)


def pick(records: list[dict], panel: Panel) -> dict | None:
    """The recorded step that passes the panel's test with the lowest score (the earliest on ties), or None."""
    best = None
    for r in records:
        if panel.test(r) and (best is None or panel.score(r) < panel.score(best)):
            best = r
    return best


def record_drive(seed: int, style: str, traffic_seed: int, scenario: str):
    """Simulate the pEDAS drive of a person with a recording controller; (drive log, records)."""
    from pedas.drive import drive, study_route_and_reference

    route, v_dp = study_route_and_reference(scenario)
    ctrl = RecordingController(route, v_dp=v_dp)
    df = drive(seed, style, "pedas", traffic_seed=traffic_seed, scenario=scenario, controller=ctrl)
    return df, ctrl.records


def situation_record(panel: Panel, who: str, r: dict) -> dict:
    """The JSON record of a found panel: letter, caption, sentence, choice, whose drive and when, and the inputs of
    pedas.hud.advisory (state, plan, context) that reproduce it."""
    lead = r["leader"]
    return {"key": panel.key, "caption": panel.caption, "sentence": panel.sentence, "choice": panel.choice,
            "drive": who, "t": round(r["t"], 3), "s": round(r["s"], 3), "controller": r["controller"],
            "leader": None if lead is None else {"gap": lead[0], "v": lead[1]},
            "state": dataclasses.asdict(r["state"]), "plan": [r["plan0"]], "context": dataclasses.asdict(r["context"])}


def search(people, progress=print) -> list[dict]:
    """people: (label, seed, style, traffic_seed, scenario); drives each and keeps, per panel, the step with the
    lowest score over all drives (the earlier drive on ties); the situation records in panel order. RuntimeError
    when a panel is found in none of the drives."""
    found: dict[str, tuple[float, dict]] = {}
    for label, seed, style, tseed, scenario in people:
        _, records = record_drive(seed, style, tseed, scenario)
        for p in PANELS:
            r = pick(records, p)
            if r is not None and (p.key not in found or p.score(r) < found[p.key][0]):
                found[p.key] = (p.score(r), situation_record(p, label, r))
        progress(f"{label}: {len(records)} steps, panels found so far: {''.join(sorted(found))}")
    missing = [p.key for p in PANELS if p.key not in found]
    if missing:
        raise RuntimeError(f"no drive shows Fig. 7 panel(s) {', '.join(missing)}")
    return [found[p.key][1] for p in PANELS]

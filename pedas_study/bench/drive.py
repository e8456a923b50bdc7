"""Time of simulated drives (`pedas-study bench drive`): real-time factor of single drives (baseline, pEDAS with the
default QP backend, and pEDAS with the other backend), the traffic simulation alone, the cohort's worker speed-up.

A drive's wall time counts the drive loop only (SUMO start, traffic, driver, controller, invariants); the
one-time setup per process (network build check, route, DP reference) is reported separately. The cohort
speed-up runs the same small cohort on 1 and on 2 worker processes with empty caches; the projection to 68 drives
on 2 workers = one worker's start-up overhead + the mean drive-loop time x 68 / 2 (the drives of a cohort are
independent, so two workers share them evenly).

The traffic simulation alone is the floor under every drive of a scenario: the baseline drive's logged speeds are
replayed into a fresh SUMO run of the same traffic seed (:func:`traffic_alone`), and only the commands a drive sends
SUMO each step are timed (set the ego's speed, step, did it arrive). No driver model, controller, invariant or log
runs, so no drive of that scenario, assisted or not, can run faster than this. SUMO's start (network, the seeded
traffic) and the steps before the ego is inserted are timed apart (``start_s``): a drive's wall time counts them
too, once per drive.

Rounds: with ``repeats`` R, the drives run in R rounds, each round every drive once and then one replay of the
traffic alone. A drive's ratio to the traffic alone is taken within its round (ms per step over the replay's ms per
step of the same round) and reported as the median and range of the R ratios (``over_traffic``): on a shared
machine whose speed drifts over minutes, neighbours in time are the fair pair, where medians of separate blocks of
repeats compare different minutes.
"""
from __future__ import annotations

import statistics
import tempfile
import time

from pedas.constants import DT
from pedas.vocabulary import CONDITIONS, STYLES


def bench_drive(repeats: int = 1, cohort: int = 3, seed: int = 1, style: str = "normal",
                scenario: str | None = None) -> dict:
    """{'setup_s', 'scenario', 'baseline': {...}, 'pedas': {...}, 'pedas_<backend>': {...}, 'pedas_over_baseline',
    'traffic_alone': {...}, 'over_traffic': {...}, 'cohort': {...}|None}. 'pedas' runs the default QP backend
    (CONTROLLER.qp_backend), 'pedas_<backend>' the other one on the same drive; 'traffic_alone' replays the baseline
    drive (:func:`traffic_alone`); every drive in the traffic `scenario` (default pedas.scenario.DEFAULT_SCENARIO).
    `repeats` rounds (module docstring): 'over_traffic' = {drive key: {'median', 'min', 'max', 'rounds'}}, a drive's
    ms per step over the traffic alone's in the same round."""
    import dataclasses

    from pedas.drive import drive, study_route_and_reference
    from pedas.params import CONTROLLER
    from pedas.qp import BACKENDS
    from pedas.scenario import get_scenario

    sc = get_scenario(scenario).name
    t0 = time.perf_counter()
    study_route_and_reference(sc)
    setup = time.perf_counter() - t0
    out: dict = {"setup_s": setup, "scenario": sc}
    other = [b for b in BACKENDS if b != CONTROLLER.qp_backend]
    runs = [(cond, cond, None) for cond in CONDITIONS] + [
        (f"pedas_{b}", "pedas", dataclasses.replace(CONTROLLER, qp_backend=b)) for b in other]
    infos: dict[str, list[dict]] = {key: [] for key, _, _ in runs}
    replays: list[tuple[float, float]] = []   # (wall s, start s) of the traffic alone, one per round
    logs = {}
    for _ in range(repeats):
        for key, cond, settings in runs:
            logs[key] = drive(seed, style, cond, settings=settings, scenario=sc)
            infos[key].append(logs[key].attrs["drive"])
        replays.append(_replay(logs["baseline"]))
    for key, cond, settings in runs:
        info = infos[key][-1]
        wall = statistics.median(i["wall_s"] for i in infos[key])
        out[key] = {"sim_s": info["duration_s"], "wall_s_median": wall, "repeats": repeats,
                    "rtf_median": info["duration_s"] / wall, "ms_per_step": 1000.0 * wall / info["steps"],
                    "max_vehicles": info["max_vehicles"],
                    "backend": (settings or CONTROLLER).qp_backend if cond == "pedas" else None}
    out["pedas_over_baseline"] = out["pedas"]["wall_s_median"] / out["baseline"]["wall_s_median"]
    base = logs["baseline"].attrs["drive"]
    out["traffic_alone"] = _traffic_summary(base, replays)
    out["over_traffic"] = {}
    for key in infos:
        ratios = [(i["wall_s"] / i["steps"]) / (w / base["steps"]) for i, (w, _) in zip(infos[key], replays)]
        out["over_traffic"][key] = {"median": statistics.median(ratios), "min": min(ratios), "max": max(ratios),
                                    "rounds": ratios}
    out["cohort"] = _cohort_speedup(cohort, seed, sc) if cohort > 0 else None
    return out


def traffic_alone(log, repeats: int = 1) -> dict:
    """Time SUMO alone on a drive: replay the drive log's speeds (m/s) as the ego's speed commands into a new
    simulation of the drive's scenario and traffic seed. {'ms_per_step', 'rtf_median', 'steps', 'repeats',
    'start_s'}, medians over `repeats` replays; 'start_s': SUMO's start and the steps up to the ego's insertion (s),
    which the replay's steps do not count and a drive's wall time does.

    The replay must reproduce the drive: the ego has to arrive after exactly the logged number of steps (SUMO is
    deterministic for a seed), else RuntimeError, because a replay that drove elsewhere timed something else.
    """
    return _traffic_summary(log.attrs["drive"], [_replay(log) for _ in range(repeats)])


def _replay(log) -> tuple[float, float]:
    """One replay of :func:`traffic_alone`: (wall time of the replayed steps, SUMO's start and the steps up to the
    ego's insertion), both in s."""
    from pedas.traffic import Traffic

    info = log.attrs["drive"]
    v = log["v"].to_numpy(float)
    # the command of step k is the speed logged at step k + 1; the last one is the logged a applied once more
    cmds = [*v[1:].tolist(), max(float(v[-1] + log["a"].iloc[-1] * DT), 0.0)]
    t_start = time.perf_counter()
    with Traffic(info["traffic_seed"], scenario=info["scenario"]) as tr:
        tr.insert_ego()
        steps, arrived = 0, False
        t0 = time.perf_counter()
        for cmd in cmds:
            tr.set_ego_speed(cmd)
            tr.step()
            steps += 1
            if tr.ego_arrived():
                arrived = True
                break
        wall = time.perf_counter() - t0
    if not arrived or steps != info["steps"]:
        raise RuntimeError(f"the replay of the {info['scenario']} drive (traffic seed {info['traffic_seed']}) "
                           f"did not reproduce it: {steps} steps of {info['steps']}")
    return wall, t0 - t_start


def _traffic_summary(info: dict, replays: list[tuple[float, float]]) -> dict:
    """:func:`traffic_alone`'s dict from the replays' (wall s, start s) of the drive `info` describes."""
    wall = statistics.median(w for w, _ in replays)
    return {"ms_per_step": 1000.0 * wall / info["steps"], "rtf_median": info["duration_s"] / wall,
            "steps": info["steps"], "repeats": len(replays), "start_s": statistics.median(s for _, s in replays)}


def _cohort_speedup(n: int, seed: int, scenario: str) -> dict:
    import pandas as pd

    from pedas.cohort import cohort_tasks, simulate_cohort

    people = pd.DataFrame({"participant_id": [f"B{i:03d}" for i in range(n)],
                           "style": [STYLES[i % len(STYLES)] for i in range(n)]})
    tasks = cohort_tasks(people, base_seed=seed, scenario=scenario)
    walls, drive_wall = {}, 0.0
    for workers in (1, 2):
        with tempfile.TemporaryDirectory(prefix="bench-cohort-") as cache:
            t0 = time.perf_counter()
            res = simulate_cohort(tasks, workers=workers, cache_dir=cache, progress=False)
            walls[workers] = time.perf_counter() - t0
            if workers == 1:
                drive_wall = sum(df.attrs["drive"]["wall_s"] for df in res.values())
    # per-process overhead (spawn, imports, route, DP) = 1-worker wall - sum of the drive loops
    overhead = max(walls[1] - drive_wall, 0.0)
    return {"drives": len(tasks), "wall_1": walls[1], "wall_2": walls[2], "speedup": walls[1] / walls[2],
            "drive_wall_sum": drive_wall, "worker_overhead_s": overhead,
            "projected_68_on_2_s": overhead + drive_wall / len(tasks) * 68 / 2}

"""Cohort simulation: worker processes, Dask distributed, the input-hash cache, and the CLI commands."""
from __future__ import annotations

import pandas as pd
import pytest

from pedas.cohort import DriveTask, cohort_tasks, load_cached, participant_seed, simulate_cohort, task_key

pytestmark = pytest.mark.sumo


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("drive-cache")


def test_task_keys_and_seeds_are_stable():
    t = DriveTask("P001", 5, "normal", "pedas")
    assert task_key(t) == task_key(DriveTask("P009", 5, "normal", "pedas"))  # the person, not the label
    assert len({task_key(t), task_key(DriveTask("P001", 6, "normal", "pedas")),
                task_key(DriveTask("P001", 5, "sporty", "pedas")),
                task_key(DriveTask("P001", 5, "normal", "baseline")),
                task_key(DriveTask("P001", 5, "normal", "pedas", scenario="single-lane"))}) == 5
    assert participant_seed("P001", 0) == participant_seed("P001", 0) != participant_seed("P001", 1)
    tasks = cohort_tasks(pd.DataFrame({"participant_id": ["P001", "P002"], "style": ["sporty", None]}))
    assert [(x.participant_id, x.condition, x.style) for x in tasks] == [
        ("P001", "baseline", "sporty"), ("P001", "pedas", "sporty"),
        ("P002", "baseline", "normal"), ("P002", "pedas", "normal")]
    assert tasks[0].seed == tasks[1].seed  # the same person drives both conditions


# the baseline drives of the CLI test's participants (P001 sporty, P002 cautious, cohort seed 0): simulated here
# once, then reused from the cache by the other tests
POOL_TASKS = [DriveTask("P001", participant_seed("P001", 0), "sporty", "baseline"),
              DriveTask("P002", participant_seed("P002", 0), "cautious", "baseline")]


def test_process_pool_then_cached_rerun_starts_no_worker(cache, monkeypatch):
    tasks = POOL_TASKS
    first = simulate_cohort(tasks, workers=2, cache_dir=cache, progress=False)
    assert set(first) == {("P001", "baseline"), ("P002", "baseline")}
    assert all(load_cached(t, cache) is not None for t in tasks)

    import pedas.cohort as cohort

    def no_pool(*a, **k):
        raise AssertionError("a worker pool was started although everything is cached")

    monkeypatch.setattr(cohort, "ProcessPoolExecutor", no_pool)
    again = simulate_cohort(tasks, workers=2, cache_dir=cache, progress=False)
    for key in first:
        pd.testing.assert_frame_equal(first[key], again[key])


def test_dask_local_cluster_gives_the_same_drives(cache, tmp_path):
    from distributed import Client, LocalCluster

    tasks = POOL_TASKS
    pooled = simulate_cohort(tasks, workers=2, cache_dir=cache, progress=False)  # cached by the test above
    with LocalCluster(n_workers=2, threads_per_worker=2, processes=True, dashboard_address=None) as lc, \
            Client(lc) as client:
        on_dask = simulate_cohort(tasks, client=client, cache_dir=tmp_path / "dask-cache", progress=False)
    for key in pooled:
        pd.testing.assert_frame_equal(pooled[key].reset_index(drop=True), on_dask[key].reset_index(drop=True))


# ------------------------------------------------------------------------------------------------ the CLI
def _people(cli):
    """Two participants in the store of the paper's study (the test's `paper_db`)."""
    assert cli("participant", "add", "P001", "--style", "sporty").code == 0
    assert cli("participant", "add", "P002", "--style", "cautious").code == 0
    assert cli("participant", "add", "P003", "--style", "normal").code == 0
    r = cli("exclude", "P003", "--scope", "objective", "--reason", "technical_issue")
    assert r.code == 0, r.err


def test_cli_simulate_cohort_stores_drives_and_reruns_unchanged(cli, paper_db, cache):
    _people(cli)
    r = cli("simulate", "cohort", "--workers", "2", "--no-progress", "--cache-dir", str(cache))
    assert r.code == 0, r.err
    assert "4 drives of 2 participants (4 stored, 0 unchanged)" in r.out
    from study.store.store import Store

    with Store.open(paper_db, read_only=True) as st:
        drives = st.df("SELECT participant_id, condition, source, n_samples, seed FROM drives ORDER BY 1, 2")
        n = st.df("SELECT count(*) AS n FROM drive_samples")["n"][0]
    assert drives[["participant_id", "condition"]].values.tolist() == [
        ["P001", "baseline"], ["P001", "pedas"], ["P002", "baseline"], ["P002", "pedas"]]
    assert (drives["source"] == "simulation").all() and n == drives["n_samples"].sum()
    assert drives.groupby("participant_id")["seed"].nunique().eq(1).all()  # same person in both conditions
    again = cli("simulate", "cohort", "--workers", "2", "--no-progress", "--cache-dir", str(cache))
    assert again.code == 0 and "(0 stored, 4 unchanged)" in again.out
    one = cli("drive", "simulate", "P001", "pedas", "--cache-dir", str(cache))
    assert one.code == 0 and "unchanged" in one.out


def test_cli_bad_input_leaves_the_store_unchanged(cli, paper_db, cache):
    _people(cli)
    r = cli("drive", "simulate", "P999", "baseline", "--cache-dir", str(cache))
    assert r.code == 2 and r.err.count("\n") == 1 and "P999" in r.err
    r = cli("simulate", "cohort", "--workers", "0", "--cache-dir", str(cache))
    assert r.code == 2 and "--workers" in r.err
    r = cli("drive", "simulate", "P001", "sideways")
    assert r.code == 2
    r = cli("simulate", "cohort", "--scenario", "autobahn", "--cache-dir", str(cache))
    assert r.code == 2 and r.err.count("\n") == 1 and "autobahn" in r.err and "motorway" in r.err
    from study.store.store import Store

    with Store.open(paper_db, read_only=True) as st:
        assert st.df("SELECT count(*) AS n FROM drives")["n"][0] == 0


def test_cli_simulate_cohort_without_participants(cli, paper_db, cache):
    r = cli("simulate", "cohort", "--cache-dir", str(cache))
    assert r.code == 2 and "no participants" in r.err


def test_cli_simulate_cohort_on_a_dask_scheduler(cli, paper_db, tmp_path, cache):
    """`simulate cohort --scheduler ADDRESS` runs the drives on the cluster; the stored drives equal the pool's."""
    from distributed import LocalCluster

    assert cli("participant", "add", "P002", "--style", "cautious").code == 0
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None) as lc:
        r = cli("simulate", "cohort", "--scheduler", lc.scheduler_address, "--no-progress",
                "--cache-dir", str(tmp_path / "fresh"))
    assert r.code == 0, r.err
    assert "2 drives of 1 participant (2 stored, 0 unchanged)" in r.out
    pooled = load_cached(POOL_TASKS[1], cache)  # P002's baseline drive from the process-pool test
    if pooled is not None:
        from study.store.store import Store

        with Store.open(paper_db, read_only=True) as st:
            n = st.df("SELECT n_samples FROM drives WHERE participant_id = 'P002' AND condition = 'baseline'")
        assert n["n_samples"][0] == len(pooled)


def test_a_failed_drive_is_recorded_when_asked_and_raised_otherwise():
    from pedas.cohort import _collect
    from pedas.drive import SafetyViolation

    task = DriveTask("P001", 5, "normal", "baseline")

    def boom():
        raise SafetyViolation("red light TL4 crossed", "red_light")

    out, failures = {}, []
    _collect([task], boom, out, failures)
    assert out == {} and failures[0][0] == task and failures[0][1].kind == "red_light"
    with pytest.raises(SafetyViolation, match="TL4"):
        _collect([task], boom, out, None)
    _collect([task], lambda: (task, pd.DataFrame({"v": [1.0]})), out, failures)
    assert list(out) == [("P001", "baseline")] and len(failures) == 1
    # a failed drive shared by two tasks is a failure of each, named after each
    twin = DriveTask("P002", 5, "normal", "baseline")
    _collect([task, twin], boom, out, failures)
    assert [f[0] for f in failures[1:]] == [task, twin] and failures[2][1].kind == "red_light"
    assert str(failures[2][1]).startswith("P002 (the same drive as P001): ")


def test_tasks_with_one_key_are_one_drive(tmp_path, monkeypatch):
    """Two tasks that differ only in the participant id (two sweep points with the same settings) have one cache
    key: the pool simulates it once and both get the log."""
    from concurrent.futures import ThreadPoolExecutor

    from pedas import cohort

    ran = []

    def fake_run(task, cache_dir, key):
        ran.append(key)
        return task, pd.DataFrame({"t": [0.0, 0.2], "v": [0.0, 1.0]})

    monkeypatch.setattr(cohort, "_run_task_keyed", fake_run)
    monkeypatch.setattr(cohort, "ProcessPoolExecutor", lambda max_workers, mp_context: ThreadPoolExecutor(max_workers))
    tasks = [DriveTask("S001", 7, "normal", "pedas"), DriveTask("S002", 7, "normal", "pedas"),
             DriveTask("S003", 8, "normal", "pedas")]
    out = simulate_cohort(tasks, workers=2, cache_dir=tmp_path, progress=False)
    assert sorted(ran) == sorted({task_key(t) for t in tasks}) and len(ran) == 2
    assert set(out) == {(t.participant_id, "pedas") for t in tasks}
    assert out[("S001", "pedas")].equals(out[("S002", "pedas")]) and out[("S001", "pedas")] is not out[("S002", "pedas")]

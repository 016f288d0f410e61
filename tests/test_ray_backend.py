"""The Ray backend on a local two-CPU Ray instance: same runs as the local backend, resumption, failed tasks."""

import os
import signal
import subprocess
import sys

import pandas as pd
import pytest
from processes import alive, tree, wait_for

from sb3_er.experiments.records import read_record
from sb3_er.experiments.reproduce import reproduce
from sb3_er.experiments.runner import RAY_ENV_VARS, RunFailure, RunJob, import_ray, plan_jobs, run_csv_path, run_jobs
from sb3_er.experiments.specs import EXPERIMENTS

ray = pytest.importorskip("ray")

ALGOS = ["sarsa_lambda", "er_sigma"]
SEEDS = [0, 1]
SETTINGS = {"n_seeds": 2, "algos": ALGOS, "budget": 4, "show_progress": False}  # 4 grid-world episodes per run


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance with 2 CPUs for the module; the runs use it instead of starting their own."""
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    # address="local": a new instance even when another one runs on this machine (ray.init() would join that)
    ray.init(address="local", num_cpus=2, include_dashboard=False, runtime_env={"env_vars": RAY_ENV_VARS})
    yield
    ray.shutdown()


@pytest.mark.slow
def test_ray_runs_equal_local_runs_and_resume(tmp_path, local_ray):
    local = reproduce("gridworld", out_dir=tmp_path / "local", n_workers=1, **SETTINGS)
    on_ray = reproduce("gridworld", out_dir=tmp_path / "ray", backend="ray", **SETTINGS)
    assert (on_ray.runs_done, on_ray.runs_skipped) == (4, 0)
    assert ray.is_initialized()  # an instance the command did not start is left running
    for algo in ALGOS:
        for seed in SEEDS:
            local_csv, ray_csv = run_csv_path(local.out_dir, algo, seed), run_csv_path(on_ray.out_dir, algo, seed)
            # the same learning on a Ray worker; only the wall times differ
            pd.testing.assert_frame_equal(
                pd.read_csv(ray_csv).drop(columns="wall_time_s"), pd.read_csv(local_csv).drop(columns="wall_time_s")
            )
            local_record, ray_record = read_record(local_csv), read_record(ray_csv)
            for field in ("run", "config", "resolved", "sb3_er_version", "git_commit", "dependencies"):
                assert ray_record[field] == local_record[field]
    table = pd.read_csv(on_ray.table_csv)
    pd.testing.assert_frame_equal(table, pd.read_csv(local.table_csv))
    assert {path.name for path in on_ray.figures} == {path.name for path in local.figures}

    written = {path: path.stat().st_mtime_ns for path in (tmp_path / "ray" / "runs").rglob("seed_*")}
    resumed = reproduce("gridworld", out_dir=tmp_path / "ray", backend="ray", **SETTINGS)
    assert (resumed.runs_done, resumed.runs_skipped) == (0, 4)
    assert {path: path.stat().st_mtime_ns for path in written} == written
    pd.testing.assert_frame_equal(pd.read_csv(resumed.table_csv), table)


@pytest.mark.slow
def test_a_failing_ray_task_is_reported_and_the_others_are_written(tmp_path, local_ray):
    jobs, _ = plan_jobs(EXPERIMENTS["gridworld"], ["er"], SEEDS, 3, tmp_path)
    # zero episodes: the worker's EpisodeReturnProtocol refuses the run
    failing = RunJob(EXPERIMENTS["gridworld"], "er", 7, 0.5, run_csv_path(tmp_path, "er", 7))
    with pytest.raises(RunFailure) as failure:
        run_jobs([jobs[0], failing, jobs[1]], backend="ray", show_progress=False)
    message = str(failure.value)
    assert message.startswith("1 of 3 runs failed:\ner/seed_7:\n")
    assert "execute_run" in message and "ValueError: n_episodes must be a positive integer, got 0" in message
    assert "\x1b[" not in message  # no terminal colours
    for job in jobs:
        assert len(pd.read_csv(job.csv_path)) == 3 and read_record(job.csv_path)["run"] == job.key
    assert not failing.csv_path.exists() and not failing.csv_path.with_suffix(".json").exists()


def test_ray_usage_statistics_stay_off(monkeypatch):
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "1")
    import_ray()
    assert os.environ["RAY_USAGE_STATS_ENABLED"] == "0"
    try:  # Ray's own switch, read from the environment
        from ray._common.usage import usage_lib
    except ImportError:  # Ray before 2.5x
        from ray._private.usage import usage_lib

    assert not usage_lib.usage_stats_enabled()


@pytest.mark.slow
def test_a_killed_driver_leaves_no_ray_process_behind(tmp_path):
    """SIGKILL of a driver that started its own local Ray instance: Ray's agents, which outlive a killed driver on
    their own, are ended by the driver's reaper, and nothing of the instance is left."""
    driver = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "sb3_er.cli",
            "reproduce",
            "pendulum",
            "--seeds",
            "2",
            "--algos",
            "er",
            "--budget",
            "30",
            "--backend",
            "ray",
            "--jobs",
            "2",
            "--out",
            str(tmp_path),
            "--no-progress",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wait_for(
        lambda: any("execute_run" in command for command in tree(driver.pid).values()) or None, "a Ray task to run", 180
    )
    started = tree(driver.pid)
    assert any("raylet" in command for command in started.values())
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    wait_for(lambda: not alive(started) or None, f"Ray's processes {alive(started)} to end", 30)

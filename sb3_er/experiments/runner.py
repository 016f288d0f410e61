"""Runs every (algorithm, seed) pair of an experiment on worker processes or a Ray cluster, with one progress bar.

One function, :func:`execute_run`, does a run's work on either backend and returns its result as data (the protocol's
records and the run's version record); the driver, the process that called :func:`run_jobs`, writes each result as it
arrives with :func:`write_run`: the run's artifacts, ``<out>/runs/<algo>/seed_<seed>.csv``, then ``seed_<seed>.json``
(the version record, see :mod:`sb3_er.experiments.records`, with the checksums of the files before it), each atomically
(:mod:`sb3_er.experiments.files`). A run whose record matches its files is finished (:func:`check_run`), so an
interrupted reproduction resumes where it stopped, a damaged run is moved aside and done again
(:func:`split_finished`), and Ray workers need no shared file system.

Backends: ``"local"`` runs the jobs in this process (one worker) or in spawned worker processes of the driver's own
(one job each at a time, one BLAS/OpenMP thread each, so that N workers use N cores; a worker that dies costs only its
own run, which is started again once); ``"ray"`` runs each job as a Ray task with one CPU, on a local Ray instance
that the driver starts (and stops) or on an existing cluster (``address="auto"`` or ``"HOST:PORT"``). Every process the
driver starts ends with it, however the driver ends (:mod:`sb3_er.experiments.lifetime`). Ray's usage statistics are
switched off for the driver, the instance it starts and the workers.

The thesis's analyses (:data:`~sb3_er.experiments.specs.ANALYSES`) use the same machinery: the sigma study's runs are
walker runs told apart by their ``label``, and the runs of an :class:`~sb3_er.experiments.specs.Analysis` are done by
the function its ``task`` names in :data:`TASKS` instead of a protocol callback.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import re
import time
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm.auto import tqdm

from sb3_er.experiments import files, lifetime, records

# The job, its settings and its paths live in jobs.py (records.py uses them too); importable from here.
from sb3_er.experiments.jobs import (  # noqa: F401
    RUNNER_ARGUMENTS,
    RunJob,
    accepted_parameters,
    check_algo_kwargs,
    job_model_kwargs,
    run_csv_path,
)
from sb3_er.experiments.specs import Experiment

BACKENDS = ("local", "ray")
THREAD_LIMITS = {
    name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS")
}
RAY_ENV_VARS = {"RAY_USAGE_STATS_ENABLED": "0", **THREAD_LIMITS}
RAY_MISSING = "the Ray backend needs the ray package: pip install 'sb3-er[ray]'"


@dataclass
class RunResult:
    """What one run returns: the protocol's records (one row per measurement, plus ``diverged``), its version record
    (see :mod:`sb3_er.experiments.records`), its wall time in seconds, and the files of its per-run figures as bytes
    (``artifacts``: a suffix such as ``"gait.csv"`` to content; written beside the CSV as ``seed_<n>_<suffix>``).

    :param key: the run's key, ``<label>/seed_<seed>``.
    :param frame: the protocol's records, one row per measurement.
    :param record: the run's version record.
    :param wall_time_s: the run's wall time in seconds.
    :param artifacts: file suffix to content of its per-run figures (default none).
    """

    key: str
    frame: pd.DataFrame
    record: dict[str, Any]
    wall_time_s: float
    artifacts: dict[str, bytes] = field(default_factory=dict)


TASKS = {
    "replay_order": "sb3_er.experiments.replay_order:replay_order_run",
    "pessimistic": "sb3_er.experiments.pessimistic:pessimistic_run",
    "framework": "sb3_er.experiments.framework:framework_run",
    "sigma_regime": "sb3_er.experiments.sigma_regime:sigma_regime_run",
}
"""Runs that are no learning run under a protocol (see :class:`~sb3_er.experiments.specs.Analysis`): the task name
of the job's experiment to ``module:function``. The function takes ``(job, env, report)`` (the env made from the
experiment's env id and the job's env kwargs; ``report(fraction)`` feeds the progress bar) and returns a
:class:`TaskOutput`."""


@dataclass
class TaskOutput:
    """What a task returns to :func:`execute_run`: its records (one row per measurement, with a ``diverged``
    column), the model whose settings its version record holds (e.g. the model that collected the data), and the data
    of its per-run figures (as ``RunResult.artifacts``).

    :param frame: the task's records, one row per measurement, with a ``diverged`` column.
    :param model: the model whose settings the version record holds.
    :param artifacts: file suffix to content of its per-run figures (default none).
    """

    frame: pd.DataFrame
    model: Any
    artifacts: dict[str, bytes] = field(default_factory=dict)


def task_function(task: str):
    """The function of a task name in TASKS; ValueError naming the known tasks for another name.

    :param task: the task's name, a key of TASKS.
    """
    import importlib

    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {', '.join(TASKS)}")
    module, _, name = TASKS[task].partition(":")
    return getattr(importlib.import_module(module), name)


def _limit_threads_of_children() -> None:
    for variable, value in THREAD_LIMITS.items():
        os.environ.setdefault(variable, value)


def build_protocol(experiment: Experiment, env, budget: float, seed: int, progress=None, env_kwargs=None):
    """The experiment's protocol callback and the number of timesteps to give `learn` (the callback stops earlier).
    The walking protocols evaluate on envs made with the learning env's `env_kwargs`.

    :param experiment: the experiment the runs belong to.
    :param env: the learning env.
    :param budget: run length in the experiment's unit (episodes or seconds of learning time).
    :param seed: the run's seed (its evaluation envs are seeded from it).
    :param progress: called with the finished fraction of the run (default None).
    :param env_kwargs: ``gymnasium.make`` keyword arguments of the runs' envs (default None: none).
    """
    import gymnasium as gym

    from sb3_er.experiments.protocols import EpisodeReturnProtocol, GreedyDistanceProtocol

    if experiment.protocol == "episodes":
        callback = EpisodeReturnProtocol(int(budget), progress=progress)
        return callback, int(budget) * int(env.unwrapped.max_episode_steps)
    eval_envs = [gym.make(experiment.env_id, **(env_kwargs or {})) for _ in range(experiment.eval_runs)]
    callback = GreedyDistanceProtocol(
        eval_envs,
        dt=env.unwrapped.dt,
        eval_interval=experiment.eval_interval,
        learning_time=budget,
        eval_seed=10_000 + seed,
        progress=progress,
    )
    return callback, callback.total_steps


def execute_run(job: RunJob, progress_queue=None) -> RunResult:
    """Learn one run and return its result; writes nothing. The one code path of both backends.

    `progress_queue` (anything with ``put((key, fraction))``: a queue.SimpleQueue, a multiprocessing or a Ray queue)
    receives the finished fraction of the run in steps of at least 1 %, and 1.0 at the end. A queue whose ``put`` raises
    gets no more reports from this run (a RuntimeWarning says so); the run itself goes on. A run whose Q-function
    diverges is finished too: its frame holds the records up to the divergence and every row has ``diverged`` set, so
    that the summary can count it instead of averaging a truncated curve. Errors of the run (an unknown env id, a
    missing zoo config entry, ...) propagate.

    :param job: the run.
    :param progress_queue: where progress goes (anything with ``put((key, fraction))``; default None: nowhere).
    """
    import gymnasium as gym
    import torch

    from sb3_er import DivergenceError
    from sb3_er.common.base_class import ValueBoundWarning
    from sb3_er.common.env_ids import register_env_id
    from sb3_er.zoo import algorithm_classes

    torch.set_num_threads(1)
    start = time.perf_counter()
    code = records.code_version()  # the code this run starts with
    experiment = job.experiment
    register_env_id(experiment.env_id)  # sb3_er/ (or dm_control/) ids, in this worker process
    last_reported = [-1.0]
    reports_to = [progress_queue]

    def send(fraction: float) -> None:
        # The progress bar is a convenience: a queue that breaks (a worker's connection to the manager lost, seen
        # intermittently in long process-pool runs) stops this run's reports, with a warning, and never the run.
        if reports_to[0] is None:
            return
        try:
            reports_to[0].put((job.key, fraction))
        except Exception as error:  # noqa: BLE001  (any transport error of any backend's queue)
            reports_to[0] = None
            warnings.warn(
                f"{job.key}: progress reports stopped, the run goes on ({type(error).__name__}: {error})",
                RuntimeWarning,
                stacklevel=2,
            )

    def report(fraction: float) -> None:
        if fraction - last_reported[0] >= 0.01:
            last_reported[0] = fraction
            send(fraction)

    env_kwargs = dict(job.env_kwargs)
    env = gym.make(experiment.env_id, **env_kwargs)
    task = getattr(experiment, "task", "")
    if task:  # an analysis (specs.Analysis): the task does the run's work
        output = task_function(task)(job, env, report)
        env.close()
        wall_time_s = time.perf_counter() - start
        record = records.finished_record(job, output.model, env, wall_time_s, code)
        send(1.0)
        return RunResult(job.key, output.frame, record, wall_time_s, output.artifacts)
    model = algorithm_classes()[job.algo]("TileQ", env, seed=job.seed, **job_model_kwargs(job))
    callback, total_timesteps = build_protocol(experiment, env, job.budget, job.seed, report, env_kwargs)
    try:
        with warnings.catch_warnings():  # counted in the CSV and the record instead (values_out_of_range)
            warnings.simplefilter("ignore", ValueBoundWarning)
            model.learn(total_timesteps=total_timesteps, callback=callback)
        diverged = False
    except DivergenceError:
        diverged = True
    for used_env in [env, *getattr(callback, "eval_envs", [])]:
        used_env.close()
    frame = pd.DataFrame(callback.records, columns=list(callback.COLUMNS))
    frame["diverged"] = diverged
    artifacts = figure_artifacts(job, model) if job.figure_run and not diverged else {}
    wall_time_s = time.perf_counter() - start
    record = records.finished_record(job, model, env, wall_time_s, code)
    record["value_excursion"] = getattr(model, "value_excursion", None)  # the first value outside the returns
    send(1.0)
    return RunResult(job.key, frame, record, wall_time_s, artifacts)


GAIT_SECONDS = 10.0


def figure_artifacts(job: RunJob, model) -> dict[str, bytes]:
    """The data of a run's own figures, made where the run ran: for the simplest walker, the final greedy policy's
    gait from Garcia's fixed point (thesis Figures 4.6 / 6.3) as ``gait.csv`` (with the distance walked at each step)
    and an animation of the same walk as ``walker.gif``.

    :param job: the run.
    :param model: the trained model.
    """
    if not job.experiment.env_id.endswith("SimplestWalker-v0"):
        return {}
    import tempfile

    import gymnasium as gym

    from sb3_er.experiments.gait import gait_trace, save_walker_gif

    env = gym.make(job.experiment.env_id, render_mode="rgb_array", **dict(job.env_kwargs))
    trace = gait_trace(model, env, seconds=GAIT_SECONDS)
    table = pd.DataFrame(
        {
            "time": trace.time,
            "stance_angle": trace.stance_angle,
            "hip_angle": trace.hip_angle,
            "swing_foot_height": trace.swing_foot_height,
            "fell": trace.fell,
            "distance": trace.distances,  # walked since the start, what the GIF's caption gives
        }
    )
    with tempfile.TemporaryDirectory() as folder:
        gif = save_walker_gif(model, Path(folder) / "walker.gif", seconds=GAIT_SECONDS, env=env).read_bytes()
    env.close()
    return {"gait.csv": files.csv_bytes(table), "walker.gif": gif}


def read_run_csv(csv_path: str | Path) -> pd.DataFrame:
    """The CSV of a run; DamagedFileError (a ValueError) naming the file and what to do when it is empty or torn.

    :param csv_path: the run's CSV file.
    """
    return files.read_csv(csv_path, records.RECORD_REMEDY)


def artifact_path(csv_path: Path, suffix: str) -> Path:
    """Where a run's figure data `suffix` (e.g. ``"gait.csv"``) lives: ``seed_<n>_<suffix>`` beside its CSV.

    :param csv_path: the run's CSV file.
    :param suffix: the artifact's name, e.g. ``"gait.csv"``.
    """
    return csv_path.with_name(f"{csv_path.stem}_{suffix}")


def write_run(job: RunJob, result: RunResult) -> None:
    """Write `result`: its artifacts, then its CSV ``job.csv_path``, then its version record beside it (see
    :func:`sb3_er.experiments.records.sealed`), each atomically. The record, written last, holds the checksums and row
    count of the files before it, so a run is finished exactly when its record matches them (:func:`check_run`).

    :param job: the run.
    :param result: what :func:`execute_run` returned.
    """
    job.csv_path.parent.mkdir(parents=True, exist_ok=True)
    artifacts = {artifact_path(job.csv_path, suffix).name: content for suffix, content in result.artifacts.items()}
    for name, content in artifacts.items():
        files.write_atomically(job.csv_path.with_name(name), content)
    csv_data = files.csv_bytes(result.frame)
    files.write_atomically(job.csv_path, csv_data)
    files.write_json(
        records.record_path(job.csv_path), records.sealed(result.record, job.csv_path.name, csv_data, artifacts)
    )


def run_single(job: RunJob, progress_queue=None) -> float:
    """Learn one run in this process, write its CSV and record, and return its wall time in seconds.

    :param job: the run.
    :param progress_queue: where progress goes (anything with ``put((key, fraction))``; default None: nowhere).
    """
    result = execute_run(job, progress_queue)
    write_run(job, result)
    return result.wall_time_s


def expected_rows(job: RunJob) -> int | None:
    """The rows a finished, not diverged run of `job` has under its protocol: one per learning episode, or one per
    evaluation (at the start, every evaluation interval and at the end) for the walking protocol; None for a task
    (an analysis's run), whose length its task decides.

    :param job: the run.
    """
    experiment = job.experiment
    if getattr(experiment, "task", ""):
        return None
    if experiment.protocol == "episodes":
        return int(job.budget)
    import gymnasium as gym

    from sb3_er.common.env_ids import register_env_id

    register_env_id(experiment.env_id)
    env = gym.make(experiment.env_id, **dict(job.env_kwargs))
    dt = env.unwrapped.dt
    env.close()
    every, total = max(1, round(experiment.eval_interval / dt)), max(1, round(job.budget / dt))
    return 1 + total // every + (1 if total % every else 0)


class DamagedRunWarning(UserWarning):
    """A run's files did not match its record (cut short, empty, edited, or written by a command that was stopped):
    they were moved aside (renamed, kept) and the run is done again."""


class RecordUpgradeWarning(UserWarning):
    """Finished runs whose records predate checksums were checked and their records given checksums, once."""


def run_files(csv_path: Path) -> list[Path]:
    """The files of the run whose CSV is `csv_path`: the CSV, its record and its artifacts (``seed_<n>_*``).

    :param csv_path: the run's CSV file.
    """
    artifacts = (
        path
        for path in csv_path.parent.glob(f"{csv_path.stem}_*")
        if path.is_file() and ".damaged-" not in path.name and files.PARTIAL_MARK not in path.name
    )
    return [csv_path, records.record_path(csv_path), *sorted(artifacts)]


def check_run(job: RunJob) -> tuple[bool, str | None]:
    """(finished, what is wrong) for the files of `job`.

    Finished: the CSV exists and its record matches it (see :func:`sb3_er.experiments.records.check_sealed`). A
    record that predates checksums is checked as :func:`~sb3_er.experiments.records.check_legacy_csv` does, with the
    protocol's length (:func:`expected_rows`), and, when the CSV passes, sealed with the checksums of the files as they
    are, once (its ``upgraded_from_format`` field says so). Not finished without a problem: no CSV. Not finished with a
    problem (a message naming the file): anything else.

    :param job: the run.
    """
    csv_path = job.csv_path
    if not csv_path.is_file():
        return False, None
    try:
        record = records.read_record(csv_path)
    except files.DamagedFileError as error:
        return False, str(error).split("; ")[0]
    if record is None:
        return False, (
            f"{csv_path} has no version record (its command was stopped between writing the CSV and "
            "the record, or the run predates records)"
        )
    if records.CHECKSUM_FIELD in record:
        problem = records.check_sealed(record, csv_path)
        return problem is None, problem
    problem = records.check_legacy_csv(csv_path, expected_rows(job))
    if problem is not None:
        return False, problem
    artifacts = {path.name: path.read_bytes() for path in run_files(csv_path)[2:]}
    files.write_json(
        records.record_path(csv_path),
        records.sealed(
            record, csv_path.name, csv_path.read_bytes(), artifacts, upgraded_from_format=record.get("format", 1)
        ),
    )
    return True, "upgraded"


def split_finished(jobs: list[RunJob]) -> tuple[list[RunJob], list[RunJob]]:
    """`jobs` split into (to run, finished) by :func:`check_run`. The files of a run that does not match its record
    are moved aside (``<name>.damaged-<time>``, see :func:`sb3_er.experiments.files.move_aside`) with a
    DamagedRunWarning naming them, and the run is to run again. Needs the folder's lock (it renames files).

    :param jobs: the runs.
    """
    to_run, finished, upgraded = [], [], []
    for folder in dict.fromkeys(job.csv_path.parent for job in jobs):
        files.remove_partial_files(folder)
    for job in jobs:
        done, problem = check_run(job)
        if done:
            finished.append(job)
            if problem == "upgraded":
                upgraded.append(job.key)
            continue
        to_run.append(job)
        if problem is not None:
            moved = [path.name for path in map(files.move_aside, run_files(job.csv_path)) if path is not None]
            warnings.warn(
                f"{problem}; moved aside as {', '.join(moved)} and done again", DamagedRunWarning, stacklevel=2
            )
    if upgraded:
        warnings.warn(
            f"{records.counted(len(upgraded), 'finished run')} had "
            f"{'a record' if len(upgraded) == 1 else 'records'} without checksums "
            f"({records.compact_runs(upgraded)}): their CSVs were checked (well-formed, the protocol's "
            "number of rows) and their records given checksums",
            RecordUpgradeWarning,
            stacklevel=2,
        )
    return to_run, finished


def row_jobs(
    experiment: Experiment, row: str, seeds, budget: float, out_dir: Path, env_kwargs=None, algo_kwargs=None
) -> list[RunJob]:
    """The jobs of one row of a table over `seeds` (the first seed's run makes the per-run figures' data): a stable
    row runs its algorithm with ``preset="stable"`` (:func:`sb3_er.experiments.thesis.row_algorithm`).

    :param experiment: the experiment the runs belong to.
    :param row: the row, an algorithm's rl-zoo name or a stable learner's row such as "er_sigma_stable".
    :param seeds: the seeds.
    :param budget: run length in the experiment's unit (episodes or seconds of learning time).
    :param out_dir: the results folder.
    :param env_kwargs: ``gymnasium.make`` keyword arguments of the runs' envs (default None: none).
    :param algo_kwargs: constructor overrides by parameter name (default None: none).
    """
    from sb3_er.experiments.thesis import row_algorithm

    seeds = list(seeds)
    algo, own = row_algorithm(row)
    algo_items = tuple(sorted({**(algo_kwargs or {}), **own}.items()))
    return [
        RunJob(
            experiment,
            algo,
            seed,
            budget,
            run_csv_path(out_dir, row, seed),
            tuple(sorted((env_kwargs or {}).items())),
            algo_items,
            figure_run=seed == seeds[0],
            label="" if row == algo else row,
        )
        for seed in seeds
    ]


def plan_jobs(
    experiment: Experiment, algos, seeds, budget: float, out_dir: Path, env_kwargs=None, algo_kwargs=None
) -> tuple[list[RunJob], list[RunJob]]:
    """All jobs of the reproduction (:func:`row_jobs` of each row), split into (to run, already finished) by
    :func:`split_finished` (which moves damaged runs aside).

    :param experiment: the experiment the runs belong to.
    :param algos: the table's rows: the algorithms' rl-zoo names, or a stable learner's row such as
        "er_sigma_stable" (:data:`sb3_er.experiments.thesis.STABLE_ROWS`).
    :param seeds: the seeds.
    :param budget: run length in the experiment's unit (episodes or seconds of learning time).
    :param out_dir: the results folder.
    :param env_kwargs: ``gymnasium.make`` keyword arguments of the runs' envs (default None: none).
    :param algo_kwargs: constructor overrides by parameter name (default None: none).
    """
    jobs = [job for row in algos for job in row_jobs(experiment, row, seeds, budget, out_dir, env_kwargs, algo_kwargs)]
    return split_finished(jobs)


class RunFailure(RuntimeError):
    """One or more learning runs raised; the message names each run and its traceback."""


WORKER_DEATH_RETRIES = 1
"""How often a run whose worker process died (killed by the OOM killer or a signal) is started again, on a fresh
worker, before it counts as failed; a run that raises is not retried (it would raise again). Both backends."""


class _Driver:
    """The driver's side of both backends: progress bar, version checks of returned runs, writing, failures."""

    def __init__(self, jobs: list[RunJob], show_progress: bool, allow_mixed_versions: bool, on_written=None) -> None:
        self.jobs = jobs
        self.allow_mixed_versions = allow_mixed_versions
        self.on_written = on_written
        self.wall_times: dict[str, float] = {}
        self.failures: list[str] = []
        self.fractions = {job.key: 0.0 for job in jobs}
        # disable=None: tqdm's own rule, no bar when stderr is not a terminal (a log file or CI would get every redraw)
        disable = True if not show_progress or not jobs else None
        self.bar = tqdm(total=len(jobs), unit="run", desc="runs", disable=disable, smoothing=0.0)
        self.expected: dict[str, dict[str, Any]] = {}
        self.reaper: lifetime.Reaper | None = None
        code = records.code_version()
        for job in jobs:
            try:
                self.expected[job.key] = records.current_record(job, code)
            except Exception:  # noqa: BLE001  (the job is reported as failed, the others run)
                self.failed(job, traceback.format_exc())

    @property
    def runnable(self) -> list[RunJob]:
        return [job for job in self.jobs if job.key in self.expected]

    def progress(self, key: str, fraction: float) -> None:
        self.fractions[key] = max(self.fractions.get(key, 0.0), fraction)

    def refresh(self) -> None:
        self.bar.n = round(sum(self.fractions.values()), 2)
        self.bar.refresh()

    def failed(self, job: RunJob, text: str) -> None:
        self.failures.append(f"{job.key}:\n{text}")

    def restarted(self, job: RunJob, why: str) -> None:
        self.fractions[job.key] = 0.0
        warnings.warn(f"{job.key}: {why}; the run is started again on a fresh worker", RuntimeWarning, stacklevel=2)

    def finished(self, job: RunJob, result: RunResult) -> None:
        """Write a returned run, unless it ran with other code or configuration than this driver expects."""
        refusals, cautions = records.compare_records(result.record, self.expected[job.key])
        if refusals and not self.allow_mixed_versions:
            host = result.record.get("host", "?")
            self.failed(
                job,
                f"ran on {host} with other code or configuration than the driver's (worker -> driver): "
                f"{'; '.join(refusals)}. Install the driver's version there, or pass "
                f"{records.OVERRIDE_HINT}.\n",
            )
            return
        if refusals or cautions:
            warnings.warn(
                f"{job.key} ran with (worker -> driver): {'; '.join(refusals + cautions)}",
                records.MixedVersionsWarning,
                stacklevel=2,
            )
        write_run(job, result)
        self.wall_times[job.key] = result.wall_time_s
        self.fractions[job.key] = 1.0
        if self.on_written is not None:
            self.on_written(job)

    def close(self) -> dict[str, float]:
        self.refresh()
        self.bar.close()
        if self.failures:
            raise RunFailure(f"{len(self.failures)} of {len(self.jobs)} runs failed:\n" + "\n".join(self.failures))
        return self.wall_times


def run_jobs(
    jobs: list[RunJob],
    n_workers: int | None = None,
    show_progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    allow_mixed_versions: bool = False,
    on_written=None,
) -> dict[str, float]:
    """Run `jobs`, write each finished one, and return each run's wall time in seconds by key.

    `backend` ``"local"``: `n_workers` processes (default: all CPUs; in this process when 1). ``"ray"``: one Ray task
    with one CPU per job; with `address` None on a new local Ray instance of `n_workers` CPUs (default all), else on
    the cluster at `address` (``"auto"`` or ``"HOST:PORT"``), whose CPUs set the parallelism. When Ray is already
    initialised in this process, its instance is used as it is. A run whose version record differs from the driver's
    (e.g. a cluster node with other code) fails unless `allow_mixed_versions`. Runs that fail do not stop the others;
    the finished ones are written and a RunFailure naming each failed run with its traceback is raised at the end. A
    run whose worker process dies is started again on a fresh worker (WORKER_DEATH_RETRIES times), the other runs go
    on. Every process the call starts ends with it, also when the driver is killed: local workers die with their
    parent (:func:`sb3_er.experiments.lifetime.die_with_parent`), and what a local Ray instance started is ended by a
    :class:`~sb3_er.experiments.lifetime.Reaper`; a cluster the call did not start is never stopped.
    `on_written(job)` is called after each run is written (e.g. to pin the folder's settings).
    Raises ValueError for a bad backend, worker count or an address without the Ray backend, and ImportError naming
    ``pip install 'sb3-er[ray]'`` when Ray is not installed.

    :param jobs: the runs.
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance).
    :param allow_mixed_versions: accept runs whose version record differs from the driver's (default False).
    :param on_written: called with each job after it is written (default None).
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if n_workers is not None and (int(n_workers) != n_workers or n_workers < 1):
        raise ValueError(f"n_workers must be a positive integer, got {n_workers}")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) is for the Ray backend only; add backend='ray' (--backend ray)")
    if address is not None and n_workers is not None:
        raise ValueError(
            "n_workers (--jobs) sets the CPUs of a local Ray instance; a cluster at an address uses its own"
        )
    driver = _Driver(jobs, show_progress, allow_mixed_versions, on_written)
    runnable = driver.runnable
    try:
        if backend == "ray":
            _run_on_ray(runnable, driver, address, n_workers)
        elif (n_workers or os.cpu_count() or 1) == 1 or len(runnable) <= 1:
            _run_here(runnable, driver)
        else:
            _run_on_workers(runnable, driver, n_workers or os.cpu_count() or 1)
    except BaseException:
        driver.bar.close()  # interrupted: the runs written so far stay, a rerun resumes after them
        raise
    return driver.close()


def _run_here(jobs: list[RunJob], driver: _Driver) -> None:
    local_queue: queue.SimpleQueue = queue.SimpleQueue()
    for job in jobs:
        try:
            result = execute_run(job, local_queue)
        except Exception:  # noqa: BLE001  (reported with the run's name)
            driver.failed(job, traceback.format_exc())
        else:
            driver.finished(job, result)
        while not local_queue.empty():
            driver.progress(*local_queue.get())
        driver.refresh()


class _PipeReports:
    """A worker's progress reports, sent over its pipe to the driver (``put`` as a queue's)."""

    def __init__(self, connection) -> None:
        self.connection = connection

    def put(self, item) -> None:
        self.connection.send(("progress", item))


def _worker_main(connection, parent_pid: int) -> None:
    """A local worker process: runs the jobs its driver sends over `connection`, one at a time, and sends back
    ``("result", RunResult)`` or ``("error", traceback text)``; ends at None, at the end of the pipe, and when the
    driver dies. Ctrl-C is the driver's to handle (it ends the workers)."""
    import signal

    lifetime.die_with_parent(parent_pid, name=WORKER_NAME)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    reports = _PipeReports(connection)
    while True:
        try:
            job = connection.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        try:
            message = ("result", execute_run(job, reports))
        except Exception:  # noqa: BLE001  (sent to the driver with the run's traceback)
            message = ("error", traceback.format_exc())
        try:
            connection.send(message)
        except (OSError, EOFError):  # the driver is gone
            return
        except Exception:  # noqa: BLE001  (a result that does not pickle)
            connection.send(("error", traceback.format_exc()))


WORKER_NAME = "sb3-er-worker"
"""The name of a local worker process (``ps -C sb3-er-worker``), set once it dies with its driver."""


class _Worker:
    """One local worker process, its end of the pipe and the job it runs (None when idle)."""

    def __init__(self, context) -> None:
        self.connection, child_end = context.Pipe(duplex=True)
        self.process = context.Process(
            target=_worker_main, args=(child_end, os.getpid()), daemon=True, name="sb3-er-worker"
        )
        self.process.start()
        child_end.close()
        self.job: RunJob | None = None

    def assign(self, job: RunJob) -> bool:
        """Send `job` to the worker; False when its pipe is gone (the worker died)."""
        try:
            self.connection.send(job)
        except OSError:
            return False
        self.job = job
        return True

    def stop(self) -> None:
        """End the worker: asked to when idle, terminated (then killed) when it still runs a job."""
        if self.process.is_alive():
            try:
                self.connection.send(None)
            except OSError:
                pass
        self.process.join(timeout=5 if self.job is None else 0)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.connection.close()


def _run_on_workers(jobs: list[RunJob], driver: _Driver, n_workers: int) -> None:
    """Run `jobs` on up to `n_workers` spawned worker processes of this driver, one job per worker at a time.

    A worker that dies (a signal, the OOM killer) takes only its own run with it: that run is started again on a fresh
    worker (WORKER_DEATH_RETRIES times, then it fails), the other workers go on and the jobs not yet started are
    started. Workers die with the driver (see :func:`_worker_main`); on any exit of this function they are ended."""
    import collections
    from multiprocessing.connection import wait as wait_for

    _limit_threads_of_children()
    context = multiprocessing.get_context("spawn")
    pending = collections.deque(jobs)
    deaths: dict[str, int] = {}
    workers: list[_Worker] = []
    try:
        while pending or workers:
            for worker in [worker for worker in workers if worker.job is None]:
                if not pending:  # nothing left for it
                    workers.remove(worker)
                    worker.stop()
                elif not worker.assign(pending[0]):  # it died idle: the job never started
                    workers.remove(worker)
                    worker.stop()
                else:
                    pending.popleft()
            while pending and len(workers) < n_workers:
                worker = _Worker(context)
                workers.append(worker)
                if worker.assign(pending[0]):
                    pending.popleft()
            wait_for(
                [worker.connection for worker in workers] + [worker.process.sentinel for worker in workers], timeout=0.5
            )
            for worker in list(workers):
                job, messages = worker.job, []
                try:
                    while worker.connection.poll():
                        messages.append(worker.connection.recv())
                except (EOFError, OSError):
                    pass  # the worker died; its sentinel says so below
                for kind, content in messages:
                    if kind == "progress":
                        driver.progress(*content)
                        continue
                    worker.job = None
                    if kind == "result":
                        driver.finished(job, content)
                    else:
                        driver.failed(job, content)
                if job is not None and worker.job is not None and not worker.process.is_alive():
                    worker.process.join()
                    why = f"its worker process died ({_exit_description(worker.process.exitcode)})"
                    workers.remove(worker)
                    worker.job = None
                    worker.stop()
                    deaths[job.key] = deaths.get(job.key, 0) + 1
                    if deaths[job.key] <= WORKER_DEATH_RETRIES:
                        driver.restarted(job, why)
                        pending.appendleft(job)
                    else:
                        driver.failed(job, f"{why} {deaths[job.key]} times; out of memory? (see dmesg)\n")
            driver.refresh()
    finally:
        for worker in workers:
            worker.stop()


def _exit_description(code: int | None) -> str:
    import signal

    if code is not None and code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def import_ray():
    """The ray module, with usage statistics switched off first; ImportError naming the extra when it is missing."""
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    try:
        import ray
    except ImportError as error:
        raise ImportError(RAY_MISSING) from error
    return ray


def _run_on_ray(jobs: list[RunJob], driver: _Driver, address: str | None, n_cpus: int | None) -> None:
    if not jobs:
        return
    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here and address is None:  # a local instance: its processes end with this driver, however it ends
        driver.reaper = lifetime.Reaper()
    if started_here:
        ray.init(
            address=address or "local",
            num_cpus=n_cpus if address is None else None,
            include_dashboard=False if address is None else None,
            runtime_env={"env_vars": RAY_ENV_VARS},
        )
    progress_queue = None
    pending: list = []
    try:
        from ray.util.queue import Empty, Queue

        progress_queue = Queue(actor_options={"num_cpus": 0})
        remote_run = ray.remote(num_cpus=1, max_retries=WORKER_DEATH_RETRIES)(execute_run)
        refs = {remote_run.remote(job, progress_queue): job for job in jobs}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=len(pending), timeout=0.5)
            for ref in done:
                job = refs[ref]
                try:
                    result = ray.get(ref)
                except Exception as error:  # noqa: BLE001  (RayTaskError carries the worker's traceback)
                    text = str(error) if isinstance(error, ray.exceptions.RayError) else traceback.format_exc()
                    driver.failed(job, re.sub(r"\x1b\[[0-9;]*m", "", text))  # without the terminal colours
                else:
                    driver.finished(job, result)
            try:
                while progress_queue.qsize():
                    for item in progress_queue.get_nowait_batch(progress_queue.qsize()):
                        driver.progress(*item)
            except Empty:
                pass
            driver.refresh()
    finally:
        for ref in pending:  # only when interrupted
            ray.cancel(ref, force=True)
        if progress_queue is not None:
            progress_queue.shutdown()
        if started_here:
            ray.shutdown()
        if driver.reaper is not None:
            driver.reaper.close()
            driver.reaper = None

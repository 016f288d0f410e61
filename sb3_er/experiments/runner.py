"""Runs every (algorithm, seed) pair of an experiment on worker processes or a Ray cluster, with one progress bar.

One function, :func:`execute_run`, does a run's work on either backend and returns its result as data (the protocol's
records and the run's version record); the driver, the process that called :func:`run_jobs`, writes each result as it
arrives with :func:`write_run`: ``<out>/runs/<algo>/seed_<seed>.json`` (the version record, see
:mod:`sb3_er.experiments.records`), then ``seed_<seed>.csv``, each atomically. A run whose CSV exists is finished, so an
interrupted reproduction resumes where it stopped, and Ray workers need no shared file system.

Backends: ``"local"`` runs the jobs in this process (one worker) or in spawned worker processes with one BLAS/OpenMP
thread each, so that N workers use N cores; ``"ray"`` runs each job as a Ray task with one CPU, on a local Ray instance
that the driver starts (and stops) or on an existing cluster (``address="auto"`` or ``"HOST:PORT"``). Ray's usage
statistics are switched off for the driver, the instance it starts and the workers.

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
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm.auto import tqdm

from sb3_er.experiments import records
# The job and its derived settings and paths live in jobs.py (records.py uses them too); importable from here.
from sb3_er.experiments.jobs import RunJob, accepted_parameters, job_model_kwargs, run_csv_path  # noqa: F401
from sb3_er.experiments.specs import Experiment

BACKENDS = ("local", "ray")
THREAD_LIMITS = {name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
                                        "OPENBLAS_NUM_THREADS")}
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
    """The function of a task name in TASKS; ValueError naming the known tasks for another name."""
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
    The walking protocols evaluate on envs made with the learning env's `env_kwargs`."""
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
    """
    import gymnasium as gym
    import torch

    import sb3_er_envs  # noqa: F401  (registers the environment ids)
    from sb3_er import DivergenceError
    from sb3_er.common.base_class import ValueBoundWarning
    from sb3_er.zoo import algorithm_classes

    torch.set_num_threads(1)
    start = time.perf_counter()
    code = records.code_version()  # the code this run starts with
    experiment = job.experiment
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
            warnings.warn(f"{job.key}: progress reports stopped, the run goes on ({type(error).__name__}: {error})",
                          RuntimeWarning, stacklevel=2)

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
    gait from Garcia's fixed point (thesis Figures 4.6 / 6.3) as ``gait.csv`` and an animation as ``walker.gif``."""
    if not job.experiment.env_id.endswith("SimplestWalker-v0"):
        return {}
    import io
    import tempfile

    import gymnasium as gym

    from sb3_er.experiments.gait import gait_trace, save_walker_gif

    env = gym.make(job.experiment.env_id, render_mode="rgb_array", **dict(job.env_kwargs))
    trace = gait_trace(model, env, seconds=GAIT_SECONDS)
    table = pd.DataFrame({"time": trace.time, "stance_angle": trace.stance_angle, "hip_angle": trace.hip_angle,
                          "swing_foot_height": trace.swing_foot_height, "fell": trace.fell})
    buffer = io.StringIO()
    table.to_csv(buffer, index=False)
    with tempfile.TemporaryDirectory() as folder:
        gif = save_walker_gif(model, Path(folder) / "walker.gif", seconds=GAIT_SECONDS, env=env).read_bytes()
    env.close()
    return {"gait.csv": buffer.getvalue().encode(), "walker.gif": gif}


def artifact_path(csv_path: Path, suffix: str) -> Path:
    """Where a run's figure data `suffix` (e.g. ``"gait.csv"``) lives: ``seed_<n>_<suffix>`` beside its CSV."""
    return csv_path.with_name(f"{csv_path.stem}_{suffix}")


def write_run(job: RunJob, result: RunResult) -> None:
    """Write `result` to ``job.csv_path`` and its version record beside it, each atomically, the CSV last."""
    job.csv_path.parent.mkdir(parents=True, exist_ok=True)
    for suffix, content in result.artifacts.items():
        artifact_path(job.csv_path, suffix).write_bytes(content)
    records.write_json_atomically(records.record_path(job.csv_path), result.record)
    partial = job.csv_path.with_suffix(".csv.partial")
    result.frame.to_csv(partial, index=False)
    os.replace(partial, job.csv_path)


def run_single(job: RunJob, progress_queue=None) -> float:
    """Learn one run in this process, write its CSV and record, and return its wall time in seconds."""
    result = execute_run(job, progress_queue)
    write_run(job, result)
    return result.wall_time_s


def plan_jobs(experiment: Experiment, algos, seeds, budget: float, out_dir: Path, env_kwargs=None,
              algo_kwargs=None) -> tuple[list[RunJob], list[RunJob]]:
    """All jobs of the reproduction, split into (to run, already finished). The first seed's runs make the per-run
    figures' data."""
    env_items = tuple(sorted((env_kwargs or {}).items()))
    algo_items = tuple(sorted((algo_kwargs or {}).items()))
    seeds = list(seeds)
    jobs = [RunJob(experiment, algo, seed, budget, run_csv_path(out_dir, algo, seed), env_items, algo_items,
                   figure_run=seed == seeds[0]) for algo in algos for seed in seeds]
    finished = [job for job in jobs if job.csv_path.is_file()]
    return [job for job in jobs if not job.csv_path.is_file()], finished


class RunFailure(RuntimeError):
    """One or more learning runs raised; the message names each run and its traceback."""


class _Driver:
    """The driver's side of both backends: progress bar, version checks of returned runs, writing, failures."""

    def __init__(self, jobs: list[RunJob], show_progress: bool, allow_mixed_versions: bool) -> None:
        self.jobs = jobs
        self.allow_mixed_versions = allow_mixed_versions
        self.wall_times: dict[str, float] = {}
        self.failures: list[str] = []
        self.fractions = {job.key: 0.0 for job in jobs}
        self.bar = tqdm(total=len(jobs), unit="run", desc="runs", disable=not show_progress or not jobs,
                        smoothing=0.0)
        self.expected: dict[str, dict[str, Any]] = {}
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

    def finished(self, job: RunJob, result: RunResult) -> None:
        """Write a returned run, unless it ran with other code or configuration than this driver expects."""
        refusals, cautions = records.compare_records(result.record, self.expected[job.key])
        if refusals and not self.allow_mixed_versions:
            host = result.record.get("host", "?")
            self.failed(job, f"ran on {host} with other code or configuration than the driver's (worker -> driver): "
                             f"{'; '.join(refusals)}. Install the driver's version there, or pass "
                             f"{records.OVERRIDE_HINT}.\n")
            return
        if refusals or cautions:
            warnings.warn(f"{job.key} ran with (worker -> driver): {'; '.join(refusals + cautions)}",
                          records.MixedVersionsWarning, stacklevel=2)
        write_run(job, result)
        self.wall_times[job.key] = result.wall_time_s
        self.fractions[job.key] = 1.0

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
) -> dict[str, float]:
    """Run `jobs`, write each finished one, and return each run's wall time in seconds by key.

    `backend` ``"local"``: `n_workers` processes (default: all CPUs; in this process when 1). ``"ray"``: one Ray task
    with one CPU per job; with `address` None on a new local Ray instance of `n_workers` CPUs (default all), else on
    the cluster at `address` (``"auto"`` or ``"HOST:PORT"``), whose CPUs set the parallelism. When Ray is already
    initialised in this process, its instance is used as it is. A run whose version record differs from the driver's
    (e.g. a cluster node with other code) fails unless `allow_mixed_versions`. Runs that fail do not stop the others;
    the finished ones are written and a RunFailure naming each failed run with its traceback is raised at the end.
    Raises ValueError for a bad backend, worker count or an address without the Ray backend, and ImportError naming
    ``pip install 'sb3-er[ray]'`` when Ray is not installed.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if n_workers is not None and (int(n_workers) != n_workers or n_workers < 1):
        raise ValueError(f"n_workers must be a positive integer, got {n_workers}")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) is for the Ray backend only; add backend='ray' (--backend ray)")
    if address is not None and n_workers is not None:
        raise ValueError("n_workers (--jobs) sets the CPUs of a local Ray instance; a cluster at an address uses its own")
    driver = _Driver(jobs, show_progress, allow_mixed_versions)
    runnable = driver.runnable
    try:
        if backend == "ray":
            _run_on_ray(runnable, driver, address, n_workers)
        elif (n_workers or os.cpu_count() or 1) == 1 or len(runnable) <= 1:
            _run_here(runnable, driver)
        else:
            _run_on_process_pool(runnable, driver, n_workers or os.cpu_count() or 1)
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


def _run_on_process_pool(jobs: list[RunJob], driver: _Driver, n_workers: int) -> None:
    _limit_threads_of_children()
    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager, ProcessPoolExecutor(max_workers=n_workers, mp_context=context) as pool:
        progress_queue = manager.Queue()
        futures: dict[Future, RunJob] = {pool.submit(execute_run, job, progress_queue): job for job in jobs}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            for future in done:
                job = futures[future]
                try:
                    result = future.result()
                except Exception:  # noqa: BLE001
                    driver.failed(job, traceback.format_exc())
                else:
                    driver.finished(job, result)
            while True:
                try:
                    driver.progress(*progress_queue.get_nowait())
                except queue.Empty:
                    break
            driver.refresh()


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
        remote_run = ray.remote(num_cpus=1)(execute_run)
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

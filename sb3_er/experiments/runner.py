"""Runs every (algorithm, seed) pair of an experiment in worker processes, with one progress bar and resumption.

Each finished run is one CSV, ``<out>/runs/<algo>/seed_<seed>.csv``, written atomically when the run ends; a run whose
CSV exists is skipped, so an interrupted reproduction resumes where it stopped. Workers are spawned with one BLAS/OpenMP
thread each, so that N workers use N cores.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from tqdm.auto import tqdm

from sb3_er.experiments.specs import EXPERIMENTS, Experiment


@dataclass(frozen=True)
class RunJob:
    """One learning run: an algorithm on an experiment with one seed, for `budget` episodes or seconds."""

    experiment: str
    algo: str
    seed: int
    budget: float
    csv_path: Path

    @property
    def key(self) -> str:
        return f"{self.algo}/seed_{self.seed}"


def run_csv_path(out_dir: Path, algo: str, seed: int) -> Path:
    """Where the CSV of one run lives."""
    return Path(out_dir) / "runs" / algo / f"seed_{seed}.csv"


def _limit_threads_of_children() -> None:
    for variable in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(variable, "1")


def build_protocol(experiment: Experiment, env, budget: float, seed: int, progress=None):
    """The experiment's protocol callback and the number of timesteps to give `learn` (the callback stops earlier)."""
    import gymnasium as gym

    from sb3_er.experiments.protocols import EpisodeReturnProtocol, GreedyDistanceProtocol

    if experiment.protocol == "episodes":
        callback = EpisodeReturnProtocol(int(budget), progress=progress)
        return callback, int(budget) * int(env.unwrapped.max_episode_steps)
    eval_envs = [gym.make(experiment.env_id) for _ in range(experiment.eval_runs)]
    callback = GreedyDistanceProtocol(
        eval_envs,
        dt=env.unwrapped.dt,
        eval_interval=experiment.eval_interval,
        learning_time=budget,
        eval_seed=10_000 + seed,
        progress=progress,
    )
    return callback, callback.total_steps


def run_single(job: RunJob, progress_queue=None) -> float:
    """Learn one run, write its CSV atomically and return its wall time in seconds.

    A run whose Q-function diverges is finished too: its CSV holds the records up to the divergence and every row has
    ``diverged`` set, so that the summary can count it instead of averaging a truncated curve.
    """
    import gymnasium as gym
    import torch

    import sb3_er_envs  # noqa: F401  (registers the environment ids)
    from sb3_er import DivergenceError
    from sb3_er.zoo import algorithm_classes, model_kwargs

    torch.set_num_threads(1)
    experiment = EXPERIMENTS[job.experiment]
    last_reported = [-1.0]

    def report(fraction: float) -> None:
        if progress_queue is not None and fraction - last_reported[0] >= 0.01:
            last_reported[0] = fraction
            progress_queue.put((job.key, fraction))

    start = time.perf_counter()
    env = gym.make(experiment.env_id)
    model = algorithm_classes()[job.algo]("TileQ", env, seed=job.seed, **model_kwargs(job.algo, experiment.env_id))
    callback, total_timesteps = build_protocol(experiment, env, job.budget, job.seed, report)
    try:
        model.learn(total_timesteps=total_timesteps, callback=callback)
        diverged = False
    except DivergenceError:
        diverged = True
    for used_env in [env, *getattr(callback, "eval_envs", [])]:
        used_env.close()
    job.csv_path.parent.mkdir(parents=True, exist_ok=True)
    partial = job.csv_path.with_suffix(".csv.partial")
    frame = pd.DataFrame(callback.records, columns=list(callback.COLUMNS))
    frame["diverged"] = diverged
    frame.to_csv(partial, index=False)
    os.replace(partial, job.csv_path)
    if progress_queue is not None:
        progress_queue.put((job.key, 1.0))
    return time.perf_counter() - start


def plan_jobs(experiment: Experiment, algos, seeds, budget: float, out_dir: Path) -> tuple[list[RunJob], list[RunJob]]:
    """All jobs of the reproduction, split into (to run, already finished)."""
    jobs = [
        RunJob(experiment.name, algo, seed, budget, run_csv_path(out_dir, algo, seed)) for algo in algos for seed in seeds
    ]
    finished = [job for job in jobs if job.csv_path.is_file()]
    return [job for job in jobs if not job.csv_path.is_file()], finished


class RunFailure(RuntimeError):
    """One or more learning runs raised; the message names each run and its traceback."""


def run_jobs(jobs: list[RunJob], n_workers: int, show_progress: bool = True) -> dict[str, float]:
    """Run `jobs` on `n_workers` processes (in this process when 1) and return each run's wall time by key."""
    if n_workers < 1:
        raise ValueError(f"n_workers must be at least 1, got {n_workers}")
    wall_times: dict[str, float] = {}
    failures: list[str] = []
    bar = tqdm(total=len(jobs), unit="run", desc="runs", disable=not show_progress or not jobs, smoothing=0.0)
    fractions = {job.key: 0.0 for job in jobs}

    def refresh() -> None:
        bar.n = round(sum(fractions.values()), 2)
        bar.refresh()

    if n_workers == 1 or len(jobs) <= 1:
        local_queue: queue.SimpleQueue = queue.SimpleQueue()
        for job in jobs:
            try:
                wall_times[job.key] = run_single(job, local_queue)
            except Exception:  # noqa: BLE001  (reported with the run's name below)
                failures.append(f"{job.key}:\n{traceback.format_exc()}")
            while not local_queue.empty():
                key, fraction = local_queue.get()
                fractions[key] = fraction
            refresh()
    else:
        _limit_threads_of_children()
        context = multiprocessing.get_context("spawn")
        with context.Manager() as manager, ProcessPoolExecutor(max_workers=n_workers, mp_context=context) as pool:
            progress_queue = manager.Queue()
            futures: dict[Future, RunJob] = {pool.submit(run_single, job, progress_queue): job for job in jobs}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                for future in done:
                    job = futures[future]
                    try:
                        wall_times[job.key] = future.result()
                        fractions[job.key] = 1.0
                    except Exception:  # noqa: BLE001
                        failures.append(f"{job.key}:\n{traceback.format_exc()}")
                while True:
                    try:
                        key, fraction = progress_queue.get_nowait()
                    except queue.Empty:
                        break
                    fractions[key] = max(fractions[key], fraction)
                refresh()
    bar.close()
    if failures:
        raise RunFailure(f"{len(failures)} of {len(jobs)} runs failed:\n" + "\n".join(failures))
    return wall_times

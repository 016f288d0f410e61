"""The thesis's evaluation protocols (sections 4.2 and 5.1) as Stable-Baselines3 callbacks.

Both callbacks read the standard locals of an SB3 learning loop (``rewards``, ``dones``, ``infos``), count falls from
``info["fell"]`` and keep their measurements in ``records`` (a list of dicts, one per measurement, ready for a CSV).
Every record also holds ``values_out_of_range``: how many targets and Q-values the learner's value watch had seen
outside the possible returns by then (``TileQAlgorithm.values_out_of_range``; -1 for a learner without a watch).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

ProgressHook = Callable[[float], None]


def values_out_of_range(model) -> int:
    """The learner's count of values seen outside the possible returns so far; -1 without a value watch.

    :param model: the learning sb3-er algorithm.
    """
    if getattr(model, "value_bounds", None) is None:
        return -1
    return int(model.values_out_of_range)


class EpisodeReturnProtocol(BaseCallback):
    """Records the undiscounted return of every learning episode and stops learning after ``n_episodes``.

    This is the pendulum protocol (thesis 4.2.1, "every episode, the cumulative reward is recorded") and the learning
    curve of the grid world. Each record holds ``episode`` (1-based), ``timesteps``, ``return``, ``length``,
    ``cumulative_falls``, ``goal_reached``, ``wall_time_s`` and ``values_out_of_range`` (module docstring).

    :param n_episodes: learning episodes after which learning stops (a positive integer).
    :param progress: called with the fraction of the run done, for a progress bar; None (default) for none.
    :param verbose: SB3's callback verbosity (default 0).
    """

    COLUMNS = (
        "episode",
        "timesteps",
        "return",
        "length",
        "cumulative_falls",
        "goal_reached",
        "wall_time_s",
        "values_out_of_range",
    )

    def __init__(self, n_episodes: int, progress: ProgressHook | None = None, verbose: int = 0) -> None:
        super().__init__(verbose)
        if int(n_episodes) != n_episodes or n_episodes < 1:
            raise ValueError(f"n_episodes must be a positive integer, got {n_episodes}")
        self.n_episodes = int(n_episodes)
        self.progress = progress
        self.records: list[dict[str, float]] = []
        self.falls = 0
        self._returns = np.zeros(0)
        self._lengths = np.zeros(0, dtype=np.int64)
        self._start = 0.0

    def _on_training_start(self) -> None:
        self._returns = np.zeros(self.training_env.num_envs)
        self._lengths = np.zeros(self.training_env.num_envs, dtype=np.int64)
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        self._returns += np.asarray(self.locals["rewards"], dtype=float)
        self._lengths += 1
        for index in np.flatnonzero(self.locals["dones"]):
            info = self.locals["infos"][index]
            self.falls += bool(info.get("fell", False))
            self.records.append(
                {
                    "episode": len(self.records) + 1,
                    "timesteps": self.num_timesteps,
                    "return": float(self._returns[index]),
                    "length": int(self._lengths[index]),
                    "cumulative_falls": self.falls,
                    "goal_reached": bool(info.get("goal_reached", False)),
                    "wall_time_s": time.perf_counter() - self._start,
                    "values_out_of_range": values_out_of_range(self.model),
                }
            )
            self.logger.record("protocol/episode_return", float(self._returns[index]))
            self.logger.record("protocol/cumulative_falls", self.falls)
            self._returns[index] = 0.0
            self._lengths[index] = 0
            if self.progress is not None:
                self.progress(min(len(self.records), self.n_episodes) / self.n_episodes)
        return len(self.records) < self.n_episodes


class GreedyDistanceProtocol(BaseCallback):
    """Every ``eval_interval`` seconds of learning time, walks ``n_runs`` greedy episodes and records their mean
    distance.

    This is the walking protocol: the simplest walker (thesis 4.2.2: every 100 s, 10 runs of 100 s) and LEO (4.2.3:
    every 200 s, one run of 25 s). Learning time is ``num_timesteps * dt``. The greedy runs use ``eval_envs`` (one
    environment per run, reset with seeds drawn from ``eval_seed`` so that every algorithm meets the same initial
    states); a run lasts one episode of the evaluation environment and its distance is the last ``info["distance"]``.
    Each record holds ``learning_time_s``, ``timesteps``, ``distance`` (mean over runs), ``distance_std``,
    ``cumulative_falls`` (falls while learning), ``episodes``, ``wall_time_s`` and ``values_out_of_range`` (module
    docstring). Learning stops after ``learning_time`` seconds, with a final evaluation. With several envs the learning
    time counts every env's steps, and an evaluation runs when the count reaches or passes each interval.

    :param eval_envs: the evaluation environments, one per greedy run (at least one).
    :param dt: the learning env's control step in seconds.
    :param eval_interval: seconds of learning time between evaluations (walker 100, LEO 200).
    :param learning_time: seconds of learning time after which learning stops.
    :param eval_seed: seed of the evaluation runs' initial states (default 0).
    :param progress: called with the fraction of the run done, for a progress bar; None (default) for none.
    :param verbose: SB3's callback verbosity (default 0).
    """

    COLUMNS = (
        "learning_time_s",
        "timesteps",
        "distance",
        "distance_std",
        "cumulative_falls",
        "episodes",
        "wall_time_s",
        "values_out_of_range",
    )

    def __init__(
        self,
        eval_envs: Sequence[gym.Env],
        dt: float,
        eval_interval: float,
        learning_time: float,
        eval_seed: int = 0,
        progress: ProgressHook | None = None,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if len(eval_envs) == 0:
            raise ValueError("eval_envs must hold at least one evaluation environment")
        if dt <= 0 or eval_interval <= 0 or learning_time <= 0:
            raise ValueError(
                f"dt, eval_interval and learning_time must be positive, got {dt}, {eval_interval}, {learning_time}"
            )
        self.eval_envs = list(eval_envs)
        self.dt = float(dt)
        self.eval_every_steps = max(1, round(eval_interval / dt))
        self.total_steps = max(1, round(learning_time / dt))
        self.progress = progress
        self.records: list[dict[str, float]] = []
        self.falls = 0
        self.episodes = 0
        self._seeds = np.random.default_rng(eval_seed)
        self._start = 0.0
        self._next_evaluation = self.eval_every_steps

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()
        self._next_evaluation = (self.num_timesteps // self.eval_every_steps + 1) * self.eval_every_steps
        self._evaluate()

    def _on_step(self) -> bool:
        for index in np.flatnonzero(self.locals["dones"]):
            self.episodes += 1
            self.falls += bool(self.locals["infos"][index].get("fell", False))
        # an evaluation when num_timesteps reaches or crosses the next multiple (it moves by the number of envs)
        if self.num_timesteps >= self._next_evaluation or self.num_timesteps >= self.total_steps:
            while self._next_evaluation <= self.num_timesteps:
                self._next_evaluation += self.eval_every_steps
            self._evaluate()
            if self.progress is not None:
                self.progress(min(self.num_timesteps, self.total_steps) / self.total_steps)
        return self.num_timesteps < self.total_steps

    def greedy_distances(self) -> np.ndarray:
        """Distance walked in one greedy episode of every evaluation environment, stepped as one batch."""
        seeds = self._seeds.integers(0, 2**31 - 1, size=len(self.eval_envs))
        observations = np.stack([env.reset(seed=int(seed))[0] for env, seed in zip(self.eval_envs, seeds, strict=True)])
        distances = np.zeros(len(self.eval_envs))
        running = np.ones(len(self.eval_envs), dtype=bool)
        while running.any():
            active = np.flatnonzero(running)
            actions, _ = self.model.predict(observations[active], deterministic=True)
            for index, action in zip(active, actions, strict=True):
                observation, _, terminated, truncated, info = self.eval_envs[index].step(action)
                observations[index] = observation
                distances[index] = info["distance"]
                running[index] = not (terminated or truncated)
        return distances

    def _evaluate(self) -> None:
        distances = self.greedy_distances()
        record = {
            "learning_time_s": self.num_timesteps * self.dt,
            "timesteps": self.num_timesteps,
            "distance": float(distances.mean()),
            "distance_std": float(distances.std()),
            "cumulative_falls": self.falls,
            "episodes": self.episodes,
            "wall_time_s": time.perf_counter() - self._start,
            "values_out_of_range": values_out_of_range(self.model),
        }
        self.records.append(record)
        self.logger.record("protocol/greedy_distance", record["distance"])
        self.logger.record("protocol/cumulative_falls", self.falls)

"""The uniformly random policy on the thesis's tasks, scored with each table's own metric.

A run that learned nothing is worth what a policy that knows nothing does: on the pendulum swing-up (Table 6.1) the
undiscounted return of an episode, on the walkers (Tables 6.2 and 6.3) the distance of one evaluation run, each with
every action drawn uniformly from the env's action space. ``benchmarks/random_policy.py`` measures these and commits
them to ``results/measured/random_policy/``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from sb3_er.common.checks import check_integer
from sb3_er.experiments.specs import Experiment

#: What one score of :func:`random_policy_scores` is, by protocol.
METRICS = {
    "episodes": "undiscounted return of one episode",
    "walking": "distance of one evaluation run [m]",
}


def random_policy_scores(
    experiment: Experiment, n_runs: int, seed: int = 0, env_kwargs: dict[str, Any] | None = None
) -> np.ndarray:
    """The table metric of `n_runs` episodes of the uniformly random policy: each episode's undiscounted return
    ("episodes" protocol) or the distance of its last step (``info["distance"]``, "walking" protocol), one episode
    being one learning episode or one evaluation run of the experiment's env.

    :param experiment: the experiment (its env id and protocol).
    :param n_runs: the number of episodes (a positive integer).
    :param seed: seeds the episodes' initial states and the actions (default 0).
    :param env_kwargs: ``gymnasium.make`` keyword arguments (default None: none).
    """
    check_integer("n_runs", n_runs, minimum=1)
    if experiment.protocol not in METRICS:
        raise ValueError(f"{experiment.name}: no table metric for the {experiment.protocol!r} protocol")
    env = gym.make(experiment.env_id, **(env_kwargs or {}))
    try:
        env.action_space.seed(seed)
        reset_seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=n_runs)
        scores = np.empty(n_runs)
        for run, reset_seed in enumerate(reset_seeds):
            env.reset(seed=int(reset_seed))
            total, info, done = 0.0, {}, False
            while not done:
                _, reward, terminated, truncated, info = env.step(env.action_space.sample())
                total += float(reward)
                done = terminated or truncated
            scores[run] = total if experiment.protocol == "episodes" else float(info["distance"])
        return scores
    finally:
        env.close()

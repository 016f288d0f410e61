"""Issue 26's targets for the shipped defaults on Gymnasium's continuous-action classic control, seed by seed.

    python benchmarks/continuous_targets.py [--algos sarsa_lambda er_sigma] [--envs ...] [--seeds 0 1 2 3 4]

Each run is exactly what a new user writes: ``Algo("TileQ", env_id, seed=seed).learn(100_000)``, nothing but the env
id (so the class defaults, 7 action levels per dimension from bound to bound, and sb3-er's tilings for the id,
sb3_er/data/tilings.yml). Then 20 greedy episodes (``evaluate_policy(deterministic=True)``) on a fresh env reset with
seed 1000 + seed. Printed per seed: the median and mean of the 20 returns, whether the median reaches the issue's
level (Pendulum-v1 -200, where rl-zoo's tuned TD3 and SAC reach about -150; MountainCarContinuous-v0 90, its
``reward_threshold``), learning CPU seconds and episodes; then a markdown table with the median over seeds. Runs go
one after another in this process; CPU time is this process's.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import classic_targets  # noqa: E402  (the same runs, evaluation and tables as the discrete-action targets)

#: Issue 26's level for the median greedy return of each seed.
TARGETS = {"Pendulum-v1": -200.0, "MountainCarContinuous-v0": 90.0}


if __name__ == "__main__":
    classic_targets.main(targets=TARGETS, description=__doc__)

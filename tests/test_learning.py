"""Every algorithm learns MountainCar-v0 with tile coding to the textbook level (Sutton and Barto, Example 10.1).

Sutton and Barto's semi-gradient Sarsa with 8 tilings of 8 x 8 reaches the goal in roughly 100-170 steps after a few
hundred episodes. Here every algorithm gets 50,000 steps (300-350 episodes with gymnasium's 200-step limit) and must
then reach the goal greedily within 170 steps on average over 3 seeds.

Readings behind the settings: the ER family replays old data and, with gamma = 1 and alpha >= 0.3, vanilla ER can
diverge here through the self-affecting states of thesis 5.3 (the package raises DivergenceError), so it uses
gamma = 0.99. Successive MountainCar states share nearly all tiles, so the residual direction of Eq. 5.7 with zeta = 1
nearly cancels (phi(s, a) - gamma phi(s', a) ~ (1 - gamma) phi); the residual variants use zeta = 0.5 (Eq. 5.9).
"""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import ER, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

TILES = dict(n_tilings=8, tiles_per_dimension=8)
REPLAY = dict(replays_per_stored_trajectory=2.0, learning_rate=0.3, gamma=0.99)
SETTINGS = {
    "SarsaLambda": (SarsaLambda, dict(learning_rate=0.5, gamma=1.0, trace_lambda=0.9)),
    "ER": (ER, REPLAY),
    "ERSigma": (ERSigma, REPLAY),
    "ResidualER": (ResidualER, dict(REPLAY, residual_zeta=0.5)),
    "ResidualERSigma": (ResidualERSigma, dict(REPLAY, residual_zeta=0.5)),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SETTINGS))
def test_mountain_car_textbook_level(name):
    algo, kwargs = SETTINGS[name]
    returns = []
    for seed in range(3):
        model = algo("TileQ", "MountainCar-v0", exploration_rate=0.0, policy_kwargs=TILES, seed=seed, **kwargs)
        model.learn(50_000)
        mean_return, _ = evaluate_policy(model, Monitor(gym.make("MountainCar-v0")), n_eval_episodes=10)
        returns.append(mean_return)
    assert np.mean(returns) >= -170.0, returns

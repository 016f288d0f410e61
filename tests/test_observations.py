"""Every observation is checked where it enters (issue 37): from the env while learning (every algorithm), through
predict and evaluate_policy; a wrong shape, a non-number or a NaN is a ValueError naming the space and what came,
never a numba TypingError nor a silent read past the tile coder's arrays."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI]
BAD = {
    "size 3": np.zeros(3, dtype=np.float32),
    "size 1": np.zeros(1, dtype=np.float32),
    "size 0": np.zeros(0, dtype=np.float32),
    "shape (1, 2)": np.zeros((1, 2), dtype=np.float32),
    "a Python int": 3,
    "None": None,
    "strings": np.array(["a", "b"]),
}


class Broken(gym.Env):
    """A 2-D Box env whose 4th step returns ``bad`` (its reset and first steps are fine)."""

    observation_space = gym.spaces.Box(-1.0, 1.0, shape=(2,))
    action_space = gym.spaces.Discrete(2)
    tile_widths = [0.5, 0.5]

    def __init__(self, bad):
        self.bad, self.t = bad, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(2, dtype=np.float32), {}

    def step(self, action):
        self.t += 1
        obs = self.bad if self.t == 4 else np.zeros(2, dtype=np.float32)
        return obs, 0.0, False, self.t >= 10, {}


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("what", list(BAD))
def test_a_bad_observation_from_the_env_is_named(algo, what):
    model = algo("TileQ", Broken(BAD[what]), seed=0)
    with pytest.raises(ValueError, match=r"observation .*does not fit the observation space Box") as caught:
        model.learn(20)
    assert "returned from step at step 4" in str(caught.value)


@pytest.mark.parametrize("algo", ALGOS)
def test_a_nan_from_the_env_cannot_be_tiled(algo):
    model = algo("TileQ", Broken(np.array([np.nan, 0.0], dtype=np.float32)), seed=0)
    with pytest.raises(ValueError, match="cannot be tiled: NaN or infinite values in dimensions"):
        model.learn(20)


@pytest.mark.parametrize("what", ["size 3", "size 0", "shape (1, 2)", "a Python int", "None"])
def test_a_bad_observation_to_predict_is_named(what):
    model = SarsaLambda("TileQ", Broken(np.zeros(2)), seed=0)
    bad = BAD[what]
    if what == "shape (1, 2)":  # a batch of one observation: fine
        assert model.predict(bad, deterministic=True)[0].shape == (1,)
        return
    with pytest.raises(ValueError, match="observation"):
        model.predict(bad, deterministic=True)


def test_evaluate_policy_on_an_env_that_goes_bad():
    model = SarsaLambda("TileQ", Broken(np.zeros(2)), seed=0)
    with pytest.raises(ValueError, match=r"Observation \[inf, 0.0\] cannot be tiled"):
        evaluate_policy(model, Broken(np.array([np.inf, 0.0])), n_eval_episodes=1)


def test_a_learning_rate_schedule_that_turns_negative_stops():
    """A schedule is checked at every reading, not only at the start: one that turns negative stops with its value."""
    schedule = lambda progress: 1.0 * progress - 0.5  # noqa: E731  (0.5 at the start, negative past half)
    model = SarsaLambda("TileQ", "CartPole-v1", learning_rate=schedule, seed=0)
    with pytest.raises(ValueError, match="learning-rate schedule gave -"):
        model.learn(2000)
    assert 900 <= model.num_timesteps <= 1100  # it ran until the schedule went below 0, halfway

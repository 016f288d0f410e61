"""What the tests of SB3's behaviours (docs/sb3_tests.md maps SB3's test modules to ours) run on: the eight
algorithms, and SB3's own small test envs with a discrete and a Box action space (stable_baselines3.common.envs)."""

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.wrappers import FlattenObservation
from stable_baselines3.common.envs import IdentityEnv, IdentityEnvBox
from stable_baselines3.common.logger import Logger

from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI]
#: A small weight table: the default 2^22 weights cost a 32 MB allocation per model.
SMALL_TABLE = dict(n_tilings=4, memory_size=2**14)


def discrete_env() -> gym.Env:
    """SB3's IdentityEnv(4), observed one-hot (TileQ tiles Box observations; a Discrete one it refuses by name):
    reward 1 when the action names the state, 100-step episodes."""
    return FlattenObservation(IdentityEnv(4))


def box_env() -> gym.Env:
    """SB3's IdentityEnvBox with a tolerance of 0.5: a Box action within 0.5 of the Box state pays 1."""
    return IdentityEnvBox(eps=0.5)


ENVS = {"discrete": discrete_env, "box": box_env}
#: SB3's own choice of env per action space in test_predict, test_callbacks and test_deterministic.
ENV_IDS = {"discrete": "CartPole-v1", "box": "Pendulum-v1"}


def model(algo, env, seed=None, **kwargs):
    """``algo`` on ``env`` with the small table, the value watch counting without warning, and for FQI and LSPI a fit
    every episode (their default of 5 episodes would leave short tests without a fit)."""
    if algo in (FQI, LSPI):
        kwargs.setdefault("fit_every", 1)
    kwargs.setdefault("policy_kwargs", SMALL_TABLE)
    kwargs.setdefault("value_bound_action", "ignore")  # the value watch has its own tests; here it would only warn
    return algo("TileQ", env, seed=seed, **kwargs)


class InMemoryLogger(Logger):
    """SB3's test pattern: a logger without output formats whose values stay readable; ``dumped`` keeps each dump."""

    def __init__(self):
        super().__init__("", [])
        self.dumped = []

    def dump(self, step: int = 0) -> None:
        self.dumped.append(dict(self.name_to_value))


class OneStepEnv(gym.Env):
    """SB3's TimeDelayEnv: one-step episodes whose step sleeps ``delay`` seconds (so at most 1 / delay steps per
    second); counts its steps."""

    observation_space = spaces.Box(-20.0, 20.0, shape=(4,), dtype=np.float32)
    action_space = spaces.Discrete(2)

    def __init__(self, delay: float = 0.001, clock=None):
        self.delay = delay
        self.clock = clock
        self.steps = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        if self.clock is None:
            import time

            time.sleep(self.delay)
        else:
            self.clock[0] += int(self.delay * 1e9)
        self.steps += 1
        return self.observation_space.sample(), 0.0, True, False, {}

"""Small test environments for the algorithm tests."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces


class LineWalkEnv(gym.Env):
    """Walk on [0, 10] with MultiDiscrete([3, 2]) actions: direction (-1, 0, +1) times stride (1 or 2).

    -1 per step, +20 and termination at the right end; 40-step episodes. Optionally emits a NaN observation after
    ``nan_after`` steps, or a segment end every ``segment_every`` steps.
    """

    def __init__(self, nan_after=None, segment_every=None, reward_scale=1.0):
        self.observation_space = spaces.Box(0.0, 10.0, shape=(1,), dtype=np.float64)
        self.action_space = spaces.MultiDiscrete([3, 2])
        self.tile_widths = np.array([1.0])
        self.nan_after = nan_after
        self.segment_every = segment_every
        self.reward_scale = reward_scale

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.position = float(self.np_random.integers(0, 3))
        self.steps = 0
        return np.array([self.position]), {}

    def step(self, action):
        direction, stride = int(action[0]) - 1, int(action[1]) + 1
        self.position = float(np.clip(self.position + direction * stride, 0.0, 10.0))
        self.steps += 1
        terminated = self.position >= 10.0
        reward = (20.0 if terminated else -1.0) * self.reward_scale
        obs = np.array([self.position])
        if self.nan_after is not None and self.steps >= self.nan_after:
            obs[0] = np.nan
        info = {"segment_end": bool(self.segment_every and self.steps % self.segment_every == 0)}
        return obs, reward, terminated, self.steps >= 40, info


@pytest.fixture
def line_env():
    return LineWalkEnv()

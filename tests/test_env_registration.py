"""Gymnasium registration of the sb3-er environments and the interface every one of them promises."""

import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_er_envs

ALL_IDS = [
    "sb3_er/WindyCliff-v0",
    "sb3_er/PendulumSwingup-v0",
    "sb3_er/SimplestWalker-v0",
    "sb3_er/CompassWalker-v0",
    "sb3_er/Leo-v0",
]


def make(env_id, **kwargs):
    if env_id == "sb3_er/Leo-v0":
        pytest.importorskip("sb3_er_envs.leo.leo", reason="LEO needs the dmc extra")
    return gymnasium.make(env_id, **kwargs)


def test_the_ids_are_registered_without_a_wrapper_time_limit():
    assert sorted(sb3_er_envs.ENV_IDS) == sorted(ALL_IDS)
    for env_id in ALL_IDS:
        spec = gymnasium.spec(env_id)
        assert isinstance(spec.entry_point, str) and spec.entry_point.startswith("sb3_er_envs.")
        assert spec.max_episode_steps is None


def test_importing_the_package_imports_no_environment_or_physics_engine():
    probe = (
        "import sys, sb3_er_envs\n"
        "heavy = ('dm_control', 'mujoco', 'numba', 'torch', 'sb3_er', 'sb3_er_envs.')\n"
        "print(sorted(m for m in sys.modules if m.startswith(heavy) and m != 'sb3_er_envs'))\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_every_id_makes_an_environment_with_the_shared_interface(env_id):
    """Box observations with finite bounds, Discrete (or flat MultiDiscrete, LEO's voltage levels per joint) actions,
    tile widths and wrap periods per observation dimension, a control period, seeded resets and SB3 compatibility."""
    env = make(env_id)
    base = env.unwrapped
    observation_space, action_space = env.observation_space, env.action_space
    assert isinstance(observation_space, spaces.Box)
    assert isinstance(action_space, spaces.Discrete) or (
        isinstance(action_space, spaces.MultiDiscrete) and action_space.nvec.ndim == 1
    )
    assert np.all(np.isfinite(observation_space.low)) and np.all(np.isfinite(observation_space.high))
    dimensions = observation_space.shape[0]
    assert observation_space.shape == (dimensions,)
    assert isinstance(base.tile_widths, np.ndarray) and base.tile_widths.shape == (dimensions,)
    assert np.all(base.tile_widths > 0)
    assert base.wrap_periods is None or (
        len(base.wrap_periods) == dimensions and all(p is None or p > 0 for p in base.wrap_periods)
    )
    assert base.dt > 0

    first, _ = env.reset(seed=3)
    again, _ = env.reset(seed=3)
    np.testing.assert_array_equal(first, again)
    assert observation_space.contains(first)
    observation, reward, terminated, truncated, info = env.step(action_space.sample())
    assert observation_space.contains(observation)
    assert np.isfinite(reward) and isinstance(terminated, bool) and isinstance(truncated, bool)
    sb3_check_env(base)
    env.close()


def test_keyword_arguments_reach_the_environment():
    env = gymnasium.make("sb3_er/WindyCliff-v0", width=6, max_episode_steps=5)
    assert env.observation_space.high.tolist() == [5.0, 6.0]
    env.reset(seed=0)
    truncations = [env.step(6)[3] for _ in range(5)]
    assert truncations == [False, False, False, False, True]
    assert gymnasium.make("sb3_er/PendulumSwingup-v0", max_torque=0.3).unwrapped.torques[-1] == 0.3

"""CompassWalker-v0 against GRL's walk task as read from its source (github wcaarls/grl:
base/src/environments/compass_walker/compass_walker.cpp, cfg/compass_walker/sarsa_walk.yaml); the physics is
SimplestWalkerEnv's, tested there."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er_envs.compass_walker import LEARNING_EPISODE_STEPS, TEST_EPISODE_STEPS, CompassWalkerEnv
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT

ZERO = 1  # index of hip acceleration 0 among {-1.2, 0, 1.2}
SLOPE = 0.004


def grl_steps_until(time_limit, control_step=0.2):
    """GRL ends an episode once its time, summed in control steps, exceeds the limit."""
    time, steps = 0.0, 0
    while not time > time_limit:
        time += control_step
        steps += 1
    return steps


def test_grl_walk_task_settings():
    env = gym.make("sb3_er/CompassWalker-v0").unwrapped
    assert isinstance(env, CompassWalkerEnv)
    assert env.action_space == gym.spaces.Discrete(3)
    assert env.hip_accelerations == (-1.2, 0.0, 1.2)
    np.testing.assert_array_equal(env.tile_widths, [0.0838, 0.1047, 0.1111, 0.2222, 10.0])
    assert env.wrap_periods is None
    assert env.observation_space.shape == (5,)
    assert (env.dt, env.substeps, env.slope) == (0.2, 20, 0.004)
    assert (env.reward, env.fall, env.observation) == ("schuitema", "angles", "grl")
    assert (env.time_reward, env.step_reward, env.step_reward_cap, env.fall_reward) == (-1.0, 50.0, 30.0, -100.0)
    assert env.initial_state_variation == 0.2
    assert env.max_episode_steps == LEARNING_EPISODE_STEPS == grl_steps_until(100.0) == 500
    assert TEST_EPISODE_STEPS == grl_steps_until(200.0) == 1001


def test_the_test_env_walks_passively_for_1001_steps_from_garcias_fixed_point():
    env = gym.make("sb3_er/CompassWalker-v0", episode_steps=TEST_EPISODE_STEPS, initial_state_variation=0.0)
    observation, _ = env.reset(seed=5)
    s = GARCIA_FIXED_POINT
    np.testing.assert_allclose(observation, [s[0], s[1] - 2 * s[0], s[2], s[3] - 2 * s[2], 0.0], atol=1e-15)
    total, steps, footsteps = 0.0, 0, 0
    while True:
        observation, reward, terminated, truncated, info = env.step(ZERO)
        total += reward
        steps += 1
        footsteps += info["footstep"]
        assert observation[4] == (1.0 if info["footstep"] else 0.0)  # GRL's stance-leg-changed flag
        if terminated or truncated:
            break
    assert truncated and not terminated and steps == 1001
    assert footsteps >= 50
    assert total > 0.0


def test_observation_is_grls_with_the_stance_change_flag():
    env = CompassWalkerEnv()
    observation, _ = env.reset(options={"state": [0.12, 0.31, -0.2, 0.4]})
    np.testing.assert_allclose(observation, [0.12, 0.07, -0.2, 0.8, 0.0], rtol=0, atol=1e-15)
    env.reset(options={"state": GARCIA_FIXED_POINT})
    flags = []
    for _ in range(60):
        observation, _, terminated, _, info = env.step(ZERO)
        s = env.state
        expected = [s[0], s[1] - 2 * s[0], s[2], s[3] - 2 * s[2], float(info["footstep"])]
        np.testing.assert_allclose(observation, expected, rtol=0, atol=1e-15)
        flags.append(observation[4])
        if terminated:
            break
    assert 1.0 in flags and 0.0 in flags


def test_a_fall_pays_minus_100():
    env = CompassWalkerEnv()
    env.reset(options={"state": [0.40, 0.80, 0.05, 0.10]})  # stance leg beyond pi/8
    _, reward, terminated, truncated, info = env.step(ZERO)
    assert terminated and not truncated and info["fell"] and reward == -100.0


def test_footstep_reward_is_capped_200_sin_of_the_end_stance_angle():
    env = CompassWalkerEnv(episode_steps=TEST_EPISODE_STEPS, initial_state_variation=0.0)
    env.reset()
    rewards = []
    for _ in range(300):
        observation, reward, _, _, info = env.step(ZERO)
        if info["footstep"]:
            assert reward == pytest.approx(min(200.0 * math.sin(observation[0]), 30.0), rel=1e-12)
            rewards.append(reward)
        else:
            assert reward == -1.0
    assert len(rewards) >= 14 and max(rewards) <= 30.0 and min(rewards) > 24.0


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_start_distribution(seed):
    """Each of Garcia's values times a factor in [0.8, 1.2], and enough stance-leg energy to lift the hip to its height
    at phi_st = 0: phi_st'^2 / 2 + cos(phi_st) cos(mu) >= cos(mu). Passive from there, the walker passes mid-stance."""
    env = CompassWalkerEnv()
    observation, _ = env.reset(seed=seed)
    state = env.state
    factors = state / GARCIA_FIXED_POINT
    assert np.all(factors >= 0.8 - 1e-12) and np.all(factors <= 1.2 + 1e-12)
    assert 0.5 * state[2] ** 2 + math.cos(state[0]) * math.cos(SLOPE) >= math.cos(SLOPE)
    assert observation[4] == 0.0
    for _ in range(20):
        _, _, terminated, _, _ = env.step(ZERO)
        assert not terminated
        if env.state[0] < 0.0:
            break
    assert env.state[0] < 0.0


def test_the_energy_condition_rejects_starts():
    """About half of the raw draws lack the energy; none of the env's starts does, and the accepted stance rates are
    therefore faster on average than the raw draws' -0.1561."""
    rng = np.random.default_rng(0)
    raw = GARCIA_FIXED_POINT * rng.uniform(0.8, 1.2, size=(20_000, 4))
    lacking = 0.5 * raw[:, 2] ** 2 + np.cos(raw[:, 0]) * math.cos(SLOPE) < math.cos(SLOPE)
    assert 0.3 < lacking.mean() < 0.7
    env = CompassWalkerEnv()
    env.reset(seed=0)
    rates = [env.reset()[0][2] for _ in range(400)]
    assert np.mean(rates) < -0.1561 - 0.005


@pytest.mark.parametrize("kwargs", [{}, {"episode_steps": TEST_EPISODE_STEPS, "initial_state_variation": 0.0}])
def test_gymnasium_and_sb3_env_checkers_pass(kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gym.make("sb3_er/CompassWalker-v0", render_mode="rgb_array", **kwargs).unwrapped)
        sb3_check_env(CompassWalkerEnv(**kwargs))


@pytest.mark.parametrize("episode_steps", [0, 2.5, True, -3])
def test_bad_episode_steps_are_named(episode_steps):
    with pytest.raises(ValueError, match="episode_steps"):
        CompassWalkerEnv(episode_steps=episode_steps)

"""Pendulum swing-up (thesis 4.2.1, Table 4.1, Eq. 4.1) against analytic physics and hand-computed rewards."""

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from sb3_er_envs.pendulum import PendulumSwingupEnv, wrap_angle

MASS, INERTIA, LENGTH, GRAVITY = 1.113, 3.773e-3, 8.5e-2, 9.81
GRAVITY_TORQUE = MASS * GRAVITY * LENGTH  # 0.9282 N m
ZERO_TORQUE, MAX_NEGATIVE, MAX_POSITIVE = 3, 0, 6


@pytest.fixture
def env():
    environment = PendulumSwingupEnv()
    environment.reset(seed=0)
    return environment


def test_seven_torques_up_to_the_limit(env):
    assert env.action_space.n == 7
    assert env.torques == pytest.approx([-0.6, -0.4, -0.2, 0.0, 0.2, 0.4, 0.6])
    assert env.torques[ZERO_TORQUE] == 0.0


def test_starts_hanging_down_at_rest(env):
    observation, info = env.reset(seed=5)
    assert abs(observation[0]) == pytest.approx(math.pi) and observation[1] == 0.0
    assert info == {"goal_reached": False, "fell": False}


def test_energy_is_conserved_without_torque_or_damping(env):
    env.set_state(1.0, 0.0)
    initial_energy = env.energy()
    assert initial_energy == pytest.approx(GRAVITY_TORQUE * math.cos(1.0))
    for _ in range(1500):
        env.step(ZERO_TORQUE)
        assert env.energy() == pytest.approx(initial_energy, abs=1e-6 * GRAVITY_TORQUE)


def test_damping_drains_energy():
    env = PendulumSwingupEnv(damping=1e-3)
    env.reset(seed=0)
    env.set_state(1.0, 0.0)
    energies = [env.energy()]
    for _ in range(300):
        env.step(ZERO_TORQUE)
        energies.append(env.energy())
    assert np.all(np.diff(energies) <= 1e-12) and energies[-1] < energies[0] - 0.1


def test_small_swings_follow_the_linearised_oscillation(env):
    """theta = pi + phi with phi'' = -(m g l / J) phi: phi(t) = phi0 cos(omega t), omega = sqrt(m g l / J)."""
    phi0, omega = 1e-3, math.sqrt(GRAVITY_TORQUE / INERTIA)
    env.set_state(math.pi + phi0, 0.0)
    for step in range(1, 101):
        observation, *_ = env.step(ZERO_TORQUE)
        phi = wrap_angle(observation[0] - math.pi)
        assert phi == pytest.approx(phi0 * math.cos(omega * step * env.dt), abs=1e-3 * phi0)


@pytest.mark.parametrize("theta, action", [(math.pi / 2, MAX_NEGATIVE), (-math.pi / 2, MAX_POSITIVE)])
def test_the_maximum_torque_cannot_hold_the_pendulum_horizontal(env, theta, action):
    env.set_state(theta, 0.0)
    observation, *_ = env.step(action)
    # Net torque m g l - 0.6 = 0.33 N m pulls it down: theta moves away from upright, starting from rest.
    assert abs(observation[0]) > abs(theta)
    assert np.sign(observation[1]) == np.sign(theta)
    expected_rate = (GRAVITY_TORQUE - 0.6) / INERTIA * env.dt
    assert abs(observation[1]) == pytest.approx(expected_rate, rel=1e-2)


def test_constant_maximum_torque_swings_only_to_the_energy_balance_angle(env):
    """From rest hanging down, u * phi = m g l (1 - cos phi) gives the largest deflection phi: about 1.615 rad < pi."""
    low, high = 0.5, 3.0
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if 1 - math.cos(middle) < 0.6 / GRAVITY_TORQUE * middle else (low, middle)
    largest_deflection = 0.0
    for _ in range(1500):
        observation, _, terminated, *_ = env.step(MAX_POSITIVE)
        largest_deflection = max(largest_deflection, math.pi - abs(observation[0]))
        assert not terminated
    assert largest_deflection == pytest.approx(low, abs=1e-3)


def nearest_action(env, torque):
    return int(np.argmin([abs(u - torque) for u in env.torques]))


def test_pumping_then_catching_reaches_the_goal_after_swinging_back(env):
    """Thesis 4.2.1: the torque is too weak to lift the pendulum directly, so it must swing back and forth first.

    A hand-written controller pushes along the motion until the energy suffices to reach upright, and catches the
    pendulum there with a PD law.
    """
    observation, _ = env.reset(seed=0)
    velocity_signs = []
    for _ in range(env.max_episode_steps):
        theta, velocity = observation
        if abs(theta) < 0.6:
            torque = -(2.0 * theta + 0.15 * velocity)
        else:
            torque = 0.6 * np.sign(velocity) if env.energy() < GRAVITY_TORQUE else 0.0
        observation, _, terminated, truncated, info = env.step(nearest_action(env, torque))
        velocity_signs.append(np.sign(observation[1]))
        if terminated or truncated:
            break
    assert terminated and info["goal_reached"]
    assert np.count_nonzero(np.diff(velocity_signs)) >= 1


def test_reward_is_equation_4_1(env):
    assert env.reward(0.2, -1.5, 0.6) == pytest.approx(-0.2 - 0.225 - 0.36)
    env.set_state(0.2, -1.5)
    observation, reward, *_ = env.step(MAX_POSITIVE)
    assert reward == pytest.approx(-5 * observation[0] ** 2 - 0.1 * observation[1] ** 2 - 0.36)


def test_reaching_the_goal_terminates(env):
    env.set_state(0.05, 0.0)
    observation, reward, terminated, truncated, info = env.step(ZERO_TORQUE)
    assert abs(observation[0]) < 0.1 and abs(observation[1]) < 1.0
    assert terminated and not truncated and info == {"goal_reached": True, "fell": False}  # a goal is no fall
    assert reward == pytest.approx(-5 * observation[0] ** 2 - 0.1 * observation[1] ** 2)


@pytest.mark.parametrize("theta, velocity", [(0.05, 3.0), (0.3, 0.0)])
def test_near_misses_do_not_terminate(env, theta, velocity):
    env.set_state(theta, velocity)
    _, _, terminated, truncated, info = env.step(ZERO_TORQUE)
    assert not terminated and not truncated and not info["goal_reached"]


def test_goal_thresholds_are_parameters():
    env = PendulumSwingupEnv(goal_angle=0.5, goal_velocity=5.0)
    env.reset(seed=0)
    env.set_state(0.3, 3.0)
    assert env.step(ZERO_TORQUE)[2]


def test_episode_is_truncated_after_15_seconds(env):
    for step in range(1, 1501):
        _, _, terminated, truncated, _ = env.step(ZERO_TORQUE)
        assert not terminated
        assert truncated == (step == 1500)


@settings(max_examples=40, deadline=None)
@given(
    theta=st.floats(-20.0, 20.0),
    velocity=st.floats(-40.0, 40.0),
    actions=st.lists(st.integers(0, 6), min_size=1, max_size=50),
)
def test_observations_stay_wrapped_and_bounded(theta, velocity, actions):
    env = PendulumSwingupEnv()
    env.reset(seed=0)
    env.set_state(theta, velocity)
    for action in actions:
        observation, reward, terminated, truncated, _ = env.step(action)
        assert env.observation_space.contains(observation)
        assert -math.pi <= observation[0] < math.pi
        assert reward <= 0.0
        if terminated:
            break


def test_reset_with_a_seed_reproduces_the_episode():
    actions = np.random.default_rng(7).integers(0, 7, size=300)

    def trajectory():
        env = PendulumSwingupEnv()
        observations = [env.reset(seed=11)[0]]
        observations += [env.step(action)[0] for action in actions]
        return np.array(observations)

    np.testing.assert_array_equal(trajectory(), trajectory())


def test_passes_the_gymnasium_and_sb3_env_checkers():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gymnasium.make("sb3_er/PendulumSwingup-v0", render_mode="rgb_array").unwrapped)
        sb3_check_env(PendulumSwingupEnv())


def test_render_draws_the_rod_towards_the_angle():
    env = PendulumSwingupEnv(render_mode="rgb_array")
    env.reset(seed=0)
    hanging = env.render()
    assert hanging.dtype == np.uint8 and hanging.shape == (128, 128, 3)
    env.set_state(0.0, 0.0)
    upright = env.render()
    above_pivot, below_pivot = (40, 64), (88, 64)
    assert hanging[below_pivot].tolist() != [255, 255, 255] and hanging[above_pivot].tolist() == [255, 255, 255]
    assert upright[above_pivot].tolist() != [255, 255, 255] and upright[below_pivot].tolist() == [255, 255, 255]


def test_thesis_attributes(env):
    np.testing.assert_array_equal(env.tile_widths, [0.33, 0.33])
    assert env.wrap_periods == (2 * math.pi, None) and env.dt == 0.01
    assert env.gravity_torque == pytest.approx(GRAVITY_TORQUE)


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"max_torque": 1.0}, "max_torque"),
        ({"max_torque": 0.0}, "max_torque"),
        ({"n_torques": 1}, "n_torques"),
        ({"substeps": 0}, "substeps"),
        ({"mass": -1.0}, "mass"),
        ({"dt": float("nan")}, "dt"),
        ({"damping": -0.1}, "damping"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_parameters_are_named(kwargs, word):
    with pytest.raises(ValueError, match=word):
        PendulumSwingupEnv(**kwargs)


def test_bad_actions_and_states_are_named(env):
    for action in (7, -1, 0.5, "3", None, np.array([3])):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    with pytest.raises(ValueError, match="velocity"):
        env.set_state(0.0, 100.0)

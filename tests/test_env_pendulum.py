"""Pendulum swing-up (thesis 4.2.1, Table 4.1, Eq. 4.1) against analytic physics and hand-computed rewards.

Expected values are computed here from Table 4.1 and the DCSC constants of GRL (base/src/environments/pendulum.cpp),
never read back from the env.
"""

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from sb3_er_envs.pendulum import DCSC_MOPS, PendulumSwingupEnv, wrap_angle

MASS, INERTIA, LENGTH, GRAVITY = 1.113, 3.773e-3, 8.5e-2, 9.81
GRAVITY_TORQUE = MASS * GRAVITY * LENGTH  # 0.9282 N m
# Table 4.1's J about the centre of mass (the default): parallel axis theorem, J + m l^2 = 3.773e-3 + 8.0414e-3.
PIVOT_INERTIA = {"center_of_mass": 0.011814425, "pivot": INERTIA}
# The DCSC pendulum in GRL: J (pivot), m, l, b, motor constant K and resistance R.
DCSC_J, DCSC_M, DCSC_L, DCSC_B, DCSC_K, DCSC_R = 1.91e-4, 0.055, 0.042, 3e-6, 0.0536, 9.5
ZERO_TORQUE, MAX_NEGATIVE, MAX_POSITIVE = 3, 0, 6


@pytest.fixture
def env():
    environment = PendulumSwingupEnv()
    environment.reset(seed=0)
    return environment


def test_seven_torques_up_to_the_limit(env):
    assert env.action_space.n == 7 and env.actuation == "torque" and env.action_unit == "N m"
    assert env.torques == pytest.approx([-0.6, -0.4, -0.2, 0.0, 0.2, 0.4, 0.6])
    assert env.action_levels == env.torques and env.torques[ZERO_TORQUE] == 0.0


def test_starts_hanging_down_at_rest(env):
    observation, info = env.reset(seed=5)
    assert abs(observation[0]) == pytest.approx(math.pi) and observation[1] == 0.0
    assert info == {"goal_reached": False, "fell": False}


def test_the_default_inertia_is_about_the_centre_of_mass(env):
    assert env.inertia_about == "center_of_mass" and env.inertia == INERTIA
    assert env.pivot_inertia == pytest.approx(PIVOT_INERTIA["center_of_mass"], rel=1e-12)
    assert PendulumSwingupEnv(inertia_about="pivot").pivot_inertia == INERTIA


@pytest.mark.parametrize("inertia_about", ["center_of_mass", "pivot"])
def test_energy_is_conserved_without_torque_or_damping(inertia_about):
    """E = J_pivot theta'^2 / 2 + m g l cos(theta) with the hand-computed pivot inertia, along 15 s of free swinging."""
    env = PendulumSwingupEnv(inertia_about=inertia_about)
    env.reset(seed=0)

    def energy(theta, velocity):
        return 0.5 * PIVOT_INERTIA[inertia_about] * velocity**2 + GRAVITY_TORQUE * math.cos(theta)

    env.set_state(1.0, 2.0)
    initial_energy = energy(1.0, 2.0)
    assert env.energy() == pytest.approx(initial_energy, rel=1e-12)
    for _ in range(1500):
        observation, *_ = env.step(ZERO_TORQUE)
        assert energy(*observation) == pytest.approx(initial_energy, abs=1e-6 * GRAVITY_TORQUE)


@pytest.mark.parametrize("inertia_about", ["center_of_mass", "pivot"])
def test_small_swings_have_the_period_of_the_pivot_inertia(inertia_about):
    """The small-angle period 2 pi sqrt(J_pivot / (m g l)), measured from the zero crossings of a simulated swing.

    Centre of mass: 2 pi sqrt(0.011814 / 0.92817) = 0.7089 s; pivot: 2 pi sqrt(0.003773 / 0.92817) = 0.4006 s.
    """
    expected_period = 2 * math.pi * math.sqrt(PIVOT_INERTIA[inertia_about] / GRAVITY_TORQUE)
    env = PendulumSwingupEnv(inertia_about=inertia_about)
    env.reset(seed=0)
    env.set_state(math.pi + 1e-3, 0.0)
    crossings, previous = [], 1e-3
    for step in range(1, 1001):
        observation, *_ = env.step(ZERO_TORQUE)
        phi = wrap_angle(observation[0] - math.pi)
        if previous > 0.0 >= phi:  # downward zero crossing, interpolated inside the control step
            crossings.append((step - 1 + previous / (previous - phi)) * env.dt)
        previous = phi
    measured_period = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert len(crossings) >= 10
    assert measured_period == pytest.approx(expected_period, rel=1e-4)


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
    """theta = pi + phi, phi'' = -(m g l / J_pivot) phi: phi(t) = phi0 cos(omega t), omega = sqrt(m g l / J_pivot)."""
    phi0, omega = 1e-3, math.sqrt(GRAVITY_TORQUE / PIVOT_INERTIA["center_of_mass"])
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
    expected_rate = (GRAVITY_TORQUE - 0.6) / PIVOT_INERTIA["center_of_mass"] * env.dt
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


def test_reward_in_degrees_is_equation_4_1_in_degrees():
    env = PendulumSwingupEnv(reward_units="degrees")
    # theta = 0.2 rad = 11.459 deg, theta' = -1.5 rad/s = -85.944 deg/s: -5 * 131.31 - 0.1 * 7386.4 - 0.36
    assert env.reward(0.2, -1.5, 0.6) == pytest.approx(-5 * 11.4591559**2 - 0.1 * 85.9436693**2 - 0.36, rel=1e-8)
    env.reset(seed=0)
    _, reward, *_ = env.step(ZERO_TORQUE)  # hanging down at rest: -5 * 180^2
    assert reward == pytest.approx(-162000.0)


def test_a_semi_implicit_euler_step_by_hand():
    """One Euler step of 0.01 s from theta = 1 rad at rest with 0.6 N m: rate first, then the angle with the new
    rate."""
    env = PendulumSwingupEnv(integrator="euler", substeps=1, inertia_about="pivot")
    env.reset(seed=0)
    env.set_state(1.0, 0.0)
    acceleration = (GRAVITY_TORQUE * math.sin(1.0) + 0.6) / INERTIA  # 366.03 rad/s^2
    observation, *_ = env.step(MAX_POSITIVE)
    assert observation[1] == pytest.approx(0.01 * acceleration, rel=1e-12)
    assert observation[0] == pytest.approx(1.0 + 0.01 * 0.01 * acceleration, rel=1e-12)


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_both_integrators_follow_the_small_swing_oscillation(integrator):
    """theta(t) = theta0 cos(omega t) about the upright's mirror (hanging down), omega^2 = m g l / J_pivot; Euler with
    20 substeps stays within 1 % of the amplitude over a second, RK4 a thousand times closer."""
    env = PendulumSwingupEnv(integrator=integrator, substeps=20)
    env.reset(seed=0)
    env.set_state(-math.pi + 1e-3, 0.0)
    omega = math.sqrt(GRAVITY_TORQUE / PIVOT_INERTIA["center_of_mass"])
    for _ in range(100):
        observation, *_ = env.step(ZERO_TORQUE)
    expected = 1e-3 * math.cos(omega * 1.0)
    tolerance = 1e-5 if integrator == "euler" else 1e-9  # Euler is off by about 2e-6 here, RK4 by the sin's 3e-10
    assert wrap_angle(observation[0] + math.pi) == pytest.approx(expected, abs=tolerance)


def test_reaching_the_goal_terminates(env):
    assert (env.goal_angle, env.goal_velocity) == (0.2, 2.0)  # the screened goal
    env.set_state(0.15, -1.5)
    observation, reward, terminated, truncated, info = env.step(ZERO_TORQUE)
    assert abs(observation[0]) < 0.2 and abs(observation[1]) < 2.0
    assert terminated and not truncated and info == {"goal_reached": True, "fell": False}  # a goal is no fall
    assert reward == pytest.approx(-5 * observation[0] ** 2 - 0.1 * observation[1] ** 2)


@pytest.mark.parametrize("theta, velocity", [(0.05, 3.0), (0.3, 0.0), (-0.1, -2.5)])
def test_near_misses_do_not_terminate(env, theta, velocity):
    env.set_state(theta, velocity)
    _, _, terminated, truncated, info = env.step(ZERO_TORQUE)
    assert not terminated and not truncated and not info["goal_reached"]


def test_without_a_rate_condition_passing_through_upright_reaches_the_goal():
    fast = dict(theta=0.05, velocity=-8.0)  # passing upright at 8 rad/s: no goal for the default's 2 rad/s
    for goal_velocity, expected in ((2.0, False), (None, True)):
        env = PendulumSwingupEnv(goal_velocity=goal_velocity)
        env.reset(seed=0)
        env.set_state(fast["theta"], fast["velocity"])
        observation, _, terminated, _, info = env.step(ZERO_TORQUE)
        assert abs(observation[0]) < 0.2 and abs(observation[1]) > 7.0
        assert terminated == info["goal_reached"] == expected
    assert PendulumSwingupEnv(goal_velocity=None).goal_velocity == math.inf


def test_goal_thresholds_are_parameters():
    env = PendulumSwingupEnv(goal_angle=0.5, goal_velocity=5.0)
    env.reset(seed=0)
    env.set_state(0.3, 3.0)
    assert env.step(ZERO_TORQUE)[2]
    earlier = PendulumSwingupEnv(goal_angle=0.1, goal_velocity=1.0)  # the earlier default goal
    earlier.reset(seed=0)
    earlier.set_state(0.15, -1.5)
    assert not earlier.step(ZERO_TORQUE)[2]


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
    np.testing.assert_array_equal(env.tile_widths, [0.33, 0.33])  # thesis 4.2.1: "0.33 rad and 0.33 rad/s"
    assert env.wrap_periods == (2 * math.pi, None) and env.dt == 0.01
    assert env.gravity_torque == pytest.approx(GRAVITY_TORQUE)


def test_the_default_tile_widths_are_the_printed_ones():
    """Thesis 4.2.1 prints "a tile width of 0.33 rad and 0.33 rad/s": the readings rule makes a printed value the
    default; the env's widths are what a model built from the registered id tiles with."""
    from sb3_er import SarsaLambda

    env = gymnasium.make("sb3_er/PendulumSwingup-v0")
    assert env.unwrapped.velocity_tile_width == 0.33
    model = SarsaLambda("TileQ", env, policy_kwargs={"memory_size": 2**12})
    np.testing.assert_array_equal(model.policy.tile_coder.tile_widths, [0.33, 0.33])


@pytest.mark.parametrize("width", [0.33, 1.0, 3.3])
def test_the_velocity_tile_width_is_the_one_a_model_uses(width):
    from sb3_er import SarsaLambda

    env = gymnasium.make("sb3_er/PendulumSwingup-v0", velocity_tile_width=width)
    np.testing.assert_array_equal(env.unwrapped.tile_widths, [0.33, width])
    model = SarsaLambda("TileQ", env, policy_kwargs={"memory_size": 2**12})
    np.testing.assert_array_equal(model.policy.tile_coder.tile_widths, [0.33, width])


def test_voltage_actions_drive_the_dcsc_motor():
    """u in +-3 V, 7 levels; torque (K/R)(u - K theta') = 0.0536/9.5 * (u - 0.0536 theta')."""
    env = PendulumSwingupEnv(**DCSC_MOPS)
    env.reset(seed=0)
    assert env.action_unit == "V" and env.action_levels == pytest.approx([-3, -2, -1, 0, 1, 2, 3])
    assert env.torque(3.0, 0.0) == pytest.approx(0.0536 / 9.5 * 3.0, rel=1e-12)
    assert env.torque(3.0, 5.0) == pytest.approx(0.0536 / 9.5 * (3.0 - 0.0536 * 5.0), rel=1e-12)
    assert env.torque(-2.0, -7.0) == pytest.approx(0.0536 / 9.5 * (-2.0 + 0.0536 * 7.0), rel=1e-12)
    assert env.max_torque == pytest.approx(3 * 0.0536 / 9.5) and env.max_torque < DCSC_M * GRAVITY * DCSC_L
    assert env.pivot_inertia == DCSC_J  # GRL integrates J theta'' = ..., J about the pivot


def test_a_voltage_step_follows_the_motor_equation():
    """Upright (no gravity torque at first) from rest with +3 V: J v' = (K/R) u - (b + K^2/R) v, so over a short step
    v(t) = (K u / (R c)) (1 - exp(-c t / J)) with c = b + K^2/R (gravity adds a relative 1e-4 within 1 ms)."""
    env = PendulumSwingupEnv(**{**DCSC_MOPS, "dt": 1e-3})
    env.reset(seed=0)
    env.set_state(0.0, 0.0)
    damping = DCSC_B + DCSC_K**2 / DCSC_R
    expected = DCSC_K * 3.0 / (DCSC_R * damping) * (1 - math.exp(-damping * 1e-3 / DCSC_J))
    observation, reward, *_ = env.step(6)
    assert observation[1] == pytest.approx(expected, rel=3e-4)
    assert reward == pytest.approx(-5 * observation[0] ** 2 - 0.1 * observation[1] ** 2 - 9.0)  # a^2 in volts


def test_without_zero_voltage_the_back_emf_brakes():
    env = PendulumSwingupEnv(**DCSC_MOPS)
    env.reset(seed=0)
    env.set_state(1.0, 0.0)
    energies = [env.energy()]
    for _ in range(200):
        env.step(ZERO_TORQUE)
        energies.append(env.energy())
    assert np.all(np.diff(energies) <= 1e-15) and energies[-1] < energies[0] - 1e-3


def test_the_dcsc_pendulum_can_be_swung_up_and_caught():
    """The same pump-and-catch controller as for Table 4.1's pendulum, in volts: the DCSC model is a swing-up task."""
    env = PendulumSwingupEnv(**DCSC_MOPS)
    observation, _ = env.reset(seed=0)
    gravity_torque = DCSC_M * GRAVITY * DCSC_L
    for _ in range(env.max_episode_steps):
        theta, velocity = observation
        if abs(theta) < 0.6:
            voltage = -(40.0 * theta + 2.0 * velocity)
        else:
            voltage = 3.0 * np.sign(velocity) if env.energy() < gravity_torque else 0.0
        observation, _, terminated, truncated, info = env.step(nearest_action(env, voltage))
        if terminated or truncated:
            break
    assert terminated and info["goal_reached"]


def test_without_goal_termination_episodes_run_to_the_time_limit():
    env = PendulumSwingupEnv(terminate_at_goal=False, episode_seconds=0.05)
    env.reset(seed=0)
    env.set_state(0.05, 0.0)
    _, _, terminated, truncated, info = env.step(ZERO_TORQUE)
    assert not terminated and not truncated and info["goal_reached"]
    for _ in range(4):
        _, _, terminated, truncated, _ = env.step(ZERO_TORQUE)
    assert not terminated and truncated


OPTION_COMBINATIONS = [
    {"inertia_about": inertia_about, "velocity_tile_width": width, "terminate_at_goal": goal, **actuation}
    for inertia_about in ("center_of_mass", "pivot")
    for width in (0.33, 1.0, 3.3)
    for goal in (True, False)
    for actuation in ({}, {"max_torque": 0.3}, {"actuation": "voltage", "mass": 0.055, "length": 0.042})
]


@pytest.mark.parametrize("kwargs", OPTION_COMBINATIONS, ids=lambda kwargs: "-".join(map(str, kwargs.values())))
def test_every_option_combination_passes_the_env_checkers(kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gymnasium.make("sb3_er/PendulumSwingup-v0", **kwargs).unwrapped)
        sb3_check_env(PendulumSwingupEnv(**kwargs))


def test_the_dcsc_preset_passes_the_env_checkers():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gymnasium.make("sb3_er/PendulumSwingup-v0", **DCSC_MOPS, render_mode="rgb_array").unwrapped)
        sb3_check_env(PendulumSwingupEnv(**DCSC_MOPS))


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"max_torque": 1.0}, "max_torque"),
        ({"max_torque": 0.0}, "max_torque"),
        ({"max_torque": float("inf")}, "max_torque"),
        ({"n_actions": 1}, "n_actions"),
        ({"n_actions": 2.5}, "n_actions"),
        ({"inertia_about": "cog"}, "inertia_about"),
        ({"inertia_about": None}, "inertia_about"),
        ({"velocity_tile_width": 0.0}, "velocity_tile_width"),
        ({"velocity_tile_width": -3.3}, "velocity_tile_width"),
        ({"velocity_tile_width": float("nan")}, "velocity_tile_width"),
        ({"velocity_tile_width": 1e-320}, "velocity_tile_width"),
        ({"velocity_tile_width": "3.3x"}, "velocity_tile_width"),
        ({"actuation": "current"}, "actuation"),
        ({"max_voltage": 3.0}, "max_voltage"),
        ({"motor_constant": 0.05}, "motor_constant"),
        ({"motor_resistance": 9.5}, "motor_resistance"),
        ({"actuation": "voltage", "max_torque": 0.5}, "max_torque"),
        ({"actuation": "voltage", "max_voltage": 0.0}, "max_voltage"),
        ({"actuation": "voltage", "motor_constant": -1.0}, "motor_constant"),
        ({"actuation": "voltage", "motor_resistance": float("inf")}, "motor_resistance"),
        ({**DCSC_MOPS, "max_voltage": 5.0}, "stall torque"),  # 0.0282 N m > m g l = 0.0227 N m
        ({"terminate_at_goal": "yes"}, "terminate_at_goal"),
        ({"reward_units": "rad"}, "reward_units"),
        ({"goal_velocity": 0.0}, "goal_velocity"),
        ({"goal_velocity": float("inf")}, "goal_velocity"),
        ({"integrator": "rk45"}, "integrator"),
        ({"inertia": 0.0}, "inertia"),
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

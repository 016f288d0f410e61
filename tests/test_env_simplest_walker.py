"""Simplest walker: physics against independent facts (Garcia's gait, impact geometry, pendulum falls), rewards, API."""

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
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT, GRL_TILE_WIDTHS, SimplestWalkerEnv, impact_manifold_state

SLOPE = 0.004
ZERO = 7  # index of hip acceleration 0 among the 15 levels


def stance_energy(state):
    """Energy of the hip mass on the stance leg, which Eq. 4.3 conserves between footsteps (unit mass, legs, g)."""
    return 0.5 * state[2] ** 2 + math.cos(state[0] - SLOPE)


def reference_derivative(x, hip_acceleration):
    """Eq. 4.3 written out again, for the fine-step reference integration."""
    stance, hip, stance_rate, hip_rate = x
    return np.array(
        [
            stance_rate,
            hip_rate,
            math.sin(stance - SLOPE),
            math.sin(hip) * (stance_rate**2 - math.cos(stance - SLOPE)) + math.sin(stance - SLOPE) + hip_acceleration,
        ]
    )


def reference_step(x, hip_acceleration, h):
    k1 = reference_derivative(x, hip_acceleration)
    k2 = reference_derivative(x + 0.5 * h * k1, hip_acceleration)
    k3 = reference_derivative(x + 0.5 * h * k2, hip_acceleration)
    k4 = reference_derivative(x + h * k3, hip_acceleration)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def reference_impact(x):
    """Eq. 4.4 as printed (matrix form)."""
    c = math.cos(2.0 * x[0])
    matrix = np.array([[-1, 0, 0, 0], [-2, 0, 0, 0], [0, 0, c, 0], [0, 0, c * (1 - c), 0]], dtype=float)
    return matrix @ x


def reference_control_step(before, dt, h=1e-5):
    """(heel-strike time, end state) of one control step with zero hip action from ``before``, by fine RK4 steps of
    Eq. 4.3 with the heel strike interpolated inside its fine step and Eq. 4.4 applied there (one heel strike)."""
    x = np.array(before, dtype=float)
    t = 0.0
    while True:
        x_next = reference_step(x, 0.0, h)
        gap, gap_next = x[1] - 2 * x[0], x_next[1] - 2 * x_next[0]
        if gap < 0.0 <= gap_next and x_next[0] < 0.0:
            fraction = -gap / (gap_next - gap)
            strike_time = t + fraction * h
            x = reference_impact(reference_step(x, 0.0, fraction * h))
            break
        x, t = x_next, t + h
        assert t < dt, "no heel strike in this control step"
    remaining = dt - strike_time
    n = int(round(remaining / h))
    for _ in range(n):
        x = reference_step(x, 0.0, remaining / n)
    return strike_time, x


PHYSICAL = dict(fall="hip", observation="thesis", start="impact")
"""Most tests here check the simulation itself: the hip-on-slope fall, the state of Eq. 4.2 as the observation and
starts on the impact manifold make its facts visible. The defaults are tested on their own."""


def walker(**kwargs):
    return SimplestWalkerEnv(**{**PHYSICAL, **kwargs})


def test_defaults_are_the_readings_rules():
    """The thesis's fall, observation and numbers; Schuitema's footstep reward; GRL's start redrawn until it steps."""
    env = SimplestWalkerEnv()
    assert (env.reward, env.fall, env.observation, env.start) == ("schuitema", "hip", "thesis", "grl_footstep")
    assert env.action_space.n == 15 and env.fall_reward == -50.0  # the thesis's numbers
    np.testing.assert_array_equal(env.tile_widths, [0.10, 0.10, 0.11, 0.21])  # Table 4.2
    assert env.initial_state_variation == 0.2
    observation, _ = env.reset(seed=0)
    s = env.state  # GRL's draw: each of Garcia's values times U[0.8, 1.2]
    assert np.all(np.abs(s / GARCIA_FIXED_POINT - 1.0) <= 0.2 + 1e-12)
    np.testing.assert_array_equal(observation, s)  # Eq. 4.2's state itself
    grl = SimplestWalkerEnv(fall="angles", observation="grl", start="grl")  # the earlier defaults, kept as options
    observation, _ = grl.reset(seed=0)
    s = grl.state
    np.testing.assert_allclose(observation, [s[0], s[1] - 2 * s[0], s[2], s[3] - 2 * s[2]])


def step_until_footstep(env, max_steps=40):
    """Step with zero hip acceleration until a heel strike and return its info; fail on a fall or after max_steps."""
    for _ in range(max_steps):
        _, _, terminated, _, info = env.step(ZERO)
        assert not terminated, "the walker fell before its first footstep"
        if info["footstep"]:
            return info
    pytest.fail(f"no footstep within {max_steps} control steps")


def test_spaces_and_thesis_parameters():
    env = walker()
    assert env.dt == 0.2
    np.testing.assert_array_equal(env.tile_widths, [0.10, 0.10, 0.11, 0.21])
    assert env.action_space.n == 15
    np.testing.assert_allclose(env.hip_accelerations, np.linspace(-1.2, 1.2, 15))
    assert env.hip_accelerations[ZERO] == 0.0
    assert env.observation_space.shape == (4,)
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    assert env.max_episode_steps == 500


def test_fixed_point_walks_100_steps_back_to_the_fixed_point():
    env = walker(episode_seconds=450.0)
    env.reset(options={"state": GARCIA_FIXED_POINT})
    expected_length = 2.0 * math.sin(0.1534)
    footsteps = 0
    for _ in range(env.max_episode_steps):
        _, _, terminated, truncated, info = env.step(ZERO)
        assert not terminated
        if info["footstep"]:
            footsteps += 1
            np.testing.assert_allclose(env.post_impact_state, GARCIA_FIXED_POINT, atol=1e-3)
            assert info["step_length"] == pytest.approx(expected_length, abs=1e-3)
        if truncated:
            break
    assert footsteps >= 100
    # The fixed point's swing rate is negative: Eq. 4.5's +0.0073 is a sign typo.
    assert env.post_impact_state[3] == pytest.approx(-0.0073, abs=2e-4)
    assert info["distance"] == pytest.approx(footsteps * expected_length, rel=1e-3)


def test_impact_keeps_the_hip_velocity_perpendicular_to_the_new_stance_leg():
    """Heel strike from Cartesian geometry: the impulse runs along the new stance leg, so only the hip's velocity
    component perpendicular to it survives, and the stance leg's energy drops by the factor cos^2(2 phi_st-)."""
    env = walker()
    start = np.array([-0.05, -0.35, -0.4, 0.2])  # past mid-stance, swing leg ahead: it lands within a few steps
    env.reset(options={"state": start})
    energy = stance_energy(start)
    info = step_until_footstep(env)
    post = env.post_impact_state
    before_stance = -post[0]
    before_rate = -math.sqrt(2.0 * (energy - math.cos(before_stance - SLOPE)))  # stance energy is conserved
    hip_velocity = before_rate * np.array([-math.cos(before_stance), -math.sin(before_stance)])
    new_foot = np.array([-2.0 * math.sin(before_stance), 0.0])
    hip = np.array([-math.sin(before_stance), math.cos(before_stance)])
    new_leg = (hip - new_foot) / np.linalg.norm(hip - new_foot)
    surviving = hip_velocity - (hip_velocity @ new_leg) * new_leg
    expected_rate = -np.linalg.norm(surviving)  # the new stance leg keeps rotating forward
    assert post[2] == pytest.approx(expected_rate, rel=1e-9)
    assert post[2] ** 2 / before_rate**2 == pytest.approx(math.cos(2.0 * before_stance) ** 2, rel=1e-9)
    assert post[3] == pytest.approx((1.0 - math.cos(2.0 * post[0])) * post[2], rel=1e-9)
    assert post[1] == pytest.approx(2.0 * post[0], abs=1e-12)
    assert info["step_length"] == pytest.approx(np.linalg.norm(new_foot), rel=1e-12)


def test_passive_gait_loses_at_impact_what_the_slope_gives():
    """On a periodic gait the kinetic energy lost at each heel strike equals the potential energy of one step down the
    slope, step_length * sin(mu)."""
    env = walker(episode_seconds=100.0)
    env.reset(options={"state": GARCIA_FIXED_POINT})
    for _ in range(env.max_episode_steps):
        _, _, _, truncated, info = env.step(ZERO)
        if truncated:
            break
    post = env.post_impact_state
    before_rate = post[2] / math.cos(2.0 * post[0])
    lost = 0.5 * (before_rate**2 - post[2] ** 2)
    assert lost == pytest.approx(2.0 * math.sin(post[0]) * math.sin(SLOPE), rel=1e-3)


def test_heel_strike_is_located_inside_the_control_step():
    env = walker()
    env.reset(options={"state": GARCIA_FIXED_POINT})
    for _ in range(40):
        before = env.state.copy()
        _, _, _, _, info = env.step(ZERO)
        if info["footstep"]:
            break
    strike_time = info["heel_strike_time"]
    assert 0.0 < strike_time < env.dt

    reference_time, x = reference_control_step(before, env.dt)
    assert strike_time == pytest.approx(reference_time, abs=1e-7)
    np.testing.assert_allclose(env.state, x, atol=1e-8)

    h = 1e-5
    # An impact moved to the end of the control step would land measurably elsewhere.
    x = before.copy()
    for _ in range(int(round(env.dt / h))):
        x = reference_step(x, 0.0, h)
    at_boundary = reference_impact(x)
    assert np.max(np.abs(at_boundary - env.state)) > 1e-3


def test_a_swing_foot_rising_out_of_the_slope_is_no_heel_strike():
    """Mid-stance scuffing: behind the stance foot's vertical, the swing foot below the slope (phi_h > 2 phi_st) and
    swinging forward rises through the surface; the symmetric-legs condition holds there, but nothing lands."""
    env = walker()
    start = np.array([-0.02, -0.03, -0.15, -0.5])

    def foot_height(state):
        return math.cos(state[0]) - math.cos(state[0] - state[1])

    assert foot_height(start) < 0.0
    env.reset(options={"state": start})
    _, _, _, _, info = env.step(ZERO)
    assert foot_height(env.state) > 0.0 and env.state[0] < 0.0
    assert not info["footstep"]


def pendulum_fall_time(stance_angle, stance_rate):
    """Time for the stance leg, an inverted pendulum (Eq. 4.3) moving away from the top without turning back, to reach
    |phi_st| = pi/2: the quadrature of dt = dphi / |phi_st'| with the rate from energy conservation."""
    energy = 0.5 * stance_rate**2 + math.cos(stance_angle - SLOPE)
    target = math.copysign(math.pi / 2, stance_rate)
    angles = np.linspace(stance_angle, target, 2_000_001)
    rates = np.sqrt(np.maximum(2.0 * (energy - np.cos(angles - SLOPE)), 0.0))
    middles = 0.5 * (rates[1:] + rates[:-1])
    return float(np.sum(np.abs(np.diff(angles)) / middles))


@pytest.mark.parametrize("reading", ["schuitema", "literal"])
@pytest.mark.parametrize(
    "start, side",
    [
        (np.array([0.15, 0.30, -0.5, 0.0]), -1.0),  # too fast: the stance leg falls forward before the swing leg lands
        (np.array([0.15, 0.30, 0.3, 0.0]), 1.0),  # rotating backwards: falls back over the heel
    ],
)
def test_fall_ends_the_episode_with_minus_50(start, side, reading):
    env = walker(reward=reading)
    env.reset(options={"state": start})
    rewards = []
    for _ in range(env.max_episode_steps):
        observation, reward, terminated, truncated, info = env.step(ZERO)
        rewards.append(reward)
        if terminated:
            break
    assert terminated and not truncated and info["fell"]
    assert reward == -50.0
    assert all(r == -1.0 for r in rewards[:-1])
    assert observation[0] == pytest.approx(side * math.pi / 2, abs=1e-12)
    expected_steps = math.ceil(pendulum_fall_time(start[0], start[2]) / env.dt)
    assert len(rewards) == expected_steps
    with pytest.raises(RuntimeError, match="reset"):
        env.step(ZERO)


def test_literal_reading_pays_50_per_unit_step_length_and_minus_1_per_step():
    env = walker(reward="literal")
    env.reset(options={"state": GARCIA_FIXED_POINT})
    total = 0.0
    for step in range(env.max_episode_steps):  # noqa: B007 (the count is checked after the loop)
        _, reward, terminated, truncated, info = env.step(ZERO)
        total += reward
        if info["footstep"]:
            assert info["segment_end"]
            assert info["step_length"] == pytest.approx(2.0 * math.sin(env.post_impact_state[0]), rel=1e-12)
            assert reward == pytest.approx(-1.0 + 50.0 * info["step_length"], rel=1e-12)
        else:
            assert reward == -1.0 and info["step_length"] == 0.0 and not info["segment_end"]
        if truncated:
            break
    assert not terminated and truncated and step + 1 == 500
    assert total == pytest.approx(-500.0 + 50.0 * info["distance"], rel=1e-12)
    assert info["distance"] > 7.0  # about 25 steps of 0.306


def test_hip_action_is_an_added_hip_acceleration_and_leaves_the_stance_leg_alone():
    h = 1e-3
    env = walker(dt=h, substeps=1)
    state = np.array([0.1, 0.25, -0.2, 0.1])
    results = {}
    for action in (0, ZERO, 14):
        env.reset(options={"state": state})
        env.step(action)
        results[action] = env.state.copy()
    for action, u in ((0, -1.2), (14, 1.2)):
        np.testing.assert_array_equal(results[action][[0, 2]], results[ZERO][[0, 2]])
        assert results[action][3] - results[ZERO][3] == pytest.approx(u * h, rel=1e-5)
    expected = reference_derivative(state, 0.0)
    np.testing.assert_allclose((results[ZERO] - state) / h, expected, atol=5e-3)


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), variation=st.sampled_from([0.1, SimplestWalkerEnv.max_initial_state_variation]))
def test_every_random_start_takes_a_step_without_actuation(seed, variation):
    env = walker(initial_state_variation=variation)
    observation, _ = env.reset(seed=seed)
    assert observation[1] == pytest.approx(2.0 * observation[0], abs=1e-15)
    surplus = stance_energy(observation) - 1.0
    assert 0.4 * 0.00105 - 1e-12 <= surplus <= 1.6 * 0.00105 + 1e-12
    step_until_footstep(env)


@pytest.mark.parametrize("seed", range(20))
def test_every_default_start_makes_a_passive_footstep(seed):
    """Thesis 4.2.2: "the walker always has enough energy to start walking": from the default start of each of seeds
    0-19, a zero-action episode under the default fall test makes at least one footstep."""
    env = SimplestWalkerEnv()
    env.reset(seed=seed)
    step_until_footstep(env)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), reading=st.sampled_from([{}, {"fall": "hip", "observation": "thesis"}]))
def test_grl_starts_redrawn_until_they_step_all_step(seed, reading):
    env = SimplestWalkerEnv(start="grl_footstep", **reading)
    env.reset(seed=seed)
    assert np.all(np.abs(env.state / GARCIA_FIXED_POINT - 1.0) <= 0.2 + 1e-12)  # still GRL's U[0.8, 1.2] draw
    step_until_footstep(env)


def test_a_start_without_enough_energy_makes_no_passive_footstep():
    env = SimplestWalkerEnv(start="grl_footstep")
    # the stance leg's energy 0.05^2 / 2 + cos(0.1534) = 0.98951 < cos(mu): it swings back and falls
    assert not env.makes_passive_footstep([0.1534, 0.3068, -0.05, -0.0073])
    assert env.makes_passive_footstep(GARCIA_FIXED_POINT)
    grl = SimplestWalkerEnv(start="grl")  # seed 0's GRL draw falls before its first footstep without actuation
    grl.reset(seed=0)
    assert not env.makes_passive_footstep(grl.state)
    for _ in range(40):
        _, _, terminated, _, info = grl.step(ZERO)
        assert not info["footstep"]
        if terminated:
            break
    assert terminated


@pytest.mark.parametrize("stance_scale", [0.8, 1.0, 1.2])
@pytest.mark.parametrize("surplus", [0.4, 1.0, 1.6])
def test_the_start_distribution_edges_take_a_step(stance_scale, surplus):
    start = impact_manifold_state(0.1534 * stance_scale, 1.0 + surplus * 0.00105)
    env = walker()
    env.reset(options={"state": start})
    step_until_footstep(env)


def test_reset_is_reproducible_and_varies_with_the_seed():
    env = walker()
    first, _ = env.reset(seed=3)
    again, _ = env.reset(seed=3)
    other, _ = env.reset(seed=4)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    fixed, _ = walker(initial_state_variation=0.0).reset(seed=3)
    np.testing.assert_array_equal(fixed, GARCIA_FIXED_POINT)


def test_random_hip_actions_make_the_walker_fall():
    env = walker()
    falls = 0
    rng = np.random.default_rng(0)
    for episode in range(5):
        env.reset(seed=episode)
        while True:
            _, _, terminated, truncated, _ = env.step(int(rng.integers(15)))
            if terminated or truncated:
                falls += terminated
                break
    assert falls == 5


@pytest.mark.parametrize("reading", ["schuitema", "literal"])
@pytest.mark.parametrize("fall", ["hip", "angles"])
@pytest.mark.parametrize("observation", ["thesis", "grl"])
def test_gymnasium_and_sb3_env_checkers_pass(reading, fall, observation):
    options = dict(reward=reading, fall=fall, observation=observation)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gym.make("sb3_er/SimplestWalker-v0", render_mode="rgb_array", **options).unwrapped)
        sb3_check_env(walker(**options))


def test_render_draws_legs_on_the_slope():
    env = walker(render_mode="rgb_array")
    env.reset(options={"state": GARCIA_FIXED_POINT})
    image = env.render()
    assert image.shape == (240, 320, 3) and image.dtype == np.uint8
    colours = {tuple(c) for c in image.reshape(-1, 3)}
    assert {(40, 80, 200), (200, 60, 40), (0, 0, 0), (170, 150, 120)} <= colours
    for _ in range(5):
        env.step(ZERO)
    assert not np.array_equal(env.render(), image)
    with pytest.warns(UserWarning, match="render_mode"):
        assert walker().render() is None


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"dt": 0.0}, "dt"),
        ({"substeps": 0}, "substeps"),
        ({"n_actions": 2.5}, "n_actions"),
        ({"initial_state_variation": 0.5}, "initial_state_variation"),
        ({"slope": -0.1}, "slope"),
        ({"render_mode": "human"}, "render_mode"),
        ({"reward": "thesis"}, "reward must be one of 'schuitema', 'literal'"),
        ({"fall": "torso"}, "fall must be one of 'hip', 'angles'"),
        ({"start": "garcia"}, "start must be one of 'grl_footstep', 'grl', 'impact'"),
        ({"observation": "state"}, "observation must be one of 'thesis', 'grl'"),
        ({"observation": None}, "observation must be one of"),
        ({"step_reward_cap": math.nan}, "step_reward_cap"),
    ],
)
def test_bad_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        walker(**kwargs)


def test_bad_actions_and_states_are_named():
    env = walker()
    env.reset(seed=0)
    for action in (15, -1, 2.5):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": [0.1, 0.2, 0.3]})
    with pytest.raises(ValueError, match="outside"):
        env.reset(options={"state": [2.0, 0.2, 0.3, 0.0]})
    with pytest.raises(ValueError, match="options"):
        env.reset(options={"stance": 0.1})
    with pytest.raises(ValueError, match="energy"):
        impact_manifold_state(0.15, 0.5)


# --- Reward readings -------------------------------------------------------------------------------------------------


def passive_walk(env, steps):
    """Zero hip action from Garcia's fixed point: per control step (state before, reward, state after, info)."""
    env.reset(options={"state": GARCIA_FIXED_POINT})
    records = []
    for _ in range(steps):
        before = env.state.copy()
        _, reward, terminated, truncated, info = env.step(ZERO)
        assert not terminated
        records.append((before, reward, env.state.copy(), dict(info, post_impact_state=env.post_impact_state.copy())))
        if truncated:
            break
    return records


def test_schuitema_footstep_reward_replaces_minus_1_and_reads_the_stance_angle_at_the_end_of_the_step():
    """Hand computation: integrate the control step of a footstep with fine RK4 steps, apply Eq. 4.4 at the heel
    strike, integrate to the end of the control step and pay min(50 * 4 sin(phi_st), 30) from that end state."""
    env = walker()
    records = passive_walk(env, 400)
    footsteps = [r for r in records if r[3]["footstep"]]
    assert all(reward == -1.0 for _, reward, _, info in records if not info["footstep"])
    capped = [r for r in footsteps if 200.0 * math.sin(r[2][0]) > 30.0]
    uncapped = [r for r in footsteps if 200.0 * math.sin(r[2][0]) < 29.0]
    assert capped and uncapped  # the heel strike drifts through the control step from footstep to footstep
    for before, reward, _, _ in (capped[0], uncapped[0]):
        _, end = reference_control_step(before, env.dt)
        assert reward == pytest.approx(min(50.0 * 4.0 * math.sin(end[0]), 30.0), abs=1e-5)
    assert capped[0][1] == 30.0
    _, reward, _, info = uncapped[0]
    # Not read right after the impact, and not added to the step's -1.
    assert abs(reward - 200.0 * math.sin(info["post_impact_state"][0])) > 0.1
    assert 24.0 < reward < 30.0


def test_schuitema_reward_parameters():
    env = walker(step_reward=25.0, step_reward_cap=math.inf, time_reward=-2.0)
    records = passive_walk(env, 100)
    assert any(info["footstep"] for *_, info in records)
    for _, reward, after, info in records:
        assert reward == (pytest.approx(100.0 * math.sin(after[0]), rel=1e-12) if info["footstep"] else -2.0)
    assert walker().step_reward_cap == 30.0


def test_literal_reading_caps_only_when_asked():
    assert walker(reward="literal").step_reward_cap == math.inf
    for _, reward, _, info in passive_walk(walker(reward="literal", step_reward_cap=10.0), 100):
        assert reward == (9.0 if info["footstep"] else -1.0)


@pytest.mark.parametrize("reading", ["schuitema", "literal"])
def test_passive_walking_earns_a_positive_return_per_footstep_only_under_schuitemas_reward(reading):
    """Garcia's passive gait takes a footstep every 19 or 20 control steps (period about 3.85). After the impact the
    new stance angle 0.1534 shrinks by at most 0.2 * 0.17 before the control step ends, so Schuitema's footstep pays
    between 200 sin(0.1194) = 23.8 and the cap 30, and a footstep's segment (18 or 19 steps of -1, then the footstep)
    returns between 23.8 - 19 = 4.8 and 30 - 18 = 12. Literally, a footstep of 2 sin(0.1534) = 0.3055 pays
    -1 + 15.27, and the segment returns -19 + 15.27 or -20 + 15.27: walking loses."""
    records = passive_walk(walker(reward=reading), 500)
    segments, segment_return, segment_steps = [], 0.0, 0
    for _, reward, _, info in records:
        segment_return += reward
        segment_steps += 1
        if info["footstep"]:
            segments.append((segment_steps, segment_return))
            segment_return, segment_steps = 0.0, 0
    assert len(segments) >= 25
    step_length = 2.0 * math.sin(0.1534)
    for steps, ret in segments:
        assert steps in (19, 20)
        if reading == "schuitema":
            assert 200.0 * math.sin(0.1534 - 0.2 * 0.17) - (steps - 1) <= ret <= 30.0 - (steps - 1)
            assert ret > 0.0
        else:
            assert ret == pytest.approx(-steps + 50.0 * step_length, abs=0.05)
            assert ret < 0.0


def test_a_dive_beats_walking_only_under_the_literal_reading():
    """A constant hip action of -0.51 throws the swing leg far forward: one long step, then a fall. Literally that
    returns about -5 against about -118 for 100 s of passive walking; under Schuitema's reward the dive is worse."""
    returns = {}
    for reading in ("schuitema", "literal"):
        for label, action in (("dive", 4), ("walk", ZERO)):
            env = walker(reward=reading)
            env.reset(options={"state": GARCIA_FIXED_POINT})
            total, footsteps = 0.0, 0
            while True:
                _, reward, terminated, truncated, info = env.step(action)
                total += reward
                footsteps += info["footstep"]
                if terminated or truncated:
                    break
            if label == "dive":
                assert terminated and footsteps == 1 and info["distance"] > 1.0
            returns[reading, label] = total
    assert returns["literal", "dive"] > returns["literal", "walk"]
    assert returns["literal", "walk"] == pytest.approx(-500.0 + 50.0 * 7.64, abs=1.0)
    assert returns["schuitema", "walk"] > 0.0 > returns["schuitema", "dive"]


# --- Fall criteria ---------------------------------------------------------------------------------------------------


def gap(state):
    return state[1] - 2.0 * state[0]


@pytest.mark.parametrize(
    "state, falls",
    [
        ([0.40, 0.80, 0.05, 0.10], True),  # stance leg beyond pi/8, rotating further back
        ([-0.41, -0.82, -0.05, -0.10], True),  # ... and forward
        ([0.10, 1.10, 0.0, 0.0], True),  # legs 0.9 from symmetric (gap beyond pi/4)
        ([0.10, -0.70, 0.0, 0.0], True),  # ... the other way
        ([0.10, 0.90, 0.0, 1.0], True),  # gap 0.7 inside at the start, opening to about 0.89 by the step's end
        ([0.10, 1.05, 0.0, -1.5], False),  # gap 0.85 outside at the start, closing to about 0.53: checked at the end
        ([0.30, 0.80, 0.0, 0.0], False),  # inside both limits
    ],
)
def test_grl_fall_angles_are_checked_at_the_end_of_the_control_step(state, falls):
    env = walker(fall="angles")
    env.reset(options={"state": state})
    _, reward, terminated, truncated, info = env.step(ZERO)
    end = env.state
    assert (abs(end[0]) > math.pi / 8 or abs(gap(end)) > math.pi / 4) == falls
    assert terminated == info["fell"] == falls and not truncated
    assert reward == (-50.0 if falls else -1.0)
    hip_env = walker(fall="hip")
    hip_env.reset(options={"state": state})
    _, _, terminated, _, _ = hip_env.step(ZERO)
    assert not terminated  # the hip is far from the slope


@settings(max_examples=100, deadline=None)
@given(
    stance=st.floats(-0.5, 0.5),
    leg_gap=st.floats(-1.2, 1.2),
    stance_rate=st.floats(-1.0, 1.0),
    gap_rate=st.floats(-3.0, 3.0),
)
def test_grl_fall_is_the_angle_test_on_the_end_state(stance, leg_gap, stance_rate, gap_rate):
    state = [stance, leg_gap + 2.0 * stance, stance_rate, gap_rate + 2.0 * stance_rate]
    env = walker(fall="angles", fall_reward=-7.0)
    env.reset(options={"state": state})
    _, reward, terminated, _, _ = env.step(ZERO)
    end = env.state
    expected = abs(end[0]) > math.pi / 8 or abs(gap(end)) > math.pi / 4
    assert terminated == expected
    assert (reward == -7.0) == expected


def test_hip_on_the_slope_is_a_fall_under_both_criteria():
    for fall in ("hip", "angles"):
        env = walker(fall=fall)
        env.reset(options={"state": [1.4, 2.8, 1.5, 0.0]})  # rotating back hard: the hip hits the slope in the step
        _, reward, terminated, _, info = env.step(ZERO)
        assert terminated and info["fell"] and reward == -50.0
        assert env.state[0] == pytest.approx(math.pi / 2, abs=1e-12)


# --- Observations and info -------------------------------------------------------------------------------------------


def test_grl_observation_coordinates_by_hand():
    env = walker(observation="grl")
    np.testing.assert_array_equal(env.tile_widths, [0.10, 0.10, 0.11, 0.21])  # Table 4.2's, whichever coordinates
    grl = walker(observation="grl", tile_widths=GRL_TILE_WIDTHS)
    np.testing.assert_array_equal(grl.tile_widths, [0.0838, 0.1047, 0.1111, 0.2222])
    assert env.wrap_periods is None
    np.testing.assert_allclose(env.observation_space.high, [math.pi / 2, 2 * math.pi, 5.0, 60.0])
    observation, _ = env.reset(options={"state": [0.12, 0.31, -0.2, 0.4]})
    np.testing.assert_allclose(observation, [0.12, 0.07, -0.2, 0.8], rtol=0, atol=1e-15)
    observation, _ = env.reset(options={"state": GARCIA_FIXED_POINT})
    np.testing.assert_allclose(observation, [0.1534, 0.0, -0.1561, -0.0073 + 0.3122], rtol=0, atol=1e-15)
    for _ in range(60):
        observation, _, _, _, info = env.step(ZERO)
        s = env.state
        np.testing.assert_allclose(observation, [s[0], s[1] - 2 * s[0], s[2], s[3] - 2 * s[2]], rtol=0, atol=1e-15)
        if info["footstep"]:
            assert abs(observation[1]) < 0.05  # legs symmetric at the heel strike, a little apart by the step's end
    thesis = walker()
    assert thesis.wrap_periods is None
    np.testing.assert_array_equal(thesis.tile_widths, [0.10, 0.10, 0.11, 0.21])
    observation, _ = thesis.reset(options={"state": [0.12, 0.31, -0.2, 0.4]})
    np.testing.assert_array_equal(observation, [0.12, 0.31, -0.2, 0.4])


@pytest.mark.parametrize("observation", ["thesis", "grl"])
def test_rates_beyond_the_bounds_are_clipped(observation):
    env = walker(observation=observation)
    env.reset(options={"state": [0.0, 0.2, -4.99, 0.0]})  # about to fall forward fast
    observation_values, *_ = env.step(14)
    s = env.state
    assert s[2] < -5.0 and env.observation_space.contains(observation_values)
    hip, hip_rate = (s[1], s[3]) if observation == "thesis" else (s[1] - 2 * s[0], s[3] - 2 * s[2])
    np.testing.assert_allclose(observation_values, [s[0], hip, -5.0, hip_rate], rtol=0, atol=1e-15)


def test_swing_foot_height_from_the_geometry_of_two_unit_legs():
    def height(state):
        stance, hip = state[0], state[1]
        hip_point = np.array([-math.sin(stance), math.cos(stance)])  # stance foot at the origin, y along the normal
        swing_angle = stance - hip  # absolute angle of the swing leg
        foot = hip_point + np.array([math.sin(swing_angle), -math.cos(swing_angle)])
        return foot[1]

    env = walker()
    _, info = env.reset(options={"state": [0.1, 0.5, 0.0, 0.0]})
    assert info["swing_foot_height"] == pytest.approx(math.cos(0.1) - math.cos(0.4), rel=1e-12)
    _, info = env.reset(options={"state": GARCIA_FIXED_POINT})
    assert info["swing_foot_height"] == pytest.approx(0.0, abs=1e-15)  # legs symmetric: both feet on the slope
    heights = []
    for _ in range(40):
        _, _, _, _, info = env.step(ZERO)
        assert info["swing_foot_height"] == pytest.approx(height(env.state), abs=1e-14)
        heights.append(info["swing_foot_height"])
    assert min(heights) < 0.001 < 0.01 < max(heights)  # grazes the slope at mid-stance, swings clear before landing

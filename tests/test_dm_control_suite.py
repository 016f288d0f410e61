"""Every task of dm_control's suite by id: a domain's tiling for its tasks, derived tilings for the others, the clear
refusals (more than 3 action dimensions, unlimited actuators), lqr's reward bounds, and the full sweep."""

import importlib.util
import pickle
import re
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

# Skip without importing dm_control at collection (it picks its OpenGL backend once, when first imported).
if importlib.util.find_spec("shimmy") is None or importlib.util.find_spec("dm_control") is None:
    pytest.skip("the dm_control ids need the dmc extra", allow_module_level=True)

from sb3_er import ERSigma, SarsaLambda  # noqa: E402
from sb3_er.common import dm_control_tilings  # noqa: E402
from sb3_er.common.dict_observations import (  # noqa: E402
    DM_CONTROL_REWARD_BOUNDS,
    RegisteredEntryPoint,
    dm_control_reward_bounds,
    is_image,
    register_dm_control_envs,
)
from sb3_er.common.dm_control_tilings import DerivedTilingWarning  # noqa: E402
from sb3_er.common.tile_coding import package_tilings  # noqa: E402

SMALL = dict(n_tilings=2, memory_size=2**12)
SWEEP = Path(__file__).resolve().parents[1] / "benchmarks" / "dmc_suite.py"


def build(cls, env_id, **kwargs):
    """A model of ``env_id`` and the DerivedTilingWarnings its construction gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = cls("TileQ", env_id, seed=0, **kwargs)
    return model, [w for w in caught if issubclass(w.category, DerivedTilingWarning)]


# --- a domain's tiling serves its tasks ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("env_id", "shipped"),
    [
        ("dm_control/cartpole-balance-v0", "dm_control/cartpole-swingup-v0"),
        ("dm_control/cartpole-balance_sparse-v0", "dm_control/cartpole-swingup-v0"),
        ("dm_control/cartpole-swingup_sparse-v0", "dm_control/cartpole-swingup-v0"),
        ("dm_control/acrobot-swingup_sparse-v0", "dm_control/acrobot-swingup-v0"),
    ],
)
def test_a_task_observing_what_its_domains_shipped_task_observes_gets_that_tiling(env_id, shipped):
    model, derived = build(SarsaLambda, env_id)
    entry = package_tilings()[shipped]
    np.testing.assert_allclose(model.policy.tile_coder.tile_widths, entry["tile_widths"])
    assert model.policy.tile_coder.n_tilings == entry["n_tilings"] and not derived
    # the layout really is the shipped one: dm_control's cart-pole observes the cart's x and the pole's (cos, sin),
    # then both velocities, in every task with one pole (dm_control/suite/cartpole.py)
    assert gym.make(env_id).observation_space.spaces.keys() == gym.make(shipped).observation_space.spaces.keys()


def test_a_task_with_another_layout_in_the_same_domain_gets_a_derived_tiling():
    """cartpole-two_poles observes 2 poles: position (5) and velocity (3), not the swing-up's 3 and 2."""
    model, derived = build(SarsaLambda, "dm_control/cartpole-two_poles-v0", policy_kwargs=dict(SMALL))
    assert model.policy.tile_coder.n_dims == 8 and len(derived) == 1
    assert "[['position', 5], ['velocity', 3]]" in str(derived[0].message)


# --- a derived tiling -------------------------------------------------------------------------------------------------


def _documented_rollout(env_id: str, levels: list[float], action_dims: int) -> np.ndarray:
    """The rollout the module documents: 3 episodes of at most 1,000 steps, reset with seeds 0, 1, 2, each step a
    uniformly random level per action dimension drawn by numpy's default_rng(0)."""
    env = gym.wrappers.FlattenObservation(gym.make(env_id))
    rng = np.random.default_rng(0)
    rows = []
    for episode in range(3):
        observation, _ = env.reset(seed=episode)
        rows.append(observation)
        for _ in range(1000):
            action = np.array([rng.choice(levels) for _ in range(action_dims)])
            observation, _, terminated, truncated, _ = env.step(action)
            rows.append(observation)
            if terminated or truncated:
                break
    return np.asarray(rows)


def test_a_task_without_a_shipped_tiling_gets_k_tiles_over_its_observed_ranges_and_a_warning_to_pin_them():
    env_id = "dm_control/point_mass-easy-v0"  # 4 dimensions (position 2, velocity 2), 2 actuators in [-1, 1]
    dm_control_tilings._DERIVED.clear()
    model, derived = build(ERSigma, env_id, policy_kwargs=dict(SMALL))
    observations = _documented_rollout(env_id, list(np.linspace(-1.0, 1.0, 7)), 2)
    # the generic rule for 4 dimensions: min(10, floor(16384 ** (1 / 4))) = min(10, 11) = 10 tiles over each range
    ranges = observations.max(axis=0) - observations.min(axis=0)
    np.testing.assert_allclose(model.policy.tile_coder.tile_widths, ranges / 10, rtol=1e-3)

    assert len(derived) == 1
    message = str(derived[0].message)
    printed = [float(w) for w in re.search(r"tile_widths=\[([^\]]*)\]", message).group(1).split(",")]
    assert printed == list(model.policy.tile_coder.tile_widths) and "10 tiles" in message
    assert "[['position', 2], ['velocity', 2]]" in message and "3003 observations" in message

    # the same tiling again, from a fresh rollout; pinning the printed widths rebuilds it without a rollout
    dm_control_tilings._DERIVED.clear()
    again, _ = build(ERSigma, env_id, policy_kwargs=dict(SMALL))
    np.testing.assert_array_equal(again.policy.tile_coder.tile_widths, model.policy.tile_coder.tile_widths)
    pinned, derived = build(ERSigma, env_id, policy_kwargs=dict(SMALL, tile_widths=printed))
    np.testing.assert_array_equal(pinned.policy.tile_coder.tile_widths, model.policy.tile_coder.tile_widths)
    assert not derived


def test_the_rollout_acts_with_the_models_own_levels():
    env_id = "dm_control/point_mass-easy-v0"
    dm_control_tilings._DERIVED.clear()
    model, _ = build(SarsaLambda, env_id, policy_kwargs=dict(SMALL, action_bins=2))  # pushes of -1 and 1 only
    observations = _documented_rollout(env_id, [-1.0, 1.0], 2)
    ranges = observations.max(axis=0) - observations.min(axis=0)
    np.testing.assert_allclose(model.policy.tile_coder.tile_widths, ranges / 10, rtol=1e-3)


# --- what stays refused -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", ["dm_control/cheetah-run-v0", "dm_control/manipulator-bring_ball-v0"])
def test_more_than_3_action_dimensions_keep_the_action_bins_error_and_run_no_rollout(env_id):
    with pytest.raises(ValueError, match=r"dimensions would get 7\^\d = \d+ joint actions.*action_bins=3"):
        build(SarsaLambda, env_id)
    assert not [key for key in dm_control_tilings._DERIVED if key[0] == env_id]


def test_a_small_array_of_state_in_the_dict_is_flattened_and_only_images_are_refused():
    """manipulator's arm_pos holds the cos and sin of 8 joints, an (8, 2) array of floats: state, not pixels."""
    assert not is_image(spaces.Box(-np.inf, np.inf, (8, 2)))
    assert not is_image(spaces.Box(-1, 1, (5,)))
    assert is_image(spaces.Box(0, 255, (84, 84, 3), np.uint8))
    assert is_image(spaces.Box(0, 255, (84, 84), np.uint8))  # grayscale
    assert is_image(spaces.Box(0.0, 1.0, (64, 64)))  # a picture of floats
    assert is_image(spaces.Box(0, 255, (4, 2), np.uint8))  # integers in two dimensions are pixels
    model, derived = build(
        SarsaLambda, "dm_control/manipulator-bring_ball-v0", policy_kwargs=dict(SMALL, action_bins=2)
    )
    assert model.policy.tile_coder.n_dims == 16 + 8 + 4 + 4 + 3 + 4 + 5 and len(derived) == 1


def test_unlimited_actuators_ask_for_action_values():
    """lqr's motors have no control range: MuJoCo reports +-1e10 (mjMAXVAL), and 7 levels between them would push
    with forces of 3e9 that blow the simulation up."""
    import mujoco

    assert gym.make("dm_control/lqr-lqr_2_1-v0").action_space.high[0] == mujoco.mjMAXVAL
    with pytest.raises(ValueError, match=r"unbounded.*MuJoCo's 1e10.*action_values"):
        build(SarsaLambda, "dm_control/lqr-lqr_2_1-v0")


# --- rewards ----------------------------------------------------------------------------------------------------------


def test_lqr_rewards_one_minus_a_quadratic_cost_unbounded_below():
    """dm_control/suite/lqr.py: r = 1 - (|q|^2 / 2 + 0.1 |u|^2 / 2), computed here from the observed position and the
    force applied; a strong push drives it below 0, and it never exceeds 1."""
    register_dm_control_envs()
    env = gym.make("dm_control/lqr-lqr_2_1-v0")
    env.reset(seed=0)
    rewards = []
    for force in [20.0] * 30 + [0.0] * 10:
        observation, reward, *_ = env.step(np.array([force]))
        q = observation["position"]
        assert reward == pytest.approx(1.0 - (0.5 * q @ q + 0.1 * 0.5 * force**2))
        rewards.append(reward)
    assert min(rewards) < 0.0 and max(rewards) <= 1.0
    assert dm_control_reward_bounds("dm_control/lqr-lqr_2_1-v0") == {
        "step": (-np.inf, 1.0),
        "terminal": (-np.inf, 1.0),
    }


def test_lqr_learns_with_action_values_and_its_values_are_bounded_above_only():
    model, _ = build(ERSigma, "dm_control/lqr-lqr_2_1-v0", policy_kwargs=dict(SMALL, action_values=[[-1, 0, 1]]))
    assert model._watch.source == "env" and model.value_bounds == (-np.inf, pytest.approx(100.0))  # 1 / (1 - 0.99)
    model.learn(1_100)
    assert model.num_timesteps == 1_100 and np.all(np.isfinite(model.policy.theta_array))


@pytest.mark.parametrize(
    "env_id",
    ["dm_control/cartpole-balance-v0", "dm_control/ball_in_cup-catch-v0", "dm_control/humanoid_CMU-run-v0"],
)
def test_other_suite_tasks_reward_in_the_unit_interval_and_ids_outside_the_suite_declare_nothing(env_id):
    register_dm_control_envs()
    assert dm_control_reward_bounds(env_id) == DM_CONTROL_REWARD_BOUNDS
    assert dm_control_reward_bounds("dm_control/CmuHumanoidRunWalls-v0") is None  # shimmy's locomotion: not the suite
    assert dm_control_reward_bounds("Pendulum-v1") is None


# --- specs that pickle --------------------------------------------------------------------------------------------


def test_a_suite_spec_pickles_and_makes_its_env_in_a_process_that_registered_nothing():
    register_dm_control_envs()
    spec = gym.spec("dm_control/cartpole-balance-v0")
    assert spec.entry_point == RegisteredEntryPoint("dm_control/cartpole-balance-v0")
    env = gym.make("dm_control/cartpole-balance-v0")
    data = pickle.dumps(env.spec)
    probe = (
        "import pickle, sys, gymnasium as gym\n"
        "spec = pickle.loads(sys.stdin.buffer.read())\n"
        "assert 'dm_control/cartpole-balance-v0' not in gym.registry\n"
        "env = gym.make(spec)\n"
        "print(sorted(env.observation_space.spaces), env.action_space.shape)\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], input=data, capture_output=True, timeout=300)
    assert result.returncode == 0, result.stderr.decode()[-2000:]
    assert result.stdout.decode().strip().splitlines()[-1] == "['position', 'velocity'] (1,)"


# --- the sweep --------------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_every_task_of_the_suite_learns_or_is_refused_as_its_action_spec_says(tmp_path):
    """benchmarks/dmc_suite.py over suite.ALL_TASKS (about a minute and a half): the tasks with up to 3
    action dimensions, each with a control range, build, learn 1,000 steps, save, load and predict; the others raise
    the error naming action_bins (more than 3) or action_values (lqr's unlimited motors). The expectation here is
    counted from dm_control's own action specs."""
    from dm_control import suite

    command = [sys.executable, str(SWEEP), "--out", str(tmp_path)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert (tmp_path / "summary.md").read_text() == result.stdout  # the printed table, written at the end
    rows = {
        cells[0]: cells[3]
        for line in result.stdout.splitlines()
        if line.startswith("| ") and not line.startswith("| task")
        for cells in [[cell.strip() for cell in line.strip("|").split("|")]]
    }
    expected = {}
    for domain, task in suite.ALL_TASKS:
        spec = suite.load(domain, task).action_spec()
        unlimited = np.any(np.abs(spec.maximum) >= 1e10)
        expected[f"{domain}-{task}"] = (
            "action_bins" if spec.shape[0] > 3 else "action_values" if unlimited else "learns"
        )
        if unlimited and spec.shape[0] <= 3:
            expected[f"{domain}-{task} with action_values -1, 0, 1"] = "learns"
    assert rows == expected

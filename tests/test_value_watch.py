"""The value watch: the possible returns of each env, the kernels' figures, and what learn does when values leave
them."""

import functools
import math
import operator
import warnings

import gymnasium as gym
import kernel_bundles as bundles
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sb3_er_envs  # noqa: F401  (registers the env ids)
from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, SarsaLambda
from sb3_er.common import kernels
from sb3_er.common.base_class import ValueBoundWarning
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.tile_coding import TileCoder
from sb3_er.common.value_bounds import RewardBounds, ValueBoundError, margin, reward_changing_wrapper, widened
from sb3_er_envs.leo.gym_env import LeoEnv
from sb3_er_envs.pendulum import PendulumSwingupEnv
from sb3_er_envs.simplest_walker import SimplestWalkerEnv
from sb3_er_envs.windy_cliff import WindyCliffEnv

# --- the bound formula against hand computations --------------------------------------------------------------------


def test_cartpole_returns():
    """CartPole pays +1 on every step, the terminating one too: returns lie in [1, 1 / (1 - gamma)]."""
    assert RewardBounds((1.0, 1.0), (1.0, 1.0)).returns(0.99) == pytest.approx((1.0, 100.0))


def test_mountain_car_returns():
    """MountainCar pays -1 on every step, the goal's too: [-1 / (1 - gamma), -1]."""
    assert RewardBounds((-1.0, -1.0), (-1.0, -1.0)).returns(0.99) == pytest.approx((-100.0, -1.0))


def test_grid_world_returns():
    """-1 per step, -50 for the cliff and 0..50 at the goal, gamma 0.98: min(-50, -50) and max(-50, 50)."""
    env = WindyCliffEnv()
    assert RewardBounds.from_attribute(env.reward_bounds).returns(0.98) == pytest.approx((-50.0, 50.0))


def test_walker_returns():
    """Schuitema's reward: -1, footsteps at most min(50 * 4, 30) = 30 (at least -200 when phi_st < 0), a fall -50;
    gamma 0.99: no return above 30 / 0.01 = 3000."""
    bounds = RewardBounds.from_attribute(SimplestWalkerEnv().reward_bounds)
    assert bounds.step == (-200.0, 30.0) and bounds.terminal == (-50.0, -50.0)
    assert bounds.returns(0.99) == pytest.approx((-20_000.0, 3000.0))


def test_a_goal_at_any_rate_is_bounded_by_the_rate_clip():
    """goal_velocity=None: a terminating step has |theta| < 0.2 and |theta'| <= 40, so it pays at least
    -0.2 - 160 - 0.36."""
    bounds = RewardBounds.from_attribute(PendulumSwingupEnv(goal_velocity=None).reward_bounds)
    assert bounds.terminal == pytest.approx((-0.2 - 160.0 - 0.36, 0.0))


def test_pendulum_returns():
    """Eq. 4.1 at |theta| = pi, |theta'| = 40, |u| = 0.6 is -5 pi^2 - 160 - 0.36; the goal (|theta| < 0.2,
    |theta'| < 2) pays at least -0.2 - 0.4 - 0.36; gamma 0.98."""
    bounds = RewardBounds.from_attribute(PendulumSwingupEnv(max_torque=0.6).reward_bounds)
    step_low = -5 * math.pi**2 - 0.1 * 40**2 - 0.36
    assert bounds.step == pytest.approx((step_low, 0.0)) and bounds.terminal == pytest.approx((-0.96, 0.0))
    assert bounds.returns(0.98) == pytest.approx((step_low / 0.02, 0.0))


def test_undiscounted_returns_need_a_horizon():
    """gamma = 1: -1 per step and 0 at the end within H = 200 steps gives [-199, 0]; without H, -inf."""
    assert RewardBounds((-1.0, -1.0), (0.0, 0.0), horizon=200).returns(1.0) == (-199.0, 0.0)
    assert RewardBounds((-1.0, -1.0), (0.0, 0.0)).returns(1.0) == (-math.inf, 0.0)
    assert RewardBounds((0.0, 1.0), None).returns(1.0) == (0.0, math.inf)


@pytest.mark.parametrize(
    "bad",
    [
        (1.0, 0.0),
        "step",
        {"terminal": (0, 1)},
        {"step": (0, 1), "extra": 1},
        {"step": (0, float("nan"))},
        {"step": (0, 1), "horizon": 0},
    ],
)
def test_bad_reward_bounds_are_refused(bad):
    with pytest.raises(ValueError, match="reward_bounds"):
        RewardBounds.from_attribute(bad)


@pytest.mark.parametrize(
    "rewards, bounds, expected",
    [
        # MountainCar: -1 a step; the margin is 5 % of one reward, whatever the width of the returns
        (RewardBounds(step=(-1.0, -1.0)), (-100.0, 0.0), 0.05),
        (RewardBounds(step=(-1.0, -1.0)), (-math.inf, 0.0), 0.05),  # gamma 1: half-infinite, the same
        # the walker's literal rewards: -1 a step, footsteps to +30, falls -50: the largest reward is the fall
        (RewardBounds(step=(-1.0, 30.0), terminal=(-50.0, -50.0)), (-100.0, 3000.0), 2.5),
        # dm_control's suite: rewards in [0, 1]
        (RewardBounds(step=(0.0, 1.0), terminal=(0.0, 1.0)), (0.0, 100.0), 0.05),
        # the pendulum swing-up: rewards <= 0, the largest cost 5 pi^2 + 0.1 * 25^2 + 0.36 = 112.21 (a width of
        # 10,485 at gamma 0.99 would have let a Q of +87.6 pass)
        (RewardBounds(step=(-112.21, 0.0)), (-11221.0, 0.0), 0.05 * 112.21),
        (None, (0.0, 0.0), 0.0),  # nothing observed yet: rounding only
    ],
)
def test_the_margin_is_five_percent_of_the_largest_reward(rewards, bounds, expected):
    got = margin(rewards, bounds)
    rounding = 1e-9 * max([1.0] + [abs(b) for b in bounds if math.isfinite(b)])  # 1e-9 of the bounds' magnitude
    assert got == pytest.approx(expected + rounding, rel=1e-12, abs=1e-15)
    assert widened(bounds, got) == pytest.approx((bounds[0] - got, bounds[1] + got))


# --- every env's declared bounds hold for its reward code ------------------------------------------------------------


def _check_rollout(env, bounds, seed, steps):
    env.action_space.seed(seed)
    env.reset(seed=seed)
    for _ in range(steps):
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        low, high = bounds["terminal"] if terminated else bounds["step"]
        assert low <= reward <= high, (reward, terminated, bounds)
        if terminated or truncated:
            env.reset()


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_declared_bounds_hold_in_random_rollouts(seed):
    for env in (
        WindyCliffEnv(),
        PendulumSwingupEnv(),
        PendulumSwingupEnv(velocity_tile_width=3.3),
        PendulumSwingupEnv(goal_velocity=None, reward_units="degrees", integrator="euler"),
        SimplestWalkerEnv(),
        SimplestWalkerEnv(reward="literal", step_reward_cap=20.0),
    ):
        _check_rollout(env, env.reward_bounds, seed, 300)


@settings(max_examples=200, deadline=None)
@given(theta=st.floats(-math.pi, math.pi), velocity=st.floats(-40.0, 40.0), action=st.integers(0, 6))
def test_pendulum_rewards_lie_in_the_bounds_everywhere(theta, velocity, action):
    env = PendulumSwingupEnv()
    env.reset(seed=0)
    env.set_state(theta, velocity)
    _, reward, terminated, _, _ = env.step(action)
    low, high = env.reward_bounds["terminal" if terminated else "step"]
    assert low <= reward <= high


def test_leo_bounds_hold():
    pytest.importorskip("dm_control")
    env = LeoEnv()
    _check_rollout(env, env.reward_bounds, 0, 200)


# --- the kernels' figures against a NumPy recomputation of one replay phase -----------------------------------------

GAMMA, ALPHA = 0.9, 0.5


def _chain_buffer(coder):
    """One trajectory 0.2 -> 1.7 -> 5.3 -> 8.1 (rewards 3, -1, 2, then a terminal 7) and one 4.4 -> 0.2 (reward -2,
    open at its end); state 1.7 was visited with action 2 only."""
    buffer = TrajectoryReplayBuffer(16, coder)
    for s, a, r, s_next in ((0.2, 1, 3.0, 1.7), (1.7, 2, -1.0, 5.3), (5.3, 0, 2.0, 8.1), (8.1, 1, 7.0, 9.9)):
        buffer.add(np.array([s]), coder.slots(np.array([s])), a, r, np.array([s_next]))
    buffer.close_trajectory(np.array([9.9]), True)
    buffer.add(np.array([4.4]), coder.slots(np.array([4.4])), 0, -2.0, np.array([0.2]))
    buffer.close_trajectory(np.array([0.2]), False)
    return buffer


def _numpy_phase(coder, buffer, theta, sigma_on):
    """Reversed replay of each closed trajectory once, oldest first, epsilon 0, in NumPy: the targets, Q(s, a) before
    each update and the sigma shifts (Alg. 8 and 10)."""
    targets, values, shifts = [], [], []
    n = coder.n_tilings
    for trajectory in buffer.trajectories():
        obs, actions, rewards = trajectory["observations"], trajectory["actions"], trajectory["rewards"]
        for t in range(len(actions) - 1, -1, -1):
            active = coder.feature_indices(obs[t], actions[t])
            q_sa = theta[active].sum()
            target = rewards[t]
            last = t == len(actions) - 1
            if not (last and trajectory["terminated"]):
                s_next = trajectory["next_obs"] if last else obs[t + 1]
                q = np.array([theta[coder.feature_indices(s_next, b)].sum() for b in range(coder.n_actions)])
                plain = q.max()
                if sigma_on:
                    w = np.array(
                        [buffer.visits[coder.feature_indices(s_next, b)].sum() for b in range(coder.n_actions)],
                        dtype=float,
                    )
                    if w.sum() > 0:
                        visited = w > 0
                        sigma = 0.5 * (q.sum() / w.sum() + (q[visited] / w[visited]).min())
                        q = q + (n - w) * sigma
                target = target + GAMMA * q.max()
                shifts.append(GAMMA * (q.max() - plain))
            elif sigma_on:
                shifts.append(0.0)
            targets.append(target)
            values.append(q_sa)
            theta[active] += ALPHA / n * (target - q_sa)
    return np.array(targets), np.array(values), np.array(shifts)


@pytest.mark.parametrize("sigma", [kernels.SIGMA_NONE, kernels.SIGMA_AVERAGE_WORST])
def test_kernel_figures_equal_a_numpy_recomputation(sigma):
    coder = TileCoder([1.0], [3], n_tilings=2, memory_size=2**16)
    buffer = _chain_buffer(coder)
    rng = np.random.default_rng(3)
    theta = rng.normal(0.0, 2.0, coder.n_weights)
    theta[buffer.visits == 0] = 0.0  # as in any run: only the features of stored samples leave their initial value
    expected_targets, expected_values, expected_shifts = _numpy_phase(coder, buffer, theta.copy(), sigma >= 0)
    low, high = -4.0, 6.0
    watch = kernels.new_watch(low, high)
    replay_rng = kernels.new_rng_state(0, 1)
    n_closed = buffer.n_trajectories
    # replay each closed trajectory once, oldest first: a uniform pick from one stored trajectory at a time
    for j in range(n_closed):
        data = buffer.replay_data()._replace(
            oldest_trajectory=(buffer.oldest_trajectory + j) % buffer.capacity, n_closed_trajectories=1
        )
        bundles.replay_phase(
            theta,
            buffer,
            bundles.rule(ALPHA / coder.n_tilings, GAMMA, sigma=sigma),
            watch=watch,
            picks_rng=replay_rng,
            data=data,
        )
    assert watch[kernels.WATCH_TARGET_MIN] == pytest.approx(expected_targets.min())
    assert watch[kernels.WATCH_TARGET_MAX] == pytest.approx(expected_targets.max())
    assert watch[kernels.WATCH_Q_MIN] == pytest.approx(expected_values.min())
    assert watch[kernels.WATCH_Q_MAX] == pytest.approx(expected_values.max())
    outside = np.concatenate([expected_targets, expected_values])
    assert watch[kernels.WATCH_OUT_OF_RANGE] == np.count_nonzero((outside < low) | (outside > high))
    assert watch[kernels.WATCH_UPDATES] == len(expected_targets)
    first = np.flatnonzero(
        (expected_targets < low) | (expected_targets > high) | (expected_values < low) | (expected_values > high)
    )
    assert watch[kernels.WATCH_FIRST_UPDATE] == (first[0] if first.size else -1)
    if sigma >= 0:
        assert watch[kernels.WATCH_SHIFT_COUNT] == len(expected_shifts)
        assert watch[kernels.WATCH_SHIFT_SUM] == pytest.approx(expected_shifts.sum())
        assert watch[kernels.WATCH_RAISED] == np.count_nonzero(expected_shifts > 0)
        assert watch[kernels.WATCH_LOWERED] == np.count_nonzero(expected_shifts < 0)


def test_the_first_update_outside_is_the_one_flagged():
    """Sarsa(lambda) steps whose target crosses the bound at the third step: flagged there and not before."""
    coder = TileCoder([1.0], [1], n_tilings=1, memory_size=2**10)
    watch = kernels.new_watch(-10.0, 10.0)
    theta = np.zeros(coder.n_weights)
    trace = tuple(bundles.trace(coder.n_weights, 8, decay=0.0, cutoff=0.5))
    statuses = []
    for reward in (5.0, 9.0, 12.0, 20.0):
        transition = (coder.slots(np.array([0.5])), 0, reward, True, np.array([3.5]), np.zeros(1, np.int64))
        _, _, status = kernels.sarsa_lambda_step(
            tuple(bundles.weights(theta)),
            trace,
            tuple(coder.layout),
            tuple(bundles.rule(0.1, GAMMA)),
            transition,
            kernels.new_rng_state(0),
            tuple(bundles.scratch(1)),
            watch,
        )
        statuses.append(status)
    assert statuses == [kernels.STATUS_OK, kernels.STATUS_OK, kernels.STATUS_OUT_OF_BOUNDS, kernels.STATUS_OK]
    assert watch[kernels.WATCH_FIRST_UPDATE] == 2 and watch[kernels.WATCH_FIRST_VALUE] == 12.0
    assert watch[kernels.WATCH_OUT_OF_RANGE] == 2


# --- learn: warn, raise, ignore; sane runs are never flagged; the watch changes nothing ------------------------------


def _pendulum_er_sigma(**kwargs):
    """ER-sigma on the pendulum's earlier default reading (velocity tiles 3.3 rad/s, the goal |theta| < 0.1 rad and
    |theta'| < 1 rad/s), where its values turn positive from rewards <= 0."""
    env = gym.make("sb3_er/PendulumSwingup-v0", velocity_tile_width=3.3, goal_angle=0.1, goal_velocity=1.0)
    return ERSigma(
        "TileQ",
        env,
        learning_rate=0.2,
        gamma=0.98,
        exploration_rate=0.1,
        replays_per_stored_trajectory=10,
        seed=0,
        **kwargs,
    )


@pytest.mark.slow
def test_er_sigma_on_the_wide_pendulum_tiles_warns_once():
    model = _pendulum_er_sigma()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.learn(30_000)
    flagged = [w for w in caught if issubclass(w.category, ValueBoundWarning)]
    assert len(flagged) == 1
    message = str(flagged[0].message)
    assert message.startswith("ERSigma: at step") and "above them" in message and "reward_bounds" in message
    excursion = model.value_excursion
    assert excursion["high"] == 0.0 and excursion["value"] > excursion["margin"] > 0.0
    assert model.largest_excursion >= excursion["value"]
    assert model.values_out_of_range > 0


@pytest.mark.slow
def test_raise_stops_at_the_phase_and_ignore_only_counts():
    with pytest.raises(ValueBoundError, match="ERSigma: at step"):
        _pendulum_er_sigma(value_bound_action="raise").learn(30_000)
    quiet = _pendulum_er_sigma(value_bound_action="ignore")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ValueBoundWarning)
        quiet.learn(30_000)
    assert quiet.value_excursion is not None and quiet.values_out_of_range > 0


@pytest.mark.parametrize(
    "make",
    [
        lambda: SarsaLambda("TileQ", "sb3_er/WindyCliff-v0", learning_rate=0.25, gamma=0.98, seed=1),
        lambda: SarsaLambda(
            "TileQ",
            gym.make("sb3_er/PendulumSwingup-v0", velocity_tile_width=0.33),
            gamma=0.98,
            exploration_rate=0.1,
            seed=1,
        ),
        lambda: ER("TileQ", "sb3_er/WindyCliff-v0", learning_rate=0.25, gamma=0.98, n_replays=2, seed=1),
    ],
)
def test_sane_runs_are_never_flagged(make):
    """Sarsa(lambda), the control arm, on the grid world and on the pendulum at its printed tiles; ER with light
    replay. (ER with 10 replays per stored trajectory on the grid world does leave the bounds, barely: -55.5 where no
    return is below -50, at replay phase 4 with seed 1.)"""
    model = make()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ValueBoundWarning)
        model.learn(6000)
    assert model.value_excursion is None and model.values_out_of_range == 0
    low, high = model.value_bounds
    assert low < 0.0 <= high


@pytest.mark.parametrize(
    "make",
    [
        lambda **k: SarsaLambda("TileQ", "sb3_er/WindyCliff-v0", seed=2, **k),
        lambda **k: ERSigma("TileQ", "sb3_er/WindyCliff-v0", seed=2, replays_per_stored_trajectory=5, **k),
        lambda **k: ER("TileQ", "sb3_er/WindyCliff-v0", seed=2, replay_order="prioritized", **k),
        lambda **k: Dyna("TileQ", "sb3_er/WindyCliff-v0", seed=2, planning_steps=5, **k),
        lambda **k: FQI("TileQ", "sb3_er/WindyCliff-v0", seed=2, fit_every=3, n_iterations=3, **k),
        lambda **k: LSPI("TileQ", "sb3_er/WindyCliff-v0", seed=2, fit_every=3, n_iterations=3, **k),
    ],
)
def test_results_are_bit_identical_with_the_watch_on_and_off(make):
    on, off = make(), make(value_watch=False)
    on.learn(1500)
    off.learn(1500)
    np.testing.assert_array_equal(on.policy.theta_array, off.policy.theta_array)
    assert np.array_equal(on.action_rng, off.action_rng)
    assert on._watch.array[kernels.WATCH_UPDATES] > 0 and off.value_bounds is None


def test_the_watch_is_logged():
    from stable_baselines3.common.logger import KVWriter, Logger

    model = ERSigma("TileQ", "sb3_er/WindyCliff-v0", seed=0, replays_per_stored_trajectory=5)
    seen = {}

    class Capture(KVWriter):
        def write(self, key_values, key_excluded, step=0):
            seen.update(key_values)

        def close(self):
            pass

    model.set_logger(Logger(None, [Capture()]))
    model.learn(800)
    for key in (
        "train/q_min",
        "train/q_max",
        "train/target_min",
        "train/target_max",
        "train/q_out_of_range",
        "train/sigma_shift",
        "train/sigma_raised",
        "train/sigma_lowered",
        "train/value_bound_low",
        "train/value_bound_high",
    ):
        assert key in seen, key
    assert (
        seen["train/value_bound_low"] == pytest.approx(-100.0) and seen["train/value_bound_high"] == 50.0
    )  # gamma 0.99
    assert seen["train/q_min"] <= seen["train/q_max"]
    assert 0.0 <= seen["train/sigma_raised"] + seen["train/sigma_lowered"] <= 1.0


def test_observed_bounds_for_undeclared_envs_and_reward_wrappers():
    """CartPole declares nothing: its observed rewards (+1) bound the values in [0 (initial), 100]. Under a reward
    wrapper the grid world's declared bounds no longer hold and observed ones are used."""
    model = SarsaLambda("TileQ", "CartPole-v1", seed=0)
    model.learn(500)
    assert model._watch.source == "observed" and model.value_bounds == pytest.approx((0.0, 100.0))
    scaled = gym.wrappers.TransformReward(gym.make("sb3_er/WindyCliff-v0"), lambda r: 10.0 * r)
    assert reward_changing_wrapper(scaled) == "TransformReward"
    model = SarsaLambda("TileQ", scaled, seed=0, gamma=0.98)
    model.learn(500)
    assert model._watch.source == "observed" and "TransformReward" in model._watch.reason
    assert model.value_bounds[0] <= -10.0 / 0.02 + 1e-9
    assert reward_changing_wrapper(gym.make("sb3_er/WindyCliff-v0")) is None


class _EarlyPenalty(gym.Wrapper):
    """MountainCar's -1 a step, but -5 for the first 300 steps the wrapper sees: the rewards that set observed bounds
    of [-500, 0] at gamma 0.99 come only early in a run."""

    def __init__(self, env):
        super().__init__(env)
        self.steps = 0

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        return obs, (-5.0 if self.steps <= 300 else reward), terminated, truncated, info


def _early_penalty_env():
    return _EarlyPenalty(gym.wrappers.TimeLimit(gym.make("MountainCar-v0").unwrapped, 100))


@pytest.mark.parametrize("algo", [SarsaLambda, ERSigma])
def test_observed_bounds_survive_save_load_and_a_new_run(algo, tmp_path):
    """The rewards a model observed bound its values after ``save``/``load`` (without the replay buffer) and across
    ``learn`` calls: otherwise a loaded stable model would project its learned values onto the narrower bounds of the
    rewards seen since, and the watch would flag them."""
    model = algo("TileQ", _early_penalty_env(), seed=0, value_bound_action="ignore").learn(400)
    assert model.value_bounds == pytest.approx((-500.0, 0.0))
    assert model.observed_rewards == {"step": [-5.0, -1.0], "terminal": None}  # current, not only once saved
    model.learn(200)  # a new run: a new watch, the same rewards known
    assert model.value_bounds == pytest.approx((-500.0, 0.0))
    model.save(tmp_path / "m")
    loaded = algo.load(tmp_path / "m", env=_early_penalty_env(), value_bound_action="raise")
    assert loaded.observed_rewards == {"step": [-5.0, -1.0], "terminal": None}
    assert loaded.value_bounds == pytest.approx((-500.0, 0.0))
    loaded.learn(200)  # no ValueBoundError: the learned values still lie inside
    assert loaded.value_bounds == pytest.approx((-500.0, 0.0))
    assert algo.load(tmp_path / "m", allow_pickle=False).observed_rewards == loaded.observed_rewards


@pytest.mark.parametrize(
    "bad", [{"step": [float("nan"), 1.0], "terminal": None}, {"step": [2.0, 1.0], "terminal": None}, {"step": [0, 1]}]
)
def test_observed_rewards_are_checked_when_read_back(bad, tmp_path):
    model = SarsaLambda("TileQ", "CartPole-v1", seed=0)
    model._observed_rewards = bad
    model._remember_observed_rewards = lambda: None  # write the bad value as it stands
    model.save(tmp_path / "m")
    with pytest.raises(ValueError, match=r"m.zip: observed_rewards"):
        SarsaLambda.load(tmp_path / "m")


def test_a_stable_models_warning_names_what_its_stabilizers_do_not_cover():
    model = ERSigma("TileQ", "CartPole-v1", seed=0, preset="stable")
    assert "already replays with project_weights" in model._value_watch_remedy()
    assert "preset='stable'" in ERSigma("TileQ", "CartPole-v1", seed=0)._value_watch_remedy()


def test_bad_watch_settings_are_refused():
    with pytest.raises(ValueError, match="value_bound_action"):
        SarsaLambda("TileQ", "sb3_er/WindyCliff-v0", value_bound_action="shout")
    with pytest.raises(ValueError, match="value_watch"):
        SarsaLambda("TileQ", "sb3_er/WindyCliff-v0", value_watch="yes")


def test_the_first_excursion_survives_save_and_load(tmp_path):
    model = SarsaLambda("TileQ", "sb3_er/WindyCliff-v0", seed=0, value_bound_action="ignore")
    model.value_excursion = {"step": 12, "value": 99.0, "low": -50.0, "high": 50.0, "where": "a test"}
    model.save(tmp_path / "m")
    loaded = SarsaLambda.load(tmp_path / "m", env=gym.make("sb3_er/WindyCliff-v0"))
    assert loaded.value_excursion == model.value_excursion
    assert loaded.value_bounds == pytest.approx((-100.0, 50.0))  # gamma 0.99: -1 / 0.01


@pytest.mark.parametrize(
    "rewards, value, where",
    [
        (RewardBounds(step=(-1.0, -1.0)), 7.0, "7 above"),  # bounds [-100, 0], margin 0.05
        (RewardBounds(step=(-1.0, 30.0), terminal=(-50.0, -50.0)), 4165.5, "1165.5 above"),  # no exponent
        (RewardBounds(step=(-1.0, -1.0)), -103.0, "3 below"),
    ],
)
def test_the_warning_says_what_happened_how_far_what_to_check_and_where_to_read(rewards, value, where):
    """The ValueBoundWarning states the excursion, the margin and its rule, that the policy may still be good and how
    to check it (evaluate_policy), and the documentation page; without exponents."""
    model = SarsaLambda("TileQ", "CartPole-v1", seed=0)
    watch = model._watch
    watch.source, watch._declared = "env", rewards
    watch._update_bounds()
    watch.array[kernels.WATCH_FIRST_VALUE] = value
    with pytest.warns(ValueBoundWarning) as caught:
        model._value_out_of_bounds("a hand-made excursion")
    message = str(caught[0].message)
    size = max(abs(end) for end in (*rewards.step, *(rewards.terminal or ())))
    assert f"lies {where} them" in message, message
    assert f"beyond the margin of {0.05 * size + 1e-9 * max(1.0, *map(abs, watch.bounds)):.6g}" in message
    assert "5 % of the largest reward" in message
    assert "policy may still be good" in message and "evaluate_policy" in message
    assert "docs/value_watch.md" in message and "e+" not in message
    assert model.value_excursion["margin"] == pytest.approx(watch.margin)


@pytest.mark.parametrize("algo", [ER, ERSigma])
def test_a_buffer_assigned_directly_is_observed_before_it_is_replayed(algo):
    """CartPole declares no reward bounds: a learner handed another learner's buffer has seen none of its rewards (+1
    each), and without observing them would flag the first replayed value above its initial [0, 0]."""
    source = algo("TileQ", "CartPole-v1", seed=0).learn(400)
    model = algo("TileQ", "CartPole-v1", seed=1)
    assert model.value_bounds == (0.0, 0.0)
    model.replay_buffer = source.replay_buffer
    with warnings.catch_warnings():
        warnings.simplefilter("error", ValueBoundWarning)
        assert model.replay(20)["updates"] > 0
    assert model.value_bounds == source.value_bounds
    assert model.value_bounds == pytest.approx((0.0, 100.0))  # 1 / (1 - 0.99)
    # read once per watch: later phases do not scan the buffer again
    reads = []
    original = model.replay_buffer.stored_rewards
    model.replay_buffer.stored_rewards = lambda: reads.append(1) or original()
    model.replay(5)
    assert reads == []


@settings(max_examples=30, deadline=None)
@given(
    env_id=st.sampled_from(["CartPole-v1", "sb3_er/PendulumSwingup-v0", "sb3_er/WindyCliff-v0", None]),
    wrappers=st.lists(
        st.sampled_from(["Monitor", "TimeLimit", "TransformReward", "ClipAction", "RecordEpisodeStatistics"]),
        max_size=3,
    ),
)
def test_the_wrapper_chain_is_read_from_the_envs_description(env_id, wrappers):
    """What a subprocess worker reports (``str(env)``) gives the wrapper classes and the env's class, never a piece of
    the id (``sb3_er/...``, ``CartPole-v1``), with or without a spec."""
    from gymnasium.envs.classic_control import CartPoleEnv
    from stable_baselines3.common.monitor import Monitor

    from sb3_er.common.value_bounds import _wrapper_names

    env = CartPoleEnv() if env_id is None else gym.make(env_id)
    for name in wrappers:
        if name == "ClipAction" and not isinstance(env.action_space, gym.spaces.Box):
            continue
        env = {
            "Monitor": lambda e: Monitor(e),
            "TimeLimit": lambda e: gym.wrappers.TimeLimit(e, 50),
            "TransformReward": lambda e: gym.wrappers.TransformReward(e, lambda r: 2 * r),
            "ClipAction": lambda e: gym.wrappers.ClipAction(e),
            "RecordEpisodeStatistics": lambda e: gym.wrappers.RecordEpisodeStatistics(e),
        }[name](env)
    chain, level = [], env
    while True:
        chain.append(type(level).__name__)
        if not hasattr(level, "env") or level is level.unwrapped:
            break
        level = level.env
    assert _wrapper_names(str(env)) == chain


def test_a_subprocess_envs_declared_bounds_reach_the_watch_and_a_reward_wrapper_is_seen():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from sb3_er.common.value_bounds import vec_reward_changer

    plain = make_vec_env("sb3_er/WindyCliff-v0", n_envs=1, vec_env_cls=SubprocVecEnv)
    scaled = make_vec_env(
        "sb3_er/WindyCliff-v0",
        n_envs=1,
        vec_env_cls=SubprocVecEnv,
        wrapper_class=gym.wrappers.TransformReward,
        wrapper_kwargs=dict(func=functools.partial(operator.mul, 10.0)),  # picklable for the worker
    )
    # an observation wrapper off the allow-list keeps the rewards, in a worker as in this process
    observed = make_vec_env(
        "sb3_er/WindyCliff-v0",
        n_envs=1,
        vec_env_cls=SubprocVecEnv,
        wrapper_class=gym.wrappers.TransformObservation,
        wrapper_kwargs=dict(func=functools.partial(operator.add, 0), observation_space=None),
    )
    try:
        assert vec_reward_changer(plain) is None
        assert vec_reward_changer(scaled) == "TransformReward"
        assert vec_reward_changer(observed) is None
    finally:
        for vec in (plain, scaled, observed):
            vec.close()

"""Dyna (Sutton 1991; thesis 3.4, Alg. 3-5): the update rule by hand, the nearest-neighbour model by hand, tabular
Dyna-Q to Q* with an exact model, the SB3 verbs, save/load, errors and a short learning check."""

import math

import gymnasium as gym
import kernel_bundles as bundles
import numpy as np
import pytest
from chain_mdp import ChainEnv, chain_q_star, chain_step
from conftest import LineWalkEnv
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import Dyna, TileCoder
from sb3_er.common import kernels
from sb3_er.dyna import NearestNeighbourModel

GAMMA = 0.9
ALPHA = 0.5
ONE_HOT = dict(n_tilings=1, memory_size=2**12)


def phi(coder, s, a):
    return np.bincount(coder.feature_indices(np.array([s]), a), minlength=coder.n_weights).astype(np.float64)


def q(theta, coder, s):
    return np.array([theta @ phi(coder, s, a) for a in range(coder.n_actions)])


@pytest.mark.parametrize("target", [kernels.TARGET_Q_LEARNING, kernels.TARGET_SARSA])
def test_direct_and_planning_updates_by_hand(target):
    """theta <- theta + alpha/N (r + gamma c v(s') - Q(s, a)) phi(s, a) for the real transition (c = 1), then for each
    covered planned transition in turn (c = P(not terminal)); uncovered ones (c < 0) are skipped. With epsilon = 0
    and no ties, Sarsa's a' is greedy too."""
    coder = TileCoder([1.0], [3], n_tilings=2, memory_size=2**12)
    theta = np.random.default_rng(0).normal(size=coder.n_weights)
    real = (0.2, 1, 3.0, 1.7)
    planned = [(5.3, 0, -1.0, 0.2, 1.0), (1.7, 2, 9.0, 0.2, -1.0), (1.7, 2, 2.0, 5.3, 0.5)]
    expected = theta.copy()
    for s, a, r, s_next, c in [(*real, 1.0), *planned]:
        if c < 0:
            continue
        delta = r + GAMMA * c * q(expected, coder, s_next).max() - expected @ phi(coder, s, a)
        expected += ALPHA / coder.n_tilings * delta * phi(coder, s, a)

    slots = lambda states: np.array([coder.slots(np.array([s])) for s in states])  # noqa: E731
    next_slots = np.zeros(coder.n_tilings, dtype=np.int64)
    transition = (coder.slots(np.array([real[0]])), real[1], real[2], False, np.array([real[3]]), next_slots)
    plan = (
        slots([p[0] for p in planned]),
        np.array([p[1] for p in planned]),
        np.array([p[2] for p in planned]),
        np.array([p[4] for p in planned]),
        slots([p[3] for p in planned]),
        0,
        3,
    )
    delta, updates, _, status = kernels.dyna_step(
        tuple(bundles.weights(theta)),
        tuple(coder.layout),
        tuple(bundles.rule(ALPHA / coder.n_tilings, GAMMA, target=target)),
        transition,
        plan,
        kernels.new_rng_state(0),
        tuple(bundles.scratch(coder.n_actions)),
        kernels.NO_WATCH,
    )
    assert (updates, status) == (2, kernels.STATUS_OK)
    np.testing.assert_array_equal(next_slots, coder.slots(np.array([real[3]])))
    np.testing.assert_allclose(theta, expected, rtol=1e-12)


def test_nearest_neighbour_model_by_hand():
    """k nearest stored transitions of the action within the radius (in tile widths, the angle wrapping round):
    r^ = mean r, s'^ = s + mean (s' - s) taken the short way round, P(not terminal) = 1 - mean terminal."""
    coder = TileCoder([0.5, 1.0], [2], n_tilings=1, wrap_periods=[2 * math.pi, None])
    width = 2 * math.pi / 13  # 13 whole tiles per period
    obs = np.array([[math.pi - 0.05, 0.0], [-math.pi + 0.05, 0.2], [0.0, 0.0], [math.pi - 0.05, 0.0]])
    next_obs = np.array([[-math.pi + 0.05, 0.5], [-math.pi + 0.25, 0.4], [0.1, 0.0], [0.0, 0.0]])
    rewards = np.array([1.0, 2.0, 7.0, 5.0])
    terminal = np.array([False, True, False, False])
    actions = np.array([0, 0, 0, 1])
    model = NearestNeighbourModel(coder, n_neighbors=3, radius=1.0).fit(obs, actions, rewards, next_obs, terminal)

    query = np.array([[math.pi, 0.1], [math.pi, 0.1], [1.0, 5.0]])
    predicted, r, continuation, covered = model.predict(query, np.array([0, 1, 0]))
    # query 0: rows 0 and 1 lie 0.05 rad (~0.1 tile) and 0.1 across the wrap; row 2 is ~6.5 tiles away
    displacement = np.mean([[0.1, 0.5], [0.2, 0.2]], axis=0)
    np.testing.assert_allclose(predicted[0], query[0] + displacement, atol=1e-12)
    assert r[0] == pytest.approx(1.5) and continuation[0] == pytest.approx(0.5)
    # query 1: the single action-1 transition, at distance 0.05 / width tiles
    np.testing.assert_allclose(predicted[1], query[1] + [math.pi + 0.05 - 2 * math.pi, 0.0], atol=1e-12)
    assert r[1] == pytest.approx(5.0) and continuation[1] == 1.0
    assert covered.tolist() == [True, True, False]  # query 2 has no action-0 data within one tile

    actual_next = np.array([query[0] + [0.1, 0.5], [0.15, 0.1]])  # predicted: query 0 + (0.15, 0.35); (0.05, 0.1)
    state_error, reward_error, hit = model.errors(query[:2], np.array([0, 1]), np.array([1.0, 5.0]), actual_next)
    np.testing.assert_allclose(state_error, [np.hypot(0.05 / width, 0.15), 0.1 / width], atol=1e-9)
    np.testing.assert_allclose(reward_error, [0.5, 0.0])


@pytest.mark.parametrize("planning_actions", ["stored", "uniform"])
def test_tabular_dyna_q_with_an_exact_model_reaches_q_star(planning_actions):
    """One tiling of width 1 and a model radius below one state: the model is the chain's exact transition table, and
    Q-learning planning converges to value iteration's Q*."""
    n_states = 5
    model = Dyna(
        "TileQ",
        ChainEnv(n_states),
        gamma=GAMMA,
        learning_rate=ALPHA,
        exploration_rate=1.0,
        planning_steps=20,
        planning_actions=planning_actions,
        model_radius=0.5,
        policy_kwargs=ONE_HOT,
        seed=0,
    )
    model.learn(500)
    states = np.repeat(np.arange(n_states - 1.0), 2)[:, None]
    actions = np.tile([0, 1], n_states - 1)
    predicted, rewards, continuation, covered = model.dynamics_model.predict(states, actions)
    truth = [chain_step(n_states, int(s), a) for s, a in zip(states[:, 0], actions, strict=True)]
    assert covered.all()
    np.testing.assert_array_equal(predicted[:, 0], [t[0] for t in truth])
    np.testing.assert_array_equal(rewards, [t[1] for t in truth])
    np.testing.assert_array_equal(continuation, [0.0 if t[2] else 1.0 for t in truth])
    q_values = model.policy.q_values(np.arange(n_states - 1.0)[:, None])
    np.testing.assert_allclose(q_values, chain_q_star(n_states, GAMMA), atol=1e-9)
    assert model.planning_updates > 0


def test_without_planning_it_is_plain_q_learning():
    model = Dyna("TileQ", ChainEnv(), planning_steps=0, policy_kwargs=ONE_HOT, seed=0).learn(300)
    assert model.planning_updates == 0 and model.model_fits == 0 and model.dynamics_model is None
    assert np.any(model.policy.theta_array != 0)


def test_sb3_verbs_eval_callback_and_tensorboard(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    eval_env = Monitor(ChainEnv())
    callback = EvalCallback(eval_env, eval_freq=200, n_eval_episodes=2, log_path=str(tmp_path / "eval"), verbose=0)
    model = Dyna(
        "TileQ",
        LineWalkEnv(),
        planning_steps=3,
        model_refit_every=50,
        seed=0,
        tensorboard_log=str(tmp_path),
        policy_kwargs=dict(n_tilings=4, memory_size=2**14),
    )
    model.learn(600, tb_log_name="dyna")
    events = EventAccumulator(str(next(tmp_path.glob("dyna_*")))).Reload()
    tags = set(events.Tags()["scalars"])
    assert {
        "rollout/ep_rew_mean",
        "rollout/falls",
        "train/td_error",
        "train/model_error",
        "train/model_reward_error",
        "train/model_coverage",
        "train/planning_updates",
        "train/model_fits",
        "train/transitions",
        "time/fps",
    } <= tags
    logged = [e.value for e in events.Scalars("train/planning_updates")]
    assert logged == sorted(logged) and 0 < logged[-1] <= model.planning_updates
    assert all(e.value >= 0 for e in events.Scalars("train/model_error"))
    assert model.planning_updates == pytest.approx(3 * 600, rel=0.01)  # stored actions are always covered

    chain = Dyna("TileQ", ChainEnv(), planning_steps=2, seed=0, policy_kwargs=ONE_HOT)
    chain.learn(400, callback=callback)
    assert len(callback.evaluations_results) == 2
    mean_reward, _ = evaluate_policy(chain, eval_env, n_eval_episodes=2)
    assert np.isfinite(mean_reward)


@pytest.mark.parametrize("target", ["q_learning", "sarsa"])
def test_seeded_runs_are_bit_identical(target):
    def weights(seed):
        model = Dyna(
            "TileQ",
            LineWalkEnv(),
            target=target,
            planning_actions="uniform",
            exploration_rate=0.3,
            model_refit_every=100,
            seed=seed,
            policy_kwargs=dict(n_tilings=4, memory_size=2**14),
        )
        return model.learn(1500).policy.theta_array.copy()

    a, b, c = weights(7), weights(7), weights(8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_save_load_round_trip_with_buffer_and_model(tmp_path):
    kwargs = dict(
        planning_steps=4,
        target="sarsa",
        planning_actions="uniform",
        n_neighbors=3,
        model_radius=0.8,
        model_refit_every=77,
        gamma=0.95,
        policy_kwargs=dict(n_tilings=4, memory_size=2**14),
    )
    model = Dyna("TileQ", LineWalkEnv(), seed=3, **kwargs).learn(700)
    model.save(tmp_path / "dyna.zip")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = Dyna.load(tmp_path / "dyna.zip", env=LineWalkEnv())
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    for name in (
        "planning_steps",
        "target",
        "planning_actions",
        "n_neighbors",
        "model_radius",
        "model_refit_every",
        "gamma",
        "planning_updates",
        "model_fits",
    ):
        assert getattr(loaded, name) == getattr(model, name)
    np.testing.assert_array_equal(loaded.action_rng, model.action_rng)
    assert loaded.dynamics_model is None  # rebuilt from the buffer
    loaded.load_replay_buffer(tmp_path / "buffer.pkl")
    model.fit_model()
    loaded.fit_model()
    probes = np.linspace(0.0, 10.0, 21)[:, None]
    for a in range(6):
        actions = np.full(len(probes), a)
        for x, y in zip(
            loaded.dynamics_model.predict(probes, actions), model.dynamics_model.predict(probes, actions), strict=True
        ):
            np.testing.assert_array_equal(x, y)
    loaded.learn(200, reset_num_timesteps=False)
    assert loaded.num_timesteps == 900


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(planning_steps=-1), "planning_steps must be an integer of at least 0"),
        (dict(target="expected_sarsa"), "target"),
        (dict(planning_actions="all"), "planning_actions"),
        (dict(n_neighbors=0), "n_neighbors"),
        (dict(model_radius=0.0), "model_radius"),
        (dict(model_radius=float("inf")), "model_radius"),
        (dict(model_refit_every=0), "model_refit_every"),
        (dict(buffer_size=0), "buffer_size"),
    ],
)
def test_bad_hyperparameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Dyna("TileQ", ChainEnv(), **kwargs)


def test_nan_observation_is_reported():
    with pytest.raises(ValueError, match="NaN or infinite"):
        Dyna("TileQ", LineWalkEnv(nan_after=3), exploration_rate=0.0, policy_kwargs=dict(n_tilings=4)).learn(50)


@pytest.mark.slow
def test_learns_mountain_car():
    """Random play never reaches the goal within MountainCar's 200 steps (return -200); Dyna-Q does after 15,000."""
    model = Dyna(
        "TileQ",
        "MountainCar-v0",
        learning_rate=0.2,
        gamma=1.0,
        exploration_rate=0.0,
        seed=0,
        policy_kwargs=dict(n_tilings=8, tiles_per_dimension=8),
    ).learn(15_000)
    mean_return, _ = evaluate_policy(model, Monitor(gym.make("MountainCar-v0")), n_eval_episodes=10)
    assert mean_return > -170.0


@pytest.mark.parametrize("env_id", ["sb3_er/WindyCliff-v0", "sb3_er/PendulumSwingup-v0"])
def test_zoo_config_and_sampler_build_the_algorithm(env_id):
    import optuna
    import rl_zoo3

    import sb3_er_envs  # noqa: F401
    from sb3_er import zoo

    zoo.register_algorithms()
    assert rl_zoo3.ALGOS["dyna"] is Dyna
    assert zoo.load_hyperparameters("dyna", env_id)["policy"] == "TileQ"
    Dyna("TileQ", env_id, seed=0, **zoo.model_kwargs("dyna", env_id)).learn(150)
    trial = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0)).ask()
    Dyna("TileQ", env_id, **zoo.SAMPLERS["dyna"](trial, 0, 1, {})).learn(50)


def test_an_env_reset_closes_the_open_episode_as_truncated():
    """A new learn() resets the env: the episode in progress is stored as truncated at its last s' (as ER does)."""
    model = Dyna("TileQ", ChainEnv(max_steps=50), exploration_rate=1.0, policy_kwargs=ONE_HOT, seed=1)
    model.learn(7)
    buffer = model.replay_buffer
    open_length, closed = buffer.open_length, buffer.n_trajectories
    assert open_length > 0
    model.learn(1)
    cut = buffer.trajectories()[closed]
    assert len(cut["rewards"]) == open_length and not cut["terminated"]

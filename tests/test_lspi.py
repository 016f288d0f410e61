"""LSPI (thesis 3.3.2): LSTD-Q against a dense NumPy solve, policy iteration to Q* on a chain, the size refusal, the
SB3 verbs, save/load, errors and a short learning check."""

import gymnasium as gym
import numpy as np
import pytest
from chain_mdp import ChainEnv, chain_database, chain_q_star, dense_features, random_database
from conftest import LineWalkEnv
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import LSPI

GAMMA = 0.9
ONE_HOT = dict(n_tilings=1, memory_size=2**12)


@pytest.mark.parametrize("initial_value", [0.0, -3.0, (-1.0, 2.0)])
def test_lstdq_matches_a_dense_solve(initial_value):
    """One policy evaluation: pi greedy on the starting Q at s'; over the touched weights, with every other weight
    at its initial value theta_0, w solves Phi^T (Phi w - gamma Phi'_pi theta') + lambda (w - theta_0) = Phi^T r,
    where theta' is w on the touched weights and theta_0 elsewhere."""
    ridge = 0.2
    tiles = dict(n_tilings=2, memory_size=2**12, initial_value=initial_value, initial_value_seed=5)
    model = LSPI("TileQ", ChainEnv(), gamma=GAMMA, n_iterations=1, ridge=ridge, policy_kwargs=tiles, seed=0)
    buffer, (obs, actions, rewards, next_obs, terminal) = random_database(model, 80, seed=3)
    model.replay_buffer = buffer
    coder = model.policy.tile_coder
    theta0 = np.random.default_rng(4).normal(size=coder.n_weights)
    model.policy.theta_array[:] = theta0

    phi = dense_features(coder, obs, actions)
    touched = np.flatnonzero(phi.sum(axis=0))
    initial = model.policy.initial_weights(np.arange(coder.n_weights))
    untouched = np.setdiff1d(np.arange(coder.n_weights), touched)
    q0 = initial.copy()
    q0[touched] = theta0[touched]
    next_phi = [dense_features(coder, next_obs, np.full(len(obs), a)) for a in range(coder.n_actions)]
    greedy = np.argmax(np.stack([p @ q0 for p in next_phi], axis=1), axis=1)
    phi_next = np.where(terminal[:, None], 0.0, np.choose(greedy[:, None], next_phi))
    x, x_next = phi[:, touched], phi_next[:, touched]
    constant_next = phi_next[:, untouched] @ initial[untouched]
    a = x.T @ (x - GAMMA * x_next) + ridge * np.eye(len(touched))
    expected = initial.copy()
    expected[touched] = np.linalg.solve(a, x.T @ (rewards + GAMMA * constant_next) + ridge * initial[touched])

    stats = model.fit()
    np.testing.assert_allclose(model.policy.theta_array, expected, rtol=1e-9, atol=1e-10)
    assert stats["policy_iterations"] == 1 and stats["features"] == len(touched)


def test_policy_iteration_reaches_q_star_on_a_chain_and_stops():
    n_states = 5
    model = LSPI("TileQ", ChainEnv(n_states), gamma=GAMMA, n_iterations=50, ridge=1e-10, policy_kwargs=ONE_HOT)
    model.replay_buffer = chain_database(model, n_states)
    stats = model.fit()
    states = np.arange(n_states - 1, dtype=np.float64)[:, None]
    np.testing.assert_allclose(model.policy.q_values(states), chain_q_star(n_states, GAMMA), atol=1e-7)
    assert stats["policy_changes"] == 0 and stats["policy_iterations"] < 50


def test_too_large_a_system_is_refused_with_advice():
    model = LSPI("TileQ", LineWalkEnv(), max_features=10, fit_every=1, policy_kwargs=dict(n_tilings=8))
    with pytest.raises(ValueError, match=r"unknowns.*max_features=10.*fewer tilings.*wider tiles.*buffer_size"):
        model.learn(200)


def test_sb3_verbs_eval_callback_and_tensorboard(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    eval_env = Monitor(ChainEnv())
    callback = EvalCallback(eval_env, eval_freq=200, n_eval_episodes=2, log_path=str(tmp_path / "eval"), verbose=0)
    model = LSPI("TileQ", ChainEnv(), fit_every=2, seed=0, tensorboard_log=str(tmp_path), policy_kwargs=ONE_HOT)
    model.learn(600, callback=callback, tb_log_name="lspi")
    assert len(callback.evaluations_results) == 3 and model.fits > 0
    single, _ = model.predict(np.array([1.0]), deterministic=True)
    batch, _ = model.predict(np.array([[0.0], [2.0]]))
    assert single.shape == () and batch.shape == (2,)
    tags = set(EventAccumulator(str(next(tmp_path.glob("lspi_*")))).Reload().Tags()["scalars"])
    assert {
        "rollout/ep_rew_mean",
        "train/fits",
        "train/bellman_error",
        "train/policy_iterations",
        "train/policy_changes",
        "train/features",
        "train/transitions",
        "time/fps",
    } <= tags


def test_seeded_runs_are_bit_identical():
    def weights(seed):
        model = LSPI(
            "TileQ",
            LineWalkEnv(),
            fit_every=2,
            seed=seed,
            exploration_rate=0.3,
            policy_kwargs=dict(n_tilings=4, memory_size=2**14),
        )
        return model.learn(1200).policy.theta_array.copy()

    a, b, c = weights(5), weights(5), weights(6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_save_load_round_trip(tmp_path):
    kwargs = dict(
        fit_every=2,
        n_iterations=4,
        ridge=0.3,
        max_features=5000,
        gamma=0.95,
        policy_kwargs=dict(n_tilings=4, memory_size=2**14),
    )
    model = LSPI("TileQ", LineWalkEnv(), seed=3, **kwargs).learn(600)
    model.save(tmp_path / "lspi.zip")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = LSPI.load(tmp_path / "lspi.zip", env=LineWalkEnv())
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    for name in ("fit_every", "n_iterations", "ridge", "max_features", "gamma", "fits", "policy_iterations"):
        assert getattr(loaded, name) == getattr(model, name)
    loaded.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)  # the same data, episode still open
    model.fit()
    loaded.fit()
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(n_iterations=0), "n_iterations"),
        (dict(fit_every=-1), "fit_every"),
        (dict(ridge=float("nan")), "ridge"),
        (dict(max_features=0), "max_features"),
        (dict(exploration_rate=2.0), "exploration_rate"),
    ],
)
def test_bad_hyperparameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        LSPI("TileQ", ChainEnv(), **kwargs)


@pytest.mark.slow
def test_learns_mountain_car():
    """Random play never reaches the goal within MountainCar's 200 steps (return -200); LSPI does after 12,000 steps."""
    model = LSPI(
        "TileQ",
        "MountainCar-v0",
        gamma=0.99,
        fit_every=5,
        exploration_rate=0.0,
        seed=0,
        policy_kwargs=dict(n_tilings=8, tiles_per_dimension=8),
    ).learn(12_000)
    mean_return, _ = evaluate_policy(model, Monitor(gym.make("MountainCar-v0")), n_eval_episodes=10)
    assert mean_return > -170.0


@pytest.mark.parametrize("env_id", ["sb3_er/WindyCliff-v0", "sb3_er/PendulumSwingup-v0"])
def test_zoo_config_and_sampler_build_the_algorithm(env_id):
    import optuna
    import rl_zoo3

    import sb3_er_envs  # noqa: F401
    from sb3_er import zoo

    zoo.register_algorithms()
    assert rl_zoo3.ALGOS["lspi"] is LSPI
    assert zoo.load_hyperparameters("lspi", env_id)["policy"] == "TileQ"
    LSPI("TileQ", env_id, seed=0, **zoo.model_kwargs("lspi", env_id)).learn(150)
    trial = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0)).ask()
    LSPI("TileQ", env_id, **zoo.SAMPLERS["lspi"](trial, 0, 1, {})).learn(50)

"""FQI (thesis 3.3.1, Alg. 6): the projection against dense NumPy least squares, the Bellman fixed point on a chain,
the database view, the SB3 verbs, save/load, errors and a short learning check."""

import gymnasium as gym
import numpy as np
import pytest
from chain_mdp import ChainEnv, chain_database, chain_q_star, chain_step, dense_features, random_database
from conftest import LineWalkEnv
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import FQI, TrajectoryReplayBuffer
from sb3_er.common.batch import stored_transitions

GAMMA = 0.9
EXACT = dict(ridge=1e-10, solver_iterations=200, solver_tolerance=1e-13)
ONE_HOT = dict(n_tilings=1, memory_size=2**12)


@pytest.mark.parametrize("initial_value", [0.0, 4.0, (-1.0, 2.0)])
def test_one_sweep_is_the_dense_ridge_least_squares_fit(initial_value):
    """T = r + gamma max_a Q0(s', a) (Eq. 3.1, T = r when terminal), then theta = (Phi^T Phi + lambda I)^-1
    (Phi^T T + lambda theta_0) over the touched weights (Alg. 6 line 3), the others at their initial values theta_0,
    with two overlapping tilings."""
    ridge = 0.3
    tiles = dict(n_tilings=2, memory_size=2**12, initial_value=initial_value, initial_value_seed=9)
    model = FQI(
        "TileQ",
        ChainEnv(),
        gamma=GAMMA,
        n_iterations=1,
        ridge=ridge,
        solver_iterations=500,
        solver_tolerance=1e-14,
        policy_kwargs=tiles,
        seed=0,
    )
    buffer, (obs, actions, rewards, next_obs, terminal) = random_database(model, 60, seed=1)
    model.replay_buffer = buffer
    coder = model.policy.tile_coder
    theta0 = np.random.default_rng(2).normal(size=coder.n_weights)
    model.policy.theta_array[:] = theta0

    phi = dense_features(coder, obs, actions)
    touched = np.flatnonzero(phi.sum(axis=0))
    initial = model.policy.initial_weights(np.arange(coder.n_weights))
    q0 = initial.copy()
    q0[touched] = theta0[touched]  # Q depends on the data alone: untouched weights hold their initial values
    next_q = np.stack([dense_features(coder, next_obs, np.full(len(obs), a)) @ q0 for a in range(coder.n_actions)], 1)
    targets = rewards + GAMMA * np.where(terminal, 0.0, next_q.max(axis=1))
    x = phi[:, touched]
    expected = initial.copy()
    normal = x.T @ x + ridge * np.eye(len(touched))
    expected[touched] = np.linalg.solve(normal, x.T @ targets + ridge * initial[touched])

    stats = model.fit()
    np.testing.assert_allclose(model.policy.theta_array, expected, rtol=1e-7, atol=1e-9)
    assert stats["features"] == len(touched)
    assert stats["bellman_error"] == pytest.approx(np.mean(np.abs(targets - x @ q0[touched])))


def test_fixed_point_on_a_chain_is_value_iterations_q_star():
    """One tiling of width 1: one-hot features, so FQI's fixed point is the Bellman optimality fixed point Q*."""
    n_states = 4
    model = FQI("TileQ", ChainEnv(n_states), gamma=GAMMA, n_iterations=300, policy_kwargs=ONE_HOT, **EXACT)
    model.replay_buffer = chain_database(model, n_states)
    model.fit()
    states = np.arange(n_states - 1, dtype=np.float64)[:, None]
    np.testing.assert_allclose(model.policy.q_values(states), chain_q_star(n_states, GAMMA), atol=1e-8)


def test_ridge_fixed_point_on_a_chain():
    """With ridge lambda and c copies of (s, a), the one-hot fit shrinks: Q(s, a) = c / (c + lambda) * T(s, a)."""
    n_states, ridge = 4, 0.5

    def copies(s, a):
        return 1 + (s + 2 * a) % 3

    q = np.zeros((n_states - 1, 2))
    for _ in range(500):
        new = np.empty_like(q)
        for s in range(n_states - 1):
            for a in range(2):
                s_next, r, terminal = chain_step(n_states, s, a)
                target = r if terminal else r + GAMMA * q[s_next].max()
                new[s, a] = copies(s, a) / (copies(s, a) + ridge) * target
        q = new
    model = FQI(
        "TileQ",
        ChainEnv(n_states),
        gamma=GAMMA,
        n_iterations=500,
        ridge=ridge,
        solver_iterations=50,
        solver_tolerance=1e-13,
        policy_kwargs=ONE_HOT,
    )
    model.replay_buffer = chain_database(model, n_states, repeats=copies)
    model.fit()
    states = np.arange(n_states - 1, dtype=np.float64)[:, None]
    np.testing.assert_allclose(model.policy.q_values(states), q, atol=1e-8)


def test_cold_start_restarts_from_zero():
    n_states = 4
    kwargs = dict(gamma=GAMMA, n_iterations=1, policy_kwargs=ONE_HOT, warm_start=False, **EXACT)
    model = FQI("TileQ", ChainEnv(n_states), **kwargs)
    model.replay_buffer = chain_database(model, n_states)
    model.fit()
    model.fit()  # a second one-sweep fit from Q = 0 again: Q = r
    states = np.arange(n_states - 1, dtype=np.float64)[:, None]
    rewards = [[chain_step(n_states, s, a)[1] for a in range(2)] for s in range(n_states - 1)]
    np.testing.assert_allclose(model.policy.q_values(states), rewards, atol=1e-8)


def test_stored_transitions_match_the_buffers_trajectories():
    """The database view (also across the ring's wrap-around and evictions) against buffer.trajectories()."""
    model = FQI(
        "TileQ",
        LineWalkEnv(segment_every=7),
        policy_kwargs=dict(n_tilings=4, memory_size=2**14),
        seed=0,
        buffer_size=150,
        fit_every=10**6,
    )
    model.learn(1000)
    buffer = model.replay_buffer
    data = stored_transitions(buffer)
    trajectories = buffer.trajectories()
    assert buffer.n_transitions < 1000 and len(data) == sum(len(t["rewards"]) for t in trajectories)
    obs = np.concatenate([t["observations"] for t in trajectories])
    next_obs = np.concatenate([np.vstack([t["observations"][1:], t["next_obs"][None]]) for t in trajectories])
    terminal = np.concatenate([[False] * (len(t["rewards"]) - 1) + [t["terminated"]] for t in trajectories])
    np.testing.assert_array_equal(data.observations, obs)
    np.testing.assert_array_equal(data.next_observations, next_obs)
    np.testing.assert_array_equal(data.terminal, terminal)
    np.testing.assert_array_equal(data.actions, np.concatenate([t["actions"] for t in trajectories]))
    np.testing.assert_array_equal(data.rewards, np.concatenate([t["rewards"] for t in trajectories]))
    coder = model.policy.tile_coder
    np.testing.assert_array_equal(data.next_slots, [coder.slots(o) for o in next_obs])
    with_open = stored_transitions(buffer, include_open=True)
    assert len(with_open) == len(data) + buffer.open_length
    if buffer.open_length:
        np.testing.assert_array_equal(with_open.next_observations[-1], buffer.open_next_obs)


def test_fits_every_fit_every_episodes_and_acts_between():
    model = FQI("TileQ", ChainEnv(), fit_every=3, n_iterations=2, seed=0, policy_kwargs=ONE_HOT).learn(400)
    assert model.fits == model._episode_num // 3 > 0
    assert np.any(model.policy.theta_array != 0)


def test_sb3_verbs_eval_callback_and_tensorboard(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    eval_env = Monitor(ChainEnv())
    callback = EvalCallback(eval_env, eval_freq=200, n_eval_episodes=2, log_path=str(tmp_path / "eval"), verbose=0)
    model = FQI("TileQ", ChainEnv(), fit_every=2, seed=0, tensorboard_log=str(tmp_path), policy_kwargs=ONE_HOT)
    model.learn(600, callback=callback, tb_log_name="fqi")
    assert len(callback.evaluations_results) == 3
    mean_reward, _ = evaluate_policy(model, eval_env, n_eval_episodes=2)
    assert np.isfinite(mean_reward)
    tags = set(EventAccumulator(str(next(tmp_path.glob("fqi_*")))).Reload().Tags()["scalars"])
    assert {
        "rollout/ep_rew_mean",
        "train/fits",
        "train/bellman_error",
        "train/fit_residual",
        "train/features",
        "train/solver_iterations",
        "train/transitions",
        "train/td_error",
        "time/fps",
    } <= tags


def test_seeded_runs_are_bit_identical():
    def weights(seed):
        model = FQI(
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
        n_iterations=7,
        ridge=0.7,
        solver_iterations=12,
        warm_start=False,
        gamma=0.95,
        policy_kwargs=dict(n_tilings=4, memory_size=2**14),
    )
    model = FQI("TileQ", LineWalkEnv(), seed=3, **kwargs).learn(600)
    model.save(tmp_path / "fqi.zip")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = FQI.load(tmp_path / "fqi.zip", env=LineWalkEnv())
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    for name in ("fit_every", "n_iterations", "ridge", "solver_iterations", "warm_start", "gamma", "fits"):
        assert getattr(loaded, name) == getattr(model, name)
    assert loaded.replay_buffer.n_transitions == 0
    loaded.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)  # the same data, episode still open
    assert loaded.replay_buffer.n_transitions == model.replay_buffer.n_transitions
    model.fit()
    loaded.fit()
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    loaded.learn(200, reset_num_timesteps=False)
    assert loaded.num_timesteps == 800


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(n_iterations=0), "n_iterations"),
        (dict(fit_every=0), "fit_every"),
        (dict(ridge=0.0), "ridge"),
        (dict(ridge=-1.0), "ridge"),
        (dict(solver_iterations=0), "solver_iterations"),
        (dict(solver_tolerance=0.0), "solver_tolerance"),
        (dict(buffer_size=0), "buffer_size"),
        (dict(gamma=1.5), "gamma"),
    ],
)
def test_bad_hyperparameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FQI("TileQ", ChainEnv(), **kwargs)


def test_buffer_of_another_tile_coding_is_refused(tmp_path):
    model = FQI("TileQ", ChainEnv(), policy_kwargs=ONE_HOT, fit_every=100).learn(50)
    model.save_replay_buffer(tmp_path / "buffer")
    other = FQI("TileQ", ChainEnv(), policy_kwargs=dict(n_tilings=2, memory_size=2**12))
    with pytest.raises(ValueError, match="different tile coding"):
        other.load_replay_buffer(tmp_path / "buffer.pkl")
    assert isinstance(other.replay_buffer, TrajectoryReplayBuffer)


@pytest.mark.slow
def test_learns_mountain_car():
    """Random play never reaches the goal within MountainCar's 200 steps (return -200); FQI does after 12,000 steps."""
    model = FQI(
        "TileQ",
        "MountainCar-v0",
        gamma=0.99,
        fit_every=2,
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
    assert rl_zoo3.ALGOS["fqi"] is FQI
    assert zoo.load_hyperparameters("fqi", env_id)["policy"] == "TileQ"
    FQI("TileQ", env_id, seed=0, **zoo.model_kwargs("fqi", env_id)).learn(150)
    trial = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0)).ask()
    FQI("TileQ", env_id, **zoo.SAMPLERS["fqi"](trial, 0, 1, {})).learn(50)

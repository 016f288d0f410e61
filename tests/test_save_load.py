"""Saving and loading lose nothing: weights, tile coding, hyperparameters, generators, the replay buffer and w."""

import copy
import pickle

import numpy as np
import pytest
import torch as th
from conftest import LineWalkEnv

from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma]
KWARGS = dict(policy_kwargs=dict(n_tilings=8, memory_size=2**15, tile_widths=[0.7]), exploration_rate=0.1)
PROBES = np.linspace(0.0, 10.0, 41)[:, None]


@pytest.mark.parametrize("algo", ALGOS)
def test_save_load_predict_and_continue(algo, tmp_path):
    model = algo("TileQ", LineWalkEnv(), gamma=0.95, seed=3, **KWARGS).learn(800)
    path = tmp_path / "model.zip"
    model.save(path)

    loaded = algo.load(path, env=LineWalkEnv())
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    np.testing.assert_array_equal(loaded.policy.q_values(PROBES), model.policy.q_values(PROBES))
    np.testing.assert_array_equal(
        loaded.predict(PROBES, deterministic=True)[0], model.predict(PROBES, deterministic=True)[0]
    )
    assert loaded.policy.tile_coder.config() == model.policy.tile_coder.config()
    assert (loaded.gamma, loaded.exploration_rate, loaded.num_timesteps) == (0.95, 0.1, 800)
    np.testing.assert_array_equal(loaded.action_rng, model.action_rng)
    for name in ("sigma", "residual_zeta", "replay_order", "n_replays", "trace_lambda"):
        assert getattr(loaded, name, None) == getattr(model, name, None)

    params = model.get_parameters()
    assert set(params) == {"policy"}
    np.testing.assert_array_equal(params["policy"]["theta"].numpy(), model.policy.theta_array)
    loaded.learn(300, reset_num_timesteps=False)
    assert loaded.num_timesteps == 1100
    assert np.shares_memory(loaded.policy.theta_array, loaded.policy.theta.numpy())
    assert not np.array_equal(loaded.policy.theta_array, model.policy.theta_array)


def test_load_without_env_predicts(tmp_path):
    model = SarsaLambda("TileQ", LineWalkEnv(), seed=0, **KWARGS).learn(300)
    model.save(tmp_path / "m")
    loaded = SarsaLambda.load(tmp_path / "m")
    np.testing.assert_array_equal(loaded.predict(PROBES)[0], model.predict(PROBES)[0])


def test_set_parameters_writes_into_the_shared_weights():
    source = ER("TileQ", LineWalkEnv(), seed=0, **KWARGS).learn(300)
    target = ER("TileQ", LineWalkEnv(), seed=1, **KWARGS)
    view = target.policy.theta_array
    target.set_parameters(source.get_parameters())
    assert np.shares_memory(view, target.policy.theta.numpy())
    np.testing.assert_array_equal(view, source.policy.theta_array)


def test_replay_buffer_round_trip_with_visits(tmp_path):
    model = ERSigma("TileQ", LineWalkEnv(segment_every=7), seed=0, **KWARGS).learn(500)
    model.save_replay_buffer(tmp_path / "buffer")
    fresh = ERSigma("TileQ", LineWalkEnv(), seed=0, **KWARGS)
    fresh.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)  # exactly as saved, open episode too
    assert fresh.replay_buffer.n_trajectories == model.replay_buffer.n_trajectories
    assert fresh.replay_buffer.open_length == model.replay_buffer.open_length
    np.testing.assert_array_equal(fresh.replay_buffer.visits, model.replay_buffer.visits)
    assert fresh.replay_buffer.visits.any()

    fresh.policy.theta_array[:] = model.policy.theta_array
    model.seed_replay(5)
    fresh.seed_replay(5)
    fresh.action_rng[:] = model.action_rng
    assert fresh.replay(20) == model.replay(20)
    np.testing.assert_array_equal(fresh.policy.theta_array, model.policy.theta_array)


def test_replay_buffer_of_another_tile_coding_is_refused(tmp_path):
    model = ER("TileQ", LineWalkEnv(), seed=0, **KWARGS).learn(100)
    model.save_replay_buffer(tmp_path / "buffer")
    other = ER("TileQ", LineWalkEnv(), policy_kwargs=dict(n_tilings=4, tile_widths=[0.7]))
    with pytest.raises(ValueError, match="different tile coding"):
        other.load_replay_buffer(tmp_path / "buffer.pkl")


def test_same_data_same_replays_across_variants():
    """Thesis 5.2-5.4: variants given one buffer and one replay seed replay exactly the same trajectories."""
    source = ER("TileQ", LineWalkEnv(), seed=0, **KWARGS).learn(600)
    touched = []
    for algo in (ER, ERSigma, ResidualER, ResidualERSigma):
        model = algo("TileQ", LineWalkEnv(), seed=0, **KWARGS)
        model.replay_buffer = source.replay_buffer
        model.seed_replay(11)
        result = model.replay(25)
        touched.append(result["updates"])
    assert len(set(touched)) == 1 and touched[0] > 0


# --- one weight array through every copy ------------------------------------------------------------------------------

EVERY_ALGO = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI]
EVERY_KWARGS = {
    Dyna: dict(planning_steps=3, model_refit_every=50),
    FQI: dict(fit_every=1, n_iterations=2),
    LSPI: dict(fit_every=1, n_iterations=2),
}


def fresh_model(algo, seed=0):
    return algo("TileQ", LineWalkEnv(segment_every=7), seed=seed, **KWARGS, **EVERY_KWARGS.get(algo, {}))


def pickle_round_trip(model, tmp_path):
    return pickle.loads(pickle.dumps(model))


def load_round_trip(model, tmp_path):
    model.save(tmp_path / "copied")
    loaded = type(model).load(tmp_path / "copied.zip", env=LineWalkEnv(segment_every=7))
    if hasattr(model, "replay_buffer"):
        model.save_replay_buffer(tmp_path / "copied_buffer.npz")
        loaded.load_replay_buffer(tmp_path / "copied_buffer.npz")
    return loaded


def set_env_copy(model, tmp_path):
    model.set_env(LineWalkEnv(segment_every=7))
    return model


def set_parameters_copy(model, tmp_path):
    target = fresh_model(type(model), seed=1)
    target.set_parameters(model.get_parameters())
    return target


COPIES = {
    "deepcopy": lambda model, tmp_path: copy.deepcopy(model),
    "pickle": pickle_round_trip,
    "load": load_round_trip,
    "set_env": set_env_copy,
    "set_parameters": set_parameters_copy,
}


def assert_one_weight_array(model, tmp_path):
    """Acting (the kernels' array), get_parameters and a saved file see the same numbers."""
    policy = model.policy
    assert np.shares_memory(policy.theta_array, policy.theta.numpy())
    np.testing.assert_array_equal(model.get_parameters()["policy"]["theta"].numpy(), policy.theta_array)
    model.save(tmp_path / "check")
    reloaded = type(model).load(tmp_path / "check.zip")
    np.testing.assert_array_equal(reloaded.policy.q_values(PROBES), policy.q_values(PROBES))
    np.testing.assert_array_equal(
        reloaded.predict(PROBES, deterministic=True)[0], model.predict(PROBES, deterministic=True)[0]
    )


@pytest.mark.parametrize("how", list(COPIES))
@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_a_copy_learns_saves_and_acts_on_one_weight_array(algo, how, tmp_path):
    """Copy a model that has learned (deepcopy, pickle as Ray and multiprocessing do, save/load, set_env,
    set_parameters), learn on the copy, and the copy's acting, get_parameters, save and set_parameters agree; the
    original keeps its own weights."""
    model = fresh_model(algo).learn(300)
    before = model.policy.q_values(PROBES)
    copied = COPIES[how](model, tmp_path)
    copied.learn(400, reset_num_timesteps=False)
    assert_one_weight_array(copied, tmp_path)
    if copied is not model:
        np.testing.assert_array_equal(model.policy.q_values(PROBES), before)
        assert not np.array_equal(copied.policy.q_values(PROBES), before)  # it learned on its own array
        if hasattr(model, "replay_buffer"):
            assert not np.shares_memory(copied.replay_buffer.visits, model.replay_buffer.visits)
            assert copied.replay_buffer.tile_coder is copied.policy.tile_coder
            assert copied.replay_buffer.n_transitions > model.replay_buffer.n_transitions
    # set_parameters on the copy changes how it acts
    zeros = {"policy": {"theta": th.zeros(copied.policy.tile_coder.n_weights, dtype=th.float64)}}
    copied.set_parameters(zeros)
    assert not copied.policy.theta_array.any()
    np.testing.assert_array_equal(copied.policy.q_values(PROBES), 0.0)


@pytest.mark.parametrize("algo", [SarsaLambda, Dyna])
def test_a_deep_copy_mid_episode_continues_like_the_original(algo):
    """Traces (Sarsa(lambda)) and the model data (Dyna) are copied with the weights: the copy and the original,
    continued from the same state, make the same updates."""
    model = fresh_model(algo).learn(317)  # mid-episode
    copied = copy.deepcopy(model)
    model.learn(200, reset_num_timesteps=False)
    copied.learn(200, reset_num_timesteps=False)
    np.testing.assert_array_equal(copied.policy.theta_array, model.policy.theta_array)
    assert np.shares_memory(copied.policy.theta_array, copied.policy.theta.numpy())


def test_assigning_theta_rebuilds_the_kernels_view():
    model = SarsaLambda("TileQ", LineWalkEnv(), seed=0, **KWARGS)
    n = model.policy.tile_coder.n_weights
    model.policy.theta = th.ones(n, dtype=th.float64)
    assert np.shares_memory(model.policy.theta_array, model.policy.theta.numpy())
    np.testing.assert_array_equal(model.policy.q_values(PROBES), 8.0)  # 8 tilings of weight 1
    with pytest.raises(ValueError, match="one contiguous float64 CPU tensor of 32768 entries"):
        model.policy.theta = th.ones(n, dtype=th.float32)
    np.testing.assert_array_equal(model.policy.q_values(PROBES), 8.0)  # refused before it replaced anything
    assert model.policy.theta.dtype == th.float64


def test_a_model_that_logged_to_tensorboard_can_be_copied(tmp_path, capsys):
    """A logger's writers hold open files; copies leave it out and log on their own from their next learn()."""
    model = ER("TileQ", LineWalkEnv(), seed=0, verbose=1, tensorboard_log=str(tmp_path / "tb"), **KWARGS).learn(100)
    for copied in (copy.deepcopy(model), pickle.loads(pickle.dumps(model))):
        assert np.shares_memory(copied.policy.theta_array, copied.policy.theta.numpy())
        copied.learn(100)  # a new TensorBoard run, as a new learn() of the original would start
        assert copied.logger.dir != model.logger.dir and copied.logger is not model.logger
    assert sorted(p.name for p in (tmp_path / "tb").iterdir()) == ["ER_1", "ER_2", "ER_3"]

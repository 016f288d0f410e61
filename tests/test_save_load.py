"""Saving and loading lose nothing: weights, tile coding, hyperparameters, generators, the replay buffer and w."""

import copy
import io
import pickle
import tempfile
import warnings
from collections import OrderedDict

import numpy as np
import pytest
import torch as th
from conftest import LineWalkEnv
from sb3_cases import ENVS, model
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.utils import get_device
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda, TileQPolicy

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


@pytest.mark.parametrize("algo", [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI])
def test_load_refuses_a_keyword_that_is_not_a_parameter(algo, tmp_path):
    """SB3's load sets its keyword arguments as attributes: one the class does not take would be read by nothing
    (SarsaLambda.load(path, preset="stable") loading the thesis's Sarsa(lambda) without a word)."""
    model(algo, LineWalkEnv(), seed=0).save(tmp_path / "m")
    with pytest.raises(TypeError, match=rf"{algo.__name__}.load\(\) got 'presett': not a parameter"):
        algo.load(tmp_path / "m", presett="stable")
    taken = "preset" if algo in (ER, ERSigma, ResidualER, ResidualERSigma) else "exploration_rate"
    value = "stable" if taken == "preset" else 0.2
    assert getattr(algo.load(tmp_path / "m", **{taken: value}), taken) == value


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


# --- SB3's test_save_load, for every algorithm on a discrete- and a Box-action env (docs/sb3_tests.md) ----------------


CASES = [(algo, kind) for algo in EVERY_ALGO for kind in ENVS]
CASE_IDS = [f"{algo.__name__}-{kind}" for algo, kind in CASES]


def _observations(env, n=10):
    env.reset()
    return np.concatenate([env.step([env.action_space.sample()])[0] for _ in range(n)], axis=0)


@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_sb3_save_load_and_set_parameters(algo, kind, tmp_path):
    """SB3's test_save_load: set_parameters refuses unknown and missing objects and missing tensors, takes part of
    them with exact_match=False; a saved model predicts the same on every device and goes on learning."""
    env = DummyVecEnv([ENVS[kind]])
    agent = model(algo, env, learning_rate=0.1).learn(128)
    observations = _observations(env)
    original = copy.deepcopy(agent.get_parameters())
    invalid = {**copy.deepcopy(original), "I_should_not_be_a_valid_object": "and_I_am_an_invalid_tensor"}
    for exact_match in (True, False):
        with pytest.raises(ValueError):
            agent.set_parameters(invalid, exact_match=exact_match)
    with pytest.raises(ValueError):
        agent.set_parameters({}, exact_match=True)  # the policy's object is missing
    with pytest.raises(RuntimeError):
        agent.set_parameters({"policy": OrderedDict()}, exact_match=True)  # its tensor theta is missing
    agent.set_parameters({"policy": OrderedDict()}, exact_match=False)  # nothing given, nothing changed
    np.testing.assert_array_equal(agent.policy.theta_array, original["policy"]["theta"].numpy())
    randomised = {"policy": {"theta": th.rand_like(original["policy"]["theta"])}}
    agent.set_parameters(randomised, exact_match=False)
    np.testing.assert_array_equal(agent.policy.theta_array, randomised["policy"]["theta"].numpy())

    actions, _ = agent.predict(observations, deterministic=True)
    agent.save(tmp_path / "test_save.zip")
    for device in ("auto", "cpu", "cuda"):
        loaded = algo.load(str(tmp_path / "test_save.zip"), env=env, device=device)
        assert loaded.device.type == get_device(device).type
        np.testing.assert_array_equal(loaded.get_parameters()["policy"]["theta"], randomised["policy"]["theta"])
        np.testing.assert_array_equal(loaded.predict(observations, deterministic=True)[0], actions)
        loaded.learn(128)
    compiled = algo.load(tmp_path / "test_save.zip")
    compiled.policy = th.compile(compiled.policy)  # SB3 saves and loads a compiled policy too
    compiled.save(tmp_path / "test_save.zip")
    np.testing.assert_array_equal(
        algo.load(tmp_path / "test_save.zip").predict(observations, deterministic=True)[0], actions
    )


@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_sb3_set_env(algo, kind, tmp_path):
    """SB3's test_set_env: set_env with and without a reset, load with and without force_reset, and the step counts
    of each learn(); then a VecEnv of another size, which SB3 refuses and sb3-er takes."""
    env, env2, env3 = DummyVecEnv([ENVS[kind]]), DummyVecEnv([ENVS[kind]]), ENVS[kind]()
    agent = model(algo, env).learn(64)
    agent.set_env(env2, force_reset=True)
    assert agent._last_obs is None
    agent.learn(64, reset_num_timesteps=True)
    assert agent.num_timesteps == 64
    agent.set_env(env3)
    agent.learn(64)
    agent.set_env(agent.get_env(), force_reset=False)
    assert agent._last_obs is not None
    agent.learn(64, reset_num_timesteps=False)
    assert agent.num_timesteps == 2 * 64
    current = agent.get_env()
    agent.save(tmp_path / "test_save.zip")
    loaded = algo.load(tmp_path / "test_save.zip", env=current, force_reset=False)
    assert loaded._last_obs is not None
    loaded.learn(64, reset_num_timesteps=False)
    assert loaded.num_timesteps == 3 * 64
    loaded = algo.load(tmp_path / "test_save.zip", env=env3, force_reset=True)
    assert loaded._last_obs is None
    loaded.learn(64, reset_num_timesteps=False)
    assert loaded.num_timesteps == 3 * 64
    # SB3's set_env asserts the same number of envs; sb3-er's takes another (docs/guide/sb3.md, several envs)
    loaded.set_env(DummyVecEnv([ENVS[kind]] * 2))
    assert loaded.n_envs == 2 and loaded._last_obs is None
    loaded.learn(64, reset_num_timesteps=False)
    assert loaded.num_timesteps >= 4 * 64


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_load_onto_several_envs(algo, tmp_path):
    """The end of SB3's test_set_env: a model saved with one env loads onto a VecEnv of two and learns on."""
    model(algo, ENVS["discrete"]()).save(tmp_path / "test_save.zip")
    loaded = algo.load(tmp_path / "test_save.zip", env=DummyVecEnv([ENVS["discrete"]] * 2)).learn(64)
    assert loaded.n_envs == 2 and loaded.num_timesteps >= 64


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_exclude_include_and_custom_objects(algo, tmp_path):
    """SB3's test_exclude_include_saved_params: exclude leaves an attribute at its default, include overrides
    exclude, custom_objects replaces a saved entry and ignores a key that is no attribute."""
    agent = model(algo, ENVS["box"](), verbose=2)
    agent.save(tmp_path / "test_save", exclude=["verbose"])
    assert algo.load(str(tmp_path / "test_save.zip")).verbose != 2
    agent.save(tmp_path / "test_save", exclude=["verbose"], include=["verbose"])
    custom_objects = dict(learning_rate=2e-5, dummy=1.0)
    loaded = algo.load(str(tmp_path / "test_save.zip"), custom_objects=custom_objects, print_system_info=True)
    assert loaded.verbose == 2 and loaded.learning_rate == 2e-5 and not hasattr(loaded, "dummy")


BUFFERED = [algo for algo in EVERY_ALGO if algo is not SarsaLambda]


@pytest.mark.parametrize("algo", BUFFERED)
def test_sb3_save_load_replay_buffer(algo, tmp_path):
    """SB3's test_save_load_replay_buffer: into an existing folder without a warning, every stored array back, and
    the loaded buffer takes new transitions."""
    path = tmp_path / "logs" / "replay_buffer.pkl"
    path.parent.mkdir(parents=True)
    agent = model(algo, ENVS["box"](), seed=0).learn(150)
    old = copy.deepcopy(agent.replay_buffer)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent.save_replay_buffer(path)
        agent.replay_buffer = None
        agent.load_replay_buffer(path, truncate_last_traj=False)
    for name in ("observations", "actions", "rewards", "slots", "visits", "trajectory_length"):
        np.testing.assert_array_equal(getattr(agent.replay_buffer, name), getattr(old, name), err_msg=name)
    assert agent.replay_buffer.n_transitions == old.n_transitions
    agent.learn(100, reset_num_timesteps=False)
    assert agent.replay_buffer.n_transitions == old.n_transitions + 100


@pytest.mark.parametrize("algo", BUFFERED)
def test_sb3_warn_buffer_not_on_learn(algo, recwarn):
    """SB3's test_warn_buffer (a buffer that is not memory-optimised): learn, continue, learn again, no warning; the
    episode a new learn() cuts off is stored as truncated."""
    agent = model(algo, ENVS["discrete"](), seed=0)
    agent.learn(50)
    agent.learn(50, reset_num_timesteps=False)
    agent.learn(50)
    assert [str(w.message) for w in recwarn] == []


@pytest.mark.parametrize("algo", BUFFERED)
def test_load_replay_buffer_warns_as_sb3_when_it_truncates(algo, tmp_path):
    """SB3's HerReplayBuffer (its buffer of whole episodes) warns when load_replay_buffer(truncate_last_traj=True)
    closes an episode that was in progress; so does ours, and not when nothing was open or truncate_last_traj=False."""
    agent = model(algo, ENVS["box"](), seed=0).learn(150)  # 100-step episodes: 50 steps of one in progress
    assert agent.replay_buffer.open_length == 50
    agent.save_replay_buffer(tmp_path / "open")
    with pytest.warns(
        UserWarning, match=r"last trajectory in the replay buffer will be truncated(?s:.*)truncate_last_traj=False"
    ):
        agent.load_replay_buffer(tmp_path / "open.pkl")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent.load_replay_buffer(tmp_path / "open.pkl", truncate_last_traj=False)
        agent.learn(50, reset_num_timesteps=False)  # the episode ends: nothing open
        agent.save_replay_buffer(tmp_path / "closed")
        agent.load_replay_buffer(tmp_path / "closed.pkl")


@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_a_model_saved_to_a_stream_loads_without_a_seek(algo, kind):
    """SB3's DQN loads from a BytesIO it was just saved to (zipfile finds the archive from the end, wherever the
    stream stands); every load path that reads a zip does too: load and set_parameters."""
    agent = model(algo, ENVS[kind](), seed=0).learn(100)
    stream = io.BytesIO()
    agent.save(stream)
    loaded = algo.load(stream)
    np.testing.assert_array_equal(loaded.policy.theta_array, agent.policy.theta_array)
    loaded = algo.load(stream, allow_pickle=False)  # again, from wherever the first load left the stream
    np.testing.assert_array_equal(loaded.policy.theta_array, agent.policy.theta_array)
    other = model(algo, ENVS[kind](), seed=1)
    other.set_parameters(stream)
    np.testing.assert_array_equal(other.policy.theta_array, agent.policy.theta_array)
    assert not stream.closed


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_no_resource_warning_and_open_files_stay_open(algo, tmp_path):
    """SB3's test_no_resource_warning: saving and loading by path, str and open file leaves no file open and no
    warning, and leaves the caller's file open; the replay buffer's the same (a buffer file is read where it stands)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent = model(algo, ENVS["discrete"](), seed=0).learn(100)
        for path in (tmp_path / "model", str(tmp_path / "model")):
            agent.save(path)
            algo.load(path)
        with tempfile.TemporaryFile() as stream:
            agent.save(stream)
            algo.load(stream)
            assert not stream.closed
        with open(tmp_path / "opened.zip", "wb") as stream:
            agent.save(stream)
        with open(tmp_path / "opened.zip", "rb") as stream:
            algo.load(stream)
            assert not stream.closed
        if algo in BUFFERED:
            for path in (tmp_path / "replay", str(tmp_path / "replay")):
                agent.save_replay_buffer(path)
                agent.load_replay_buffer(path, truncate_last_traj=False)
            with tempfile.TemporaryFile() as stream:
                agent.save_replay_buffer(stream)
                stream.seek(0)
                agent.load_replay_buffer(stream, truncate_last_traj=False)
                assert not stream.closed


def test_sb3_file_objects_are_checked_as_sb3_checks_them(tmp_path):
    """SB3's test_open_file: anything but a binary file is a TypeError; a closed file, or one of the wrong mode, a
    ValueError, for save and load, the replay buffer's too."""
    agent = model(ER, ENVS["discrete"](), seed=0)
    agent.save(tmp_path / "model.zip")
    with open(tmp_path / "text.txt", "w") as text:
        for call in (lambda: agent.save(text), lambda: ER.load(text), lambda: agent.save_replay_buffer(text)):
            with pytest.raises(TypeError):
                call()
    with pytest.raises(TypeError):
        agent.load_replay_buffer(123)
    with open(tmp_path / "write_only.zip", "wb") as write_only:
        with pytest.raises(ValueError, match="readable"):
            ER.load(write_only)
        with pytest.raises(ValueError, match="readable"):
            agent.load_replay_buffer(write_only)
    with open(tmp_path / "model.zip", "rb") as read_only:
        with pytest.raises(ValueError, match="writable"):
            agent.save(read_only)
    closed = io.BytesIO()
    closed.close()
    for call in (lambda: agent.save(closed), lambda: ER.load(closed), lambda: agent.load_replay_buffer(closed)):
        with pytest.raises(ValueError, match="closed"):
            call()


def test_sb3_paths_suffixes_and_their_warnings(tmp_path):
    """SB3's path conventions (test_open_file_str_pathlib): .zip (model) and .pkl (buffer) added to a path without a
    suffix, another suffix kept, a path read with the suffix added when it does not exist (reported at verbose 2 for a
    buffer), a missing folder created and a folder's name turned into <name>_2, with SB3's warnings."""
    agent = model(ER, ENVS["discrete"](), seed=0).learn(50)
    agent.save(tmp_path / "t1")
    assert (tmp_path / "t1.zip").is_file()
    ER.load(tmp_path / "t1")
    agent.save(tmp_path / "t1.custom_ext")
    assert (tmp_path / "t1.custom_ext").is_file()
    ER.load(tmp_path / "t1.custom_ext")
    with pytest.warns(UserWarning, match=r"does not exist\. Will create it"):
        agent.save(tmp_path / "new_folder" / "model")
    (tmp_path / "folder.zip").mkdir()
    with pytest.warns(UserWarning, match=r"is a folder\. Will save instead to .*folder\.zip_2"):
        agent.save(tmp_path / "folder.zip")
    ER.load(tmp_path / "folder.zip_2")

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent.save_replay_buffer(tmp_path / "b1")
        agent.load_replay_buffer(tmp_path / "b1", truncate_last_traj=False)  # b1.pkl, silently at verbose 0
    assert (tmp_path / "b1.pkl").is_file()
    agent.verbose = 2
    with pytest.warns(UserWarning, match=r"not found\. Attempting .*b1\.pkl"):
        agent.load_replay_buffer(tmp_path / "b1", truncate_last_traj=False)
    with pytest.warns(UserWarning, match=r"exists, will overwrite it"):
        agent.save_replay_buffer(tmp_path / "b1")
    with pytest.warns(UserWarning, match=r"does not exist\. Will create it"):
        agent.save_replay_buffer(tmp_path / "new_buffers" / "b2.npz")
    agent.load_replay_buffer(tmp_path / "new_buffers" / "b2.npz", truncate_last_traj=False)


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_learning_rate_schedules_survive_save_and_load(algo, tmp_path):
    """SB3's test_cast_lr_schedule and test_save_load_backward_compatible: a callable learning rate's schedule returns
    a float, and the callable itself comes back from the file."""
    agent = model(algo, ENVS["box"](), learning_rate=lambda progress: progress * np.sin(1.0))
    assert type(agent.lr_schedule(1.0)) is float
    assert agent.lr_schedule(0.5) == pytest.approx(0.5 * np.sin(1.0))
    agent.save(tmp_path / "model.zip")
    loaded = algo.load(tmp_path / "model.zip")
    assert type(loaded.lr_schedule(1.0)) is float
    assert loaded.lr_schedule(0.5) == pytest.approx(0.5 * np.sin(1.0))
    assert loaded.learning_rate.__name__ == "<lambda>" and loaded.learning_rate(1.0) == pytest.approx(np.sin(1.0))


@pytest.mark.parametrize("kind", list(ENVS))
def test_a_policy_file_is_read_where_the_stream_stands(kind):
    """TileQPolicy.load reads from the stream's position, as SB3's BasePolicy.load (torch.load) does, in the plain
    format and in SB3's own (pickled) one, which is retried from that same position."""
    agent = model(ER, ENVS[kind](), seed=0).learn(100)
    stream = io.BytesIO(b"header")
    stream.seek(0, io.SEEK_END)
    agent.policy.save(stream)
    stream.seek(len(b"header"))
    np.testing.assert_array_equal(TileQPolicy.load(stream).theta_array, agent.policy.theta_array)
    sb3_format = io.BytesIO(b"header")
    sb3_format.seek(0, io.SEEK_END)
    data = {**BasePolicy._get_constructor_parameters(agent.policy), **agent.policy._get_constructor_parameters()}
    th.save({"state_dict": agent.policy.state_dict(), "data": data}, sb3_format)
    sb3_format.seek(len(b"header"))
    np.testing.assert_array_equal(TileQPolicy.load(sb3_format).theta_array, agent.policy.theta_array)


@pytest.mark.parametrize("algo", [SarsaLambda, ER, FQI])
def test_a_saved_model_is_deflated_and_sb3_reads_it(algo, tmp_path):
    """SB3's save stores a zip's entries; sb3-er's deflates them. Weights never visited keep their initial value, so
    a model of 2**20 weights (8 MiB of float64) whose few visited tiles are set is a small fraction of that on disk;
    SB3's own reader and load still read the file, to the last weight."""
    import zipfile

    from stable_baselines3.common.save_util import load_from_zip_file

    kwargs = {**KWARGS, "policy_kwargs": {**KWARGS["policy_kwargs"], "memory_size": 2**20}}
    model = algo("TileQ", LineWalkEnv(), seed=0, **kwargs).learn(300)
    model.save(tmp_path / "model.zip")
    weights_bytes = model.policy.theta_array.nbytes
    assert weights_bytes >= 8 * 2**20
    with zipfile.ZipFile(tmp_path / "model.zip") as archive:
        assert {info.compress_type for info in archive.infolist()} == {zipfile.ZIP_DEFLATED}
    assert (tmp_path / "model.zip").stat().st_size < weights_bytes / 20
    data, params, _ = load_from_zip_file(tmp_path / "model.zip")
    np.testing.assert_array_equal(params["policy"]["theta"].numpy().ravel(), model.policy.theta_array.ravel())
    loaded = algo.load(tmp_path / "model.zip", env=LineWalkEnv())
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    stream = io.BytesIO(b"before the model")
    stream.seek(0, io.SEEK_END)
    model.save(stream)  # written where the stream stands, deflated too
    assert stream.getvalue().startswith(b"before the model")
    assert len(stream.getvalue()) < weights_bytes / 20

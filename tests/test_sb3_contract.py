"""SB3's own conventions, as its test suite checks them on its algorithms, hold for every sb3-er algorithm: policy
save/load, custom loggers, the success rate, predict's input checks, hyperparameter types, file-like and partial
saves, continuing after load."""

import io
import math

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import LineWalkEnv
from gymnasium import spaces
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.policies import BasePolicy

from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda, TileQPolicy

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI]
SMALL = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**12, tile_widths=[0.7]), exploration_rate=0.1)
PROBES = np.linspace(0.0, 10.0, 21)[:, None]


class InMemoryLogger(Logger):
    """SB3's test pattern: a logger without output formats whose values stay readable."""

    def __init__(self):
        super().__init__("", [])

    def dump(self, step: int = 0) -> None:
        pass


@pytest.mark.parametrize("allow_pickle", [True, False])
@pytest.mark.parametrize("algo", ALGOS)
def test_policy_save_and_load_round_trip(algo, allow_pickle, tmp_path):
    model = algo("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(300)
    model.policy.save(tmp_path / "policy.pth")
    policy = TileQPolicy.load(tmp_path / "policy.pth", allow_pickle=allow_pickle)
    np.testing.assert_array_equal(policy.q_values(PROBES), model.policy.q_values(PROBES))
    np.testing.assert_array_equal(policy.predict(PROBES)[0], model.predict(PROBES, deterministic=True)[0])
    assert policy.tile_coder.config() == model.policy.tile_coder.config()
    assert (policy.observation_space, policy.action_space) == (model.observation_space, model.action_space)
    assert np.shares_memory(policy.theta_array, policy.theta.numpy())
    stream = io.BytesIO()
    model.policy.save(stream)
    stream.seek(0)
    np.testing.assert_array_equal(
        TileQPolicy.load(stream, allow_pickle=allow_pickle).q_values(PROBES), model.policy.q_values(PROBES)
    )


def test_a_policy_file_in_sb3s_own_format_needs_pickle(tmp_path):
    """SB3's BasePolicy.save pickles the spaces (and writes normalize_images): it loads, unless pickles are refused."""
    model = ER("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(200)
    th.save(
        {
            "state_dict": model.policy.state_dict(),
            "data": {
                **BasePolicy._get_constructor_parameters(model.policy),
                **model.policy._get_constructor_parameters(),
                "normalize_images": True,
            },
        },
        tmp_path / "sb3.pth",
    )
    np.testing.assert_array_equal(
        TileQPolicy.load(tmp_path / "sb3.pth").q_values(PROBES), model.policy.q_values(PROBES)
    )
    with pytest.raises(ValueError, match=r"sb3.pth: a policy file with pickled settings, refused"):
        TileQPolicy.load(tmp_path / "sb3.pth", allow_pickle=False)


def test_policy_vector_round_trip():
    model = ER("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(200)
    vector = model.policy.parameters_to_vector()
    assert vector.shape == (model.policy.tile_coder.n_weights,) and np.any(vector)
    other = ER("TileQ", LineWalkEnv(), seed=1, **SMALL)
    view = other.policy.theta_array
    other.policy.load_from_vector(vector)
    np.testing.assert_array_equal(view, vector)
    with pytest.raises(RuntimeError, match="theta have shape"):
        other.policy.load_from_vector(vector[:-1])


@pytest.mark.parametrize("algo", ALGOS)
def test_a_logger_without_outputs_receives_every_key(algo):
    model = algo("TileQ", LineWalkEnv(), seed=0, **SMALL)
    logger = InMemoryLogger()
    model.set_logger(logger)
    model.learn(200, log_interval=1)
    for key in (
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "rollout/falls",
        "time/episodes",
        "time/fps",
        "time/total_timesteps",
        "train/learning_rate",
        "train/weights_abs_mean",
    ):
        assert key in logger.name_to_value, key
    assert logger.name_to_value["time/total_timesteps"] <= 200


class SuccessEveryFourth(gym.Env):
    """Five-step episodes; the first of every four succeeds (info["is_success"] at the episode's end)."""

    observation_space = spaces.Box(0.0, 5.0, shape=(1,), dtype=np.float64)
    action_space = spaces.Discrete(2)

    def __init__(self):
        self.episodes = -1

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episodes += 1
        self.t = 0
        return np.zeros(1), {}

    def step(self, action):
        self.t += 1
        end = self.t == 5
        info = {"is_success": self.episodes % 4 == 0} if end else {}
        return np.array([float(self.t)]), 0.0, False, end, info


@pytest.mark.parametrize("algo", [SarsaLambda, ER, FQI])
def test_success_rate_is_logged_from_the_episodes(algo):
    env = Monitor(SuccessEveryFourth(), info_keywords=("is_success",))
    model = algo(
        "TileQ", env, stats_window_size=1000, policy_kwargs=dict(n_tilings=2, memory_size=2**10, tile_widths=[1.0])
    )
    logger = InMemoryLogger()
    model.set_logger(logger)
    model.learn(5 * 40, log_interval=40)
    assert logger.name_to_value["rollout/success_rate"] == pytest.approx(10 / 40)


def test_sb3s_own_logger_writing_nowhere_is_skipped():
    """verbose=0 without TensorBoard: SB3's logger has no outputs and no one can read it, so nothing is computed."""
    model = SarsaLambda("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(100)
    assert not model.logger.output_formats and not model._custom_logger
    model.dump_logs()
    assert model.logger.name_to_value == {}


@pytest.mark.parametrize("algo", [SarsaLambda, ER])
def test_predict_names_the_gym_vecenv_mix_up(algo):
    env = LineWalkEnv()
    model = algo("TileQ", env, seed=0, **SMALL)
    with pytest.raises(ValueError, match="mixing Gym API with SB3 VecEnv API"):
        model.predict(env.reset())
    with pytest.raises(ValueError, match="mixing Gym API with SB3 VecEnv API"):
        model.policy.predict(env.reset(), deterministic=True)
    obs, _ = env.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)
    vec_obs = model.get_env().reset()
    assert model.predict(vec_obs)[0].shape == (1, 2)
    assert model.predict(tuple(obs.tolist()), deterministic=True)[0].tolist() == action.tolist()  # a tuple observation


# --- hyperparameter types: every numeric parameter of every algorithm
# --------------------------------------------------

COMMON = ["learning_rate", "gamma", "exploration_rate", "trace_cutoff", "stats_window_size", "seed"]
ER_NUMERIC = [
    "buffer_size",
    "replay_every",
    "n_replays",
    "replays_per_stored_trajectory",
    "residual_zeta",
    "priority_threshold",
    "max_predecessors",
    "prioritized_updates",
    "online_lambda",
]
FITTED = ["buffer_size", "fit_every", "n_iterations", "ridge"]
NUMERIC = {
    SarsaLambda: [*COMMON, "trace_lambda"],
    ER: [*COMMON, *ER_NUMERIC],
    ERSigma: [*COMMON, *ER_NUMERIC],
    ResidualER: [*COMMON, *ER_NUMERIC],
    ResidualERSigma: [*COMMON, *ER_NUMERIC],
    Dyna: [*COMMON, "buffer_size", "planning_steps", "n_neighbors", "model_radius", "model_refit_every"],
    FQI: [*COMMON, *FITTED, "solver_iterations", "solver_tolerance"],
    LSPI: [*COMMON, *FITTED, "max_features"],
}
CASES = [(algo, name) for algo, names in NUMERIC.items() for name in names]
NOT_A_NUMBER = st.one_of(
    st.text(max_size=6),
    st.text(alphabet="0123456789.", min_size=1, max_size=5),  # "0.99", "5"
    st.tuples(st.floats(0.0, 1.0)),
    st.lists(st.integers(0, 9), min_size=1, max_size=3),
    st.booleans(),
    st.just(math.nan),
    st.just(math.inf),
    st.just(-math.inf),
    st.just({"value": 0.5}),
)


@settings(max_examples=120, deadline=None)
@given(case=st.sampled_from(CASES), value=NOT_A_NUMBER)
def test_a_numeric_hyperparameter_given_a_non_number_is_named(case, value):
    algo, name = case
    with pytest.raises(ValueError, match=name):
        algo("TileQ", LineWalkEnv(), **{**SMALL, name: value})


@pytest.mark.parametrize(
    "algo, name",
    [(ER, "replay_order"), (ER, "sigma"), (Dyna, "target"), (Dyna, "planning_actions"), (ER, "predecessors")],
)
def test_a_choice_given_an_unhashable_value_is_named(algo, name):
    with pytest.raises(ValueError, match=f"{name} must be one of"):
        algo("TileQ", LineWalkEnv(), **{**SMALL, name: ["reversed"]})


def test_hyperparameters_loaded_as_strings_are_named(tmp_path):
    ER("TileQ", LineWalkEnv(), **SMALL).save(tmp_path / "model")
    with pytest.raises(ValueError, match=r"model.zip: gamma must be a finite number in \[0.0, 1.0\], got '0.99'"):
        ER.load(tmp_path / "model", gamma="0.99")


# --- SB3's save/load tests: file objects, exclude/include, continuing an episode --------------------------------------


@pytest.mark.parametrize("allow_pickle", [True, False])
def test_save_and_load_through_file_objects(allow_pickle):
    model = ER("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(200)
    stream = io.BytesIO()
    model.save(stream)
    stream.seek(0)
    loaded = ER.load(stream, allow_pickle=allow_pickle)
    np.testing.assert_array_equal(loaded.policy.q_values(PROBES), model.policy.q_values(PROBES))
    buffer_file = io.BytesIO()
    model.save_replay_buffer(buffer_file)
    buffer_file.seek(0)
    loaded.load_replay_buffer(buffer_file)
    assert loaded.replay_buffer.n_trajectories == model.replay_buffer.n_trajectories + (
        1 if model.replay_buffer.open_length else 0
    )


@pytest.mark.parametrize("allow_pickle", [True, False])
def test_exclude_and_include_saved_attributes(allow_pickle, tmp_path):
    model = ER("TileQ", LineWalkEnv(), seed=0, verbose=0, **SMALL).learn(100)
    model.verbose = 2
    model.save(tmp_path / "model", exclude=["verbose", "action_rng"])
    loaded = ER.load(tmp_path / "model.zip", allow_pickle=allow_pickle)
    assert loaded.verbose == 0 and not np.array_equal(loaded.action_rng, model.action_rng)
    model.save(tmp_path / "model", exclude=["verbose"], include=["verbose"])
    loaded = ER.load(tmp_path / "model.zip", allow_pickle=allow_pickle, custom_objects={"learning_rate": 0.05})
    assert loaded.verbose == 2 and loaded.learning_rate == 0.05
    np.testing.assert_array_equal(loaded.action_rng, model.action_rng)


@pytest.mark.parametrize("allow_pickle", [True, False])
def test_load_without_reset_continues_the_episode(allow_pickle, tmp_path):
    """SB3's test_set_env: load(..., force_reset=False) on the same env keeps _last_obs and goes on from it."""
    model = SarsaLambda("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(64)
    model.save(tmp_path / "model")
    loaded = SarsaLambda.load(tmp_path / "model.zip", env=model.get_env(), force_reset=False, allow_pickle=allow_pickle)
    np.testing.assert_array_equal(loaded._last_obs, model._last_obs)
    loaded.learn(64, reset_num_timesteps=False)
    assert loaded.num_timesteps == 128
    again = SarsaLambda.load(tmp_path / "model.zip", env=LineWalkEnv(), allow_pickle=allow_pickle)
    assert again._last_obs is None


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, np.random.Generator):
        return a.bit_generator.state == b.bit_generator.state
    if isinstance(a, (list, tuple)) or type(a).__name__ == "deque":
        return (
            type(a) is type(b)
            and len(a) == len(b)
            and all(_same(x, y) for x, y in zip(a, b, strict=True))
            and (getattr(a, "maxlen", None) == getattr(b, "maxlen", None))
        )
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b and type(a) is type(b)


@pytest.mark.parametrize("algo", ALGOS)
def test_loading_without_pickle_restores_what_unpickling_does(algo, tmp_path):
    """Every attribute SB3 pickles and sb3-er also keeps in plain form comes back identical without unpickling."""
    from sb3_er.common.serialization import plain_state

    model = algo("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(150)
    model.save(tmp_path / "model")
    with_pickle = algo.load(tmp_path / "model.zip")
    without = algo.load(tmp_path / "model.zip", allow_pickle=False)
    plain = plain_state(model)
    assert {
        "observation_space",
        "action_space",
        "action_rng",
        "predict_rng",
        "ep_info_buffer",
        "_last_obs",
        "policy_class",
    } <= set(plain)
    for name in plain:
        assert _same(getattr(without, name), getattr(with_pickle, name)), name
    np.testing.assert_array_equal(without.policy.q_values(PROBES), with_pickle.policy.q_values(PROBES))

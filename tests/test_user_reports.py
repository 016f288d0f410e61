"""Cases users reported against SB3, rl-zoo and dm_control, each written as the user's input (issue 8).

LEO on a machine without OpenGL is in test_leo.py; the README's code blocks in test_readme.py.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from sb3_er import ER, ERSigma, SarsaLambda, zoo
from sb3_er.common.kernels import Trace

SMALL = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**14))


class CounterEnv(gym.Env):
    """Observation: the number of steps since the last reset. Episodes are truncated after 40 steps; reward 0."""

    def __init__(self, action_space=None):
        self.observation_space = spaces.Box(0.0, 100.0, shape=(1,), dtype=np.float64)
        self.action_space = action_space if action_space is not None else spaces.Discrete(2)
        self.tile_widths = [5.0]
        self.received = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([0.0]), {}

    def step(self, action):
        assert self.action_space.contains(action), f"action {action!r} outside {self.action_space}"
        self.received.append(np.array(action).tolist())
        self.t += 1
        return np.array([float(self.t)]), 0.0, False, self.t >= 40, {}


def assert_no_glued_episodes(buffer):
    """Every stored trajectory is one stretch of one episode: observations count up by one, s' is the next count."""
    for trajectory in buffer.trajectories():
        counts = np.concatenate([trajectory["observations"][:, 0], trajectory["next_obs"]])
        np.testing.assert_array_equal(np.diff(counts), 1.0)
        assert not trajectory["terminated"]


# --- 2. rl-zoo continue-training with a saved replay buffer ---------------------------------------------------------


def test_rl_zoo_continues_training_from_a_saved_model_and_buffer(tmp_path):
    folder = str(tmp_path)
    common = ["--algo", "er", "--env", "sb3_er/WindyCliff-v0", "-f", folder, "--eval-freq", "-1", "--verbose", "0"]
    zoo.train([*common, "-n", "650", "--seed", "1", "--save-replay-buffer"])
    run_dir = tmp_path / "er" / "sb3_er-WindyCliff-v0_1"
    assert (run_dir / "replay_buffer.pkl").is_file()
    saved = ER.load(run_dir / "sb3_er-WindyCliff-v0.zip")
    saved.load_replay_buffer(run_dir / "replay_buffer.pkl", truncate_last_traj=False)
    stored = saved.replay_buffer.n_transitions

    zoo.train(
        [*common, "-n", "300", "--seed", "2", "-i", str(run_dir / "sb3_er-WindyCliff-v0.zip"), "--save-replay-buffer"]
    )  # rl-zoo loads replay_buffer.pkl beside the model, truncate_last_traj=True
    continued = ER.load(tmp_path / "er" / "sb3_er-WindyCliff-v0_2" / "sb3_er-WindyCliff-v0.zip")
    continued.load_replay_buffer(tmp_path / "er" / "sb3_er-WindyCliff-v0_2" / "replay_buffer.pkl")
    assert continued.replay_buffer.n_transitions == stored + 300  # the saved experience, then the new


def test_load_replay_buffer_has_sb3s_signature_and_meaning(tmp_path):
    model = ER("TileQ", CounterEnv(), seed=0, **SMALL).learn(50)  # mid-episode: 10 steps into the second one
    assert model.replay_buffer.open_length == 10
    model.save_replay_buffer(tmp_path / "buffer")

    truncated = ER("TileQ", CounterEnv(), seed=0, **SMALL)
    truncated.load_replay_buffer(tmp_path / "buffer.pkl")  # truncate_last_traj=True, SB3's default
    assert truncated.replay_buffer.open_length == 0
    last = truncated.replay_buffer.trajectories()[-1]
    assert len(last["rewards"]) == 10 and not last["terminated"] and last["next_obs"][0] == 10.0

    kept = ER("TileQ", CounterEnv(), seed=0, **SMALL)
    kept.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)
    assert kept.replay_buffer.open_length == 10


# --- 3. a one-env SubprocVecEnv -------------------------------------------------------------------------------------


def test_one_env_subproc_vec_env_trains_like_a_dummy_vec_env():
    def weights(vec_env_class):
        env = vec_env_class([lambda: gym.make("MountainCar-v0")])
        model = SarsaLambda("TileQ", env, seed=3, **SMALL).learn(400)
        env.close()
        return model.policy.theta_array.copy()

    np.testing.assert_array_equal(weights(SubprocVecEnv), weights(DummyVecEnv))


# --- 4. an env reset ends the open trajectory ----------------------------------------------------------------------


@pytest.mark.parametrize("algo", [ER, ERSigma])
def test_a_second_learn_does_not_glue_the_unfinished_episode_onto_the_next(algo):
    model = algo("TileQ", CounterEnv(), seed=0, **SMALL).learn(25)
    model.learn(25)  # resets the env: the first episode is cut off after 25 steps
    assert_no_glued_episodes(model.replay_buffer)
    first = model.replay_buffer.trajectories()[0]
    assert len(first["rewards"]) == 25 and first["next_obs"][0] == 25.0


def test_continuing_without_a_reset_continues_the_episode():
    model = ER("TileQ", CounterEnv(), seed=0, **SMALL).learn(25)
    model.learn(25, reset_num_timesteps=False)
    assert_no_glued_episodes(model.replay_buffer)
    (episode,) = model.replay_buffer.trajectories()  # one 40-step episode, the second one still open
    assert len(episode["rewards"]) == 40 and model.replay_buffer.open_length == 10


def test_a_callback_stopping_mid_episode_loses_no_step():
    class StopAt(BaseCallback):
        def _on_step(self):
            return self.num_timesteps < 13

    model = ER("TileQ", CounterEnv(), seed=0, **SMALL).learn(100, callback=StopAt())
    assert model.num_timesteps == 13 and model.replay_buffer.open_length == 13
    model.learn(30, reset_num_timesteps=False)
    assert_no_glued_episodes(model.replay_buffer)


def test_load_set_env_and_loaded_buffer_do_not_glue_episodes(tmp_path):
    model = ER("TileQ", CounterEnv(), seed=0, **SMALL).learn(30)
    model.save(tmp_path / "model")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = ER.load(tmp_path / "model", env=CounterEnv())
    loaded.load_replay_buffer(tmp_path / "buffer.pkl", truncate_last_traj=False)
    loaded.learn(20, reset_num_timesteps=False)  # a loaded model has no last observation: the env is reset
    assert_no_glued_episodes(loaded.replay_buffer)
    model.set_env(CounterEnv())
    model.learn(20, reset_num_timesteps=False)
    assert_no_glued_episodes(model.replay_buffer)


def test_sarsa_lambda_starts_a_reset_episode_with_an_empty_trace():
    class TraceAtStart(BaseCallback):
        def _on_training_start(self):
            self.length = sum(int(Trace(*trace).length[0]) for trace in self.model._traces)

        def _on_step(self):
            return True

    model = SarsaLambda("TileQ", CounterEnv(), seed=0, **SMALL).learn(15)
    assert Trace(*model._traces[0]).length[0] > 0
    probe = TraceAtStart()
    model.learn(5, callback=probe)
    assert probe.length == 0
    model.learn(5, reset_num_timesteps=False, callback=probe)  # same episode: the trace lives on
    assert probe.length > 0


# --- 5. observation normalisation ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make_env",
    [
        lambda: VecNormalize(make_vec_env("MountainCar-v0")),
        lambda: gym.wrappers.NormalizeObservation(gym.make("MountainCar-v0")),
    ],
)
def test_observation_normalisation_is_refused_with_the_reason(make_env):
    with pytest.raises(ValueError, match="normalises observations.*raw observation units"):
        ER("TileQ", make_env())


def test_reward_only_normalisation_is_fine_and_set_env_is_checked_too():
    model = ER("TileQ", VecNormalize(make_vec_env("MountainCar-v0"), norm_obs=False), **SMALL).learn(200)
    with pytest.raises(ValueError, match="normalises observations"):
        model.set_env(VecNormalize(make_vec_env("MountainCar-v0")))


def test_rl_zoo_normalize_true_is_refused(tmp_path):
    with pytest.raises(ValueError, match="normalize: true"):
        zoo.train(
            [
                "--algo",
                "er",
                "--env",
                "sb3_er/WindyCliff-v0",
                "-f",
                str(tmp_path),
                "--eval-freq",
                "-1",
                "--verbose",
                "0",
                "-n",
                "100",
                "--hyperparams",
                "normalize:True",
            ]
        )


# --- 6. action spaces that start elsewhere than 0 ------------------------------------------------------------------


@pytest.mark.parametrize(
    "action_space",
    [spaces.Discrete(3, start=-1), spaces.Discrete(2, start=5), spaces.MultiDiscrete([3, 2], start=[-1, 10])],
)
@pytest.mark.parametrize("algo", [SarsaLambda, ER])
def test_actions_are_shifted_into_a_space_with_a_start(algo, action_space):
    env = CounterEnv(action_space)
    model = algo("TileQ", env, exploration_rate=0.5, seed=0, **SMALL).learn(120)  # the env asserts each action
    counts = action_space.nvec if isinstance(action_space, spaces.MultiDiscrete) else [action_space.n]
    every_action = np.array(list(np.ndindex(*counts))) + action_space.start  # by hand: each choice, shifted
    assert {tuple(np.atleast_1d(a)) for a in env.received} == {tuple(a) for a in every_action}
    for deterministic in (True, False):
        single, _ = model.predict(np.array([3.0]), deterministic=deterministic)
        assert action_space.contains(single.astype(action_space.dtype).reshape(action_space.shape))
        batch, _ = model.predict(np.array([[1.0], [7.0]]), deterministic=deterministic)
        assert all(action_space.contains(a.astype(action_space.dtype).reshape(action_space.shape)) for a in batch)


# --- 7. callbacks read self.locals["actions"] ------------------------------------------------------------------------


def test_callbacks_read_the_actions_sent_to_the_env():
    class Actions(BaseCallback):
        def __init__(self):
            super().__init__()
            self.seen = []

        def _on_step(self):
            for key in ("actions", "new_obs", "rewards", "dones", "infos"):
                assert key in self.locals, key
            self.seen.append(np.array(self.locals["actions"]).tolist())
            return True

    env = CounterEnv(spaces.MultiDiscrete([3, 2], start=[-1, 0]))
    probe = Actions()
    ERSigma("TileQ", env, seed=0, **SMALL).learn(60, callback=probe)
    assert probe.seen == [[action] for action in env.received]


# --- 8. bounds finite only on paper --------------------------------------------------------------------------------


class PaperBoundsEnv(CounterEnv):
    def __init__(self, bound):
        super().__init__()
        self.observation_space = spaces.Box(-bound, bound, shape=(2,), dtype=np.float32)
        del self.tile_widths

    def reset(self, *, seed=None, options=None):
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.zeros(2, np.float32), 0.0, False, True, {}


@pytest.mark.parametrize("bound", [np.finfo(np.float32).max, 1e35])
def test_float32_max_bounds_count_as_unbounded(bound):
    with pytest.raises(ValueError, match=r"dimensions \[0, 1\] are unbounded.*float32 max"):
        ER("TileQ", PaperBoundsEnv(bound))
    ER("TileQ", PaperBoundsEnv(bound), policy_kwargs=dict(tile_widths=[0.5, 0.5])).learn(10)


# --- siblings: numbers the tile coder cannot represent, hyperparameters at load time --------------------------------


def test_an_observation_beyond_the_tile_coordinates_is_named():
    model = ER("TileQ", CounterEnv(), **SMALL)
    with pytest.raises(ValueError, match=r"too large for their tile widths in dimensions \[0\]"):
        model.predict(np.array([1e300]))
    with pytest.raises(ValueError, match=r"NaN or infinite values in dimensions \[0\]"):
        model.policy.q_values(np.array([[np.inf]]))


@pytest.mark.parametrize(
    "policy_kwargs, message",
    [
        (dict(n_tilings=16.5), "n_tilings must be a positive integer"),
        (dict(memory_size=-4), "memory_size must be a positive integer"),
        (dict(tile_widths=[1e-320]), "tile_widths must be finite and positive"),
        (dict(tiles_per_dimension=0), "tiles_per_dimension"),
    ],
)
def test_tile_settings_the_coder_cannot_represent_are_named(policy_kwargs, message):
    with pytest.raises(ValueError, match=message):
        ER("TileQ", "MountainCar-v0", policy_kwargs=policy_kwargs)


def test_a_constant_observation_dimension_gets_one_tile():
    class Constant(PaperBoundsEnv):
        def __init__(self):
            super().__init__(1.0)
            self.observation_space = spaces.Box(np.array([0.0, 2.0]), np.array([1.0, 2.0]), dtype=np.float64)

    model = ER("TileQ", Constant())
    assert model.policy.tile_coder.tile_widths.tolist() == pytest.approx([0.1, 1.0])


@pytest.mark.parametrize(
    "overrides, message",
    [
        (dict(gamma=2.0), "gamma"),
        (dict(learning_rate=-0.1), "learning_rate"),
        (dict(n_replays=-1), "n_replays"),
        (dict(replay_every=1.5), "replay_every"),
        (dict(buffer_size=0), "buffer_size"),
        (dict(sigma="median"), "sigma"),
    ],
)
def test_hyperparameters_are_checked_when_a_model_is_loaded(tmp_path, overrides, message):
    ERSigma("TileQ", CounterEnv(), **SMALL).save(tmp_path / "model")
    with pytest.raises(ValueError, match=message):
        ERSigma.load(tmp_path / "model", env=CounterEnv(), **overrides)


@pytest.mark.parametrize("name", zoo.ALL_ALGORITHM_NAMES)
@pytest.mark.parametrize("policy", ["MlpPolicy", "CnnPolicy"])
def test_an_sb3_policy_name_says_to_use_tileq(name, policy):
    """SB3's habit of `DQN("MlpPolicy", env)` (and rl-zoo configs copied from SB3's) meets a message naming TileQ."""
    algorithm = zoo.algorithm_classes()[name]
    with pytest.raises(ValueError, match=rf'Policy {policy} unknown: .*"TileQ".*{algorithm.__name__}\("TileQ", env\)'):
        algorithm(policy, CounterEnv(), **SMALL)
    assert algorithm("TileQ", CounterEnv(), **SMALL).policy_class.__name__ == "TileQPolicy"

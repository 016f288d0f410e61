"""Every algorithm with every SB3 verb: learn, predict, callbacks, evaluation, TensorBoard, seeding, errors."""

import gymnasium as gym
import numpy as np
import pytest
from conftest import LineWalkEnv
from gymnasium import spaces
from gymnasium.envs.classic_control import CartPoleEnv
from sb3_cases import ALGOS as EVERY_ALGO
from sb3_cases import ENV_IDS, model
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback, StopTrainingOnRewardThreshold
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import ER, FQI, LSPI, DivergenceError, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma]
SMALL = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**14))


@pytest.mark.parametrize("algo", ALGOS)
def test_learn_on_bounded_box_with_default_tiles(algo):
    model = algo("TileQ", "MountainCar-v0", seed=0, **SMALL)
    assert model.policy.tile_coder.tile_widths == pytest.approx([(0.6 + 1.2) / 10, 0.14 / 10])
    model.learn(600)
    assert model.num_timesteps == 600
    assert model.falls == 0  # MountainCar episodes only end by the time limit here


@pytest.mark.parametrize("algo", ALGOS)
def test_multidiscrete_learn_and_predict_shapes(algo, line_env):
    model = algo("TileQ", line_env, seed=1, **SMALL).learn(300)
    single, _ = model.predict(np.array([3.0]), deterministic=True)
    assert single.shape == (2,) and line_env.action_space.contains(single)
    batch, _ = model.predict(np.array([[1.0], [4.0], [9.0]]), deterministic=True)
    assert batch.shape == (3, 2)
    assert all(line_env.action_space.contains(a) for a in batch)


def test_discrete_predict_shapes():
    model = SarsaLambda("TileQ", "MountainCar-v0", seed=0, **SMALL)
    single, state = model.predict(np.array([-0.5, 0.0], dtype=np.float32))
    assert single.shape == () and state is None
    batch, _ = model.predict(np.zeros((5, 2)))
    assert batch.shape == (5,)


def test_predict_is_greedy_when_deterministic_and_explores_otherwise():
    model = SarsaLambda("TileQ", "MountainCar-v0", exploration_rate=1.0, seed=0, **SMALL)
    theta = model.policy.theta_array
    obs = np.array([-0.5, 0.0])
    theta[model.policy.tile_coder.feature_indices(obs, 2)] = 1.0
    greedy = {int(model.predict(obs, deterministic=True)[0]) for _ in range(20)}
    explored = {int(model.predict(obs, deterministic=False)[0]) for _ in range(50)}
    assert greedy == {2}
    assert explored == {0, 1, 2}
    np.testing.assert_allclose(model.policy.q_values(obs[None])[0], [0, 0, 4.0])


@pytest.mark.parametrize("algo", [SarsaLambda, ERSigma])
def test_seeded_runs_are_bit_identical(algo):
    def weights(seed):
        model = algo("TileQ", "MountainCar-v0", seed=seed, exploration_rate=0.2, **SMALL)
        return model.learn(1500).policy.theta_array.copy()

    a, b, c = weights(7), weights(7), weights(8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_learning_rate_schedule():
    model = ER("TileQ", "MountainCar-v0", learning_rate=lambda progress: 0.4 * progress, seed=0, **SMALL)
    model.learn(400)
    assert model.current_learning_rate == pytest.approx(0.0, abs=1e-9)
    assert np.any(model.policy.theta_array != 0)


def test_replay_schedule_segment_trigger_and_stored_multiple():
    env = LineWalkEnv(segment_every=5)
    model = ER("TileQ", env, replay_trigger="segment", replay_unit="segment", n_replays=3, seed=0, **SMALL)
    model.learn(200)
    buffer = model.replay_buffer
    lengths = [len(t["rewards"]) for t in buffer.trajectories()]
    assert max(lengths) <= 5
    assert model.replay_phases == buffer.n_trajectories  # one phase per closed trajectory

    whole = ER("TileQ", LineWalkEnv(segment_every=5), replay_trigger="segment", n_replays=3, seed=0, **SMALL)
    whole.learn(200)  # the default unit: whole episodes, replayed at every segment end and episode end
    episodes = whole.replay_buffer.trajectories()
    assert (
        len(episodes) == whole._episode_num
        and sum(len(t["rewards"]) for t in episodes) + (whole.replay_buffer.open_length) == 200
    )
    ends = (
        sum(
            1
            for t in episodes
            for step in range(1, len(t["rewards"]) + 1)
            if step % 5 == 0 or step == len(t["rewards"])
        )
        + whole.replay_buffer.open_length // 5
    )
    assert whole.replay_phases == ends
    model = ER("TileQ", LineWalkEnv(), replays_per_stored_trajectory=2.0, replay_every=2, seed=0, **SMALL)
    model.learn(400)
    assert model.replay_phases == model._episode_num // 2


def test_online_sarsa_between_replays_learns_without_replay():
    model = ER("TileQ", "MountainCar-v0", online_lambda=0.9, n_replays=0, seed=0, **SMALL).learn(300)
    assert model.replay_updates == 0 and np.any(model.policy.theta_array != 0)


def test_callbacks_and_evaluation(tmp_path):
    eval_env = Monitor(gym.make("MountainCar-v0"))
    stop = StopTrainingOnRewardThreshold(reward_threshold=-1000.0)
    eval_callback = EvalCallback(eval_env, eval_freq=400, n_eval_episodes=2, callback_on_new_best=stop, verbose=0)
    checkpoint = CheckpointCallback(save_freq=100, save_path=str(tmp_path), name_prefix="er")
    model = ERSigma("TileQ", "MountainCar-v0", seed=0, **SMALL)
    model.learn(5000, callback=[checkpoint, eval_callback])
    assert model.num_timesteps == 400  # stopped at the first evaluation
    assert len(list(tmp_path.glob("er_*_steps.zip"))) == 4
    mean_reward, _ = evaluate_policy(model, eval_env, n_eval_episodes=2)
    assert mean_reward == pytest.approx(eval_callback.last_mean_reward)


def test_tensorboard_scalars(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    model = ERSigma("TileQ", LineWalkEnv(), tensorboard_log=str(tmp_path), seed=0, **SMALL)
    model.learn(400, tb_log_name="run", log_interval=1)  # a dump at every episode, the last one too
    events = EventAccumulator(str(next(tmp_path.glob("run_*")))).Reload()
    tags = set(events.Tags()["scalars"])
    expected = {
        "rollout/ep_rew_mean",
        "rollout/ep_len_mean",
        "rollout/falls",
        "train/replay_updates",
        "train/td_error",
        "train/weights_abs_mean",
        "train/memory_fill",
        "train/trajectories",
        "time/fps",
    }
    assert expected <= tags
    updates = [e.value for e in events.Scalars("train/replay_updates")]
    assert updates[-1] == model.replay_updates and updates == sorted(updates)
    falls = events.Scalars("rollout/falls")[-1].value
    assert falls == model.falls > 0  # reaching the end of the line terminates the episode


def test_set_env_and_continue():
    model = ER("TileQ", LineWalkEnv(), seed=0, **SMALL).learn(100)
    model.set_env(LineWalkEnv())
    model.learn(100, reset_num_timesteps=False)
    assert model.num_timesteps == 200


class DictObsEnv(LineWalkEnv):
    def __init__(self):
        super().__init__()
        self.observation_space = spaces.Dict({"x": spaces.Box(0, 10, (1,))})
        self.action_space = spaces.Discrete(2)


class TupleActionEnv(LineWalkEnv):
    def __init__(self):
        super().__init__()
        self.action_space = spaces.Tuple((spaces.Discrete(2), spaces.Discrete(3)))


class ImageObsEnv(LineWalkEnv):
    def __init__(self):
        super().__init__()
        self.observation_space = spaces.Box(0, 255, (8, 8, 3), dtype=np.uint8)
        self.action_space = spaces.Discrete(2)


@pytest.mark.parametrize(
    "make_env, message",
    [
        (TupleActionEnv, "Discrete, MultiDiscrete or Box action space"),
        # a single env's Dict observation is flattened (tests/test_dm_control.py); a VecEnv of them is refused
        (lambda: make_vec_env(DictObsEnv, n_envs=1), "this VecEnv observes a Dict"),
        (ImageObsEnv, "image observations"),
        # made without its id: sb3-er's tiling for CartPole-v1 (sb3_er/data/tilings.yml) does not apply
        (CartPoleEnv, r"dimensions \[1, 3\] are unbounded"),
    ],
)
def test_unsupported_settings_are_named(make_env, message):
    with pytest.raises(ValueError, match=message):
        ER("TileQ", make_env())


def test_unbounded_observations_work_with_tile_widths():
    model = SarsaLambda("TileQ", "CartPole-v1", policy_kwargs=dict(tile_widths=[0.5, 0.5, 0.05, 0.5]), seed=0)
    model.learn(200)


@pytest.mark.parametrize("algo", [SarsaLambda, ER])
def test_nan_observation_is_reported(algo):
    with pytest.raises(ValueError, match="NaN or infinite"):
        algo("TileQ", LineWalkEnv(nan_after=3), exploration_rate=0.0, **SMALL).learn(50)


@pytest.mark.parametrize("algo", [SarsaLambda, ER, ERSigma])
def test_divergence_is_reported_with_step_and_td_error(algo):
    env = LineWalkEnv(reward_scale=1e30)
    with pytest.raises(DivergenceError, match=r"diverged at step \d+ .*TD error"):
        algo("TileQ", env, learning_rate=1e10, gamma=1.0, **SMALL).learn(2000)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(gamma=1.5), "gamma"),
        (dict(exploration_rate=-0.1), "exploration_rate"),
        (dict(sigma="median"), "sigma"),
        (dict(replay_order="random"), "replay_order"),
        (dict(target="double_q"), "target"),
        (dict(residual_zeta=2.0), "residual_zeta"),
        (dict(replay_trigger="step"), "replay_trigger"),
        (dict(replay_every=0), "replay_every"),
        (dict(residual_action="previous"), "residual_action"),
        (dict(residual_zeta=1.0, residual_action="next", target="expected_sarsa"), "single a'"),
    ],
)
def test_bad_hyperparameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ER("TileQ", LineWalkEnv(), **kwargs)


# --- SB3's test_run, for every algorithm (docs/sb3_tests.md) ------------------------------------------------------

#: Each algorithm's schedule of learning, the counterpart of SB3's train_freq: a value and a value it refuses.
SCHEDULES = {
    SarsaLambda: ("trace_lambda", 0.5, 1.5),
    ER: ("n_replays", 3, -1),
    ERSigma: ("replay_every", 2, 0),
    ResidualER: ("replay_unit", "segment", "step"),
    ResidualERSigma: ("replays_per_stored_trajectory", 2, -1),
    Dyna: ("planning_steps", 3, -1),
    FQI: ("fit_every", 2, 0),
    LSPI: ("n_iterations", 3, 0),
}


@pytest.mark.parametrize("kind", list(ENV_IDS))
@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_run_verbose(algo, kind, capsys):
    """SB3's test_dqn, test_a2c, test_ppo, test_sac: a short verbose run on CartPole-v1 and Pendulum-v1 prints SB3's
    log table."""
    model(algo, ENV_IDS[kind], verbose=1, seed=0).learn(300, log_interval=1)
    assert "time/" in capsys.readouterr().out


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_schedule_survives_save_load_and_a_new_value_at_load(algo, tmp_path):
    """SB3's test_train_freq: learn, save, load with the env and learn on; load again overriding the schedule and
    learn on with it."""
    name, value, _ = SCHEDULES[algo]
    agent = model(algo, "Pendulum-v1", seed=0, **{name: value}).learn(150)
    agent.save(tmp_path / "test_save.zip")
    env = agent.get_env()
    loaded = algo.load(tmp_path / "test_save.zip", env=env)
    assert getattr(loaded, name) == value
    loaded.learn(150)
    other = algo.load(tmp_path / "test_save.zip", env=env, **{name: value})
    other.learn(150)
    assert getattr(other, name) == value


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_bad_schedules_are_refused(algo, tmp_path):
    """SB3's test_train_freq_fail: a schedule setting out of range is a ValueError naming it, when the model is built
    and when it is loaded with it."""
    name, _, bad = SCHEDULES[algo]
    with pytest.raises(ValueError, match=name):
        model(algo, "Pendulum-v1", **{name: bad})
    model(algo, "Pendulum-v1").save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=name):
        algo.load(tmp_path / "model.zip", **{name: bad})


@pytest.mark.parametrize("algo", EVERY_ALGO)
def test_sb3_offpolicy_multi_env(algo):
    """SB3's test_offpolicy_multi_env: two envs under a time limit of 50 steps, each counted."""
    env = make_vec_env(lambda: gym.wrappers.TimeLimit(gym.make("Pendulum-v1"), 50), n_envs=2)
    agent = model(algo, env, seed=0).learn(150)
    assert agent.num_timesteps >= 150 and agent._episode_num >= 2

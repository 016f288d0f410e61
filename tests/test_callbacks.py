"""SB3's test_callbacks behaviours for every algorithm, on SB3's own choice of envs (CartPole-v1 for discrete actions,
Pendulum-v1 for a Box): SB3's callbacks run, share the model's locals, count its steps, save checkpoints (with the
replay buffer) that load, stop training when they return a falsy value of any kind, evaluate on a vectorised eval env,
log evaluations at the step they happened, and chain."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from sb3_cases import ALGOS, ENV_IDS, ENVS, model
from stable_baselines3.common.callbacks import (
    BaseCallback,
    CallbackList,
    CheckpointCallback,
    EvalCallback,
    EveryNTimesteps,
    LogEveryNTimesteps,
    StopTrainingOnMaxEpisodes,
    StopTrainingOnNoModelImprovement,
    StopTrainingOnRewardThreshold,
)
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_er import SarsaLambda

CASES = [(algo, kind) for algo in ALGOS for kind in ENV_IDS]
CASE_IDS = [f"{algo.__name__}-{kind}" for algo, kind in CASES]


@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_sb3_callbacks(algo, kind, tmp_path):
    """SB3's test_callbacks: checkpoints, evaluation with stop conditions, event callbacks, logging, a cap on episodes,
    a list of them, then no callback, a plain list with a progress bar, and an old-style function."""
    env_id = ENV_IDS[kind]
    agent = model(algo, env_id, seed=0)
    folder = tmp_path / "logs"
    checkpoint = CheckpointCallback(save_freq=64, save_path=folder, save_replay_buffer=True)
    evaluation = EvalCallback(
        gym.make(env_id),
        callback_on_new_best=StopTrainingOnRewardThreshold(reward_threshold=-1200, verbose=1),
        callback_after_eval=StopTrainingOnNoModelImprovement(max_no_improvement_evals=2, min_evals=1, verbose=1),
        best_model_save_path=folder,
        log_path=folder,
        eval_freq=32,
        n_eval_episodes=1,
        warn=False,
    )
    on_event = CheckpointCallback(save_freq=1, save_path=folder, name_prefix="event")
    event = EveryNTimesteps(n_steps=64, callback=on_event)
    callback = CallbackList(
        [checkpoint, evaluation, event, LogEveryNTimesteps(n_steps=32), StopTrainingOnMaxEpisodes(max_episodes=100)]
    )
    agent.learn(128, callback=callback)

    assert agent.env.observation_space.contains(callback.locals["new_obs"][0])
    assert checkpoint.locals["new_obs"] is callback.locals["new_obs"]
    assert event.locals["new_obs"] is callback.locals["new_obs"]
    assert on_event.locals["new_obs"] is callback.locals["new_obs"]
    assert event.num_timesteps == agent.num_timesteps
    assert event.n_calls == agent.num_timesteps
    # the evaluation may stop training early (a mean reward above -1200: at once on CartPole)
    assert agent.num_timesteps >= 32 and (folder / "evaluations.npz").is_file()
    for step in range(64, agent.num_timesteps + 1, 64):
        assert (folder / f"rl_model_{step}_steps.zip").is_file() and (folder / f"event_{step}_steps.zip").is_file()
        restored = algo.load(folder / f"rl_model_{step}_steps.zip")
        assert restored.num_timesteps == step
        if hasattr(agent, "replay_buffer"):  # CheckpointCallback saves the buffer of a model that has one
            restored.load_replay_buffer(folder / f"rl_model_replay_buffer_{step}_steps.pkl", truncate_last_traj=False)
            # as in SB3's off-policy loop, the callback sees a step before it is stored
            assert restored.replay_buffer.n_transitions == step - 1

    agent.learn(128, callback=None)
    agent.learn(128, callback=[checkpoint, evaluation], progress_bar=True)
    agent.learn(128, callback=lambda _locals, _globals: True)


class _Stop(BaseCallback):
    def __init__(self, value):
        super().__init__()
        self.value = value

    def _on_step(self):
        return self.value


@pytest.mark.parametrize("false", [False, np.bool_(0), th.tensor(0, dtype=th.bool)], ids=["bool", "numpy", "torch"])
@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_callbacks_can_cancel_runs(algo, false):
    """SB3's test_callbacks_can_cancel_runs: any falsy return stops training after that step."""
    stop = _Stop(false)
    agent = model(algo, ENVS["discrete"](), seed=0, stats_window_size=1).learn(10, callback=stop)
    assert stop.n_calls == 1 and agent.num_timesteps == 1


@pytest.mark.parametrize("algo, kind", [(algo, kind) for algo in ALGOS for kind in ENVS], ids=str)
def test_sb3_eval_callback_with_a_vec_env(algo, kind):
    """SB3's test_eval_callback_vec_env: evaluating on a VecEnv of 3 identity envs; after learning the identity
    (reward 1 a step, 100-step episodes) the evaluation returns at least 90 of 100."""
    eval_env = DummyVecEnv([ENVS[kind]] * 3)
    evaluation = EvalCallback(eval_env, eval_freq=1000, n_eval_episodes=3, warn=False)
    model(algo, ENVS[kind](), seed=3, gamma=0.4).learn(3000, callback=evaluation)
    assert evaluation.last_mean_reward >= 90


class _SucceedsEveryOther(gym.Env):
    """Five-step episodes; every other one reports success at its end (info["is_success"])."""

    observation_space = gym.spaces.Box(0.0, 5.0, shape=(1,), dtype=np.float64)
    action_space = gym.spaces.Discrete(2)

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
        return np.array([float(self.t)]), 0.0, False, end, {"is_success": self.episodes % 2 == 0} if end else {}


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_eval_success_logging(algo, tmp_path):
    """SB3's test_eval_success_logging: the evaluation collects info["is_success"] of each evaluation episode."""
    evaluation = EvalCallback(
        DummyVecEnv([_SucceedsEveryOther]), eval_freq=50, n_eval_episodes=4, log_path=tmp_path, warn=False
    )
    model(algo, _SucceedsEveryOther(), policy_kwargs=dict(n_tilings=2, memory_size=2**10, tile_widths=[1.0])).learn(
        100, callback=evaluation
    )
    assert sorted(evaluation._is_success_buffer) == [False, False, True, True]
    assert np.load(tmp_path / "evaluations.npz")["successes"].shape == (2, 4)


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_eval_logs_are_written_at_the_evaluation_step(algo, tmp_path):
    """SB3's test_eval_callback_logs_are_written_with_the_correct_timestep: TensorBoard's eval/mean_reward sits at
    multiples of eval_freq."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    agent = model(algo, "CartPole-v1", seed=1, tensorboard_log=str(tmp_path), verbose=1)
    agent.learn(500, callback=EvalCallback(gym.make("CartPole-v1"), eval_freq=101, n_eval_episodes=1, warn=False))
    events = EventAccumulator(str(next(tmp_path.glob(f"{algo.__name__}_*")))).Reload()
    steps = [event.step for event in events.Scalars("eval/mean_reward")]
    assert steps and all(step % 101 == 0 for step in steps)


def test_sb3_eval_friendly_error():
    """SB3's test_eval_friendly_error: a VecNormalize training env (rewards normalised; TileQ refuses normalised
    observations, see test_vec_envs.py) with a plain eval env is reported by SB3's synchronisation check."""
    train_env = VecNormalize(DummyVecEnv([lambda: gym.make("CartPole-v1")]), norm_obs=False)
    agent = model(SarsaLambda, train_env, seed=0)
    agent.learn(
        100,
        callback=EvalCallback(
            VecNormalize(
                DummyVecEnv([lambda: gym.make("CartPole-v1")]), norm_obs=False, training=False, norm_reward=False
            ),
            eval_freq=50,
            warn=False,
        ),
    )
    with pytest.warns(Warning), pytest.raises(AssertionError):
        agent.learn(100, callback=EvalCallback(gym.make("CartPole-v1"), eval_freq=50, warn=False))


@pytest.mark.parametrize("algo", [algo for algo in ALGOS if algo is not SarsaLambda])
def test_sb3_checkpoint_additional_info(algo, tmp_path):
    """SB3's test_checkpoint_additional_info: the replay buffer and the VecNormalize statistics are saved with every
    checkpoint, and all three load."""
    vec_env = DummyVecEnv([lambda: gym.make("CartPole-v1")])
    env = VecNormalize(vec_env, norm_obs=False)
    folder = tmp_path / "checkpoints"
    checkpoint = CheckpointCallback(
        save_freq=200, save_path=folder, save_replay_buffer=True, save_vecnormalize=True, verbose=2
    )
    model(algo, env, seed=0).learn(200, callback=checkpoint)
    restored = algo.load(folder / "rl_model_200_steps.zip")
    restored.load_replay_buffer(folder / "rl_model_replay_buffer_200_steps.pkl")
    VecNormalize.load(folder / "rl_model_vecnormalize_200_steps.pkl", vec_env)


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_eval_callback_chaining(algo, tmp_path):
    """SB3's test_eval_callback_chaining: callbacks run on a new best and after each evaluation see the EvalCallback
    as their parent."""
    seen = []

    class Child(BaseCallback):
        def _on_step(self):
            assert isinstance(self.parent, EvalCallback) and hasattr(self.parent, "best_mean_reward")
            seen.append(self.parent.num_timesteps)
            return True

    evaluation = EvalCallback(
        gym.make("Pendulum-v1"),
        best_model_save_path=tmp_path,
        log_path=tmp_path,
        eval_freq=32,
        n_eval_episodes=1,
        deterministic=True,
        callback_on_new_best=CallbackList([Child(), StopTrainingOnRewardThreshold(reward_threshold=-200)]),
        callback_after_eval=CallbackList([Child()]),
        warn=False,
    )
    model(algo, "Pendulum-v1", seed=0).learn(64, callback=evaluation)
    assert seen and set(seen) <= {32, 64}

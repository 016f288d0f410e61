"""SB3's test_vec_envs behaviours, as they concern an algorithm, for every algorithm: it learns through a DummyVecEnv
and a SubprocVecEnv, under VecFrameStack and a reward-only VecNormalize (normalised observations are refused by name:
tile widths are in raw units), stores the episode's true last observation at a time limit (info["terminal_observation"],
not the next episode's first), seeds the env it was given, takes a Dict observation of one env and names the
alternative for a VecEnv of them, and several envs at once."""

import functools

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from sb3_cases import ALGOS, ENVS, model
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack, VecNormalize

from sb3_er import SarsaLambda

BUFFERED = [algo for algo in ALGOS if algo is not SarsaLambda]
WRAPPERS = {
    "none": lambda venv: venv,
    "VecFrameStack": lambda venv: VecFrameStack(venv, n_stack=2),
    "VecNormalize(rewards)": lambda venv: VecNormalize(venv, norm_obs=False),
}


@pytest.mark.parametrize("wrapper", list(WRAPPERS))
@pytest.mark.parametrize("vec_env_class", [DummyVecEnv, SubprocVecEnv], ids=["dummy", "subproc"])
@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_vec_env_classes_and_wrappers(algo, vec_env_class, wrapper):
    """SB3's test_vecenv_custom_calls and test_vecenv_terminal_obs run every VecEnv class under each wrapper; an
    algorithm learns through each (one env) and predicts on its observations."""
    venv = WRAPPERS[wrapper](vec_env_class([ENVS["box"]]))
    try:
        agent = model(algo, venv, seed=0).learn(150)
        obs = venv.reset()
        actions, _ = agent.predict(obs, deterministic=True)
        assert actions.shape == (1, 1) and venv.action_space.contains(actions[0])
        assert agent.num_timesteps == 150
    finally:
        venv.close()


@pytest.mark.parametrize("algo", ALGOS)
def test_normalised_observations_are_refused_by_name(algo):
    with pytest.raises(ValueError, match=r"normalises observations \(VecNormalize with norm_obs=True"):
        model(algo, VecNormalize(DummyVecEnv([ENVS["box"]])))


class StepEnv(gym.Env):
    """SB3's StepEnv: the observation counts the steps, and a time limit truncates after ``max_steps``."""

    action_space = spaces.Discrete(2)
    observation_space = spaces.Box(0.0, 999.0, shape=(1,), dtype=np.float64)

    def __init__(self, max_steps: int):
        self.max_steps = max_steps

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.current_step = 0
        return np.array([0.0]), {}

    def step(self, action):
        self.current_step += 1
        return np.array([float(self.current_step)]), 0.0, False, self.current_step >= self.max_steps, {}


@pytest.mark.parametrize("vec_env_class", [DummyVecEnv, SubprocVecEnv], ids=["dummy", "subproc"])
@pytest.mark.parametrize("algo", BUFFERED)
def test_sb3_terminal_observation_is_the_last_state_of_a_truncated_episode(algo, vec_env_class):
    """SB3's test_vecenv_terminal_obs from the learner's side: each stored episode ends in s' = max_steps (the
    terminal observation the VecEnv reports), truncated, not terminal, and never in the next episode's reset state."""
    venv = vec_env_class([functools.partial(StepEnv, 5)])
    try:
        agent = model(algo, venv, seed=0, policy_kwargs=dict(n_tilings=2, memory_size=2**10, tile_widths=[1.0]))
        agent.learn(20)
    finally:
        venv.close()
    buffer = agent.replay_buffer
    trajectories = [(buffer.oldest_trajectory + k) % buffer.capacity for k in range(buffer.n_trajectories)]
    assert len(trajectories) == 4
    for j in trajectories:
        assert buffer.trajectory_length[j] == 5
        assert buffer.trajectory_next_obs[j].tolist() == [5.0]
        assert not buffer.trajectory_terminated[j]
        start = buffer.trajectory_start[j]
        assert buffer.observations[start : start + 5, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_seeding_reaches_the_env(algo):
    """SB3's test_vec_deterministic from the algorithm's side: a model's seed seeds its env, so two models with one
    seed see the same first observations on Pendulum-v1 (random initial states)."""
    first = [model(algo, make_vec_env("Pendulum-v1"), seed=seed) for seed in (4, 4, 5)]
    observations = []
    for agent in first:
        agent.learn(1)
        observations.append(agent.get_env().reset())
    np.testing.assert_array_equal(observations[0], observations[1])
    assert not np.array_equal(observations[0], observations[2])


class DictEnv(gym.Env):
    observation_space = spaces.Dict({"a": spaces.Box(0.0, 1.0, (2,)), "b": spaces.Box(0.0, 1.0, (1,))})
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, True, False, {}


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_dict_and_tuple_observations(algo):
    """SB3's test_vecenv_dict_spaces and test_vecenv_tuple_spaces: a single env's Dict of Boxes is flattened and
    learns; a VecEnv of Dict observations is refused with the way to flatten each env; a Tuple is refused by name."""
    model(algo, DictEnv(), policy_kwargs=dict(n_tilings=2, memory_size=2**10)).learn(20)
    with pytest.raises(ValueError, match=r"this VecEnv observes a Dict .*FlattenObservation"):
        model(algo, DummyVecEnv([DictEnv]))
    tuple_env = DictEnv()
    tuple_env.observation_space = spaces.Tuple((spaces.Box(0.0, 1.0, (2,)), spaces.Box(0.0, 1.0, (1,))))
    with pytest.raises(ValueError, match=r"needs a flat Box observation space, got Tuple"):
        model(algo, tuple_env)


@pytest.mark.parametrize("vec_env_class", [DummyVecEnv, SubprocVecEnv], ids=["dummy", "subproc"])
@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_several_envs(algo, vec_env_class):
    venv = vec_env_class([ENVS["box"]] * 3)
    try:
        agent = model(algo, venv, seed=0).learn(150)
        assert agent.num_timesteps >= 150 and agent.n_envs == 3
        actions, _ = agent.predict(venv.reset(), deterministic=True)
        assert actions.shape == (3, 1)
    finally:
        venv.close()

"""SB3's test_predict behaviours for every algorithm: a Gymnasium env is wrapped on its own, predict returns actions of
the action space's shape for one observation and a batch, greedy or exploring, on every device; a subclass of Box
works; a Discrete observation (SB3's IdentityEnv) is refused by name. (Mixing the Gym and VecEnv APIs in predict:
test_sb3_contract.py.)"""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from sb3_cases import ALGOS, ENV_IDS, model
from stable_baselines3.common.envs import IdentityEnv
from stable_baselines3.common.utils import get_device
from stable_baselines3.common.vec_env import DummyVecEnv

CASES = [(algo, kind) for algo in ALGOS for kind in ENV_IDS]
CASE_IDS = [f"{algo.__name__}-{kind}" for algo, kind in CASES]


@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_sb3_auto_wrap(algo, kind):
    """SB3's test_auto_wrap: a plain Gymnasium env is wrapped into a VecEnv."""
    agent = model(algo, gym.make(ENV_IDS[kind])).learn(100)
    assert agent.get_env().num_envs == 1 and agent.num_timesteps == 100


@pytest.mark.parametrize("device", ["cpu", "cuda", "auto"])
@pytest.mark.parametrize("algo, kind", CASES, ids=CASE_IDS)
def test_sb3_predict(algo, kind, device):
    """SB3's test_predict: the policy is on the device asked for (the CPU when CUDA is absent: sb3-er's weights always
    are), one observation gives one action of the action space's shape, a batch of 2 gives 2, and with exploration
    (epsilon 1) the actions stay in the action space."""
    env_id = ENV_IDS[kind]
    agent = model(algo, env_id, device=device)
    assert agent.policy.device.type == get_device(device).type
    env = gym.make(env_id)
    vec_env = DummyVecEnv([lambda: gym.make(env_id)] * 2)
    obs, _ = env.reset(seed=0)
    vec_obs = vec_env.reset()
    for exploration_rate, deterministic in ((0.05, True), (1.0, False)):
        agent.exploration_rate = exploration_rate
        action, _ = agent.predict(obs, deterministic=deterministic)
        assert isinstance(action, np.ndarray)
        assert action.shape == env.action_space.shape and env.action_space.contains(action)
        actions, _ = agent.predict(vec_obs, deterministic=deterministic)
        assert isinstance(actions, np.ndarray) and actions.shape[0] == vec_obs.shape[0]
        assert all(env.action_space.contains(a) for a in actions)


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_discrete_observations_are_refused_by_name(algo):
    """SB3's test_dqn_epsilon_greedy predicts on IdentityEnv's Discrete observation; tile coding tiles real vectors,
    so TileQ refuses it when the model is built, naming the space it needs (FlattenObservation one-hot encodes it:
    sb3_cases.discrete_env)."""
    with pytest.raises(ValueError, match=r"needs a flat Box observation space, got Discrete\(2\)"):
        model(algo, IdentityEnv(2))


class SubClassedBox(spaces.Box):
    pass


class SubClassedSpaceEnv(gym.Env):
    """SB3's CustomSubClassedSpaceEnv: observations and actions in a subclass of Box."""

    def __init__(self):
        self.observation_space = SubClassedBox(-1, 1, shape=(2,), dtype=np.float32)
        self.action_space = SubClassedBox(-1, 1, shape=(2,), dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, bool(self.np_random.random() > 0.5), False, {}


@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_subclassed_space_env(algo, tmp_path):
    """SB3's test_subclassed_space_env: learn, act, and (sb3-er's plain copies) save and load without pickle."""
    env = SubClassedSpaceEnv()
    agent = model(algo, env, seed=0, policy_kwargs=dict(n_tilings=4, memory_size=2**12, action_bins=3)).learn(300)
    obs, _ = env.reset(seed=0)
    action, _ = agent.predict(obs)
    assert env.action_space.contains(action)
    env.step(action)
    agent.save(tmp_path / "model.zip")
    loaded = type(agent).load(tmp_path / "model.zip", env=env, allow_pickle=False)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], agent.predict(obs, deterministic=True)[0])

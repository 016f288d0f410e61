"""Several envs at once (issue 36): every algorithm learns on a VecEnv of N envs, DummyVecEnv or SubprocVecEnv; each
env keeps its own trace, pending action and open trajectory, so that a stored trajectory is one stretch of one env's
episode; time, falls and evaluations count across the envs; N can change on set_env and load; the value watch finds
reward wrappers at any level; the Dict key order is checked on load and set_env."""

import itertools

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper, VecMonitor

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda
from sb3_er.common.base_class import ValueBoundWarning

ALGOS = [SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI]
SMALL = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**14))


class Counter(gym.Env):
    """Observation (env id, step in the episode): every transition says which env and step it came from. Episodes of
    3 + env id steps (terminated), so the envs' episodes end at different times; reward = env id + step."""

    observation_space = gym.spaces.Box(0.0, 100.0, shape=(2,))
    action_space = gym.spaces.Discrete(2)
    tile_widths = np.array([1.0, 1.0])
    reward_bounds = {"step": (0.0, 100.0), "terminal": (0.0, 100.0)}

    def __init__(self, env_id: int = 0):
        self.env_id, self.t = env_id, 0

    def _obs(self):
        return np.array([self.env_id, self.t], dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        reward = float(self.env_id + self.t)
        self.t += 1
        return self._obs(), reward, self.t >= 3 + self.env_id, False, {}


def counters(n: int, vec_cls=DummyVecEnv):
    return vec_cls([lambda i=i: Counter(i) for i in range(n)])


@pytest.mark.parametrize("algo", ALGOS)
def test_every_algorithm_learns_on_several_envs(algo):
    env = make_vec_env("CartPole-v1", n_envs=3, seed=0)
    model = algo("TileQ", env, seed=0, **SMALL).learn(600)
    assert model.n_envs == 3 and model.num_timesteps == 600  # 200 steps of 3 envs
    actions, _ = model.predict(env.reset(), deterministic=True)
    assert actions.shape == (3,)


@pytest.mark.parametrize("algo", [ER, ERSigma, Dyna, FQI])
def test_a_stored_trajectory_is_one_stretch_of_one_env(algo):
    """Four envs whose episodes end at different steps: every stored trajectory holds one env's consecutive steps
    from the start of its episode, ending where the episode ended, with that env's rewards."""
    model = algo("TileQ", counters(4), seed=0, value_bound_action="ignore", **SMALL).learn(400)
    trajectories = model.replay_buffer.trajectories()
    assert len(trajectories) > 20
    for trajectory in trajectories:
        env_ids = trajectory["observations"][:, 0]
        steps = trajectory["observations"][:, 1]
        env_id = int(env_ids[0])
        assert np.all(env_ids == env_id)
        np.testing.assert_array_equal(steps, np.arange(len(steps)))
        assert len(steps) == 3 + env_id and trajectory["terminated"]
        np.testing.assert_array_equal(trajectory["rewards"], env_id + steps)
        np.testing.assert_array_equal(trajectory["next_obs"], [env_id, 3 + env_id])


def test_sarsa_lambda_keeps_one_trace_per_env():
    """Two envs, one step each with a trace that never decays away: each env's trace holds exactly the N features of
    its own first (s, a), env 0's state (0, 0) and env 1's state (1, 0)."""
    model = SarsaLambda("TileQ", counters(2), seed=0, trace_lambda=0.9, trace_cutoff=1e-6, **SMALL)
    coder = model.policy.tile_coder
    model.learn(2)
    for env_id, trace in enumerate(model._traces):
        index, _, _, length = trace[:4]
        held = set(index[: length[0]].tolist())
        own = [set(coder.feature_indices(np.array([env_id, 0.0]), a).tolist()) for a in range(coder.n_actions)]
        assert held in own, (env_id, held)


def test_time_and_falls_count_across_envs_and_evaluations_cross_their_intervals():
    from sb3_er.experiments.protocols import GreedyDistanceProtocol

    env = make_vec_env("sb3_er/SimplestWalker-v0", n_envs=3, seed=0)
    protocol = GreedyDistanceProtocol(
        [gym.make("sb3_er/SimplestWalker-v0")], dt=0.2, eval_interval=100.0, learning_time=600.0
    )
    model = SarsaLambda("TileQ", env, seed=0)
    model.learn(10_000, callback=protocol)
    times = [record["learning_time_s"] for record in protocol.records]
    assert times[0] == 0.0 and times[-1] >= 600.0
    # every 500 steps (100 s) is crossed once although num_timesteps moves by 3
    assert len(times) == 1 + 6 and all(b - a < 100.0 + 3 * 0.2 + 1e-9 for a, b in itertools.pairwise(times))
    assert protocol.falls == model.falls


def test_set_env_and_load_change_the_number_of_envs(tmp_path):
    model = ERSigma("TileQ", counters(1), seed=0, value_bound_action="ignore", **SMALL).learn(50)
    model.set_env(counters(3))
    model.learn(60, reset_num_timesteps=False)
    assert model.n_envs == 3 and model.replay_buffer.n_envs == 3
    model.save(tmp_path / "m")
    model.save_replay_buffer(tmp_path / "b.npz")
    loaded = ERSigma.load(tmp_path / "m", env=counters(2))
    loaded.load_replay_buffer(tmp_path / "b.npz")
    assert loaded.n_envs == 2 and loaded.replay_buffer.n_envs == 2
    loaded.learn(40, reset_num_timesteps=False)
    for trajectory in loaded.replay_buffer.trajectories():
        assert len(set(trajectory["observations"][:, 0].tolist())) == 1


def test_eval_callback_with_several_envs(tmp_path):
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0)
    callback = EvalCallback(
        make_vec_env("CartPole-v1", n_envs=1, seed=1), eval_freq=100, n_eval_episodes=2, log_path=str(tmp_path)
    )
    SarsaLambda("TileQ", env, seed=0, **SMALL).learn(600, callback=callback)
    assert callback.evaluations_timesteps == [200, 400, 600]  # every 100 calls of 2 env steps each


@pytest.mark.slow
@pytest.mark.parametrize("algo", [SarsaLambda, ERSigma, FQI])
def test_subprocess_envs(algo):
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0, vec_env_cls=SubprocVecEnv)
    try:
        model = algo("TileQ", env, seed=0, **SMALL).learn(400)
        assert model.num_timesteps == 400
    finally:
        env.close()


def _learned_on(vec_cls, algo, kwargs, steps=1_500):
    """theta, the falls and the last observations after ``steps`` on 2 CartPole envs of ``vec_cls``."""
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0, vec_env_cls=vec_cls)
    try:
        model = algo("TileQ", env, seed=0, value_bound_action="ignore", **SMALL, **kwargs).learn(steps)
        return model.policy.theta_array.copy(), model._episode_num, np.asarray(model._last_obs, dtype=np.float64)
    finally:
        env.close()


SUBPROCESS_CASES = [(SarsaLambda, {}), (ERSigma, {"online_lambda": 0.9}), (ER, {})]


@pytest.mark.parametrize(("algo", "kwargs"), SUBPROCESS_CASES, ids=lambda case: getattr(case, "__name__", str(case)))
def test_subprocess_envs_learn_exactly_as_envs_in_this_process(algo, kwargs):
    """Envs in subprocesses and in this process learn the same weights, bit for bit: a SubprocVecEnv goes through its
    own step, a DummyVecEnv's envs are stepped directly (with the env's float64 reward). Covers an online learner,
    ER with online Sarsa(lambda) between replays, and ER without."""
    here = _learned_on(DummyVecEnv, algo, kwargs)
    there = _learned_on(SubprocVecEnv, algo, kwargs)
    np.testing.assert_array_equal(here[0], there[0])
    assert here[1] == there[1] and here[1] > 10
    np.testing.assert_array_equal(here[2], there[2])


@pytest.mark.slow
@pytest.mark.parametrize("algo", ALGOS)
def test_every_algorithm_learns_exactly_as_in_this_process_on_subprocess_envs(algo):
    here, there = _learned_on(DummyVecEnv, algo, {}, 600), _learned_on(SubprocVecEnv, algo, {}, 600)
    np.testing.assert_array_equal(here[0], there[0])


def _non_finite_reward_once(at_step: int):
    """An env factory (pickled by value into the subprocess): CartPole whose ``at_step``-th reward is NaN."""

    def make():
        count = [0]

        def reward(value):
            count[0] += 1
            return float("nan") if count[0] == at_step else value

        return gym.wrappers.TransformReward(gym.make("CartPole-v1"), reward)

    return make


def test_an_error_while_subprocess_envs_step_ahead_leaves_them_usable():
    """Env 1's 30th reward is NaN: learn() stops with an error naming the env, the envs in their processes stay
    usable, and the next learn() resets them and goes on."""
    env = SubprocVecEnv([lambda: gym.make("CartPole-v1"), _non_finite_reward_once(30)])
    try:
        model = SarsaLambda("TileQ", env, seed=0, **SMALL)
        with pytest.raises(ValueError, match="env 1 returned a non-finite reward"):
            model.learn(200)
        assert model.num_timesteps == 60
        model.learn(200, reset_num_timesteps=False)
        assert model.num_timesteps == 260
        obs = env.reset()
        assert obs.shape == (2, 4)
    finally:
        env.close()


def _lambda_wrapped(env_id: str):
    """An env factory: ``env_id`` under TransformReward with a local function, which Gymnasium records in the env's
    spec, so that the spec of the env cannot be pickled."""

    def make():
        return gym.wrappers.TransformReward(gym.make(env_id), lambda value: value)

    return make


@pytest.mark.parametrize("env_id", ["CartPole-v1", "sb3_er/PendulumSwingup-v0"])
def test_an_env_whose_spec_cannot_be_pickled_works_in_subprocesses(env_id):
    """Resolving the tiling asks for env 0's spec (its id chooses a shipped tiling). In a SubprocVecEnv the worker
    must pickle the answer, and this spec holds a lambda: asked for it, the worker would die. The model takes the id
    from Gymnasium's description of the env instead, and gets the same tiling as in this process."""
    here = make_vec_env(
        env_id,
        n_envs=2,
        seed=0,
        wrapper_class=gym.wrappers.TransformReward,
        wrapper_kwargs={"func": lambda value: value},
    )
    env = SubprocVecEnv([_lambda_wrapped(env_id), _lambda_wrapped(env_id)])
    try:
        model = SarsaLambda("TileQ", env, seed=0, value_bound_action="ignore").learn(200)
        assert model.num_timesteps == 200
        expected = SarsaLambda("TileQ", here, seed=0).policy.tile_coder
        np.testing.assert_array_equal(model.policy.tile_coder.tile_widths, expected.tile_widths)
    finally:
        env.close()


class ScaleRewards(VecEnvWrapper):
    """A user's VecEnv wrapper that multiplies every reward by 10."""

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        return obs, rewards * 10.0, dones, infos


@pytest.mark.parametrize(
    "wrap",
    [
        lambda: ScaleRewards(DummyVecEnv([lambda: gym.make("sb3_er/WindyCliff-v0")])),
        lambda: VecMonitor(ScaleRewards(DummyVecEnv([lambda: gym.make("sb3_er/WindyCliff-v0")]))),
        lambda: ScaleRewards(VecMonitor(DummyVecEnv([lambda: gym.make("sb3_er/WindyCliff-v0")]))),
    ],
)
def test_a_reward_wrapper_at_any_level_makes_the_watch_observe(wrap):
    """WindyCliff's rewards x10 by a VecEnv wrapper (under VecMonitor or above it): the watch uses the rewards it
    observes instead of the env's declared ones, and replay raises no false ValueBoundWarning."""
    model = ER("TileQ", wrap(), seed=0, n_replays=10)
    assert model._watch.source == "observed" and "ScaleRewards" in model._watch.reason
    with _no_value_warning():
        model.learn(3000)


def test_vec_monitor_keeps_declared_bounds():
    model = ER("TileQ", VecMonitor(DummyVecEnv([lambda: gym.make("sb3_er/WindyCliff-v0")])), seed=0)
    assert model._watch.source == "env"


class _no_value_warning:
    def __enter__(self):
        import warnings

        self._catch = warnings.catch_warnings()
        self._catch.__enter__()
        warnings.simplefilter("error", ValueBoundWarning)

    def __exit__(self, *exc):
        self._catch.__exit__(*exc)
        return False


def test_the_dict_key_order_is_checked_on_set_env_and_load(tmp_path):
    """A model built on a Dict observation flattened as (a: 1, b: 2) refuses an env flattening (b: 2, a: 1) or
    renamed keys on set_env and load, naming both layouts."""

    class Keys(gym.Env):
        action_space = gym.spaces.Discrete(2)

        def __init__(self, keys=("a", "b")):
            self.observation_space = gym.spaces.Dict(
                {key: gym.spaces.Box(-1.0, 1.0, shape=(size,)) for key, size in zip(keys, (1, 2), strict=True)}
            )
            self.tile_widths = [0.5, 0.5, 0.5]

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            return self.observation_space.sample(), {}

        def step(self, action):
            return self.observation_space.sample(), 0.0, False, True, {}

    model = SarsaLambda("TileQ", Keys(), seed=0)
    assert model.observation_keys == [["a", 1], ["b", 2]]
    for other in (Keys(("c", "d")),):
        with pytest.raises(ValueError, match="flattens"):
            model.set_env(other)
    model.save(tmp_path / "m")
    with pytest.raises(ValueError, match="flattens"):
        SarsaLambda.load(tmp_path / "m", env=Keys(("c", "d")))
    assert SarsaLambda.load(tmp_path / "m", env=Keys()).observation_keys == [["a", 1], ["b", 2]]

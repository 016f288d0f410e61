"""Ctrl-C at any point of learn(), then learn(reset_num_timesteps=False), stores no transition that did not happen
(issue 37): a KeyboardInterrupt raised by a timer at a random moment (between any two Python statements of the loop,
the storage or the replay), over many trials, for one env and for several; the counter env's transitions say which
env and step they came from, so every stored one can be checked against what the env did."""

import signal

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv
from test_several_envs import Counter

from sb3_er import ER, FQI, ERSigma, SarsaLambda

SMALL = dict(policy_kwargs=dict(n_tilings=4, memory_size=2**14), value_bound_action="ignore")


def _interrupted(delay: float):
    def handler(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, delay)


def _check_buffer(buffer) -> int:
    """Every stored trajectory is a stretch of one env's episode from its start, as the counter env made it; the
    counts agree. Returns the stored transitions."""
    trajectories = buffer.trajectories()
    assert sum(len(t["actions"]) for t in trajectories) + buffer.open_length == buffer.n_transitions
    for trajectory in trajectories:
        env_id = int(trajectory["observations"][0, 0])
        steps = trajectory["observations"][:, 1]
        assert np.all(trajectory["observations"][:, 0] == env_id)
        np.testing.assert_array_equal(steps, np.arange(len(steps)))  # no step stored twice, none joined
        np.testing.assert_array_equal(trajectory["rewards"], env_id + steps)
        last = len(steps)
        np.testing.assert_array_equal(trajectory["next_obs"], [env_id, last])
        assert trajectory["terminated"] == (last == 3 + env_id)  # a truncation is never taken for a termination
    return buffer.n_transitions


@pytest.mark.parametrize("algo", [ER, ERSigma, FQI])
@pytest.mark.parametrize("n_envs", [1, 2])
def test_ctrl_c_anywhere_then_continuing_stores_only_what_happened(algo, n_envs):
    rng = np.random.default_rng(0)
    interrupted = 0
    for _ in range(12):
        model = algo("TileQ", DummyVecEnv([lambda i=i: Counter(i) for i in range(n_envs)]), seed=0, **SMALL)
        if algo is not FQI:
            model.n_replays = 3
        try:
            _interrupted(float(rng.uniform(0.0005, 0.02)))
            model.learn(20_000)
        except KeyboardInterrupt:
            interrupted += 1
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
        model.learn(300, reset_num_timesteps=False)
        assert _check_buffer(model.replay_buffer) > 0
    assert interrupted >= 10  # the trials were interrupted, mostly mid-learn


def test_ctrl_c_then_continuing_keeps_learning_online():
    """Sarsa(lambda): the traces of the cut episodes are cleared and the envs reset, so the continued run starts
    clean (no pending action, empty traces) and learns on."""
    model = SarsaLambda("TileQ", DummyVecEnv([lambda: Counter(0)]), seed=0, **SMALL)
    try:
        _interrupted(0.005)
        model.learn(1_000_000)
    except KeyboardInterrupt:
        pass
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
    steps = model.num_timesteps
    model.learn(100, reset_num_timesteps=False)
    assert model.num_timesteps == steps + 100 and not model._interrupted

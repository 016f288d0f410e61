"""SB3's test_logger behaviours for every algorithm: time/fps is the env steps per second of wall time of the current
learn() (checked against a count of the env's own steps and against a clock that only the env moves), it never divides
by zero, and the episode buffers hold stats_window_size episodes. (A logger given with set_logger and the success rate:
test_sb3_contract.py; TensorBoard scalars: test_run.py.)"""

import time
from unittest import mock

import numpy as np
import pytest
from sb3_cases import ALGOS, FQI, LSPI, InMemoryLogger, OneStepEnv, model

from sb3_er import SarsaLambda


@pytest.mark.parametrize("algo", ALGOS)
def test_fps_is_the_env_steps_of_this_learn_per_second(algo):
    """SB3's test_fps_logger: an env of at most 1,000 steps per second gives an fps of at most 1,000 and at least 100,
    at every learn(), also after num_timesteps jumps (the count restarts with each learn). FQI and LSPI fit every 25
    episodes here: a fit every one-step episode would be most of the time, rightly counted in fps."""
    env = OneStepEnv(delay=0.001)
    kwargs = dict(fit_every=25) if algo in (FQI, LSPI) else {}
    agent = model(algo, env, seed=0, **kwargs)
    agent.learn(50)  # compiles what the run needs
    for attempt in range(3):
        logger = InMemoryLogger()
        agent.set_logger(logger)
        if attempt == 2:
            agent.num_timesteps = 20_000
        steps_before, start = env.steps, time.perf_counter()
        agent.learn(100, log_interval=1, reset_num_timesteps=attempt != 2)
        elapsed = time.perf_counter() - start
        fps = logger.name_to_value["time/fps"]
        assert 100 <= fps <= 1000
        # an independent count: the env's steps over the wall time of this learn() (which also holds the last dump)
        counted = (env.steps - steps_before) / elapsed
        assert counted * 0.9 <= fps <= counted * 1.25 + 1


@pytest.mark.parametrize("algo", ALGOS)
def test_fps_counts_only_the_time_that_passed(algo):
    """A clock that only the env moves, 1 ms per step: every dump's fps is 1,000 (999 where the float division falls
    just short), however long fits, replays and logging took."""
    clock = [0]
    env = OneStepEnv(delay=0.001, clock=clock)
    agent = model(algo, env, seed=0)
    logger = InMemoryLogger()
    agent.set_logger(logger)
    with mock.patch("time.time_ns", lambda: clock[0]):
        agent.learn(60, log_interval=3)
    assert {dump["time/fps"] for dump in logger.dumped} <= {999, 1000}
    assert len(logger.dumped) == 20


@pytest.mark.parametrize("algo", ALGOS)
def test_fps_does_not_divide_by_zero(algo):
    """SB3's test_fps_no_div_zero: a clock that stands still (a coarse timer) must not break the logging."""
    agent = model(algo, OneStepEnv(delay=0.0), seed=0)
    agent.set_logger(InMemoryLogger())
    with mock.patch("time.time", lambda: 42.0), mock.patch("time.time_ns", lambda: 42):
        agent.learn(20, log_interval=1)
    assert agent.logger.name_to_value["time/fps"] > 0


@pytest.mark.parametrize("stats_window_size", [1, 42])
@pytest.mark.parametrize("algo", ALGOS)
def test_episode_buffers_hold_stats_window_size_episodes(algo, stats_window_size):
    agent = model(algo, OneStepEnv(delay=0.0), stats_window_size=stats_window_size).learn(10)
    assert agent.ep_info_buffer.maxlen == stats_window_size
    assert agent.ep_success_buffer.maxlen == stats_window_size


def test_fps_at_the_default_table_is_set_by_the_env():
    """SB3's test_fps_logger exactly: the model's defaults, a 1 ms env, a dump per one-step episode."""
    env = OneStepEnv(delay=0.001)
    agent = SarsaLambda("TileQ", env, seed=0)
    logger = InMemoryLogger()
    agent.set_logger(logger)
    agent.learn(100, log_interval=1)
    assert 100 <= logger.name_to_value["time/fps"] <= 1000


def test_the_table_statistics_are_scanned_at_most_once_per_n_weights_over_4096_steps():
    """train/weights_abs_mean and train/memory_fill scan every weight, so a dump after every one-step episode records
    them at the first dump and then once per n_weights / 4096 steps (16 at 2^16 weights): at steps 1, 17, ..., 97 of
    100; each recorded value is the table's at that dump (NumPy over theta)."""

    class Clearing(InMemoryLogger):
        def dump(self, step: int = 0) -> None:
            theta = agent.policy.weights.theta
            touched = theta != 0.0
            self.dumped.append(
                (
                    agent.num_timesteps,
                    dict(self.name_to_value),
                    np.abs(theta[touched]).mean() if touched.any() else 0.0,
                    touched.mean(),
                )
            )
            self.name_to_value.clear()

    agent = SarsaLambda("TileQ", OneStepEnv(delay=0.0), seed=0, policy_kwargs=dict(memory_size=2**16))
    logger = Clearing()
    agent.set_logger(logger)
    agent.learn(100, log_interval=1)
    scanned = [
        (step, values, mean, fill) for step, values, mean, fill in logger.dumped if "train/memory_fill" in values
    ]
    assert [step for step, *_ in scanned] == list(range(1, 101, 16))
    for _, values, mean, fill in scanned:
        assert values["train/weights_abs_mean"] == pytest.approx(mean, rel=1e-12)
        assert values["train/memory_fill"] == fill
    assert len(logger.dumped) == 100

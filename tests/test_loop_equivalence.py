"""The learn loop reproduces, bit for bit, what an earlier loop computed: final weights, every logged key and value
(the value watch's train/q_min etc. included), the episode buffers, the counters, and what a callback saw at every
step, for every algorithm, with and without a callback.

The fixture ``tests/fixtures/loop_equivalence.json`` was written by the loop before its per-step path was cut down
(``python tests/test_loop_equivalence.py --write`` rewrites it: only do so for a change that is meant to change
results, and say so in the commit). Each run is short (a few thousand steps) but long enough to pass through many
episode ends, log dumps and, for the replaying algorithms, replay phases or fits.

FQI's and LSPI's fits are the exception to "bit for bit": their solvers (conjugate gradients, SuperLU) reduce with
BLAS, whose kernels OpenBLAS picks by CPU, so the last digit of a fit can differ between machines (the fixture was
recorded on one CPU; an AMD EPYC gives, e.g., a fit residual of 0.09723489597709245 for 0.09723489597709244). For
them the logged floats compare to a relative 1e-9 and the weights by their sum, sum of squares and non-zero count
(recorded by the same earlier loop), while everything discrete (steps, episodes, actions, counters) stays exact.
"""

import hashlib
import json
import pathlib
import sys

import numpy as np
import pytest
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import KVWriter, Logger

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

FIXTURE = pathlib.Path(__file__).parent / "fixtures" / "loop_equivalence.json"
#: Logged keys that measure the clock, not the computation.
CLOCK_KEYS = ("time/fps", "time/time_elapsed", "train/fit_seconds")
SMALL_TABLE = dict(memory_size=2**16)
#: Runs whose fits reduce with BLAS (see the module docstring): floats to this relative tolerance.
SOLVER_RUNS = ("fqi_cartpole", "lspi_cartpole")
SOLVER_RTOL = 1e-9

#: name -> (class, env id, keyword arguments, learn steps, log_interval)
RUNS = {
    "sarsa_lambda_compass_walker": (
        SarsaLambda,
        "sb3_er/CompassWalker-v0",
        dict(
            learning_rate=0.4,
            gamma=0.99,
            trace_lambda=0.92,
            exploration_rate=0.05,
            policy_kwargs=dict(initial_value=(0.0, 1.0)),
        ),
        10_000,
        5,
    ),
    "sarsa_lambda_cartpole": (
        SarsaLambda,
        "CartPole-v1",
        dict(policy_kwargs=dict(n_tilings=8, **SMALL_TABLE)),
        5_000,
        20,
    ),
    "er_walker_segments": (
        ER,
        "sb3_er/SimplestWalker-v0",
        dict(preset="thesis", replay_trigger="segment", n_replays=10, policy_kwargs=dict(SMALL_TABLE)),
        3_000,
        5,
    ),
    "er_online_lambda_prioritized": (
        ER,
        "CartPole-v1",
        dict(
            preset="thesis",
            online_lambda=0.8,
            replay_order="prioritized",
            n_replays=5,
            policy_kwargs=dict(n_tilings=8, **SMALL_TABLE),
        ),
        2_000,
        3,
    ),
    "er_sigma_compass_walker": (
        ERSigma,
        "sb3_er/CompassWalker-v0",
        dict(
            preset="thesis",
            replays_per_stored_trajectory=2,
            policy_kwargs=dict(initial_value=(0.0, 1.0), **SMALL_TABLE),
        ),
        3_000,
        2,
    ),
    "residual_er_windy_cliff": (ResidualER, "sb3_er/WindyCliff-v0", dict(preset="thesis", n_replays=10), 3_000, 5),
    "residual_er_sigma_cartpole": (
        ResidualERSigma,
        "CartPole-v1",
        dict(preset="thesis", n_replays=10, policy_kwargs=dict(n_tilings=8, **SMALL_TABLE)),
        3_000,
        3,
    ),
    "dyna_mountain_car": (
        Dyna,
        "MountainCar-v0",
        dict(planning_steps=5, model_refit_every=250, policy_kwargs=dict(n_tilings=8, **SMALL_TABLE)),
        2_000,
        1,
    ),
    "fqi_cartpole": (
        FQI,
        "CartPole-v1",
        dict(fit_every=10, n_iterations=3, policy_kwargs=dict(n_tilings=4, **SMALL_TABLE)),
        2_000,
        5,
    ),
    "lspi_cartpole": (
        LSPI,
        "CartPole-v1",
        dict(fit_every=10, n_iterations=3, policy_kwargs=dict(n_tilings=4, **SMALL_TABLE)),
        2_000,
        5,
    ),
}


class RecordAll(KVWriter):
    """Keeps every dump's key/values (clock keys left out), as ``repr`` strings so that floats compare exactly."""

    def __init__(self):
        self.dumps = []

    def write(self, key_values, key_excluded, step=0):
        self.dumps.append([step, {k: repr(v) for k, v in sorted(key_values.items()) if k not in CLOCK_KEYS}])


class Witness(BaseCallback):
    """A callback that digests what SB3's callbacks read at every step (the loop's locals and the model's counters);
    it stops training at step ``stop_at`` (never by default)."""

    def __init__(self, stop_at: int = 0):
        super().__init__()
        self.digest = hashlib.sha256()
        self.stop_at = stop_at

    def _on_step(self) -> bool:
        # info values as Python scalars: an env's flag may be a NumPy bool where the value is the same
        infos = [
            {k: v.item() if isinstance(v, np.generic) else v for k, v in info.items() if k != "episode"}
            for info in self.locals["infos"]
        ]
        episodes = [info["episode"]["r"] for info in self.locals["infos"] if "episode" in info]
        seen = (
            self.num_timesteps,
            self.n_calls,
            repr(np.asarray(self.locals["actions"]).tolist()),
            repr(np.asarray(self.locals["new_obs"]).tolist()),
            repr(np.asarray(self.locals["rewards"]).tolist()),
            repr(np.asarray(self.locals["dones"]).tolist()),
            repr(infos),
            repr(episodes),
        )
        self.digest.update(repr(seen).encode())
        return self.num_timesteps != self.stop_at


def sha256(array: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def run(name: str, mode: str) -> dict:
    """One fixture run: its weights' hash, its log dumps, its episode buffer and counters, what the callback saw.

    :param mode: "no_callback"; "callback" (a Witness that never stops); or "stop_and_continue": the Witness stops
        training a third of the way (mid-episode), and a second ``learn(reset_num_timesteps=False)`` with the same
        callback runs the remaining steps, continuing the episode where it was.
    """
    algo, env_id, kwargs, steps, log_interval = RUNS[name]
    model = algo("TileQ", env_id, seed=1, **kwargs)
    recorder = RecordAll()
    model.set_logger(Logger(None, [recorder]))
    callback = None if mode == "no_callback" else Witness(steps // 3 + 1 if mode == "stop_and_continue" else 0)
    model.learn(steps, callback=callback, log_interval=log_interval)
    if mode == "stop_and_continue":
        stopped_at = model.num_timesteps
        assert stopped_at == callback.stop_at
        model.learn(steps - stopped_at, callback=callback, log_interval=log_interval, reset_num_timesteps=False)
    ep_info = [(repr(ep["r"]), ep["l"]) for ep in model.ep_info_buffer]
    theta = model.policy.theta_array
    result = {
        "weights_sha256": sha256(theta),
        "weights_summary": [float(theta.sum()), float(np.dot(theta, theta)), int(np.count_nonzero(theta))],
        "num_timesteps": int(model.num_timesteps),
        "episodes": int(model._episode_num),
        "falls": int(model.falls),
        "ep_info": hashlib.sha256(repr(ep_info).encode()).hexdigest(),
        "last_obs": repr(np.asarray(model._last_obs).tolist()),
        "dumps": recorder.dumps,
    }
    if callback is not None:
        result["callback_sha256"] = callback.digest.hexdigest()
    return result


#: Stopping and continuing for the two loops with a different after-transition path (online only, and replay)
STOP_AND_CONTINUE = ("sarsa_lambda_compass_walker", "er_walker_segments", "dyna_mountain_car")
CASES = [(name, mode) for name in RUNS for mode in ("no_callback", "callback")] + [
    (name, "stop_and_continue") for name in STOP_AND_CONTINUE
]


def case_id(name: str, mode: str) -> str:
    return f"{name}-{mode}"


@pytest.fixture(scope="module")
def expected() -> dict:
    return json.loads(FIXTURE.read_text())


@pytest.mark.parametrize("name, mode", CASES, ids=[case_id(*case) for case in CASES])
def test_the_loop_reproduces_the_recorded_runs(name, mode, expected):
    want = dict(expected[case_id(name, mode)])
    got = run(name, mode)
    assert len(got["dumps"]) == len(want["dumps"]), "a different number of log dumps"
    if name in SOLVER_RUNS:
        for (step, values), (want_step, want_values) in zip(got["dumps"], want["dumps"], strict=True):
            assert step == want_step and values.keys() == want_values.keys(), f"the log dump at step {want_step}"
            for key, value in values.items():
                assert close_reprs(value, want_values[key]), f"{key} at {want_step}: {value} for {want_values[key]}"
        summary, want_summary = got.pop("weights_summary"), want.pop("weights_summary")
        assert np.allclose(summary[:2], want_summary[:2], rtol=SOLVER_RTOL, atol=0) and summary[2] == want_summary[2]
        for key in ("weights_sha256", "dumps"):
            got.pop(key), want.pop(key)
        assert got == want
        return
    got.pop("weights_summary"), want.pop("weights_summary", None)  # the hash says more
    for (step, values), (want_step, want_values) in zip(got["dumps"], want["dumps"], strict=True):
        assert (step, values) == (want_step, want_values), f"the log dump at step {want_step} differs"
    assert got == want


def close_reprs(value: str, want: str) -> bool:
    """Two logged values (their reprs) the same, or floats equal to SOLVER_RTOL."""
    if value == want:
        return True
    try:
        return bool(np.isclose(float(value), float(want), rtol=SOLVER_RTOL, atol=0))
    except ValueError:
        return False


@pytest.mark.parametrize(
    "value, want, same",
    [
        ("1.0", "1.0", True),
        ("0.09723489597709245", "0.09723489597709244", True),
        ("0.0972349", "0.0972348", False),
        ("3", "4", False),
        ("nan", "1", False),
    ],
)
def test_close_reprs(value, want, same):
    assert close_reprs(value, want) is same


def test_without_a_callback_the_run_is_the_one_with_a_callback(expected):
    """The fixture itself: a callback that never stops changes nothing (an independent check of the recording)."""
    for name in RUNS:
        with_callback = dict(expected[case_id(name, "callback")])
        with_callback.pop("callback_sha256")
        assert with_callback == expected[case_id(name, "no_callback")], name
        assert len(with_callback["dumps"]) >= 3, f"{name}: too short to pass through several log dumps"


def test_stopping_and_continuing_is_the_uninterrupted_run(expected):
    """learn() stopped by a callback and continued with reset_num_timesteps=False ends where one learn() ends
    (weights, counters, episode buffer, what the callback saw), except for the log dumps the second learn() starts."""
    for name in STOP_AND_CONTINUE:
        continued, whole = expected[case_id(name, "stop_and_continue")], expected[case_id(name, "callback")]
        for key in whole:
            if key != "dumps":
                assert continued[key] == whole[key], (name, key)


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/test_loop_equivalence.py --write  (rewrites the fixture from the current loop)")
    FIXTURE.parent.mkdir(exist_ok=True)
    fixture = {case_id(*case): run(*case) for case in CASES}
    FIXTURE.write_text(json.dumps(fixture, indent=None, sort_keys=True) + "\n")
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size:,} bytes)")

"""Sample efficiency: how many samples each learner needs to reach a task's target, where it ends, and whether its
values stay inside the possible returns, on nine tasks, against Sarsa(lambda) and rl-zoo's tuned peers.

    python benchmarks/sample_efficiency.py --jobs 2                       # everything, 10 seeds, resumable
    python benchmarks/sample_efficiency.py --summarize                    # summary.md, summary.json and the figure
    python benchmarks/sample_efficiency.py --list                         # the tasks and methods, and what runs
    python benchmarks/sample_efficiency.py --tasks CartPole-v1 --methods sarsa_lambda --seeds 1 --scale 0.04 \\
        --eval-interval 1000 --json /tmp/smoke/runs.json                  # a smoke run, in a file of its own
    python benchmarks/sample_efficiency.py --summarize --json /tmp/smoke/runs.json   # its summary, beside it

Tasks (TASKS): Gymnasium's CartPole-v1, MountainCar-v0, Acrobot-v1, Pendulum-v1 and MountainCarContinuous-v0 and
dm_control's cartpole and pendulum swing-up: greedy evaluation every ``eval_interval`` steps (``evaluate_policy
(deterministic=True)`` over ``eval_episodes`` episodes on a separate env reset with seed 2000 + seed); the samples to
the target are the steps of the first evaluation whose mean greedy return reaches it. The thesis's tasks keep their
own protocols (sb3_er.experiments.specs, built by sb3_er.experiments.runner.build_protocol): the pendulum swing-up
records the return of every learning episode (Table 6.1; samples to the target in episodes: the first episode at which
the mean return of the last ``smoothing`` episodes reaches it), the simplest walker the greedy distance every 100 s of
learning time over 10 runs, and its falls (Table 6.2; samples in seconds of learning time). Each task states its
budget, its target and how the target was chosen, and Sarsa(lambda)'s median samples to the target in the committed
results, of which the evaluation interval is at most a tenth.

Methods (METHODS): a row is a class name and its keyword arguments, e.g. ``"er_sigma_stable": ("ERSigma", {"preset":
"stable"})``. sb3-er's classes get nothing but the env id, their class defaults and the row's arguments (``Algo("TileQ",
env, seed=seed, **kwargs)``, sb3-er's tiling for the id; the literal ER rows name ``preset="thesis"``, so that they stay
the thesis's algorithms whatever the default preset is); on the walker the ER classes replay as Table 6.2 runs them,
after every footstep or fall (the task's ``replay_protocol``, which sets when to replay and leaves the volume to the
preset; a method's own kwargs win). A row whose class does not take its
arguments (a stable variant before its option exists) is left out, with the reason. SB3's ``DQN`` and ``SAC`` run
with rl-zoo's tuned hyperparameters (read from the installed rl_zoo3 package by benchmarks/peers.py) on the tasks
rl-zoo has settings for; other tasks say "no peer settings". Every method gets the task's budget (``--peer-budget
rl-zoo`` gives the peers rl-zoo's ``n_timesteps`` instead, when smaller).

Each (task, method, seed) runs in a fresh worker subprocess (``--jobs`` at a time, one thread each), so that its CPU
seconds are its own; learn CPU and wall seconds leave out the evaluations. Short untimed warm-up runs of every (task,
sb3-er class) go first (``--no-warm-up`` skips them), so that no timed run pays for compiling numba's kernels. With
``--json FILE`` (default results/measured/sample_efficiency/runs.json) every finished run is written to FILE at once,
atomically, and runs already in it (same task, method, seed and budget) are skipped. A run records its evaluation curve,
samples to the target (None: never reached), the final return (mean of ``final_episodes`` greedy episodes after
learning, on an env reset with seed 1000 + seed; on the walker the distances of greedy 100 s runs), whether it diverged
(DivergenceError) and where, the value watch's count of values outside the possible returns and the largest excursion
beyond them (``model.largest_excursion`` where the class has it, else None), learn CPU and wall seconds, peak memory,
the package's code version, the worker's whole CPU time (imports and evaluations included, for planning), and on the
thesis's tasks their rise time, end performance and falls.

The summary (printed after every invocation; ``--summarize`` also writes summary.md, summary.json and
samples_to_target.png into ``--out``): per task and method, samples to the target as the median over seeds where a
seed that never reaches it counts as infinite (so the median is infinite once half the seeds or more never reach it),
with how many seeds reached it; the final return's mean and 95 % confidence interval over the runs that did not
diverge; the runs that diverged; the largest excursion beyond the possible returns (the largest over seeds, and the
median); CPU seconds. Then the goal's checks for ``--goal-method`` against Sarsa(lambda) (GOAL_CHECKS).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import math
import shlex
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import peers  # noqa: E402  (rl-zoo's hyperparameters, the clock, memory and the worker subprocess)

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "measured" / "sample_efficiency"
RUNS_FILE = "runs.json"
RESULT_PREFIX = "SAMPLE_EFFICIENCY_RESULT "
FORMAT = 1
DEFAULT_SEEDS = 10
REFERENCE = "sarsa_lambda"
FIGURE = "samples_to_target.png"


# --- tasks ---------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Task:
    """One task of the benchmark: its protocol, budget, target and where the target and the evaluation interval come
    from.

    :param env_id: the Gymnasium id.
    :param description: the kind of task in plain words.
    :param protocol: "greedy" (greedy evaluations every ``eval_interval`` steps), "episodes" (the return of every
        learning episode, Table 6.1) or "walking" (greedy distance every ``eval_interval`` s of learning time, Table
        6.2).
    :param budget: the run length, in ``unit``.
    :param unit: "steps", "episodes" or "s" (of learning time).
    :param eval_interval: between evaluations, in ``unit``.
    :param eval_episodes: greedy episodes (walking: runs) per evaluation.
    :param final_episodes: greedy episodes (walking: runs) after learning, for the final return (distance).
    :param target: the level the samples to the target are counted to.
    :param target_rule: how the target was chosen.
    :param sarsa_samples: Sarsa(lambda)'s median samples to the target in the committed results, in ``unit`` (a seed
        that never reached it counted as infinite).
    :param sarsa_source: where that figure comes from, seed by seed.
    :param smoothing: "episodes" only: the samples to the target count from the first episode at which the mean return
        of the last ``smoothing`` episodes reaches the target (default 1).
    :param replay_protocol: keyword arguments of the ER classes that make the task's replay protocol, as sorted
        ``(name, value)`` pairs (default none).
    :param final_metric: what the final figure is ("return", or "distance [m]" on the walker).
    """

    env_id: str
    description: str
    protocol: str
    budget: float
    unit: str
    eval_interval: float
    eval_episodes: int
    final_episodes: int
    target: float
    target_rule: str
    sarsa_samples: float
    sarsa_source: str
    smoothing: int = 1
    replay_protocol: tuple = ()
    final_metric: str = "return"

    @property
    def dm_control(self) -> bool:
        return self.env_id.startswith("dm_control/")

    @property
    def thesis_experiment(self) -> str | None:
        """The thesis experiment (sb3_er.experiments.specs.EXPERIMENTS) whose protocol the task runs, or None."""
        return {"episodes": "pendulum", "walking": "walker"}.get(self.protocol)


def _classic(env_id, description, target, sarsa_samples, eval_interval, seeds_text, source, target_rule):
    return Task(
        env_id=env_id,
        description=description,
        protocol="greedy",
        budget=100_000,
        unit="steps",
        eval_interval=eval_interval,
        eval_episodes=5,
        final_episodes=20,
        target=target,
        target_rule=target_rule,
        sarsa_samples=sarsa_samples,
        sarsa_source=f"results/measured/{source}/peers.json, seeds 0-4 (greedy evaluations every 5,000 steps): "
        + seeds_text,
    )


def _dm_control(env_id, description, target, target_rule, seeds_text):
    return Task(
        env_id=env_id,
        description=description,
        protocol="greedy",
        budget=500_000,
        unit="steps",
        eval_interval=10_000,
        eval_episodes=3,
        final_episodes=10,
        target=target,
        target_rule=target_rule,
        sarsa_samples=200_000,
        sarsa_source="results/measured/dmc_targets/runs/, seeds 0-4 (3 greedy episodes every 50,000 steps): first "
        f"point at the target {seeds_text}; the curve's coarse grid puts a seed's first point up to 50,000 steps "
        "late, so the interval is a tenth of 100,000",
    )


ISSUE_LEVEL = (
    "sb3-er's level for the greedy return after 100,000 steps (the classic control and continuous actions pages)"
)
TASKS: dict[str, Task] = {
    task.env_id: task
    for task in (
        _classic(
            "CartPole-v1",
            "balancing a pole on a cart (CartPole-v1)",
            450.0,
            35_000,
            2_500,
            "35,000, 20,000, 95,000, 15,000, never (peers.md prints 27,500, the median of the four that reached it)",
            "peers",
            ISSUE_LEVEL + " (Gymnasium's reward_threshold is 475)",
        ),
        _classic(
            "MountainCar-v0",
            "driving an underpowered car up a hill (MountainCar-v0)",
            -140.0,
            20_000,
            2_000,
            "20,000, 25,000, 20,000, 25,000, 15,000",
            "peers",
            ISSUE_LEVEL + " (Gymnasium's reward_threshold is -110)",
        ),
        _classic(
            "Acrobot-v1",
            "swinging up a two-link arm (Acrobot-v1)",
            -120.0,
            30_000,
            2_500,
            "30,000, 25,000, 30,000, 25,000, 30,000",
            "peers",
            ISSUE_LEVEL + " (Gymnasium's reward_threshold is -100)",
        ),
        _classic(
            "Pendulum-v1",
            "swinging up and holding a pendulum, continuous torque (Pendulum-v1)",
            -200.0,
            45_000,
            2_500,
            "60,000, 45,000, 40,000, 45,000, 40,000",
            "peers_continuous",
            ISSUE_LEVEL + " (rl-zoo's tuned SAC and TD3 end near -150; Gymnasium sets no reward_threshold)",
        ),
        _classic(
            "MountainCarContinuous-v0",
            "driving an underpowered car up a hill, continuous force (MountainCarContinuous-v0)",
            90.0,
            10_000,
            1_000,
            "10,000, 10,000, 15,000, 10,000, 10,000",
            "peers_continuous",
            ISSUE_LEVEL + " (Gymnasium's reward_threshold)",
        ),
        _dm_control(
            "dm_control/cartpole-swingup-v0",
            "swinging up and balancing a pole on a cart, continuous force (dm_control cartpole swing-up)",
            141.0,
            "90 % of the median over seeds 0-4 of Sarsa(λ)'s return reached after 500,000 steps in "
            "results/measured/dmc_targets (197.2, 30.4, 157.3, 234.8, 128.1: median 157.3), rounded down",
            "200,000, never, 50,000, 50,000, 350,000",
        ),
        _dm_control(
            "dm_control/pendulum-swingup-v0",
            "swinging up and holding a pendulum with a weak motor (dm_control pendulum swing-up)",
            48.0,
            "90 % of the median over seeds 0-4 of Sarsa(λ)'s return reached after 500,000 steps in "
            "results/measured/dmc_targets (121.5, 59.4, 53.6, 33.0, 52.9: median 53.6), rounded down",
            "150,000, 200,000, 200,000, 150,000, 200,000",
        ),
        Task(
            env_id="sb3_er/PendulumSwingup-v0",
            description="swinging up a pendulum whose motor is too weak to lift it at once (the thesis's pendulum)",
            protocol="episodes",
            budget=100,
            unit="episodes",
            eval_interval=1,
            eval_episodes=0,
            final_episodes=1,
            target=-24_000.0,
            target_rule="the level at which Table 6.1's rise time is measured for Sarsa(λ) in "
            "results/measured/table_6_1 (its mean curve over 20 seeds: the first episode's -54,007 plus 90 % of the "
            "way to the end performance -20,782, -24,104), rounded to the nearest 1,000; counted on the mean return "
            "of the last 10 learning episodes",
            sarsa_samples=81.5,
            sarsa_source="results/measured/table_6_1/runs/sarsa_lambda, 20 seeds (the zoo's thesis settings, "
            "gamma 0.98 and epsilon 0.1): the last 10 episodes' mean reaches -24,000 after 68-92 episodes in 19 seeds, "
            "never in one",
            smoothing=10,
        ),
        Task(
            env_id="sb3_er/SimplestWalker-v0",
            description="a walking robot in a simple simulation, where a fall ends the episode (the simplest walker)",
            protocol="walking",
            budget=5000.0,
            unit="s",
            eval_interval=100.0,
            eval_episodes=10,
            final_episodes=10,
            target=9.0,
            target_rule="90 % of Sarsa(λ)'s end performance in results/measured/table_6_2 (10.0 m walked in "
            "100 s, Table 6.2's protocol)",
            sarsa_samples=1150.0,
            sarsa_source="results/measured/table_6_2/runs/sarsa_lambda, 20 seeds: the greedy distance first reaches "
            "9.0 m after a median of 1150 s of learning time (19 of 20 seeds reach it)",
            replay_protocol=(("replay_trigger", "segment"),),
            final_metric="distance [m]",
        ),
    )
}
"""The nine tasks. The evaluation interval is at most a tenth of Sarsa(lambda)'s committed median samples to the
target (tests/test_sample_efficiency.py recomputes those from the committed files)."""


# --- methods -------------------------------------------------------------------------------------------------------

#: name -> (class, keyword arguments). sb3-er's classes by their name in ``sb3_er``; SB3's DQN and SAC with rl-zoo's
#: tuned hyperparameters. A row runs only where its class takes every keyword (method_unavailable).
METHODS: dict[str, tuple[str, dict[str, Any]]] = {
    "sarsa_lambda": ("SarsaLambda", {}),
    # The thesis's algorithms, literally, whatever the class default preset is.
    "er": ("ER", {"preset": "thesis"}),
    "er_sigma": ("ERSigma", {"preset": "thesis"}),
    # The stable variants: a preset, or single stabilizers, e.g. ("ERSigma", {"preset": "thesis", "target_copy": True}).
    "er_stable": ("ER", {"preset": "stable"}),
    "er_sigma_stable": ("ERSigma", {"preset": "stable"}),
    "residual_er": ("ResidualER", {"preset": "thesis"}),
    "residual_er_sigma": ("ResidualERSigma", {"preset": "thesis"}),
    "residual_er_stable": ("ResidualER", {"preset": "stable"}),
    "residual_er_sigma_stable": ("ResidualERSigma", {"preset": "stable"}),
    # each stabilizer alone and in combination, on ER-sigma (the thesis's preset otherwise)
    "er_sigma_truncate": ("ERSigma", {"preset": "thesis", "truncate_targets": True}),
    "er_sigma_target_copy": ("ERSigma", {"preset": "thesis", "target_copy": True}),
    "er_sigma_truncate_target_copy": ("ERSigma", {"preset": "thesis", "truncate_targets": True, "target_copy": True}),
    "er_sigma_step_bound": ("ERSigma", {"preset": "thesis", "step_size_bound": True}),
    "er_sigma_ratio_10": ("ERSigma", {"preset": "thesis", "replay_ratio": 10.0}),
    "er_sigma_truncate_target_copy_ratio_10": (
        "ERSigma",
        {"preset": "thesis", "truncate_targets": True, "target_copy": True, "replay_ratio": 10.0},
    ),
    "er_sigma_truncate_target_copy_ratio_50": (
        "ERSigma",
        {"preset": "thesis", "truncate_targets": True, "target_copy": True, "replay_ratio": 50.0},
    ),
    "er_sigma_averager": ("ERSigma", {"preset": "thesis", "averager": True}),
    "er_sigma_averager_target_copy": ("ERSigma", {"preset": "thesis", "averager": True, "target_copy": True}),
    "er_sigma_project": ("ERSigma", {"preset": "thesis", "project_weights": True}),
    "dqn": ("DQN", {}),
    "sac": ("SAC", {}),
}
#: The methods run when ``--methods`` is not given (those available; the other rows only when asked for).
DEFAULT_METHODS = ("sarsa_lambda", "er", "er_sigma", "er_stable", "er_sigma_stable", "dqn", "sac")
#: SB3's classes that run as rl-zoo's tuned peers, by their rl-zoo name.
PEER_CLASSES = {"DQN": "dqn", "SAC": "sac"}
LABELS = {
    "sarsa_lambda": "Sarsa(λ)",
    "er": "ER",
    "er_sigma": "ER-σ",
    "er_stable": "ER (stable)",
    "er_sigma_stable": "ER-σ (stable)",
    "residual_er": "residual ER",
    "residual_er_sigma": "residual ER-σ",
    "residual_er_stable": "residual ER (stable)",
    "residual_er_sigma_stable": "residual ER-σ (stable)",
    "er_sigma_truncate": "ER-σ + truncation",
    "er_sigma_target_copy": "ER-σ + target copy",
    "er_sigma_truncate_target_copy": "ER-σ + truncation + target copy",
    "er_sigma_step_bound": "ER-σ + step-size bound",
    "er_sigma_ratio_10": "ER-σ + replay ratio 10",
    "er_sigma_truncate_target_copy_ratio_10": "ER-σ + truncation + target copy + ratio 10",
    "er_sigma_truncate_target_copy_ratio_50": "ER-σ + truncation + target copy + ratio 50",
    "er_sigma_averager": "ER-σ + averager",
    "er_sigma_averager_target_copy": "ER-σ + averager + target copy",
    "er_sigma_project": "ER-σ + projection",
    "dqn": "DQN (rl-zoo)",
    "sac": "SAC (rl-zoo)",
}
NO_PEER_SETTINGS = "no peer settings"


def label(method: str) -> str:
    return LABELS.get(method, method)


def is_peer(method: str) -> bool:
    return METHODS[method][0] in PEER_CLASSES


def method_unavailable(method: str) -> str | None:
    """Why `method` cannot run with today's package (its class lacks one of its keyword arguments), or None."""
    import sb3_er
    from sb3_er.common.docstrings import accepted_parameters

    class_name, kwargs = METHODS[method]
    if class_name in PEER_CLASSES:
        return None
    cls = getattr(sb3_er, class_name)
    missing = sorted(set(kwargs) - set(accepted_parameters(cls)))
    if missing:
        return f"{class_name} takes no {', '.join(missing)} yet"
    return None


def applies(method: str, task: Task) -> bool:
    """Whether `method` runs on `task`: sb3-er's classes on every task; a peer where rl-zoo has tuned settings of it
    for the env id (rl-zoo's dqn.yml holds discrete-action envs only, its sac.yml continuous-action ones)."""
    class_name, _ = METHODS[method]
    if class_name not in PEER_CLASSES:
        return True
    return task.env_id in peers.rl_zoo_env_ids(PEER_CLASSES[class_name])


def model_kwargs(method: str, task: Task) -> dict[str, Any]:
    """The keyword arguments `method` is built with on `task`: the task's replay protocol for the ER classes (where
    the class takes them), then the method's own, which win."""
    from sb3_er.common.docstrings import accepted_parameters

    class_name, kwargs = METHODS[method]
    if class_name in PEER_CLASSES:
        return dict(kwargs)
    import sb3_er

    accepted = set(accepted_parameters(getattr(sb3_er, class_name)))
    protocol = {name: value for name, value in task.replay_protocol if name in accepted}
    return {**protocol, **kwargs}


# --- the worker: one (task, method, seed) in its own process ---------------------------------------------------------


def _make_env(task: Task, for_evaluation: bool = False):
    import gymnasium as gym

    from sb3_er.common.env_ids import register_env_id

    register_env_id(task.env_id)  # the sb3_er/ and dm_control/ namespaces
    env = gym.make(task.env_id)
    if for_evaluation and task.dm_control:  # the model flattens its own learning env; greedy episodes need it too
        env = gym.wrappers.FlattenObservation(env)
    return env


def _build_model(method: str, task: Task, env, seed: int):
    class_name, _ = METHODS[method]
    if class_name in PEER_CLASSES:
        return peers.rl_zoo_model(PEER_CLASSES[class_name], env, seed)
    import sb3_er

    return getattr(sb3_er, class_name)("TileQ", env, seed=seed, **model_kwargs(method, task))


def first_reaching_smoothed(returns: list[float], level: float, window: int) -> int | None:
    """The first episode (1-based) at which the mean of the last `window` episodes' returns reaches `level`; None if
    none does (the first `window` - 1 episodes have no full window).

    :param returns: the return of every episode, in order.
    :param level: the target.
    :param window: episodes per mean.
    """
    for end in range(window, len(returns) + 1):
        if statistics.fmean(returns[end - window : end]) >= level:
            return end
    return None


def _watch_figures(model) -> dict[str, Any]:
    from sb3_er.experiments.protocols import values_out_of_range

    if not hasattr(model, "value_excursion"):  # a peer: no value watch
        return {"values_out_of_range": None, "value_bounds": None, "first_value_excursion": None}
    bounds = model.value_bounds
    return {
        "values_out_of_range": values_out_of_range(model),
        "value_bounds": None if bounds is None else [float(bounds[0]), float(bounds[1])],
        "first_value_excursion": model.value_excursion,
    }


def _largest_excursion(model) -> float | None:
    value = getattr(model, "largest_excursion", None)
    return None if value is None else float(value)


def run_task(config: dict) -> dict:
    """Learn one (task, method, seed) under the task's protocol and return its record (see the module docstring)."""
    import warnings

    import numpy as np
    import torch

    from sb3_er import DivergenceError, ValueBoundWarning
    from sb3_er.experiments.records import code_version

    torch.set_num_threads(1)
    code = code_version()
    task = dataclasses.replace(
        TASKS[config["task"]], **{key: config[key] for key in ("eval_interval", "eval_episodes", "final_episodes")}
    )
    method, seed, budget = config["method"], config["seed"], config["budget"]
    env = _make_env(task)
    if task.protocol == "greedy":
        from stable_baselines3.common.monitor import Monitor

        env = Monitor(env)
    baseline_mb = peers.peak_rss_mb()
    model = _build_model(method, task, env, seed)
    clock = peers.Clock()
    curve: list[tuple[float, float]] = []
    extra: dict[str, Any] = {}
    callback, total_timesteps = _protocol(task, env, model, seed, budget, clock, curve)
    diverged_at = divergence = None
    try:
        with warnings.catch_warnings():  # counted in the record instead (values_out_of_range)
            warnings.simplefilter("ignore", ValueBoundWarning)
            model.learn(total_timesteps=total_timesteps, callback=callback)
    except DivergenceError as error:
        diverged_at, divergence = int(model.num_timesteps), str(error)[:500]
    learn_wall_s, learn_cpu_s = clock.learning()
    if task.protocol == "episodes":
        curve[:] = [(record["episode"], record["return"]) for record in callback.records]
        returns = [value for _, value in curve]
        samples = first_reaching_smoothed(returns, task.target, task.smoothing)
        episodes = len(callback.records)
        steps_to_target = None if samples is None else int(callback.records[samples - 1]["timesteps"])
        extra["curve_steps"] = [int(record["timesteps"]) for record in callback.records]
    elif task.protocol == "walking":
        curve[:] = [(record["learning_time_s"], record["distance"]) for record in callback.records]
        samples = peers.first_reaching(curve, task.target)
        episodes = callback.episodes
        steps_to_target = None if samples is None else round(samples / callback.dt)
        extra["curve_steps"] = [int(record["timesteps"]) for record in callback.records]
        extra["cumulative_falls"] = [int(record["cumulative_falls"]) for record in callback.records]
        extra.update(_walking_figures(task, curve, callback.falls))
    else:
        samples = peers.first_reaching(curve, task.target)
        steps_to_target = samples
        episodes = len(env.get_episode_rewards())
    final = None
    if diverged_at is None:
        final = _final_performance(task, model, callback, seed)
    if task.protocol == "episodes":
        extra.update(_episode_figures(curve))
    record = {
        **config,
        "unit": task.unit,
        "target": task.target,
        "algorithm": METHODS[method][0],
        "kwargs": model_kwargs(method, task),
        "curve": [[float(x), float(y)] for x, y in curve],
        "samples_to_target": samples,
        "steps_to_target": steps_to_target,
        "final_returns": final,
        "final_mean": None if final is None else float(np.mean(final)),
        "diverged": diverged_at is not None,
        "diverged_at_step": diverged_at,
        "divergence": divergence,
        **_watch_figures(model),
        "largest_excursion": _largest_excursion(model),
        "learn_cpu_s": learn_cpu_s,
        "learn_wall_s": learn_wall_s,
        "eval_cpu_s": clock.eval_cpu,
        "process_cpu_s": time.process_time(),  # the whole worker: imports, set-up, learning and evaluations
        "steps": int(model.num_timesteps),
        "episodes": int(episodes),
        "peak_rss_mb": peers.peak_rss_mb(),
        "baseline_rss_mb": baseline_mb,
        "code_version": code,
        **extra,
    }
    return json.loads(json.dumps(record, default=_jsonable))


def _jsonable(value):
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def _protocol(task: Task, env, model, seed: int, budget: float, clock, curve: list):
    """(the callback of the task's protocol, the timesteps to give ``learn``)."""
    if task.protocol == "greedy":
        from stable_baselines3.common.monitor import Monitor

        eval_env = Monitor(_make_env(task, for_evaluation=True))
        eval_env.reset(seed=2000 + seed)
        callback = peers.greedy_evaluations(
            model, eval_env, task.eval_episodes, int(task.eval_interval), int(budget), clock, curve
        )
        return callback, int(budget)
    from sb3_er.experiments.runner import build_protocol
    from sb3_er.experiments.specs import EXPERIMENTS

    experiment = EXPERIMENTS[task.thesis_experiment]
    if task.protocol == "walking":
        experiment = dataclasses.replace(experiment, eval_interval=task.eval_interval, eval_runs=task.eval_episodes)
    callback, total_timesteps = build_protocol(experiment, env, budget, seed)
    if task.protocol == "walking":  # the greedy runs are evaluation, not learning
        evaluate = callback._evaluate
        callback._evaluate = lambda: clock.evaluation(evaluate)
    return callback, total_timesteps


def _final_performance(task: Task, model, callback, seed: int) -> list[float]:
    """The final figure's samples: the returns of greedy episodes after learning (``evaluate_policy``, on an env reset
    with seed 1000 + seed); on the walker the distances of greedy runs of the protocol's evaluation envs."""
    if task.protocol == "walking":
        distances: list[float] = []
        while len(distances) < task.final_episodes:
            distances += [float(d) for d in callback.greedy_distances()]
        return distances[: task.final_episodes]
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    final_env = Monitor(_make_env(task, for_evaluation=True))
    final_env.reset(seed=1000 + seed)
    returns, _ = evaluate_policy(
        model, final_env, n_eval_episodes=task.final_episodes, deterministic=True, return_episode_rewards=True
    )
    return [float(r) for r in returns]


def _walking_figures(task: Task, curve, falls: int) -> dict[str, Any]:
    """A walker run's own rise time, end performance (Table 6.2's metrics on its curve) and falls."""
    from sb3_er.experiments.metrics import end_performance, rise_time
    from sb3_er.experiments.specs import EXPERIMENTS

    x = [point[0] for point in curve]
    y = [point[1] for point in curve]
    end = end_performance(y, EXPERIMENTS["walker"].success_threshold)
    return {
        "rise_time": None if math.isnan(end) else _finite_or_none(rise_time(x, y, end)),
        "end_performance": _finite_or_none(end),
        "falls": int(falls),
    }


def _episode_figures(curve) -> dict[str, Any]:
    """A pendulum run's own rise time and end performance (Table 6.1's metrics on its curve)."""
    from sb3_er.experiments.metrics import end_performance, rise_time

    if not curve:
        return {"rise_time": None, "end_performance": None}
    x = [point[0] for point in curve]
    y = [point[1] for point in curve]
    end = end_performance(y)
    return {"rise_time": _finite_or_none(rise_time(x, y, end)), "end_performance": _finite_or_none(end)}


def _finite_or_none(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


# --- the driver ------------------------------------------------------------------------------------------------------

#: The settings of a run that must agree with a finished run of the same key for it to count as done.
PROTOCOL_KEYS = ("eval_interval", "eval_episodes", "final_episodes", "algorithm", "kwargs")


def run_key(record: dict) -> tuple:
    """What makes two runs the same run: task, method, seed and budget."""
    return (record["task"], record["method"], int(record["seed"]), float(record["budget"]))


def plan_runs(
    tasks: list[str],
    methods: list[str],
    seeds: list[int],
    scale: float = 1.0,
    eval_interval: float | None = None,
    eval_episodes: int | None = None,
    final_episodes: int | None = None,
    peer_budget: str = "task",
) -> list[dict]:
    """The configurations of every (task, method, seed) to run, seeds outermost (so that the first seeds of every pair
    finish first), each method only on the tasks it applies to.

    :param tasks: env ids of TASKS.
    :param methods: names of METHODS.
    :param seeds: the seeds.
    :param scale: each task's budget times this, rounded to whole steps, episodes or seconds (smoke runs; default 1).
    :param eval_interval: the evaluation interval instead of the task's (default None).
    :param eval_episodes: episodes (walker: runs) per evaluation instead of the task's (default None).
    :param final_episodes: episodes (walker: runs) of the final evaluation instead of the task's (default None).
    :param peer_budget: "task" (every method the task's budget) or "rl-zoo" (a peer rl-zoo's n_timesteps when
        smaller).
    """
    configs = []
    for seed in seeds:
        for env_id in tasks:
            task = TASKS[env_id]
            for method in methods:
                if not applies(method, task):
                    continue
                run_budget = max(1, round(task.budget * scale))
                if peer_budget == "rl-zoo" and is_peer(method):
                    zoo_steps, _ = peers.rl_zoo_hyperparameters(PEER_CLASSES[METHODS[method][0]], env_id)
                    run_budget = min(run_budget, zoo_steps)
                configs.append(
                    {
                        "task": env_id,
                        "method": method,
                        "seed": seed,
                        "budget": run_budget,
                        "eval_interval": task.eval_interval if eval_interval is None else eval_interval,
                        "eval_episodes": task.eval_episodes if eval_episodes is None else eval_episodes,
                        "final_episodes": task.final_episodes if final_episodes is None else final_episodes,
                        "algorithm": METHODS[method][0],
                        "kwargs": model_kwargs(method, task),
                    }
                )
    return configs


#: The fields of a run record the summary reads, besides its key and protocol (PROTOCOL_KEYS).
SUMMARY_KEYS = ("samples_to_target", "final_mean", "diverged", "learn_cpu_s", "curve")
#: Those of them that are numbers, or None where the run has none (never reached, no final return).
NUMBER_KEYS = ("samples_to_target", "final_mean", "learn_cpu_s")


def _number_or_none(value) -> bool:
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))


class RunsFileError(ValueError):
    """The runs file is damaged, of another format, or holds a run made with other settings than the one planned."""


def read_runs_file(path: Path) -> dict[str, Any]:
    """A runs file: ``{"format": 1, "commands": [the command lines that wrote to it], "runs": [the runs]}``, empty
    when it does not exist; RunsFileError (or DamagedFileError) naming the file when it is not one."""
    from sb3_er.experiments.files import read_json

    if not path.exists():
        return {"format": FORMAT, "commands": [], "runs": []}
    data = read_json(path, "move it aside and run again (finished runs in it are lost)")
    if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("runs"), list):
        raise RunsFileError(f"{path} is no runs file of this benchmark (expected format {FORMAT} with a list 'runs')")
    seen: dict[tuple, int] = {}
    for index, run in enumerate(data["runs"]):
        if not isinstance(run, dict):
            raise RunsFileError(f"{path}: runs[{index}] is no run record (an object)")
        missing = [key for key in ("task", "method", "seed", "budget", *PROTOCOL_KEYS, *SUMMARY_KEYS) if key not in run]
        if missing:
            raise RunsFileError(f"{path}: runs[{index}] lacks {missing}")
        if run["task"] not in TASKS or run["method"] not in METHODS:
            raise RunsFileError(
                f"{path}: runs[{index}] is of an unknown task or method ({run['task']!r}, {run['method']!r})"
            )
        bad = [key for key in NUMBER_KEYS if not _number_or_none(run[key])]
        if bad or not isinstance(run["diverged"], bool):
            raise RunsFileError(f"{path}: runs[{index}] has bad values of {bad or ['diverged']}")
        key = run_key(run)
        if key in seen:
            raise RunsFileError(f"{path}: runs[{index}] repeats runs[{seen[key]}] ({_describe(run)})")
        seen[key] = index
    return {"format": FORMAT, "commands": list(data.get("commands", [])), "runs": data["runs"]}


def read_runs(path: Path) -> list[dict]:
    """The runs of a runs file (:func:`read_runs_file`); [] when it does not exist."""
    return read_runs_file(path)["runs"]


def write_runs(path: Path, runs: list[dict], commands: list[str]) -> None:
    """Write a runs file atomically (:func:`read_runs_file` reads it)."""
    from sb3_er.experiments.files import write_json

    write_json(path, {"format": FORMAT, "commands": commands, "runs": runs})


def pending_runs(configs: list[dict], finished: list[dict], path: Path) -> list[dict]:
    """The planned runs not yet in `finished`; RunsFileError when a finished run of the same key was made with other
    settings (another evaluation interval, other keyword arguments), so that no table mixes them."""
    done = {run_key(run): run for run in finished}
    pending = []
    for config in configs:
        run = done.get(run_key(config))
        if run is None:
            pending.append(config)
            continue
        differing = [key for key in PROTOCOL_KEYS if run[key] != config[key]]
        if differing:
            raise RunsFileError(
                f"{path} holds {config['method']} on {config['task']} (seed {config['seed']}) made with other "
                f"settings ({', '.join(f'{key} {run[key]!r}, now {config[key]!r}' for key in differing)}): use "
                "another --json file, or remove those runs from it"
            )
    return pending


def _describe(config: dict) -> str:
    return f"{config['method']} on {config['task']} (seed {config['seed']}, budget {config['budget']:g})"


#: A warm-up run's length per protocol, in the task's unit: long enough to end an episode (and replay) once or more.
WARM_UP_BUDGET = {"greedy": 2000, "episodes": 2, "walking": 100}


def warm_up_configs(configs: list[dict]) -> list[dict]:
    """One short run of every (task, sb3-er class, arguments) among `configs`, made before them and kept nowhere: it
    compiles (and caches on disk) the numba kernels those runs use, so that no timed run pays for the compilation."""
    warm_ups: dict[tuple, dict] = {}
    for config in configs:
        key = (config["task"], config["algorithm"], json.dumps(config["kwargs"], sort_keys=True))
        if is_peer(config["method"]) or key in warm_ups:
            continue
        budget = min(WARM_UP_BUDGET[TASKS[config["task"]].protocol], config["budget"])
        warm_ups[key] = {**config, "budget": budget, "eval_interval": budget, "eval_episodes": 1, "final_episodes": 1}
    return list(warm_ups.values())


def run_all(
    configs: list[dict], path: Path | None, jobs: int, command: str, python: str = sys.executable
) -> tuple[list, list]:
    """Run `configs` in worker subprocesses, `jobs` at a time; write each finished run to `path` (atomically) as it
    ends, with `command` among the file's commands (with `path` None, keep them nowhere: a warm-up). Returns (the
    finished runs, the failures as (config, message))."""
    existing = read_runs_file(path) if path is not None else {"commands": [], "runs": []}
    finished = existing["runs"]
    commands = existing["commands"] + ([command] if command not in existing["commands"] else [])
    script = Path(__file__).resolve()
    failures = []

    def one(config: dict) -> dict:
        return peers.run_in_subprocess(
            script, config, python, RESULT_PREFIX, _describe(config), environment=peers.WORKER_THREADS
        )

    pool = concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs))
    futures = {pool.submit(one, config): config for config in configs}
    try:
        for future in concurrent.futures.as_completed(futures):
            config = futures[future]
            try:
                run = future.result()
            except RuntimeError as error:
                failures.append((config, str(error)))
                print(f"FAILED: {error}", file=sys.stderr, flush=True)
                continue
            finished.append(run)
            if path is None:
                continue
            write_runs(path, finished, commands)
            reached = run["samples_to_target"]
            print(
                f"{_describe(config)}: to target {'never' if reached is None else f'{reached:g}'}, final "
                f"{'diverged' if run['diverged'] else format(run['final_mean'], '.1f')}, "
                f"{run['learn_cpu_s']:.1f} CPU s ({len(finished)} runs in the file)",
                file=sys.stderr,
                flush=True,
            )
    finally:  # Ctrl-C reaches the running workers too, a kill of this process alone by peers.end_with_parent
        pool.shutdown(wait=True, cancel_futures=True)
    return finished, failures


# --- the summary ---------------------------------------------------------------------------------------------------


def median_with_infinity(samples: list[float | None]) -> float:
    """The median of samples to the target over seeds, where None (never reached) counts as infinite: infinite once
    half the seeds or more never reach it (with an even number of seeds the middle two are averaged).

    :param samples: each seed's samples to the target, None for never.
    """
    if not samples:
        raise ValueError("no seeds to take the median of")
    return float(statistics.median([math.inf if value is None else float(value) for value in samples]))


def mean_ci(values: list[float]) -> tuple[float | None, float | None]:
    """(mean, half-width of its 95 % Student-t interval) of `values`, by sb3_er.experiments.metrics; (None, None) for
    no values and a None half-width for one."""
    from sb3_er.experiments.metrics import mean_confidence_interval

    if not values:
        return None, None
    mean, half_width = mean_confidence_interval(values)
    return float(mean), (None if math.isnan(float(half_width)) else float(half_width))


def _number(value: float) -> float | None:
    """A figure as JSON takes it: None for infinite or NaN."""
    return None if value is None or not math.isfinite(value) else float(value)


def _thesis_curves(task: Task, runs: list[dict]) -> dict[str, Any]:
    """Table 6.1's or 6.2's figures over the runs that did not diverge: the mean curve's rise time and end performance
    (with its CI), and on the walker the mean falls (with CI), as sb3_er.experiments.metrics.summarize_curves gives
    them."""
    from sb3_er.experiments.metrics import summarize_curves
    from sb3_er.experiments.specs import EXPERIMENTS

    kept = [run for run in runs if not run["diverged"]]
    lengths = {len(run["curve"]) for run in kept}
    if not kept or len(lengths) != 1 or 0 in lengths:
        return {"rise_time": None, "end_performance": None, "end_performance_ci": None, "falls": None, "falls_ci": None}
    x = [point[0] for point in kept[0]["curve"]]
    curves = [[point[1] for point in run["curve"]] for run in kept]
    falls = [run["cumulative_falls"] for run in kept] if task.protocol == "walking" else None
    threshold = EXPERIMENTS[task.thesis_experiment].success_threshold
    summary = summarize_curves(x, curves, falls, success_threshold=threshold)
    return {
        "rise_time": _number(summary.rise_time),
        "end_performance": _number(summary.end_performance),
        "end_performance_ci": _number(summary.end_performance_ci),
        "falls": summary.falls,
        "falls_ci": _number(summary.falls_ci) if summary.falls_ci is not None else None,
    }


def excursion_beyond_margin(run: dict) -> float | None:
    """How far a run's values went beyond the possible returns widened by the value watch's margin (0: never), from
    its record, with no rerun: None where the largest excursion was not recorded.

    The watch counts the values beyond the margin (``values_out_of_range``), so a run that counted none has 0 whatever
    its largest excursion (rounding: a sum of N projected weights can exceed V_max by a few ulps). Otherwise the
    largest excursion less the margin at the watch's first flag (``first_value_excursion``): the margin grows only as
    observed rewards widen the bounds, so this is never smaller than the excursion beyond the run's final margin.
    Where the record has no count or no first flag, the largest excursion as recorded (no margin known to take off);
    a NaN excursion is infinite.
    """
    largest = run.get("largest_excursion")
    if largest is None:
        return None
    if math.isnan(largest):  # the watch saw a NaN: as far out as it gets
        return math.inf
    if run.get("values_out_of_range") == 0:
        return 0.0
    # no count (-1: no bounds) or no first flag recorded: the margin is unknown, so none is taken off
    margin = (run.get("first_value_excursion") or {}).get("margin") or 0.0
    return max(0.0, float(largest) - float(margin))


def summarize_runs(task: Task, runs: list[dict]) -> dict[str, Any]:
    """The figures of one method on one task over its runs (one per seed): see the module docstring."""
    if not runs:
        raise ValueError(f"no runs to summarize on {task.env_id}")
    samples = [run["samples_to_target"] for run in runs]
    median = median_with_infinity(samples)
    finals = [run["final_mean"] for run in runs if not run["diverged"] and run["final_mean"] is not None]
    final_mean, final_ci = mean_ci(finals)
    excursions = [run["largest_excursion"] for run in runs if run.get("largest_excursion") is not None]
    beyond = [excursion_beyond_margin(run) for run in runs]
    beyond = [value for value in beyond if value is not None]
    outside = [run["values_out_of_range"] for run in runs if run.get("values_out_of_range") is not None]
    cpu = [run["learn_cpu_s"] for run in runs]
    steps = sum(run["steps"] for run in runs)
    figures = {
        "applies": True,
        "runs": len(runs),
        "seeds": sorted(run["seed"] for run in runs),
        "budget": runs[0]["budget"],
        "unit": task.unit,
        "eval_interval": runs[0]["eval_interval"],
        "target": task.target,
        "samples_to_target": _number(median),  # None: infinite
        "samples_to_target_infinite": math.isinf(median),
        "samples_per_seed": samples,
        "reached": sum(value is not None for value in samples),
        "final_mean": final_mean,
        "final_ci95": final_ci,
        "final_runs": len(finals),
        "final_metric": task.final_metric,
        "diverged": sum(run["diverged"] for run in runs),
        "diverged_runs": [{"seed": run["seed"], "step": run["diverged_at_step"]} for run in runs if run["diverged"]],
        "largest_excursion_max": max(excursions) if excursions else None,
        "largest_excursion_median": float(statistics.median(excursions)) if excursions else None,
        "largest_excursion_runs": len(excursions),
        "excursion_beyond_margin_max": max(beyond) if beyond else None,
        "excursion_beyond_margin_median": float(statistics.median(beyond)) if beyond else None,
        "runs_outside_returns": sum(count > 0 for count in outside) if outside else None,
        "values_out_of_range_max": max(outside) if outside else None,
        "learn_cpu_s_median": float(statistics.median(cpu)),
        "learn_cpu_s_total": float(sum(cpu)),
        "cpu_s_per_1000_steps": 1000.0 * sum(cpu) / steps if steps else None,
    }
    if task.thesis_experiment is not None:
        figures.update(_thesis_curves(task, runs))
    return figures


def summarize(runs: list[dict], tasks: list[str] | None = None) -> dict[str, dict[str, Any]]:
    """Per task id, per method name: the figures of summarize_runs, and for a method that does not apply to the task
    ``{"applies": False, "note": "no peer settings"}``. Tasks and methods in TASKS' and METHODS' order.

    :param runs: the finished runs.
    :param tasks: the task ids to cover (default: those with runs).
    """
    groups: dict[tuple[str, str], list[dict]] = {}
    for run in runs:
        groups.setdefault((run["task"], run["method"]), []).append(run)
    for (env_id, method), group in groups.items():
        budgets = {run["budget"] for run in group}
        settings = {json.dumps([run[key] for key in PROTOCOL_KEYS], sort_keys=True) for run in group}
        if len(budgets) > 1 or len(settings) > 1:
            raise RunsFileError(
                f"the runs of {method} on {env_id} mix budgets {sorted(budgets)} or settings: summarize them apart"
            )
    present = tasks or [env_id for env_id in TASKS if any(key[0] == env_id for key in groups)]
    methods = [method for method in METHODS if any(key[1] == method for key in groups)]
    summary: dict[str, dict[str, Any]] = {}
    for env_id in present:
        task = TASKS[env_id]
        summary[env_id] = {}
        for method in methods:
            if (env_id, method) in groups:
                summary[env_id][method] = summarize_runs(task, groups[(env_id, method)])
            elif is_peer(method):
                summary[env_id][method] = {"applies": False, "note": NO_PEER_SETTINGS}
    return summary


# --- the goal's checks -----------------------------------------------------------------------------------------------

#: How many of the nine tasks need at most half of Sarsa(lambda)'s samples to the target.
HALF_SAMPLE_TASKS = 6
GOAL_CHECKS = {
    "stability": "no run diverges on any task, and the largest excursion beyond the possible returns widened by the "
    "value watch's margin (5 % of the largest reward's size, plus rounding) is no larger than Sarsa(λ)'s on the same "
    "task",
    "samples": f"at most half of Sarsa(λ)'s median samples to the target on at least {HALF_SAMPLE_TASKS} of the "
    f"{len(TASKS)} tasks, and never more than Sarsa(λ)'s median plus one evaluation interval",
    "final_return": "the final return's mean at or above the lower end of Sarsa(λ)'s 95 % confidence interval, on "
    "every task",
    "walker": "on the walker, a rise in at most a third of Sarsa(λ)'s time, with fewer falls",
}


def _all(verdicts: list[bool | None]) -> bool | None:
    """True when every verdict holds, False when one fails, None (not judged) otherwise."""
    if any(verdict is False for verdict in verdicts):
        return False
    if not verdicts or any(verdict is None for verdict in verdicts):
        return None
    return True


def _pairs(summary: dict, method: str):
    """(task id, the method's figures, Sarsa(lambda)'s figures) of every task where both ran."""
    for env_id, figures in summary.items():
        ours, reference = figures.get(method), figures.get(REFERENCE)
        if ours and ours.get("applies") and reference and reference.get("applies"):
            yield env_id, ours, reference


def _samples(figures: dict) -> float:
    return math.inf if figures["samples_to_target_infinite"] else figures["samples_to_target"]


def _complete(holds: bool | None, measured: int, n_tasks: int) -> bool | None:
    """A check that holds on the measured tasks holds only once every task is measured (else not judged yet)."""
    return None if holds is True and measured < n_tasks else holds


def check_stability(summary: dict, method: str, n_tasks: int = len(TASKS)) -> dict[str, Any]:
    """No diverged run, and a largest excursion no larger than Sarsa(lambda)'s (largest over seeds), task by task; not
    judged where the excursion was not recorded for every run."""
    tasks = {}
    for env_id, ours, reference in _pairs(summary, method):
        ours_max, reference_max = ours["excursion_beyond_margin_max"], reference["excursion_beyond_margin_max"]
        recorded = (
            ours["largest_excursion_runs"] == ours["runs"] and reference["largest_excursion_runs"] == reference["runs"]
        )
        if ours_max is not None and reference_max is not None and ours_max > reference_max:
            excursion_ok = False  # more runs can only raise the largest excursion
        else:
            excursion_ok = True if recorded else None
        holds = False if ours["diverged"] else excursion_ok
        tasks[env_id] = {
            "holds": holds,
            "diverged": ours["diverged"],
            "runs": ours["runs"],
            "largest_excursion": ours["largest_excursion_max"],
            "sarsa_largest_excursion": reference["largest_excursion_max"],
            "excursion_beyond_margin": ours_max,
            "sarsa_excursion_beyond_margin": reference_max,
            "text": f"{ours['diverged']} of {ours['runs']} runs diverged; largest excursion beyond the margin "
            f"{_format_excursion(ours_max)} against Sarsa(λ)'s {_format_excursion(reference_max)} (beyond the "
            f"possible returns: {_format_excursion(ours['largest_excursion_max'])} against "
            f"{_format_excursion(reference['largest_excursion_max'])})",
        }
    return {"holds": _complete(_all([task["holds"] for task in tasks.values()]), len(tasks), n_tasks), "tasks": tasks}


def check_samples(summary: dict, method: str, n_tasks: int = len(TASKS)) -> dict[str, Any]:
    """At most half of Sarsa(lambda)'s median samples to the target on HALF_SAMPLE_TASKS tasks, and on none more
    than Sarsa(lambda)'s median plus one evaluation interval (a method that never reaches a target Sarsa(lambda)
    reaches is more; one that reaches a target Sarsa(lambda) never reaches needs at most half)."""
    tasks = {}
    for env_id, ours, reference in _pairs(summary, method):
        mine, theirs = _samples(ours), _samples(reference)
        half = math.isfinite(mine) and mine <= 0.5 * theirs
        limit = theirs + ours["eval_interval"]
        within = mine <= limit
        tasks[env_id] = {
            "half": half,
            "within_limit": within,
            "samples": _number(mine),
            "sarsa_samples": _number(theirs),
            "ratio": _number(mine / theirs) if math.isfinite(theirs) and theirs > 0 else None,
            "text": f"{_format(mine)} against Sarsa(λ)'s {_format(theirs)} {ours['unit']}"
            + ("" if within else f", more than Sarsa(λ)'s plus one interval ({_format(limit)})"),
        }
    halves = sum(task["half"] for task in tasks.values())
    over = [env_id for env_id, task in tasks.items() if not task["within_limit"]]
    missing = n_tasks - len(tasks)
    if over or halves + missing < HALF_SAMPLE_TASKS:
        holds = False
    elif halves >= HALF_SAMPLE_TASKS and not missing:
        holds = True
    else:  # enough tasks could still be measured either way
        holds = None
    return {
        "holds": holds,
        "tasks_at_half": halves,
        "tasks_measured": len(tasks),
        "tasks_over_limit": over,
        "tasks": tasks,
        "text": f"at most half of Sarsa(λ)'s samples on {halves} of {len(tasks)} measured tasks (needs "
        f"{HALF_SAMPLE_TASKS} of {n_tasks})"
        + (f"; above Sarsa(λ)'s plus one interval on {', '.join(over)}" if over else ""),
    }


def check_final_return(summary: dict, method: str, n_tasks: int = len(TASKS)) -> dict[str, Any]:
    """The final return's mean at or above the lower end of Sarsa(lambda)'s 95 % CI, task by task."""
    tasks = {}
    for env_id, ours, reference in _pairs(summary, method):
        mean, reference_mean, reference_ci = ours["final_mean"], reference["final_mean"], reference["final_ci95"]
        if mean is None:
            holds = False  # no run ended without diverging
        elif reference_mean is None or reference_ci is None:
            holds = None
        else:
            holds = mean >= reference_mean - reference_ci
        low = None if reference_mean is None or reference_ci is None else reference_mean - reference_ci
        tasks[env_id] = {
            "holds": holds,
            "final_mean": mean,
            "sarsa_final_mean": reference_mean,
            "sarsa_ci95": reference_ci,
            "sarsa_lower_end": low,
            "text": f"{_format(mean)} against the lower end {_format(low)} of Sarsa(λ)'s {_format(reference_mean)} "
            f"± {_format(reference_ci)}",
        }
    return {"holds": _complete(_all([task["holds"] for task in tasks.values()]), len(tasks), n_tasks), "tasks": tasks}


WALKER = "sb3_er/SimplestWalker-v0"


def check_walker(summary: dict, method: str) -> dict[str, Any]:
    """Rise time (Table 6.2's, on the mean curve) at most a third of Sarsa(lambda)'s, and fewer mean falls."""
    figures = summary.get(WALKER, {})
    ours, reference = figures.get(method), figures.get(REFERENCE)
    if not (ours and ours.get("applies") and reference and reference.get("applies")):
        return {"holds": None, "text": "not measured on the walker"}
    rise, reference_rise = ours.get("rise_time"), reference.get("rise_time")
    falls, reference_falls = ours.get("falls"), reference.get("falls")
    rise_ok = None if reference_rise is None else (rise is not None and rise <= reference_rise / 3.0)
    falls_ok = None if falls is None or reference_falls is None else falls < reference_falls
    return {
        "holds": _all([rise_ok, falls_ok]),
        "rise_time": rise,
        "sarsa_rise_time": reference_rise,
        "falls": falls,
        "sarsa_falls": reference_falls,
        "text": f"rise {_format(rise)} s against a third of Sarsa(λ)'s {_format(reference_rise)} s; falls "
        f"{_format(falls)} against {_format(reference_falls)}",
    }


def goal(summary: dict, method: str, n_tasks: int = len(TASKS)) -> dict[str, Any]:
    """The goal's checks (GOAL_CHECKS) for `method` against Sarsa(lambda), each with ``holds`` (True, False, or None
    when it cannot be judged yet: a task not measured, a figure not recorded) and its figures.

    :param summary: what :func:`summarize` returns.
    :param method: the method judged.
    :param n_tasks: the tasks the checks need (default: all of TASKS).
    """
    checks = {
        "stability": check_stability(summary, method, n_tasks),
        "samples": check_samples(summary, method, n_tasks),
        "final_return": check_final_return(summary, method, n_tasks),
        "walker": check_walker(summary, method),
    }
    for name, check in checks.items():
        check["rule"] = GOAL_CHECKS[name]
    return {"method": method, "reference": REFERENCE, "holds": _all([c["holds"] for c in checks.values()]), **checks}


def default_goal_method(summary: dict) -> str:
    """er_sigma_stable where it has runs, else er_sigma."""
    ran = {method for figures in summary.values() for method, f in figures.items() if f.get("applies")}
    return "er_sigma_stable" if "er_sigma_stable" in ran else "er_sigma"


# --- the summary's files --------------------------------------------------------------------------------------------


def _format(value, unit: str = "") -> str:
    from sb3_er.experiments.summary import format_figure

    if value is None:
        return "NA"
    if isinstance(value, float) and math.isinf(value):
        return "never (∞)"
    text = format_figure(float(value), whole=float(value).is_integer() and abs(value) >= 1)
    return f"{text} {unit}".strip()


def _format_excursion(value: float | None) -> str:
    """An excursion beyond the possible returns to 3 significant figures: small ones are compared too."""
    return "NA" if value is None else f"{value:.3g}"


def _yes_no(holds: bool | None, partial: bool = False) -> str:
    """yes, no, or why not judged: a check not measured yet, or runs that are a part of the benchmark (never)."""
    return {True: "yes", False: "no", None: "not judged (a part of the benchmark)" if partial else "not judged yet"}[
        holds
    ]


def samples_text(figures: dict) -> str:
    reached = f"{figures['reached']}/{figures['runs']}"
    if figures["samples_to_target_infinite"]:
        return f"never (∞; {reached} reached it)"
    return f"{_format(figures['samples_to_target'])} ({reached})"


def final_text(figures: dict) -> str:
    if figures["final_mean"] is None:
        return "NA (every run diverged)"
    ci = "" if figures["final_ci95"] is None else f" ± {_format(figures['final_ci95'])}"
    return f"{_format(figures['final_mean'])}{ci}" + (
        f" ({figures['final_runs']} runs)" if figures["final_runs"] < figures["runs"] else ""
    )


def excursion_text(figures: dict) -> str:
    if figures["largest_excursion_max"] is None:
        return "not recorded" if figures["values_out_of_range_max"] is not None else "no value watch"
    return (
        f"{_format_excursion(figures['largest_excursion_max'])}; "
        f"{_format_excursion(figures['largest_excursion_median'])}"
    )


#: The command that writes the committed summary.
SUMMARIZE = "python benchmarks/sample_efficiency.py --summarize"


def markdown_summary(
    summary: dict,
    goal_result: dict,
    code_versions: str,
    commands: list[str],
    summarized_by: str = SUMMARIZE,
    runs_name: str = RUNS_FILE,
) -> str:
    """summary.md: the table per task and method, the thesis tasks' own metrics, the goal's checks and the code.

    :param summarized_by: the command that writes this summary (of the runs file ``runs_name``)."""
    made_by = ", then ".join(f"`{command}`" for command in commands) or "no recorded command"
    lines = [
        "# Sample efficiency: samples to a target, final return and stability",
        "",
        f"The runs ({runs_name}) were made by {made_by}; this summary by `{summarized_by}`. Samples to the target: "
        "the median over seeds, a seed that never reaches it counted as "
        "infinite (seeds that reached it in brackets); in steps, episodes on the thesis's pendulum and seconds of "
        "learning time on the walker. Final return: mean ± 95 % CI over the runs that did not diverge (the walker: "
        "distance walked in 100 s, m). Largest excursion beyond the possible returns: the largest over seeds; the "
        "median. CPU s: learning only, the median per run.",
        "",
        "| task | method | samples to the target | final return | diverged | runs outside the possible returns "
        "| largest excursion (max; median) | learn CPU s |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for env_id, methods in summary.items():
        task = TASKS[env_id]
        for method, figures in methods.items():
            name = f"{env_id} (to {_format(task.target)})"
            if not figures.get("applies"):
                lines.append(f"| {name} | {label(method)} | {figures['note']} | | | | | |")
                continue
            runs, outside = figures["runs"], figures["runs_outside_returns"]
            lines.append(
                f"| {name} | {label(method)} | {samples_text(figures)} | {final_text(figures)} | "
                f"{figures['diverged']} of {runs} | {'—' if outside is None else f'{outside} of {runs}'} | "
                f"{excursion_text(figures)} | {_format(figures['learn_cpu_s_median'])} |"
            )
    thesis_rows = [
        (env_id, method, figures)
        for env_id, methods in summary.items()
        if TASKS[env_id].thesis_experiment
        for method, figures in methods.items()
        if figures.get("applies")
    ]
    if thesis_rows:
        lines += [
            "",
            "The thesis's tasks with their own metrics (Tables 6.1 and 6.2, on the mean curve over the runs that did "
            "not diverge): rise time in episodes (pendulum) or seconds of learning time (walker), end performance ± "
            "95 % CI, falls while learning ± 95 % CI.",
            "",
            "| task | method | rise time | end performance | falls |",
            "|---|---|---:|---:|---:|",
        ]
        for env_id, method, figures in thesis_rows:
            end = _format(figures.get("end_performance"))
            if figures.get("end_performance_ci") is not None:
                end += f" ± {_format(figures['end_performance_ci'])}"
            falls = "—"
            if figures.get("falls") is not None:
                falls = _format(figures["falls"]) + (
                    f" ± {_format(figures['falls_ci'])}" if figures.get("falls_ci") is not None else ""
                )
            lines.append(f"| {env_id} | {label(method)} | {_format(figures.get('rise_time'))} | {end} | {falls} |")
    goals = goal_overview(summary, goal_result.get("partial", []))
    overview = overview_markdown(goals) + [""] if len(goals) > 1 else []
    lines += ["", *overview, *goal_markdown(goal_result), "", code_versions, ""]
    lines += [f"Figure: `{FIGURE}`, each method's median samples to the target over Sarsa(λ)'s, task by task.", ""]
    return "\n".join(lines)


def goal_overview(summary: dict, deviations: list[str] = ()) -> dict[str, dict[str, Any]]:
    """The goal's checks (:func:`goal`) for every method of the summary but Sarsa(lambda) and the peers, by method:
    the screen's comparison of stabilizers on one footing (none holding when the runs fall short of the benchmark's
    protocol: :func:`judged`)."""
    ran = [
        m
        for m in METHODS
        if m != REFERENCE and not is_peer(m) and any(f.get(m, {}).get("applies") for f in summary.values())
    ]
    return {method: judged(goal(summary, method), list(deviations)) for method in ran}


def overview_markdown(overview: dict[str, dict[str, Any]]) -> list[str]:
    """A row per method: how many tasks pass each check, and which fail."""
    if not overview:
        return []
    lines = [
        "Every method's goal checks against Sarsa(λ) (the tasks measured; the rules are those of the table below):",
        "",
        "| method | stability: tasks that fail | samples: tasks at half or less; tasks above Sarsa(λ)'s plus one "
        "interval | final return: tasks that fail | walker | all |",
        "|---|---|---|---|---|---|",
    ]
    for method, result in overview.items():
        part = bool(result.get("partial"))
        unstable = [env_id for env_id, task in result["stability"]["tasks"].items() if task["holds"] is False]
        samples = result["samples"]
        low = [env_id for env_id, task in result["final_return"]["tasks"].items() if task["holds"] is False]
        over = samples["tasks_over_limit"]
        lines.append(
            f"| {label(method)} | {len(unstable)} of {len(result['stability']['tasks'])}"
            + (f" ({', '.join(unstable)})" if unstable else "")
            + f" | {samples['tasks_at_half']} of {samples['tasks_measured']}; {len(over)}"
            + (f" ({', '.join(over)})" if over else "")
            + f" | {len(low)} of {len(result['final_return']['tasks'])}"
            + (f" ({', '.join(low)})" if low else "")
            + f" | {_yes_no(result['walker']['holds'], part)} | {_yes_no(result['holds'], part)} |"
        )
    return lines


def goal_markdown(goal_result: dict) -> list[str]:
    method = goal_result["method"]
    part = bool(goal_result.get("partial"))
    lines = [f"Goal checks for {label(method)} against Sarsa(λ): {_yes_no(goal_result['holds'], part)}.", ""]
    if goal_result.get("partial"):
        lines += [
            "These runs are a part of the benchmark, not the whole ("
            + "; ".join(goal_result["partial"])
            + "): no check is judged to hold on them, and one that fails is a failure on these runs only.",
            "",
        ]
    lines += [
        "| check | holds | rule | figures |",
        "|---|---|---|---|",
    ]
    for name in GOAL_CHECKS:
        check = goal_result[name]
        if "tasks" in check:
            figures = "; ".join(
                f"{env_id}: {task['text']}" + ("" if task.get("holds", True) is not False else " (fails)")
                for env_id, task in check["tasks"].items()
            )
            if "text" in check:
                figures = check["text"] + (f"; {figures}" if figures else "")
        else:
            figures = check["text"]
        verdict = _yes_no(check["holds"], part)
        lines.append(f"| {name} | {verdict} | {check['rule']} | {figures or 'not measured'} |")
    return lines


def benchmarks_entries(summary: dict) -> list[dict]:
    """The summary in the format docs/_ext's "Which algorithm?" generator reads (its module docstring): one entry per
    task with the final return of every method that ran."""
    entries = []
    for env_id, methods in summary.items():
        task = TASKS[env_id]
        scores = []
        for method, figures in methods.items():
            if not figures.get("applies"):
                continue
            score = {
                "algorithm": method,
                "mean": figures["final_mean"],
                "ci95": figures["final_ci95"],
                "runs": figures["runs"],
                "averaged": figures["final_runs"],
                "text": final_text(figures),
                "speed": figures["samples_to_target"],
                "speed_text": samples_text(figures),
            }
            if figures.get("falls") is not None:
                score["falls"], score["falls_text"] = figures["falls"], _format(figures["falls"])
            if figures["diverged"]:
                score["left_out"] = f"diverged in {figures['diverged']} of {figures['runs']} runs"
            scores.append(score)
        if scores:
            entries.append(
                {
                    "task": task.description,
                    "env_id": env_id,
                    "metric": f"final {task.final_metric}",
                    "higher_is_better": True,
                    "speed_label": f"median {task.unit} to {_format(task.target)}",
                    "files": ["summary.md", FIGURE],
                    "scores": scores,
                }
            )
    return entries


#: Where the ratio figure puts a method that never reaches a target Sarsa(lambda) reaches (top), and one that reaches
#: a target Sarsa(lambda) never reaches (bottom); a task neither reaches shows nothing.
NEVER_RATIO, SARSA_NEVER_RATIO = 20.0, 0.03


def plot_ratios(summary: dict, path: Path) -> Path:
    """samples_to_target.png: each method's median samples to the target over Sarsa(lambda)'s, task by task (log
    scale); open markers at NEVER_RATIO for a method that never reaches a target Sarsa(lambda) reaches, at
    SARSA_NEVER_RATIO for one that reaches a target Sarsa(lambda) never reaches."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sb3_er.experiments.files import save_figure

    tasks = [env_id for env_id, methods in summary.items() if methods.get(REFERENCE, {}).get("applies")]
    methods = [m for m in METHODS if m != REFERENCE and any(summary[t].get(m, {}).get("applies") for t in tasks)]
    figure, axes = plt.subplots(figsize=(9.0, 4.6))
    points = 0
    for index, method in enumerate(methods):
        filled, hollow = [], []
        for position, env_id in enumerate(tasks):
            ours, reference = summary[env_id].get(method, {}), summary[env_id][REFERENCE]
            if not ours.get("applies"):
                continue
            x = position + 0.08 * (index - (len(methods) - 1) / 2)
            mine, theirs = _samples(ours), _samples(reference)
            if math.isfinite(mine) and math.isfinite(theirs):
                filled.append((x, max(mine, 1e-9) / theirs))
            elif math.isfinite(theirs):
                hollow.append((x, NEVER_RATIO))
            elif math.isfinite(mine):
                hollow.append((x, SARSA_NEVER_RATIO))
        points += len(filled) + len(hollow)
        marker = "osD^v<>ph*"[index % 10]
        axes.scatter(
            *zip(*filled or [(None, None)], strict=True), marker=marker, color=f"C{index}", label=label(method)
        )
        axes.scatter(
            *zip(*hollow or [(None, None)], strict=True), marker=marker, facecolors="none", edgecolors=f"C{index}"
        )
    if not points:
        axes.text(
            0.5,
            0.5,
            "nothing to compare: on every task measured, neither Sarsa(λ) nor the other methods reached the target",
            transform=axes.transAxes,
            ha="center",
            va="center",
            fontsize="small",
        )
    axes.axhline(1.0, color="grey", linewidth=1.0)
    axes.axhline(0.5, color="grey", linewidth=1.0, linestyle="--", label="half of Sarsa(λ)'s")
    axes.set_yscale("log")
    axes.set_ylim(SARSA_NEVER_RATIO / 1.6, NEVER_RATIO * 1.6)
    axes.set_xticks(range(len(tasks)))
    axes.set_xticklabels([env_id.split("/")[-1] for env_id in tasks], rotation=30, ha="right", fontsize="small")
    axes.set_ylabel("median samples to the target / Sarsa(λ)'s")
    axes.set_title(
        f"Samples to the target against Sarsa(λ); open markers: never reached (at {NEVER_RATIO:g}), or reached where "
        f"Sarsa(λ) never did (at {SARSA_NEVER_RATIO:g})",
        fontsize="small",
    )
    axes.grid(alpha=0.3, axis="y")
    axes.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    figure.tight_layout()
    save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path


def code_versions_text(runs: list[dict]) -> str:
    from sb3_er.experiments.records import code_versions_line

    return code_versions_line([run.get("code_version") for run in runs])


def protocol_deviations(runs: list[dict]) -> list[str]:
    """How `runs` fall short of the whole benchmark's protocol, in words ([] when they do not): fewer seeds per pair
    than DEFAULT_SEEDS, or an sb3-er run with another budget, evaluation interval or episode counts than its task's
    (--scale, --eval-*). Such runs are a part or a smoke test of the benchmark, and the goal is not judged on them."""
    seeds: dict[tuple, set] = {}
    changed: dict[str, set] = {}
    for run in runs:
        seeds.setdefault((run["task"], run["method"]), set()).add(run["seed"])
        task = TASKS[run["task"]]
        if is_peer(run["method"]):
            continue  # a peer's budget may be rl-zoo's (--peer-budget)
        own = {"budget": task.budget, "eval_interval": task.eval_interval}
        own.update(eval_episodes=task.eval_episodes, final_episodes=task.final_episodes)
        for key, value in own.items():
            if run[key] != value:
                changed.setdefault(key, set()).add(run["task"])
    notes = []
    fewest = min(len(seen) for seen in seeds.values())
    if fewest < DEFAULT_SEEDS:
        notes.append(f"as few as {fewest} seed{'s' if fewest > 1 else ''} per task and method, of {DEFAULT_SEEDS}")
    for key, tasks in changed.items():
        notes.append(f"another {key.replace('_', ' ')} than the task's on {', '.join(sorted(tasks))}")
    return notes


def judged(goal_result: dict, deviations: list[str]) -> dict:
    """`goal_result` with no check holding (True becomes None, not judged) when the runs fall short of the benchmark's
    protocol (:func:`protocol_deviations`), and the shortfall recorded as ``partial``; a check that fails still
    fails."""
    if not deviations:
        return goal_result
    result = {**goal_result, "partial": deviations}
    for name in GOAL_CHECKS:
        if result[name]["holds"] is True:
            result[name] = {**result[name], "holds": None}
    result["holds"] = _all([result[name]["holds"] for name in GOAL_CHECKS])
    return result


def write_summary(
    runs_file: dict,
    out: Path,
    goal_method: str | None = None,
    summarized_by: str = SUMMARIZE,
    runs_name: str = RUNS_FILE,
) -> dict:
    """Write summary.md, summary.json and the figure of the runs of `runs_file` (:func:`read_runs_file`) into `out`
    (each atomically) and return summary.json's data; `summarized_by` is the command that does it, for the text."""
    from sb3_er.experiments.files import write_atomically, write_json

    runs, commands = runs_file["runs"], runs_file["commands"]
    summary = summarize(runs)
    method = goal_method or default_goal_method(summary)
    goal_result = judged(goal(summary, method), protocol_deviations(runs))
    data = {
        "format": FORMAT,
        "commands": commands,
        "tasks": summary,
        "goal": goal_result,
        "goals": goal_overview(summary, goal_result.get("partial", [])),
        "task_settings": {env_id: task_settings(TASKS[env_id]) for env_id in summary},
        "methods": {name: {"class": cls, "kwargs": kwargs} for name, (cls, kwargs) in METHODS.items()},
        "benchmarks": benchmarks_entries(summary),
    }
    out.mkdir(parents=True, exist_ok=True)
    text = markdown_summary(summary, goal_result, code_versions_text(runs), commands, summarized_by, runs_name)
    write_atomically(out / "summary.md", text)
    write_json(out / "summary.json", data)
    plot_ratios(summary, out / FIGURE)
    return data


def task_settings(task: Task) -> dict[str, Any]:
    settings = dataclasses.asdict(task)
    settings["replay_protocol"] = dict(task.replay_protocol)
    return settings


def print_summary(
    runs: list[dict], commands: list[str], goal_method: str | None = None, runs_path: Path | None = None
) -> None:
    """Print the summary of `runs` (those a command planned) after it ran them; `runs_path` is their runs file."""
    if not runs:
        print("no finished runs")
        return
    summary = summarize(runs)
    method = goal_method or default_goal_method(summary)
    goal_result = judged(goal(summary, method), protocol_deviations(runs))
    summarized_by, runs_name = _summarize_command(runs_path), (runs_path or OUT / RUNS_FILE).name
    print(markdown_summary(summary, goal_result, code_versions_text(runs), commands, summarized_by, runs_name))


def _summarize_command(runs_path: Path | None, out: Path | None = None) -> str:
    """The --summarize command line for the runs file `runs_path` (None: the committed one) and summary folder `out`."""
    arguments = ["python", "benchmarks/sample_efficiency.py", "--summarize"]
    if runs_path is not None and runs_path.resolve() != (OUT / RUNS_FILE).resolve():
        arguments += ["--json", str(runs_path)]
    if out is not None and (runs_path is None or out.resolve() != runs_path.parent.resolve()):
        arguments += ["--out", str(out)]
    return shlex.join(arguments)


# --- the tables of tasks and methods (printed by --list, shown by the docs page) -------------------------------------


def tasks_table() -> str:
    lines = [
        "| task | protocol | budget | evaluation | target | how the target was chosen | Sarsa(λ)'s median samples "
        "to the target (committed) |",
        "|---|---|---:|---|---:|---|---|",
    ]
    protocols = {
        "greedy": "greedy episodes every {interval} steps",
        "episodes": "the return of every learning episode (Table 6.1); the target on the mean of the last {smoothing}",
        "walking": "greedy distance every {interval} s over {episodes} runs, falls (Table 6.2)",
    }
    for task in TASKS.values():
        evaluation = protocols[task.protocol].format(
            interval=_format(task.eval_interval), smoothing=task.smoothing, episodes=task.eval_episodes
        )
        if task.protocol == "greedy":
            evaluation = f"{task.eval_episodes} {evaluation}"
        noun = "run" if task.protocol == "walking" else "episode"
        final = f"; final: {task.final_episodes} greedy {noun}{'s' if task.final_episodes > 1 else ''}"
        if task.protocol == "episodes":
            final += " (its start and dynamics are deterministic)"
        replay = (
            "; ER replays " + ", ".join(f"{k}={v!r}" for k, v in task.replay_protocol) if task.replay_protocol else ""
        )
        lines.append(
            f"| {task.env_id} | {task.protocol} | {_format(task.budget)} {task.unit} | {evaluation}{final}{replay} | "
            f"{_format(task.target)} | {task.target_rule} | {_format(task.sarsa_samples)} {task.unit}: "
            f"{task.sarsa_source} |"
        )
    return "\n".join(lines) + "\n"


def methods_table() -> str:
    lines = ["| method | class and arguments | runs on | today |", "|---|---|---|---|"]
    for name, (class_name, kwargs) in METHODS.items():
        arguments = ", ".join(f"{key}={value!r}" for key, value in kwargs.items())
        if class_name in PEER_CLASSES:
            built = f"SB3 `{class_name}` with rl-zoo's tuned hyperparameters"
            try:
                where = ", ".join(t for t, task in TASKS.items() if applies(name, task)) or "none"
            except ImportError:
                where = "the tasks rl-zoo has settings for"
        else:
            built = f'`{class_name}("TileQ", env{", " + arguments if arguments else ""})`'
            where = "every task"
        try:
            reason = method_unavailable(name)
        except ImportError:
            reason = None
        default = "" if name in DEFAULT_METHODS else " (only when asked for)"
        lines.append(f"| {name} | {built} | {where} | {reason or 'runs'}{default} |")
    return "\n".join(lines) + "\n"


# --- the command line ------------------------------------------------------------------------------------------------


def _positive(kind):
    """An argparse type: a number of `kind` above 0."""

    def parse(text: str):
        value = kind(text)
        if not value > 0:
            raise argparse.ArgumentTypeError(f"must be above 0, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS), metavar="ENV_ID")
    parser.add_argument(
        "--methods",
        nargs="+",
        default=None,
        choices=list(METHODS),
        metavar="METHOD",
        help=f"of {', '.join(METHODS)} (default: {' '.join(DEFAULT_METHODS)})",
    )
    parser.add_argument(
        "--seeds", type=_positive(int), default=DEFAULT_SEEDS, help=f"seeds per pair (default {DEFAULT_SEEDS})"
    )
    parser.add_argument("--first-seed", type=_non_negative_int, default=0)
    parser.add_argument("--jobs", type=_positive(int), default=1, help="worker subprocesses at a time (default 1)")
    parser.add_argument(
        "--json", type=Path, default=OUT / RUNS_FILE, help="the runs file: finished runs are kept and skipped"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="where --summarize writes (default: the folder of the --json file)"
    )
    parser.add_argument("--summarize", action="store_true", help="summarize the runs file into --out; run nothing")
    parser.add_argument(
        "--goal-method",
        default=None,
        choices=[method for method in METHODS if method != REFERENCE and not is_peer(method)],
        metavar="METHOD",
        help="the method the goal's checks judge (default: er_sigma_stable where it ran, else er_sigma)",
    )
    parser.add_argument("--list", action="store_true", help="print the tasks and methods and exit")
    parser.add_argument(
        "--scale",
        type=_positive(float),
        default=1.0,
        help="each task's budget times this (smoke runs: 0.01; default 1)",
    )
    smoke = "instead of each task's (smoke runs, in a --json file of their own)"
    parser.add_argument("--eval-interval", type=_positive(float), default=None, help=smoke)
    parser.add_argument("--eval-episodes", type=_positive(int), default=None, help=smoke)
    parser.add_argument("--final-episodes", type=_positive(int), default=None, help=smoke)
    parser.add_argument(
        "--peer-budget",
        choices=("task", "rl-zoo"),
        default="task",
        help="the peers' run length: the task's budget (default) or rl-zoo's n_timesteps where smaller",
    )
    parser.add_argument(
        "--no-warm-up",
        action="store_true",
        help="skip the short untimed runs that compile the numba kernels before the timed ones",
    )
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    return parser


def _chosen_methods(requested: list[str] | None) -> tuple[list[str], list[str]]:
    """(the methods to run, notes on the ones left out); SystemExit for a requested method that cannot run."""
    chosen, notes = [], []
    for method in requested or DEFAULT_METHODS:
        reason = method_unavailable(method)
        if reason is None:
            chosen.append(method)
        elif requested:
            raise SystemExit(f"{method} cannot run: {reason}")
        else:
            notes.append(f"{method} left out: {reason}")
    return chosen, notes


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.worker is not None:
        peers.end_with_parent()
        record = run_task(json.loads(args.worker))
        print(RESULT_PREFIX + json.dumps(record), flush=True)
        return 0
    if args.list:
        print(tasks_table())
        print(methods_table())
        return 0
    out = args.out or args.json.parent  # a summary goes beside its runs file unless told otherwise
    if args.summarize:
        if args.methods or args.tasks != list(TASKS) or args.seeds != DEFAULT_SEEDS or args.first_seed:
            raise SystemExit(
                "error: --summarize summarizes every run of its --json file; --tasks, --methods and --seeds choose "
                "the runs a command makes (a part of the benchmark goes to a runs file of its own)"
            )
        if not args.json.is_file():
            raise SystemExit(f"error: no runs file {args.json} (the --json FILE a run writes)")
        runs_file = read_runs_file(args.json)
        if not runs_file["runs"]:
            raise SystemExit(f"error: {args.json} holds no runs to summarize")
        data = write_summary(runs_file, out, args.goal_method, _summarize_command(args.json, args.out), args.json.name)
        print((out / "summary.md").read_text(encoding="utf-8"))
        print(f"wrote {out / 'summary.md'}, {out / 'summary.json'} and {out / FIGURE}", file=sys.stderr)
        return 0 if data else 1
    own_protocol = args.scale == 1.0 and (args.eval_interval, args.eval_episodes, args.final_episodes) == (None,) * 3
    if not own_protocol and args.json.resolve() == (OUT / RUNS_FILE).resolve():
        raise SystemExit(
            "error: runs with --scale or --eval-* are not the benchmark's own protocol and do not belong in its "
            f"committed runs file ({OUT / RUNS_FILE}): give them a file of their own with --json FILE"
        )
    methods, notes = _chosen_methods(list(dict.fromkeys(args.methods)) if args.methods else None)
    for note in notes:
        print(note, file=sys.stderr)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    configs = plan_runs(
        list(dict.fromkeys(args.tasks)),
        methods,
        seeds,
        args.scale,
        args.eval_interval,
        args.eval_episodes,
        args.final_episodes,
        args.peer_budget,
    )
    from sb3_er.experiments.files import FolderLock

    command = shlex.join(["python", "benchmarks/sample_efficiency.py", *(sys.argv[1:] if argv is None else argv)])
    # one writer of a runs file at a time: a second command is refused at once
    with FolderLock(args.json.parent, elsewhere="give this one a runs file in another folder (--json FILE)"):
        pending = pending_runs(configs, read_runs(args.json), args.json)
        print(
            f"{len(configs) - len(pending)} of {len(configs)} runs already in {args.json}; {len(pending)} to run "
            f"on {args.jobs} worker(s)",
            file=sys.stderr,
            flush=True,
        )
        if pending and not args.no_warm_up:
            warm_ups = warm_up_configs(pending)
            print(f"warming up: {len(warm_ups)} short runs compile the kernels", file=sys.stderr, flush=True)
            _, failed = run_all(warm_ups, None, args.jobs, command)
            if failed:
                raise SystemExit(f"{len(failed)} warm-up runs failed; the first: {failed[0][1]}")
        start = time.perf_counter()
        runs, failures = run_all(pending, args.json, args.jobs, command)
    print(f"{len(pending) - len(failures)} runs in {time.perf_counter() - start:.0f} s", file=sys.stderr)
    planned = {run_key(config) for config in configs}
    print_summary(
        [run for run in runs if run_key(run) in planned],
        read_runs_file(args.json)["commands"],
        args.goal_method,
        args.json,
    )
    for config, message in failures:
        lines = [line for line in message.splitlines() if line.strip()]
        print(f"failed: {_describe(config)}: {lines[-1] if lines else message}", file=sys.stderr)
    return 1 if failures else 0


def _cli() -> int:
    """main, with the errors a user can cause (a damaged or foreign runs file, a folder another run holds, Ctrl-C)
    as one line each instead of a traceback."""
    from sb3_er.experiments.files import DamagedFileError, FolderLockedError

    try:
        return main()
    except (RunsFileError, DamagedFileError, FolderLockedError, IsADirectoryError, NotADirectoryError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: the finished runs are in the runs file; the same command resumes", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(_cli())

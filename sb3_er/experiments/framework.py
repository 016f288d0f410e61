"""`sb3-er reproduce framework`: the thesis's framework of sample re-use (chapter 3, Table 3.1), measured.

Table 3.1 places the prominent sample re-use methods in one framework and describes each qualitatively: the update
(single samples or projections), the Bellman operator, the cost function minimiser, the sample set, policy or value
iteration, the computational complexity and the representation. The thesis then studies only ER and leaves its own
question open (section 3.6: which re-use technique for which problem?). This module runs the rows that sb3-er
implements on one tile coder, behind one API, on three problems, and measures what the table states in words:

- *samples to reach a stated level*: env steps until the mean return of the last 10 learning episodes first reaches
  the problem's level (:data:`PROBLEMS`), per seed; the mean over the seeds that reach it, and how many do;
- *end performance*: the mean return of the last 10 learning episodes, mean over seeds with its 95 % CI;
- *updates per episode*: value-function updates per learning episode (the complexity column's n + K, nEi, ...):
  one per step for online Sarsa(λ), every replayed sample for ER, the direct update and the planning updates for
  Dyna, and for FQI and LSPI the samples times the sweeps (policy evaluations) of each fit, each sample's target
  being one application of the Bellman operator;
- *CPU and wall seconds per episode*: the run's own process time and wall time per learning episode (CPU time is the
  figure to compare on a shared machine).

Each run is one (problem, method, seed) on the runner (parallel, resumable, versioned records, Ray) with the records
of :class:`FrameworkProtocol`: per learning episode the return, steps, cumulative updates, CPU and wall seconds.
Settings: the grid world and the pendulum use each method's ``zoo_configs/<algo>.yml`` entry (the thesis's alpha,
gamma and epsilon; our schedules for Dyna, FQI and LSPI); MountainCar-v0 uses :data:`MOUNTAIN_CAR_SETTINGS`, stated
here in full: 16 tilings of 10 x 10 tiles over the bounds, alpha 0.2, gamma 0.99, epsilon 0.05.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.experiments import files
from sb3_er.experiments.analyses import (
    check_request,
    check_settings,
    code_line,
    run_analysis_jobs,
)
from sb3_er.experiments.metrics import mean_confidence_interval
from sb3_er.experiments.protocols import EpisodeReturnProtocol
from sb3_er.experiments.records import counted
from sb3_er.experiments.runner import RunJob, TaskOutput, job_model_kwargs, read_run_csv, run_csv_path
from sb3_er.experiments.specs import Analysis
from sb3_er.experiments.summary import _format_with_ci, format_figure

WINDOW = 10
"""Learning episodes averaged for the level and the end performance."""


@dataclass(frozen=True)
class Problem:
    """One problem of the framework experiment: env, default run length in episodes, the stated level of the mean
    return of the last ``WINDOW`` episodes, and whether the methods' settings come from the zoo configs.

    :param name: the problem's name in ``--problems``, e.g. "pendulum".
    :param env_id: the Gymnasium id of its env.
    :param title: its name in tables and figures.
    :param episodes: default run length in learning episodes.
    :param level: the mean return of the last ``WINDOW`` episodes that counts as learned (the samples-to-level
        column), in the env's reward units.
    :param zoo_configs: True (default): the methods' settings come from ``zoo_configs/<algo>.yml``; False: from
        MOUNTAIN_CAR_SETTINGS.
    """

    name: str
    env_id: str
    title: str
    episodes: int
    level: float
    zoo_configs: bool = True


PROBLEMS: dict[str, Problem] = {
    "gridworld": Problem("gridworld", "sb3_er/WindyCliff-v0", "Windy cliff grid world", 100, 0.0),
    "pendulum": Problem("pendulum", "sb3_er/PendulumSwingup-v0", "Inverted pendulum swing-up", 100, -10_000.0),
    "mountaincar": Problem("mountaincar", "MountainCar-v0", "MountainCar-v0", 200, -150.0, zoo_configs=False),
}
"""Levels: the grid world's 0 is a return above the cliff's and the south goal cells' (the goal reached in its
upper part); the pendulum's -10,000 lies between the thesis's end performances of Sarsa(λ) (-16,730) and ER
(-4,065); MountainCar's -150 is the classic "solved within 150 steps" mark (random play scores -200)."""


@dataclass(frozen=True)
class Method:
    """A row of the measured table: the algorithm (its zoo name), settings on top of the problem's, and the row of
    thesis Table 3.1 it belongs to.

    :param algo: the algorithm's rl-zoo name, e.g. "er".
    :param label: the row's name in the measured table, e.g. "ER, prioritized sweeping".
    :param thesis_row: the row of thesis Table 3.1 (a key of TABLE_3_1), e.g. "ER-sarsa".
    :param overrides: constructor arguments on top of the problem's settings, as sorted ``(name, value)`` pairs
        (default none).
    """

    algo: str
    label: str
    thesis_row: str
    overrides: tuple = ()


METHODS: dict[str, Method] = {
    "sarsa_lambda": Method("sarsa_lambda", "Sarsa(λ)", "Sarsa"),
    "er": Method("er", "ER, reversed trajectories", "ER-sarsa", (("replay_order", "reversed"),)),
    "er_prioritized": Method("er", "ER, prioritized sweeping", "ER-sarsa", (("replay_order", "prioritized"),)),
    "er_sigma": Method("er_sigma", "ER-σ", "ER-sarsa"),
    "dyna": Method("dyna", "Dyna-Q (nearest-neighbour model)", "Dyna"),
    "fqi": Method("fqi", "FQI (linear least squares)", "FQI"),
    "lspi": Method("lspi", "LSPI", "LSPI"),
}

TABLE_3_1_COLUMNS = (
    "Update",
    "Bellman operator",
    "Cost function minimizer",
    "Sample set used for updates",
    "pi or vi",
    "Computational complexity",
    "Representation",
)
_ALL = "{(s_d, a_d, s_d+1, r_d+1)}, d = 1..k"
_CURRENT = "{(s_k, a_k, s_k+1, r_k+1)}"
TABLE_3_1: dict[str, tuple[str, ...]] = {
    "Sarsa": ("samples", "T^π", "gradient descent", _CURRENT, "vi", "O(n)", "Parametric"),
    "Q-learning": ("samples", "T*", "gradient descent", _CURRENT, "vi", "O(n)", "Parametric"),
    "ER-sarsa": ("samples", "T^π", "gradient descent", _ALL, "vi", "O(n + K)", "Parametric"),
    "ER-Q learning": ("samples", "T*", "gradient descent", _ALL, "vi", "O(n + K)", "Parametric"),
    "KADP": ("projection", "T*", "kernel regressors", _ALL, "pi", "O(nEi)", "Non-parametric"),
    "FQI": ("projection", "T*", "any", _ALL, "pi", "O(nEi)", "Any"),
    "NFQ": ("projection", "T*", "gradient descent", _ALL, "pi", "O(nEi)", "ANNs"),
    "LSPI": ("projection", "T*", "least squares", _ALL, "pi", "O(nE, f^3)", "Parametric, Linear"),
    "Dyna": ("samples", "T^π / T*", "gradient descent", f"{_CURRENT} ∪ M", "vi", "O(ni + K)", "Parametric"),
}
"""Thesis Table 3.1 as printed (Algorithm properties), one tuple per row in the order of TABLE_3_1_COLUMNS."""

IMPLEMENTED = {
    "Sarsa": "`SarsaLambda` (with eligibility traces, Alg. 2); `ER(n_replays=0, online_lambda=0)` is plain Sarsa",
    "Q-learning": '`ER(target="q_learning", n_replays=0, online_lambda=0)`',
    "ER-sarsa": "`ER` (reversed, forward, uniform, prioritized sweeping), `ERSigma`, `ResidualER`, `ResidualERSigma`",
    "ER-Q learning": 'the ER classes with `target="q_learning"`',
    "KADP": "out of scope: kernel (non-parametric) representation, not the tile coder",
    "FQI": "`FQI`, with a ridge least-squares projection on the tile features",
    "NFQ": "out of scope: a neural-network representation, not the tile coder",
    "LSPI": "`LSPI`",
    "Dyna": "`Dyna` (Sarsa or Q-learning target, nearest-neighbour model)",
}
"""Which sb3-er class stands for each row of Table 3.1."""

_TILES = {"n_tilings": 16, "tile_widths": [0.18, 0.014]}
_COMMON = {"policy": "TileQ", "policy_kwargs": _TILES, "learning_rate": 0.2, "gamma": 0.99, "exploration_rate": 0.05}
_REPLAY = {"replay_trigger": "episode", "n_replays": 100}
_FIT = {"gamma": 0.99, "exploration_rate": 0.05, "policy_kwargs": _TILES, "n_iterations": 10, "ridge": 1.0}
MOUNTAIN_CAR_SETTINGS: dict[str, dict] = {
    "sarsa_lambda": {**_COMMON, "trace_lambda": 0.92},
    "er": {**_COMMON, **_REPLAY},
    "er_sigma": {**_COMMON, **_REPLAY},
    "dyna": {**_COMMON, "planning_steps": 10, "target": "q_learning"},
    "fqi": {**_FIT, "fit_every": 5},
    "lspi": {**_FIT, "fit_every": 10},
}
"""MountainCar-v0's settings per algorithm (the package's class defaults made explicit, the tiling of Sutton and
Barto's Example 10.1 refined to 16 tilings of 10 x 10 tiles, widths 1.8 / 10 and 0.14 / 10; the ER family replays
100 whole episodes after each episode, Dyna plans 10 updates per step, FQI fits every 5 episodes and LSPI every 10,
each with 10 sweeps)."""

COLUMNS = ("episode", "timesteps", "return", "length", "updates", "cpu_time_s", "wall_time_s", "diverged")


class FrameworkProtocol(EpisodeReturnProtocol):
    """The pendulum protocol (every learning episode's return), plus per episode the model's cumulative
    value-function updates (:func:`value_updates`) and the process's CPU seconds since learning began.

    :param n_episodes: learning episodes after which learning stops (a positive integer).
    :param progress: called with the fraction of the run done, for a progress bar; None (default) for none.
    :param verbose: SB3's callback verbosity (default 0).
    """

    COLUMNS = (*EpisodeReturnProtocol.COLUMNS, "updates", "cpu_time_s")

    def _on_training_start(self) -> None:
        super()._on_training_start()
        self._cpu_start = time.process_time()

    def _on_step(self) -> bool:
        episodes = len(self.records)
        keep_going = super()._on_step()
        for record in self.records[episodes:]:
            record["updates"] = value_updates(self.model)
            record["cpu_time_s"] = time.process_time() - self._cpu_start
        return keep_going


def value_updates(model) -> int:
    """Value-function updates so far: online steps (Sarsa(λ), an ER with ``online_lambda``, Dyna's direct update),
    replayed samples (ER), planning updates (Dyna), and for FQI and LSPI the sample backups of their fits (samples
    times sweeps or policy evaluations). An update at the end of an episode is counted in that episode when the
    protocol reads it after the step (replays and fits run inside the step that ends the episode).

    :param model: the learning model.
    """
    from sb3_er import Dyna
    from sb3_er.common.batch import FittedTileQAlgorithm

    if isinstance(model, FittedTileQAlgorithm):
        return int(model.sample_backups)
    online = model.num_timesteps if model.trace_lambda is not None or isinstance(model, Dyna) else 0
    return int(online + getattr(model, "replay_updates", 0) + getattr(model, "planning_updates", 0))


def framework_experiment(problem: Problem) -> Analysis:
    """The runner's experiment of one problem: a task run of ``budget`` learning episodes, the level in its
    settings (so that a resume with another level is refused).

    :param problem: the problem (an entry of :data:`PROBLEMS`).
    """
    return Analysis(
        name=f"framework-{problem.name}",
        env_id=problem.env_id,
        title=problem.title,
        protocol="framework",
        default_budget=problem.episodes,
        x_column="episode",
        x_label="learning episode",
        performance_column="return",
        performance_label="return of the learning episode",
        rise_time_unit="episodes",
        task="framework",
        unit="episodes",
        zoo_configs=problem.zoo_configs,
    ).with_settings(level=problem.level, window=WINDOW)


def method_kwargs(problem: Problem, method_name: str) -> dict:
    """The method's settings on `problem` beyond the zoo config (all of them where the problem has none).

    :param problem: the problem.
    :param method_name: the method's rl-zoo name.
    """
    method = METHODS[method_name]
    base = {} if problem.zoo_configs else dict(MOUNTAIN_CAR_SETTINGS[method.algo])
    base.pop("policy", None)
    return {**base, **dict(method.overrides)}


def framework_run(job: RunJob, env, report) -> TaskOutput:
    """One (problem, method, seed): learn ``job.budget`` episodes under :class:`FrameworkProtocol`. A divergence ends
    the run; its rows are kept and marked ``diverged``.

    :param job: the run.
    :param env: the env the runner made for it.
    :param report: called with the run's finished fraction, for the progress bar.
    """
    from sb3_er import DivergenceError
    from sb3_er.zoo import algorithm_classes

    model = algorithm_classes()[job.algo]("TileQ", env, seed=job.seed, **job_model_kwargs(job))
    episodes = int(job.budget)
    protocol = FrameworkProtocol(episodes, progress=report)
    max_steps = env.spec.max_episode_steps if env.spec is not None and env.spec.max_episode_steps else None
    max_steps = max_steps or int(env.unwrapped.max_episode_steps)
    try:
        model.learn(total_timesteps=episodes * max_steps, callback=protocol)
        diverged = False
    except DivergenceError:
        diverged = True
    frame = pd.DataFrame(protocol.records, columns=list(FrameworkProtocol.COLUMNS))
    frame["diverged"] = diverged
    return TaskOutput(frame[list(COLUMNS)], model)


def framework_jobs(
    out_dir: Path, problems: Sequence[str], methods: Sequence[str], seeds: Sequence[int], budget: float | None
) -> list[RunJob]:
    """One job per (problem, method, seed): ``<out>/<problem>/runs/<method>/seed_<n>.csv``, key
    ``<problem>/<method>/seed_<n>``.

    :param out_dir: the results folder.
    :param problems: the problems' names.
    :param methods: the methods' rl-zoo names.
    :param seeds: the seeds.
    :param budget: learning episodes per run (None: each problem's own).
    """
    jobs = []
    for name in problems:
        problem = PROBLEMS[name]
        experiment = framework_experiment(problem)
        episodes = float(problem.episodes if budget is None else budget)
        for method in methods:
            settings = tuple(sorted(method_kwargs(problem, method).items()))
            jobs += [
                RunJob(
                    experiment,
                    METHODS[method].algo,
                    seed,
                    episodes,
                    run_csv_path(Path(out_dir) / name, method, seed),
                    (),
                    settings,
                    label=f"{name}/{method}",
                )
                for seed in seeds
            ]
    return jobs


def samples_to_level(frame: pd.DataFrame, level: float, window: int = WINDOW) -> float:
    """Env steps until the mean return of the last `window` learning episodes first reaches `level` (the steps at
    the end of that episode); NaN if it never does.

    :param frame: one run's CSV (one row per learning episode).
    :param level: the return to reach.
    :param window: episodes in the moving mean (default 10).
    """
    returns = frame["return"].to_numpy(dtype=float)
    if returns.size < window:
        return math.nan
    means = np.convolve(returns, np.ones(window) / window, mode="valid")
    reached = np.flatnonzero(means >= level)
    return float(frame["timesteps"].iloc[reached[0] + window - 1]) if reached.size else math.nan


def summarize_runs(frames: dict[int, pd.DataFrame], level: float) -> dict:
    """The measured columns of one (problem, method) from its runs (seed -> frame); diverged runs are left out of
    the averages and counted.

    :param frames: the runs' CSVs by seed.
    :param level: the return of the samples-to-level column.
    """
    diverged = [seed for seed, frame in frames.items() if frame.empty or frame["diverged"].astype(bool).any()]
    complete = [frame for seed, frame in sorted(frames.items()) if seed not in diverged]
    if not complete:
        return {"seeds": 0, "diverged": len(diverged)}
    samples = np.array([samples_to_level(frame, level) for frame in complete])
    reached = samples[np.isfinite(samples)]
    end = np.array([frame["return"].iloc[-WINDOW:].mean() for frame in complete])
    episodes = np.array([len(frame) for frame in complete], dtype=float)

    def per_episode(column: str) -> float:
        return float(np.mean(np.array([frame[column].iloc[-1] for frame in complete]) / episodes))

    end_mean, end_half = mean_confidence_interval(end)
    samples_mean, samples_half = mean_confidence_interval(reached) if reached.size else (math.nan, math.nan)
    return {
        "seeds": len(complete),
        "diverged": len(diverged),
        "reached": int(reached.size),
        "samples_to_level": float(samples_mean),
        "samples_to_level_ci95": float(samples_half),
        "end_performance": float(end_mean),
        "end_performance_ci95": float(end_half),
        "updates_per_episode": per_episode("updates"),
        "cpu_s_per_episode": per_episode("cpu_time_s"),
        "wall_s_per_episode": per_episode("wall_time_s"),
        "episodes": float(episodes.mean()),
    }


def thesis_table_markdown() -> str:
    """Thesis Table 3.1 with a column saying which sb3-er class stands for each row."""
    lines = ["| Method | " + " | ".join(TABLE_3_1_COLUMNS) + " | sb3-er |", "|---" * (len(TABLE_3_1_COLUMNS) + 2) + "|"]
    for row, cells in TABLE_3_1.items():
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {IMPLEMENTED[row]} |")
    return "\n".join(lines)


def measured_table_markdown(problem: Problem, table: pd.DataFrame) -> str:
    """The measured table of one problem: Table 3.1's qualitative columns of the method's row beside ours.

    :param problem: the problem.
    :param table: its measured table (:func:`summarize_runs` per method).
    """
    lines = [
        (
            f"| Method | Update | Operator | pi/vi | Complexity (thesis) | Samples to mean return ≥ {problem.level:g} "
            "(seeds that reach it) | End performance (last 10 episodes) | Updates / episode | CPU s / episode | "
            "Wall s / episode |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in table.to_dict("records"):
        method = METHODS[row["method"]]
        update, operator, _, _, iteration, complexity, _ = TABLE_3_1[method.thesis_row]
        if method.algo == "dyna":
            operator = "T*"  # our Dyna runs use the Q-learning target (zoo configs, MOUNTAIN_CAR_SETTINGS)
        if not row.get("seeds"):
            measured = ["no finished run"] * 5
        else:
            reached = f" ({row['reached']}/{row['seeds']})"
            measured = [
                _format_with_ci(row["samples_to_level"], row["samples_to_level_ci95"]) + reached,
                _format_with_ci(row["end_performance"], row["end_performance_ci95"]),
                format_figure(row["updates_per_episode"]),
                format_figure(row["cpu_s_per_episode"]),
                format_figure(row["wall_s_per_episode"]),
            ]
        if row.get("diverged"):
            measured[1] += f" ({row['diverged']} diverged)"
        lines.append(
            f"| {method.label} | {update} | {operator} | {iteration} | {complexity} | " + " | ".join(measured) + " |"
        )
    return "\n".join(lines)


@files.holds_folder_locks
def reproduce_framework(
    n_seeds: int = 20,
    out_dir: str | Path | None = None,
    budget: float | None = None,
    n_workers: int | None = None,
    first_seed: int = 0,
    show_progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    allow_mixed_versions: bool = False,
    env_kwargs: dict | None = None,
    problems: Sequence[str] | None = None,
    methods: Sequence[str] | None = None,
):
    """`sb3-er reproduce framework`: every (problem, method, seed) run, then Table 3.1 with the measured columns.

    `problems` (default all of :data:`PROBLEMS`) and `methods` (default all of :data:`METHODS`) choose the rows;
    `budget` is the learning episodes of every problem (default: each problem's own). Writes, into `out_dir` (default
    ``results/framework``), ``<problem>/runs/<method>/seed_<n>.csv`` (and ``.json``, the version record),
    ``<problem>/settings.json``, ``<problem>/learning_curves.png``, ``summary.md`` and ``summary.csv``. An
    interrupted run resumes; a folder holding runs of other settings or code is refused as in the other
    reproductions. Returns a Reproduction.

    :param n_seeds: the number of seeds (default 20, the thesis's).
    :param out_dir: the results folder (default None: ``results/<name>``).
    :param budget: learning episodes of every problem (default None: each problem's own).
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param first_seed: the first seed; the seeds are ``first_seed, ..., first_seed + n_seeds - 1`` (default 0).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance; only with ``backend="ray"``).
    :param allow_mixed_versions: accept finished runs made by other code or settings (default False: refused).
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param problems: the problems' names (default None: all).
    :param methods: the methods' rl-zoo names (default None: all).
    """
    from sb3_er.experiments.plots import plot_mean_with_ci
    from sb3_er.experiments.reproduce import Reproduction

    start = time.perf_counter()
    problems = list(dict.fromkeys(problems or PROBLEMS))
    methods = list(dict.fromkeys(methods or METHODS))
    unknown = [name for name in problems if name not in PROBLEMS] + [name for name in methods if name not in METHODS]
    if unknown:
        raise ValueError(
            f"unknown problems or methods {unknown}; problems: {', '.join(PROBLEMS)}; methods: {', '.join(METHODS)}"
        )
    if env_kwargs:
        raise ValueError(
            "the framework experiment runs three envs with their default readings; --env-kwargs does not apply"
        )
    check_request(n_seeds, 1.0 if budget is None else budget, "episodes", backend, address)
    if budget is not None and int(budget) != budget:
        raise ValueError(f"the run length is a whole number of episodes, got {budget}")
    out_dir = Path(out_dir if out_dir is not None else Path("results") / "framework")
    settings = {
        out_dir / name: {
            "experiment": f"framework-{name}",
            "env_id": PROBLEMS[name].env_id,
            "budget": float(PROBLEMS[name].episodes if budget is None else budget),
            "level": PROBLEMS[name].level,
            "window": WINDOW,
        }
        for name in problems
    }
    files.lock_folder(out_dir, *settings)  # one writer per folder, until this function returns
    for folder, pinned in settings.items():
        check_settings(folder, pinned)
    seeds = list(range(first_seed, first_seed + n_seeds))
    jobs = framework_jobs(out_dir, problems, methods, seeds, budget)
    done, skipped = run_analysis_jobs(
        jobs, out_dir, n_workers, show_progress, backend, address, allow_mixed_versions, settings=settings
    )

    rows, sections, figures = [], [], []
    for name in problems:
        problem = PROBLEMS[name]
        episodes = int(problem.episodes if budget is None else budget)
        table_rows, curves = [], {}
        for method in methods:
            frames = {
                seed: read_run_csv(run_csv_path(out_dir / name, method, seed))
                for seed in seeds
                if run_csv_path(out_dir / name, method, seed).is_file()
            }
            summary = {"problem": name, "method": method, **summarize_runs(frames, problem.level)}
            table_rows.append(summary)
            complete = [
                frame
                for frame in frames.values()
                if len(frame) == episodes and not frame["diverged"].astype(bool).any()
            ]
            if complete:
                curves[METHODS[method].label] = (
                    np.arange(1, episodes + 1, dtype=float),
                    np.stack([frame["return"].to_numpy(dtype=float) for frame in complete]),
                )
        rows += table_rows
        if curves:
            figures.append(
                plot_mean_with_ci(
                    curves,
                    "learning episode",
                    "return of the learning episode",
                    f"{problem.title}: sample re-use methods, mean of {counted(n_seeds, 'seed')}, 95% CI",
                    out_dir / name / "learning_curves.png",
                )
            )
        sections += [
            (
                f"## {problem.title} ({problem.env_id}): {counted(n_seeds, 'seed')}, "
                f"{counted(episodes, 'episode')} per run"
            ),
            "",
            measured_table_markdown(problem, pd.DataFrame(table_rows)),
            "",
        ]
    table = pd.DataFrame(rows)
    table_csv = files.write_csv(out_dir / "summary.csv", table)
    text = [
        f"# The framework of sample re-use (thesis Table 3.1), measured: {counted(n_seeds, 'seed')}",
        "",
        "Thesis Table 3.1 (Algorithm properties) and the sb3-er class of each row:",
        "",
        thesis_table_markdown(),
        "",
        (
            "Measured, per problem. Samples to the level: env steps until the mean return of the last 10 learning "
            "episodes first reaches it (mean ± 95 % CI over the seeds that reach it; in brackets how many do). End "
            "performance: mean return of the last 10 learning episodes (± 95 % CI over seeds). Updates: value-function "
            "updates per learning episode (online steps, replayed samples, planning updates; for FQI and LSPI samples "
            "× sweeps of each fit). CPU and wall seconds per learning episode of one run, on a machine shared by "
            "`--jobs` runs. The qualitative columns are the thesis's row of the method (ER-σ and prioritized sweeping "
            "are ER-sarsa with another target or sample order)."
        ),
        "",
        *sections,
        code_line(jobs),
    ]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(text) + "\n")
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=figures,
        runs_done=done,
        runs_skipped=skipped,
        wall_time_s=time.perf_counter() - start,
    )

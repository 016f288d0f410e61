"""Thesis Appendix A (and section 4.1): reversed, forward and uniform replay compared per replayed sample.

Per seed (one run of the runner, :func:`replay_order_run`):

1. A database is collected by Sarsa(lambda) on the pendulum until ``database_episodes`` (200) episodes are complete.
   The collector is :class:`~sb3_er.ER` with ``online_lambda=0.92, n_replays=0`` (:data:`COLLECTOR_KWARGS`): it
   learns exactly like :class:`~sb3_er.SarsaLambda` with the pendulum's thesis settings (alpha 0.2, gamma 0.98,
   epsilon 0.1, lambda 0.92; the same random streams, so bit-identical weights for a seed) while storing every
   transition in whole-episode trajectories.
2. The database is saved once and loaded by three fresh ER models (zero weights, the collector's hyperparameters, the
   same seed), one per ``replay_order`` (:data:`ORDERS`), whose trajectory generators are reseeded alike
   (``seed_replay``). Each replays one trajectory at a time (reversed and forward replay a whole trajectory; uniform
   replays as many samples drawn uniformly from the whole database) until its replayed-update count reaches the next
   checkpoint: 0, ``eval_every`` (75,000), 2 x ``eval_every``, ... up to the horizon (the run length, default
   300,000). A checkpoint is therefore passed by less than one trajectory (at most one episode of samples, 1500 on
   the pendulum); the actual count is recorded beside the target.
3. At each checkpoint the greedy policy is evaluated: the undiscounted return of one greedy episode of the pendulum
   from its start (hanging at rest; the episode lasts up to the env's time limit, 15 s by default, and ends early at
   the goal). The start and the dynamics are deterministic, so one episode measures the policy exactly; the spread
   comes from the databases (seeds).

The run's frame has one row per (order, checkpoint): ``order``, ``checkpoint`` (target replayed updates),
``replayed_updates`` (actual), ``return``, ``length`` (steps of the evaluation episode), ``goal_reached``,
``diverged``, ``database_sha256`` (of the transitions the order's model replays), ``weights_at_start_sha256`` (of
its weights before the first replay) and the database's description (``database_*``, ``collector_greedy_return``).

The thesis's finding (Appendix A, Figure A.1): forward (temporal) order gains least per replayed sample; at 225,000
replays reversed trajectories are slightly better than uniformly drawn samples.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.common.env_ids import check_env_kwargs
from sb3_er.experiments import files
from sb3_er.experiments.analyses import check_request, check_settings, code_line, env_reading, run_analysis_jobs
from sb3_er.experiments.metrics import mean_confidence_interval
from sb3_er.experiments.records import counted
from sb3_er.experiments.runner import RunJob, TaskOutput, job_model_kwargs, read_run_csv, run_csv_path
from sb3_er.experiments.specs import ANALYSES, Analysis

ORDERS = ("reversed", "forward", "uniform")
COLLECTOR_KWARGS = {"online_lambda": 0.92, "n_replays": 0, "replays_per_stored_trajectory": None}
"""ER that learns like Sarsa(lambda) (the pendulum's lambda 0.92) and replays nothing: the database collector."""
RUN_FOLDER = "replay_order"
PAIRS = (("reversed", "uniform"), ("reversed", "forward"), ("uniform", "forward"))
THESIS_FINDING = "forward lowest gain per replayed sample"
THESIS_FINDING_225K = "reversed slightly better than uniform; forward clearly worst"
THESIS_CHECKPOINT = 225_000
THESIS_RANGE = 300_000
"""The replayed updates that Figure A.1 covers (its text compares the orders at 225,000); beyond them the thesis
says nothing."""
COLUMNS = (
    "order",
    "checkpoint",
    "replayed_updates",
    "return",
    "length",
    "goal_reached",
    "diverged",
    "database_sha256",
    "weights_at_start_sha256",
    "database_episodes",
    "database_transitions",
    "database_trajectories",
    "database_goal_episodes",
    "database_last10_return",
    "collector_greedy_return",
    "wall_time_s",
)


def database_digest(buffer) -> str:
    """SHA-256 hex digest of a TrajectoryReplayBuffer's stored transitions: every closed trajectory's observations,
    actions, rewards, last s' and terminal flag, oldest first, plus the open trajectory's length. Two buffers with the
    same digest hold the same data.

    :param buffer: the TrajectoryReplayBuffer.
    """
    digest = hashlib.sha256()
    for trajectory in buffer.trajectories():
        for name in ("observations", "actions", "rewards", "next_obs"):
            digest.update(np.ascontiguousarray(trajectory[name]).tobytes())
        digest.update(b"T" if trajectory["terminated"] else b"F")
    digest.update(str(buffer.open_length).encode())
    return digest.hexdigest()


def weights_digest(model) -> str:
    """SHA-256 hex digest of a tile-coded model's weight vector theta (float64 bytes).

    :param model: the tile-coded model.
    """
    return hashlib.sha256(np.ascontiguousarray(model.policy.theta_array).tobytes()).hexdigest()


def greedy_return(model, env, seed: int = 0) -> tuple[float, int, bool]:
    """(undiscounted return, steps, goal reached) of one greedy episode of `env` from its reset (seeded `seed`),
    until it terminates or is truncated by the env's time limit.

    :param model: the model (acts greedily).
    :param env: the env.
    :param seed: the seed of the reset (default 0).
    """
    observation, _ = env.reset(seed=seed)
    total, steps = 0.0, 0
    while True:
        action, _ = model.predict(observation, deterministic=True)
        observation, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        steps += 1
        if terminated or truncated:
            return total, steps, bool(info.get("goal_reached", False))


def checkpoints(horizon: int, eval_every: int) -> list[int]:
    """0, eval_every, 2 eval_every, ... up to `horizon`, and `horizon` itself (replayed updates).

    :param horizon: the last checkpoint, in replayed updates.
    :param eval_every: replayed updates between checkpoints.
    """
    points = list(range(0, int(horizon) + 1, int(eval_every)))
    return points if points[-1] == int(horizon) else [*points, int(horizon)]


def collect_database(job: RunJob, env, report=None):
    """The collector of `job` after ``database_episodes`` learning episodes, and the records of those episodes
    (EpisodeReturnProtocol's). Raises DivergenceError if Sarsa(lambda) diverges.

    :param job: the run.
    :param env: the env the runner made for it.
    :param report: called with the run's finished fraction (default None).
    """
    from sb3_er import ER
    from sb3_er.experiments.protocols import EpisodeReturnProtocol

    episodes = int(job.experiment.setting("database_episodes"))
    collector = ER("TileQ", env, seed=job.seed, **job_model_kwargs(job))
    protocol = EpisodeReturnProtocol(episodes, progress=report)
    collector.learn(total_timesteps=episodes * int(env.unwrapped.max_episode_steps), callback=protocol)
    return collector, protocol.records


def fresh_replay_model(job: RunJob, env, order: str, buffer_path: Path):
    """A fresh ER model (the collector's hyperparameters and seed, initial weights) with ``replay_order=order``,
    holding the database saved at `buffer_path`, its trajectory generator seeded with the job's seed.

    :param job: the run.
    :param env: the env the runner made for it.
    :param order: the replay order ("reversed", "forward" or "uniform").
    :param buffer_path: the saved database.
    """
    from sb3_er import ER

    model = ER("TileQ", env, seed=job.seed, **{**job_model_kwargs(job), "replay_order": order})
    model.load_replay_buffer(buffer_path, truncate_last_traj=False)
    model.replay_buffer.truncate_open_trajectory()  # the collector's run is over: an unfinished episode ends there
    model.seed_replay(job.seed)
    return model


def replay_order_run(job: RunJob, env, report) -> TaskOutput:
    """One seed of Appendix A (see the module docstring): collect, then replay the database in every order.

    `job.budget` is the horizon in replayed updates; the job's experiment gives ``database_episodes`` and
    ``eval_every``. Returns the frame described in the module docstring and the collector as the run's model.
    A divergence of a replay marks that order's remaining checkpoints ``diverged`` (return NaN); one of the
    collector marks every row.

    :param job: the run.
    :param env: the env the runner made for it.
    :param report: called with the run's finished fraction, for the progress bar.
    """
    import gymnasium as gym

    from sb3_er import ER, DivergenceError

    start = time.perf_counter()
    experiment = job.experiment
    horizon, eval_every = int(job.budget), int(experiment.setting("eval_every"))
    points = checkpoints(horizon, eval_every)
    eval_env = gym.make(experiment.env_id, **dict(job.env_kwargs))
    try:
        collector, episodes = collect_database(job, env, lambda fraction: report(0.4 * fraction))
    except DivergenceError:
        frame = pd.DataFrame(
            [
                {
                    "order": order,
                    "checkpoint": point,
                    "return": math.nan,
                    "diverged": True,
                    "wall_time_s": time.perf_counter() - start,
                }
                for order in ORDERS
                for point in points
            ],
            columns=list(COLUMNS),
        )
        return TaskOutput(frame, ER("TileQ", env, seed=job.seed, **job_model_kwargs(job)))
    collector_return, _, _ = greedy_return(collector, eval_env)
    returns = [record["return"] for record in episodes]
    database = {
        "database_episodes": len(episodes),
        "database_transitions": int(collector.replay_buffer.n_transitions),
        "database_trajectories": int(collector.replay_buffer.n_stored_trajectories),
        "database_goal_episodes": int(sum(record["goal_reached"] for record in episodes)),
        "database_last10_return": float(np.mean(returns[-10:])),
        "collector_greedy_return": collector_return,
    }
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        buffer_path = Path(scratch) / "database.pkl"
        collector.save_replay_buffer(buffer_path)
        for index, order in enumerate(ORDERS):
            model = fresh_replay_model(job, env, order, buffer_path)
            identity = {
                "database_sha256": database_digest(model.replay_buffer),
                "weights_at_start_sha256": weights_digest(model),
            }
            diverged = False
            for point in points:
                row = {"order": order, "checkpoint": point, **identity, **database}
                if not diverged:
                    try:
                        while model.replay_updates < point:
                            model.replay(1)
                    except DivergenceError:
                        diverged = True
                if diverged:
                    row.update(
                        replayed_updates=model.replay_updates,
                        diverged=True,
                        length=0,
                        goal_reached=False,
                        **{"return": math.nan},
                    )
                else:
                    total, length, goal = greedy_return(model, eval_env)
                    row.update(
                        replayed_updates=model.replay_updates,
                        diverged=False,
                        length=length,
                        goal_reached=goal,
                        **{"return": total},
                    )
                row["wall_time_s"] = time.perf_counter() - start
                rows.append(row)
                report(0.4 + 0.6 * (index + (points.index(point) + 1) / len(points)) / len(ORDERS))
    eval_env.close()
    return TaskOutput(pd.DataFrame(rows, columns=list(COLUMNS)), collector)


def _number(value: float) -> str:
    return f"{value:,.0f}" if abs(value) >= 100 else f"{value:.3g}"


def _format(value: float, half_width: float | None = None) -> str:
    """``-49,419 ± 1,203`` (returns in the pendulum's units); NA for NaN."""
    if value is None or not math.isfinite(value):
        return "NA"
    if half_width is None or not math.isfinite(half_width):
        return _number(value)
    return f"{_number(value)} ± {_number(half_width)}"


def ranking(means: dict[str, float]) -> str:
    """The orders by mean, best first, ``"reversed > uniform > forward"``; equal means joined by ``=``; NaN left
    out.

    :param means: mean greedy return by order.
    """
    finite = sorted(((mean, order) for order, mean in means.items() if math.isfinite(mean)), key=lambda item: -item[0])
    text = ""
    for index, (mean, order) in enumerate(finite):
        if index:
            text += " = " if mean == finite[index - 1][0] else " > "
        text += order
    return text


def replay_order_table(frames: dict[int, pd.DataFrame]) -> pd.DataFrame:
    """Per checkpoint: per order the mean greedy return over seeds with its 95% CI (diverged replays left out and
    counted), how many greedy episodes reached the goal, the mean actual replayed updates, the paired differences
    between the orders (same database per seed) with their 95% CI, our ranking and the thesis's finding. `frames` maps
    seeds to run frames.

    :param frames: the runs' frames by seed.
    """
    data = pd.concat([frame.assign(seed=seed) for seed, frame in frames.items()], ignore_index=True)
    rows = []
    for point in sorted(data["checkpoint"].unique()):
        at = data[data["checkpoint"] == point]
        row = {"checkpoint": int(point)}
        means = {}
        for order in ORDERS:
            values = at[(at["order"] == order) & ~at["diverged"].astype(bool)]
            n = len(values)
            mean, half = mean_confidence_interval(values["return"].to_numpy()) if n else (math.nan, math.nan)
            means[order] = float(mean)
            row.update(
                {
                    f"{order}_mean": float(mean),
                    f"{order}_ci95": float(half),
                    f"{order}_n": n,
                    f"{order}_goals": int(values["goal_reached"].astype(bool).sum()),
                    f"{order}_diverged": int(at[at["order"] == order]["diverged"].astype(bool).sum()),
                    f"{order}_updates": float(values["replayed_updates"].mean()) if n else math.nan,
                }
            )
        wide = at.pivot_table(index="seed", columns="order", values="return")
        for first, second in PAIRS:
            if first in wide and second in wide:
                differences = (wide[first] - wide[second]).dropna().to_numpy()
            else:
                differences = np.zeros(0)
            mean, half = mean_confidence_interval(differences) if differences.size else (math.nan, math.nan)
            row.update({f"{first}_minus_{second}": float(mean), f"{first}_minus_{second}_ci95": float(half)})
        row["ours_best_first"] = ranking(means)
        row["thesis"] = (
            ""
            if point == 0 or point > THESIS_RANGE
            else THESIS_FINDING_225K
            if point == THESIS_CHECKPOINT
            else THESIS_FINDING
        )
        rows.append(row)
    return pd.DataFrame(rows)


def _markdown(table: pd.DataFrame) -> str:
    lines = [
        "| Replayed updates | reversed | forward | uniform | reversed − uniform (paired) | reversed − forward "
        "(paired) | Ours: best first | Thesis (App. A, Fig. A.1) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in table.to_dict("records"):
        cells = [f"{row['checkpoint']:,}"]
        for order in ORDERS:
            text = _format(row[f"{order}_mean"], row[f"{order}_ci95"])
            text += f" (goal {row[f'{order}_goals']}/{row[f'{order}_n']})"
            if row[f"{order}_diverged"]:
                text += f" ({row[f'{order}_diverged']} diverged)"
            cells.append(text)
        for first, second in PAIRS[:2]:
            cells.append(_format(row[f"{first}_minus_{second}"], row[f"{first}_minus_{second}_ci95"]))
        cells += [row["ours_best_first"] or "NA", row["thesis"] or "—"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _check_orders_saw_one_database(frames: dict[int, pd.DataFrame]) -> list[int]:
    """Seeds whose orders did not all replay the same database from the same initial weights (should be none)."""
    return [
        seed
        for seed, frame in frames.items()
        if frame["database_sha256"].nunique(dropna=False) > 1
        or frame["weights_at_start_sha256"].nunique(dropna=False) > 1
    ]


@files.holds_folder_locks
def reproduce_replay_order(
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
    database_episodes: int | None = None,
    eval_every: int | None = None,
):
    """`sb3-er reproduce replay-order`: Appendix A with `n_seeds` databases (one run per seed on the runner).

    `budget` is the horizon in replayed updates (default 300,000), `database_episodes` the Sarsa(lambda) episodes per
    database (default 200), `eval_every` the replayed updates between evaluations (default 75,000), `env_kwargs` a
    pendulum reading other than its defaults. Writes ``runs/replay_order/seed_<n>.csv`` (and ``.json``, the version
    record, which also holds the env's resolved constructor arguments), ``summary.md``, ``summary.csv`` and
    ``replay_orders.png`` (Figure A.1) into `out_dir` (default ``results/replay-order``). Returns a Reproduction.
    ValueError for bad settings or a folder holding runs of other settings; MixedVersionsError / RunFailure as
    :func:`sb3_er.experiments.reproduce.reproduce`.

    :param n_seeds: the number of seeds (default 20, the thesis's).
    :param out_dir: the results folder (default None: ``results/<name>``).
    :param budget: the horizon in replayed updates (default None: 300,000).
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param first_seed: the first seed; the seeds are ``first_seed, ..., first_seed + n_seeds - 1`` (default 0).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance; only with ``backend="ray"``).
    :param allow_mixed_versions: accept finished runs made by other code or settings (default False: refused).
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param database_episodes: Sarsa(lambda) episodes per database (default None: 200).
    :param eval_every: replayed updates between evaluations (default None: 75,000).
    """
    from sb3_er.experiments.plots import plot_mean_with_error_bars
    from sb3_er.experiments.reproduce import Reproduction

    start = time.perf_counter()
    base: Analysis = ANALYSES["replay-order"]
    budget = float(base.default_budget if budget is None else budget)
    check_request(n_seeds, budget, base.budget_unit, backend, address)
    database_episodes = int(base.setting("database_episodes") if database_episodes is None else database_episodes)
    eval_every = int(base.setting("eval_every") if eval_every is None else eval_every)
    if database_episodes < 1 or eval_every < 1 or int(budget) != budget:
        raise ValueError(
            f"database_episodes and eval_every must be positive and the horizon a whole number of "
            f"replayed updates, got {database_episodes}, {eval_every}, {budget}"
        )
    experiment = base.with_settings(database_episodes=database_episodes, eval_every=eval_every)
    env_kwargs = dict(env_kwargs or {})
    check_env_kwargs(experiment.env_id, env_kwargs)  # once, before any run: not one failure per run
    out_dir = Path(out_dir if out_dir is not None else Path("results") / experiment.name)
    settings = {
        "experiment": experiment.name,
        "env_id": experiment.env_id,
        "budget": budget,
        "database_episodes": database_episodes,
        "eval_every": eval_every,
        "env_kwargs": env_kwargs,
    }
    files.lock_folder(out_dir)  # one writer per folder, until this function returns
    check_settings(out_dir, settings)
    seeds = list(range(first_seed, first_seed + n_seeds))
    jobs = [
        RunJob(
            experiment,
            "er",
            seed,
            budget,
            run_csv_path(out_dir, RUN_FOLDER, seed),
            tuple(sorted(env_kwargs.items())),
            tuple(sorted(COLLECTOR_KWARGS.items())),
            label=RUN_FOLDER,
        )
        for seed in seeds
    ]
    done, skipped = run_analysis_jobs(
        jobs, out_dir, n_workers, show_progress, backend, address, allow_mixed_versions, settings={out_dir: settings}
    )

    frames = {job.seed: read_run_csv(job.csv_path) for job in jobs if job.csv_path.is_file()}
    table = replay_order_table(frames)
    table_csv = files.write_csv(out_dir / "summary.csv", table)
    data = pd.concat([frame.assign(seed=seed) for seed, frame in frames.items()], ignore_index=True)
    series = {}
    for order in ORDERS:
        wide = data[data["order"] == order].pivot_table(index="seed", columns="checkpoint", values="return")
        wide = wide.dropna()  # seeds whose replay diverged are left out
        series[order] = (wide.columns.to_numpy(dtype=float), wide.to_numpy())
    collectors = data.drop_duplicates("seed")
    figure = plot_mean_with_error_bars(
        series,
        "replayed updates (samples)",
        "return of a greedy episode from the start",
        f"Pendulum, replay orders on the same {database_episodes}-episode Sarsa(λ) databases\n"
        f"(Figure A.1): mean of {counted(len(frames), 'seed')}, 95% CI",
        out_dir / "replay_orders.png",
        references={
            f"the Sarsa(λ) collectors, greedy (mean of {len(collectors)})": float(
                collectors["collector_greedy_return"].mean()
            )
        },
    )
    mismatched = _check_orders_saw_one_database(frames)
    sections = [
        f"# {experiment.title}: {counted(len(frames), 'seed')}, horizon {budget:,.0f} replayed updates",
        "",
        f"Per seed one database of {database_episodes} Sarsa(λ) episodes (ER with online_lambda 0.92 and no replay; "
        "α 0.2, γ 0.98, ε 0.1, 16 tilings), replayed by fresh ER models in each order from zero weights (ε-greedy "
        f"a' with ε 0.1), one trajectory at a time. Evaluation every {eval_every:,} replayed updates (each checkpoint "
        "passed by less than one trajectory; mean actual counts in summary.csv): the return of one greedy episode "
        "from the start (hanging at rest), at most the env's time limit. Mean ± 95 % CI over seeds (in brackets: "
        "greedy episodes that reached the goal); differences are paired by database.",
        "",
        _markdown(table),
        "",
        "Thesis (Appendix A, Figure A.1; numbers only in the figure, which covers up to about 300,000 replayed "
        "updates): forward order has the lowest gain per replayed sample; at 225,000 replays reversed trajectories are "
        "slightly better than uniformly drawn samples.",
        "",
        "Databases: {:,.0f} transitions, {:.1f} of {} episodes reaching the goal, last-10-episode learning return "
        "{:,.0f}, the collector's greedy return {:,.0f} (means over seeds).".format(
            collectors["database_transitions"].mean(),
            collectors["database_goal_episodes"].mean(),
            database_episodes,
            collectors["database_last10_return"].mean(),
            collectors["collector_greedy_return"].mean(),
        ),
        "Every order of a seed replayed the same database from the same initial weights (equal SHA-256 of the "
        "transitions and of the weights)."
        if not mismatched
        else f"**Seeds {mismatched}: the orders did not see the same database or initial weights.**",
        "",
        f"Pendulum reading (env arguments at run time): {env_reading(jobs)}.",
        "",
        code_line(jobs),
    ]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(sections) + "\n")
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=[figure],
        runs_done=done,
        runs_skipped=skipped,
        wall_time_s=time.perf_counter() - start,
    )

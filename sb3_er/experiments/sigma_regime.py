"""`sb3-er reproduce sigma-regime`: which way ER-σ moves its targets, per env and reading.

ER-σ (thesis 5.2, Alg. 9-10) replaces the values of never-visited features by σ(s'). Where vanilla ER is optimistic
about unvisited features (zero initial values above the values experience carries, thesis 5.2.1), σ lowers the
targets; where vanilla ER is pessimistic, σ raises them, and nothing in the update then holds the values to the
returns that are possible. Each run replays with ER-σ under the env's zoo settings and records, for every replay
phase, the mean shift T_σ - T of its targets over the same transitions' targets without σ (the same a' where the draw
explored, the greedy one otherwise: :func:`sb3_er.common.kernels.replay.er_sigma_td_error`), the shares of targets
raised and lowered, and the value watch's count of values outside the possible returns.

Readings (:data:`READINGS`): each is the reading of a table reproduction, with the same env settings and run length,
and names that reproduction's results folder (:attr:`Reading.results`), so that the docs can say which regime ER-σ was
in for each table: the grid world (Chapter 5), the pendulum's default (Table 6.1) and earlier default (velocity tiles
3.3 rad/s, goal 0.1 rad and 1 rad/s), the simplest walker's default (Table 6.2) and earlier default (GRL's start, fall
test and coordinates), the walker with optimistic initial values (Q starting at 100, no table), and LEO's default
(Table 6.3; a run is about 4 CPU minutes).

Learners (:data:`LEARNERS`): the thesis's ER-σ (``preset="thesis"``) and the stable learner's ER-σ (``preset="stable"``,
the projection of the weights onto the possible returns, docs/stable_replay.md), so that the table says whether σ still
raises the targets once the values are held to the possible returns.
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
from sb3_er.experiments.analyses import check_request, check_settings, code_line, run_analysis_jobs
from sb3_er.experiments.records import counted
from sb3_er.experiments.runner import RunJob, TaskOutput, job_model_kwargs, read_run_csv, run_csv_path
from sb3_er.experiments.specs import Analysis
from sb3_er.experiments.thesis import ALGORITHM_LABELS, row_algorithm

COLUMNS = (
    "phase",
    "timesteps",
    "episode",
    "updates",
    "sigma_shift",
    "sigma_raised",
    "sigma_lowered",
    "values_out_of_range",
    "diverged",
)


@dataclass(frozen=True)
class Reading:
    """One env and reading: its id, env keyword arguments, optimistic initial value (or None), run-length unit and
    default length.

    :param env_id: the Gymnasium id of the env.
    :param env_kwargs: ``gymnasium.make`` keyword arguments as sorted ``(name, value)`` pairs (default none).
    :param initial_value: an optimistic initial Q (``policy_kwargs=dict(initial_value=...)``); None (default) keeps
        the zero initial weights.
    :param unit: the unit of the run length, "episodes" (default) or seconds of learning time.
    :param budget: the default run length in that unit (default 100).
    :param title: the reading's name in tables (default "").
    :param results: the ``results/measured/`` folder of the table reproduced under this reading ("" for none).
    """

    env_id: str
    env_kwargs: tuple = ()
    initial_value: float | None = None
    unit: str = "episodes"
    budget: float = 100.0
    title: str = ""
    results: str = ""


#: The learners of each reading: the tables' ER-σ rows (their runs folders; the preset each runs and its label come
#: from :func:`sb3_er.experiments.thesis.row_algorithm` and ``ALGORITHM_LABELS``).
LEARNERS = ("er_sigma", "er_sigma_stable")

WALKER_EARLIER_DEFAULT = (("fall", "angles"), ("observation", "grl"), ("start", "grl"))
READINGS = {
    "gridworld": Reading("sb3_er/WindyCliff-v0", title="windy cliff grid world", results="gridworld"),
    "pendulum-0.33": Reading(
        "sb3_er/PendulumSwingup-v0",
        title="pendulum, default (velocity tiles 0.33 rad/s as printed)",
        results="table_6_1",
    ),
    "pendulum-3.3": Reading(
        "sb3_er/PendulumSwingup-v0",
        (("goal_angle", 0.1), ("goal_velocity", 1.0), ("velocity_tile_width", 3.3)),
        title="pendulum, earlier default (velocity tiles 3.3 rad/s, goal 0.1 rad and 1 rad/s)",
        results="table_6_1_earlier_default",
    ),
    "walker": Reading(
        "sb3_er/SimplestWalker-v0", unit="seconds", budget=5000.0, title="simplest walker, default", results="table_6_2"
    ),
    "walker-earlier": Reading(
        "sb3_er/SimplestWalker-v0",
        WALKER_EARLIER_DEFAULT,
        unit="seconds",
        budget=5000.0,
        title="simplest walker, earlier default (GRL's start, fall test and coordinates)",
        results="table_6_2_earlier_default",
    ),
    "walker-optimistic": Reading(
        "sb3_er/SimplestWalker-v0",
        initial_value=100.0,
        unit="seconds",
        budget=5000.0,
        title="simplest walker, Q starting at 100",
    ),
    "leo": Reading("sb3_er/Leo-v0", unit="seconds", budget=12000.0, title="LEO, default", results="table_6_3"),
}


def regime_experiment(name: str) -> Analysis:
    """The runner's experiment of one reading: ER-σ on the reading's env, one row per replay phase.

    :param name: the reading's name, a key of :data:`READINGS`.
    """
    reading = READINGS[name]
    return Analysis(
        name=f"sigma-regime-{name}",
        env_id=reading.env_id,
        title=f"ER-σ's target shift: {reading.title}",
        protocol="sigma_regime",
        default_budget=reading.budget,
        x_column="timesteps",
        x_label="env steps",
        performance_column="sigma_shift",
        performance_label="mean T_σ - T of a replay phase",
        rise_time_unit=reading.unit,
        task="sigma_regime",
        unit=reading.unit,
    ).with_settings(reading=name, initial_value=reading.initial_value)


def sigma_regime_run(job: RunJob, env, report) -> TaskOutput:
    """One (reading, seed): ER-σ with the env's zoo settings for ``job.budget`` episodes or seconds of learning,
    one row per replay phase.

    :param job: the run.
    :param env: the env the runner made for it.
    :param report: called with the run's finished fraction, for the progress bar.
    """
    from sb3_er import DivergenceError
    from sb3_er.zoo import algorithm_classes

    experiment = job.experiment
    initial_value = experiment.setting("initial_value")
    kwargs = job_model_kwargs(job)
    if initial_value is not None:
        kwargs["policy_kwargs"] = {**(kwargs.get("policy_kwargs") or {}), "initial_value": float(initial_value)}
    kwargs["value_bound_action"] = "ignore"  # counted in the rows instead
    model = algorithm_classes()[job.algo]("TileQ", env, seed=job.seed, **kwargs)
    if experiment.unit == "seconds":
        total = max(1, round(job.budget / env.unwrapped.dt))
    else:
        limit = env.spec.max_episode_steps if env.spec is not None and env.spec.max_episode_steps else None
        total = int(job.budget) * int(limit or env.unwrapped.max_episode_steps)
    rows = []
    replay = model.replay

    def recorded(n_trajectories: int) -> dict:
        result = replay(n_trajectories)
        if result["updates"]:
            rows.append(
                {
                    "phase": model.replay_phases,
                    "timesteps": model.num_timesteps,
                    "episode": model._episode_num + 1,
                    "updates": result["updates"],
                    "sigma_shift": result.get("sigma_shift", math.nan),
                    "sigma_raised": result.get("sigma_raised", math.nan),
                    "sigma_lowered": result.get("sigma_lowered", math.nan),
                    "values_out_of_range": model.values_out_of_range,
                }
            )
            report(min(1.0, model.num_timesteps / total))
        return result

    model.replay = recorded
    callback = None
    if experiment.unit == "episodes":
        from sb3_er.experiments.protocols import EpisodeReturnProtocol

        callback = EpisodeReturnProtocol(int(job.budget))
    try:
        model.learn(total_timesteps=total, callback=callback)
        diverged = False
    except DivergenceError:
        diverged = True
    del model.replay
    frame = pd.DataFrame(rows, columns=list(COLUMNS[:-1]))
    frame["diverged"] = diverged
    return TaskOutput(frame, model)


def regime_jobs(
    out_dir: Path,
    readings: Sequence[str],
    seeds: Sequence[int],
    budget: float | None,
    learners: Sequence[str] = ("er_sigma",),
) -> list[RunJob]:
    """One job per (reading, learner, seed): ``<out>/<reading>/runs/<learner>/seed_<n>.csv``.

    :param out_dir: the results folder.
    :param readings: the readings' names.
    :param seeds: the seeds.
    :param budget: run length (None: each reading's own).
    :param learners: the learners, names in :data:`LEARNERS` (default the thesis's ER-σ only).
    """
    jobs = []
    for name in readings:
        reading = READINGS[name]
        length = float(reading.budget if budget is None else budget)
        initial = () if reading.initial_value is None else (("initial_value", reading.initial_value),)
        for learner in learners:
            jobs += [
                RunJob(
                    regime_experiment(name),
                    "er_sigma",
                    seed,
                    length,
                    run_csv_path(Path(out_dir) / name, learner, seed),
                    reading.env_kwargs,
                    tuple(sorted({**dict(initial), "preset": "thesis", **row_algorithm(learner)[1]}.items())),
                    label=f"{name}/{learner}",
                )
                for seed in seeds
            ]
    return jobs


def summarize_regime(frames: dict[int, pd.DataFrame]) -> dict:
    """Per reading: the update-weighted mean shift and shares over every phase of every run, the runs whose values
    left the possible returns, and the diverged runs.

    :param frames: one reading's run frames by seed.
    """
    complete = [frame for frame in frames.values() if not frame.empty]
    if not complete:
        return {"runs": len(frames), "phases": 0}
    rows = pd.concat(complete)
    weights = rows["updates"].to_numpy(dtype=float)

    def weighted(column: str) -> float:
        values = rows[column].to_numpy(dtype=float)
        keep = np.isfinite(values)
        return float(np.average(values[keep], weights=weights[keep])) if keep.any() else math.nan

    return {
        "runs": len(frames),
        "phases": len(rows),
        "mean_shift": weighted("sigma_shift"),
        "raised": weighted("sigma_raised"),
        "lowered": weighted("sigma_lowered"),
        "left_bounds": int(sum(frame["values_out_of_range"].iloc[-1] > 0 for frame in complete)),
        "diverged": int(sum(frame["diverged"].astype(bool).any() for frame in frames.values())),
    }


@files.holds_folder_locks
def reproduce_sigma_regime(
    n_seeds: int = 4,
    out_dir: str | Path | None = None,
    budget: float | None = None,
    n_workers: int | None = None,
    first_seed: int = 0,
    show_progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    allow_mixed_versions: bool = False,
    env_kwargs: dict | None = None,
    readings: Sequence[str] | None = None,
    learners: Sequence[str] | None = None,
):
    """`sb3-er reproduce sigma-regime`: the ER-σ runs of each reading, then ``summary.md`` and ``summary.csv`` with the
    regime figures. `budget` (episodes or seconds of learning) applies to readings of one unit only. Returns a
    Reproduction.

    :param n_seeds: seeds per reading (default 4).
    :param out_dir: the results folder (default None: ``results/<name>``).
    :param budget: run length in episodes or seconds of learning (default None: each reading's own).
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param first_seed: the first seed; the seeds are ``first_seed, ..., first_seed + n_seeds - 1`` (default 0).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance; only with ``backend="ray"``).
    :param allow_mixed_versions: accept finished runs made by other code or settings (default False: refused).
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param readings: the readings' names (default None: all of :data:`READINGS`).
    :param learners: the learners, names in :data:`LEARNERS` (default None: both, the thesis's ER-σ and the stable
        learner's).
    """
    from sb3_er.experiments.reproduce import Reproduction

    start = time.perf_counter()
    readings = list(dict.fromkeys(readings or READINGS))
    unknown = [name for name in readings if name not in READINGS]
    if unknown:
        raise ValueError(f"unknown readings {unknown}; choose from {', '.join(READINGS)}")
    learners = list(dict.fromkeys(learners or LEARNERS))
    unknown = [name for name in learners if name not in LEARNERS]
    if unknown:
        raise ValueError(f"unknown learners {unknown}; choose from {', '.join(LEARNERS)}")
    if env_kwargs:
        raise ValueError("sigma-regime runs each reading with its own env settings; --env-kwargs does not apply")
    units = {READINGS[name].unit for name in readings}
    if budget is not None and len(units) > 1:
        raise ValueError(
            f"--budget needs readings of one unit; {', '.join(readings)} mix {' and '.join(units)}: "
            "choose the readings with --readings"
        )
    check_request(n_seeds, 1.0 if budget is None else budget, units.pop(), backend, address)
    out_dir = Path(out_dir if out_dir is not None else Path("results") / "sigma_regime")
    settings = {
        out_dir / name: {
            "experiment": f"sigma-regime-{name}",
            "env_id": READINGS[name].env_id,
            "budget": float(READINGS[name].budget if budget is None else budget),
            "env_kwargs": dict(READINGS[name].env_kwargs),
            "initial_value": READINGS[name].initial_value,
        }
        for name in readings
    }
    files.lock_folder(out_dir, *settings)  # one writer per folder, until this function returns
    for folder, pinned in settings.items():
        check_settings(folder, pinned)
    seeds = list(range(first_seed, first_seed + n_seeds))
    jobs = regime_jobs(out_dir, readings, seeds, budget, learners)
    done, skipped = run_analysis_jobs(
        jobs, out_dir, n_workers, show_progress, backend, address, allow_mixed_versions, settings=settings
    )
    # The summary covers the folder: the (reading, learner) pairs run now (their requested seeds) and every other
    # pair whose runs an earlier command left in it (all their finished seeds), so that running one keeps the others.
    summarized, lengths = {}, {}  # (reading, learner) -> its seeds; reading -> its run length; in READINGS' order
    for name in READINGS:
        for learner in LEARNERS:
            if name in readings and learner in learners:
                summarized[name, learner], lengths[name] = seeds, settings[out_dir / name]["budget"]
            elif (out_dir / name / "settings.json").is_file():
                found = sorted(
                    int(path.stem.removeprefix("seed_"))
                    for path in (out_dir / name / "runs" / learner).glob("seed_*.csv")
                )
                if found:
                    pinned = files.read_json(
                        out_dir / name / "settings.json", f"rerun the reading with --readings {name} into a new --out"
                    )
                    summarized[name, learner], lengths[name] = found, float(pinned["budget"])
    summary_jobs = [
        job
        for (name, learner), its_seeds in summarized.items()
        for job in regime_jobs(out_dir, [name], its_seeds, lengths[name], [learner])
    ]
    rows = []
    for (name, learner), its_seeds in summarized.items():
        frames = {
            seed: read_run_csv(path)
            for seed in its_seeds
            if (path := run_csv_path(out_dir / name, learner, seed)).is_file()
        }
        rows.append(
            {"reading": name, "learner": learner, "results": READINGS[name].results, **summarize_regime(frames)}
        )
    table = pd.DataFrame(rows)
    table_csv = files.write_csv(out_dir / "summary.csv", table)
    counts = {len(its_seeds) for its_seeds in summarized.values()}
    per_reading = (
        f"{counted(n_seeds, 'seed')} per reading and learner"
        if counts == {n_seeds}
        else "the runs per reading and learner are counted in the last two columns"
    )
    lines = [
        f"# Which way ER-σ moves its targets: {per_reading}",
        "",
        "Per replay phase, the mean of T_σ - T over its updates (T the same transition's target without σ), and the "
        "shares of targets σ raised and lowered; averaged over all phases of all runs, weighted by their updates. "
        "Values outside: runs whose value watch saw a target or Q-value outside the possible returns.",
        "",
        "| Reading | Learner | Its table's results | Run length | Phases | Mean T_σ - T | Raised | Lowered | "
        "Values outside | Diverged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        reading, learner = READINGS[row["reading"]], ALGORITHM_LABELS[row["learner"]]
        length = f"{lengths[row['reading']]:g} {reading.unit}"
        folder = f"results/measured/{reading.results}" if reading.results else "—"
        if not row.get("phases"):
            lines.append(f"| {reading.title} | {learner} | {folder} | {length} | 0 | — | — | — | — | — |")
            continue
        lines.append(
            f"| {reading.title} | {learner} | {folder} | {length} | {row['phases']} | {row['mean_shift']:+.3g} | "
            f"{row['raised']:.1%} | {row['lowered']:.1%} | {row['left_bounds']} of {row['runs']} | "
            f"{row['diverged']} of {row['runs']} |"
        )
    lines += ["", code_line(summary_jobs)]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(lines) + "\n")
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=[],
        runs_done=done,
        runs_skipped=skipped,
        wall_time_s=time.perf_counter() - start,
    )

"""`sb3-er reproduce`: one thesis experiment, all (algorithm, seed) pairs, the summary table and the figures."""

from __future__ import annotations

import os
import re
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from sb3_er.common.env_ids import check_env_kwargs
from sb3_er.experiments import files, records
from sb3_er.experiments.runner import BACKENDS, RunJob, plan_jobs, read_run_csv, run_jobs
from sb3_er.experiments.specs import EXPERIMENTS, Experiment
from sb3_er.experiments.summary import load_curves, markdown_table, summary_table
from sb3_er.experiments.thesis import ALGORITHM_LABELS, STABLE_ROWS

ALL_ALGORITHMS = tuple(ALGORITHM_LABELS)


@dataclass
class Reproduction:
    """What a reproduction produced: the output files and the wall times.

    :param out_dir: the output folder.
    :param table_markdown: ``summary.md``, the table beside the thesis's numbers.
    :param table_csv: ``summary.csv``, the same table as CSV.
    :param figures: the figures and animations written (default none).
    :param runs_done: runs made by this call (default 0).
    :param runs_skipped: runs already finished in ``out_dir`` and resumed (default 0).
    :param wall_time_s: wall time of the call in seconds (default 0).
    """

    out_dir: Path
    table_markdown: Path
    table_csv: Path
    figures: list[Path] = field(default_factory=list)
    runs_done: int = 0
    runs_skipped: int = 0
    wall_time_s: float = 0.0


def _checked_experiment(name: str) -> Experiment:
    if name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    return EXPERIMENTS[name]


def _checked_algorithms(algos: Sequence[str]) -> list[str]:
    unknown = [algo for algo in algos if algo not in ALL_ALGORITHMS]
    if unknown or not algos:
        raise ValueError(f"unknown or no algorithms {unknown}; choose from {', '.join(ALL_ALGORITHMS)}")
    return list(dict.fromkeys(algos))


def _settings(experiment: Experiment, budget: float, env_kwargs: dict, algo_kwargs: dict) -> dict:
    """What ``settings.json`` pins for a reproduction: the experiment, run length and reading."""
    settings = {"experiment": experiment.name, "env_id": experiment.env_id, "budget": budget}
    if env_kwargs or algo_kwargs:
        settings.update(env_kwargs=records.normalized(env_kwargs), algo_kwargs=records.normalized(algo_kwargs))
    return settings


def _check_finished_runs(finished: list[RunJob], out_dir: Path, allow_mixed_versions: bool) -> None:
    """Refuse to resume next to finished runs of other code or configuration (see sb3_er.experiments.records)."""
    if not finished:
        return
    code = records.code_version()
    records.check_versions(
        {job.key: records.read_record(job.csv_path) for job in finished},
        {job.key: records.current_record(job, code) for job in finished},
        allow_mixed_versions,
        f"{out_dir} holds finished runs that",
    )


def _code_versions_line(out_dir: Path, rows: dict[str, list[int]]) -> str:
    """Which code made the runs, e.g. "Code: sb3-er 0.1.0, code hash 1f4d0e44dc (40 runs from commit 91bd149)"."""
    from sb3_er.experiments.runner import run_csv_path

    paths = [run_csv_path(out_dir, row, seed) for row, seeds in rows.items() for seed in seeds]
    return records.code_versions_line([records.read_record(path) for path in paths if path.is_file()])


class LeftOutRunWarning(UserWarning):
    """Runs of rows a command did not run whose files do not match their records (or have none): left out of the
    summary, and named; the command with ``--algos <row>`` checks them again and redoes them."""


def _finished_rows(
    experiment: Experiment,
    out_dir: Path,
    algos: Sequence[str],
    seeds: Sequence[int],
    budget: float,
    env_kwargs: dict,
    algo_kwargs: dict,
) -> dict[str, list[int]]:
    """{row: seeds} of the summary, in the tables' order: this command's rows and seeds, and every other finished run
    of the folder (``runs/<row>/seed_<n>.csv``; one folder holds one reading and run length, pinned by its
    ``settings.json``), so that rows run by several commands (LEO's stable rows with fewer seeds) share one table. A
    run of another row or seed is summarized only when its files match its record (:func:`runner.check_run`); the
    others are named in a LeftOutRunWarning."""
    from sb3_er.experiments.runner import check_run, row_jobs

    rows: dict[str, set[int]] = {algo: set(seeds) for algo in algos}
    runs, left_out = Path(out_dir) / "runs", []
    for folder in sorted(runs.iterdir()) if runs.is_dir() else []:
        if not (folder.is_dir() and folder.name in ALGORITHM_LABELS):
            continue
        found = (re.fullmatch(r"seed_(0|[1-9]\d*)\.csv", path.name) for path in folder.iterdir() if path.is_file())
        done_here = rows.get(folder.name, set())
        others = sorted(seed for match in found if match and (seed := int(match.group(1))) not in done_here)
        for job in row_jobs(experiment, folder.name, others, budget, out_dir, env_kwargs, algo_kwargs):
            done, problem = check_run(job)
            if done:
                rows.setdefault(folder.name, set()).add(job.seed)
            else:
                left_out.append(problem or f"{job.csv_path}: not finished")
    if left_out:
        warnings.warn(
            "left out of the summary, their files do not match their records: " + "; ".join(left_out) + " (run the "
            "command with --algos naming their rows to check and redo them)",
            LeftOutRunWarning,
            stacklevel=3,
        )
    return {row: sorted(rows[row]) for row in ALGORITHM_LABELS if row in rows}


def _seeds_text(rows: dict[str, list[int]]) -> str:
    """ "20 seeds", or "20 seeds (10 for A and B)" when some rows have another number."""
    counts = {row: len(seeds) for row, seeds in rows.items()}
    most = max(counts.values(), key=list(counts.values()).count) if counts else 0
    others: dict[int, list[str]] = {}
    for row, count in counts.items():
        if count != most:
            others.setdefault(count, []).append(ALGORITHM_LABELS[row])
    text = records.counted(most, "seed")
    if others:
        text += " (" + "; ".join(f"{count} for {', '.join(labels)}" for count, labels in others.items()) + ")"
    return text


@files.holds_folder_locks
def reproduce(
    experiment_name: str,
    n_seeds: int = 20,
    algos: Sequence[str] = ALL_ALGORITHMS,
    out_dir: str | Path | None = None,
    budget: float | None = None,
    n_workers: int | None = None,
    first_seed: int = 0,
    show_progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    allow_mixed_versions: bool = False,
    env_kwargs: dict | None = None,
    algo_kwargs: dict | None = None,
) -> Reproduction:
    """Run (or resume) an experiment and write its per-run CSVs and records, summary table (markdown, CSV), figures.

    `backend` ``"local"`` runs on `n_workers` processes (default: all CPUs); ``"ray"`` runs every (algorithm, seed)
    pair as a Ray task with one CPU, on a local Ray instance of `n_workers` CPUs, or on the cluster at `address`
    (``"auto"`` or ``"HOST:PORT"``). Resuming next to finished runs whose version record differs from the current code
    or configuration, or that have no record, raises MixedVersionsError naming the runs and fields, unless
    `allow_mixed_versions`. Failed runs raise RunFailure after the others are written.

    `env_kwargs` and `algo_kwargs` run a reading other than the defaults: keyword arguments of ``gymnasium.make`` for
    the learning and evaluation envs, and constructor arguments that override the zoo config of every algorithm that
    has them (a name that no chosen algorithm accepts is a ValueError, and so is a name the runner sets itself, such
    as ``seed``). The table's heading names them.

    One command writes a folder at a time: a second one raises FolderLockedError naming the holder and changes
    nothing. A finished run whose files do not match its record is moved aside and done again (DamagedRunWarning).
    ``settings.json`` is written once a run has finished.

    :param experiment_name: "gridworld", "pendulum", "walker" or "leo".
    :param n_seeds: seeds per algorithm (default 20, the thesis's).
    :param algos: the table's rows: rl-zoo names of the algorithms, and the stable learner's rows such as
        "er_sigma_stable" (each ER class with ``preset="stable"``); default every row, the thesis's five algorithms
        and the four stable rows.
    :param out_dir: output folder; None (default) is ``results/<experiment_name>``.
    :param budget: run length in episodes (grid world, pendulum) or seconds of learning time (walker, LEO); None
        (default) is the experiment's (100 episodes, 100 episodes, 5000 s, 12000 s).
    :param n_workers: worker processes, or the CPUs of a local Ray instance; None (default): every CPU.
    :param first_seed: the first seed (default 0); the seeds are ``first_seed .. first_seed + n_seeds - 1``.
    :param show_progress: show one progress bar over all runs (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster, "auto" or "HOST:PORT"; None (default) starts a local instance.
    :param allow_mixed_versions: resume next to runs of other code or settings with a warning (default False).
    :param env_kwargs: ``gymnasium.make`` keyword arguments of the reading to run; None (default) for the defaults.
    :param algo_kwargs: constructor arguments over the zoo configs; None (default) for none.
    :returns: a :class:`Reproduction` naming the files written and the wall time.
    """
    from sb3_er.experiments.plots import plot_mean_with_ci

    start = time.perf_counter()
    experiment = _checked_experiment(experiment_name)
    algos = _checked_algorithms(algos)
    if int(n_seeds) != n_seeds or n_seeds < 1:
        raise ValueError(f"the number of seeds must be a positive integer, got {n_seeds}")
    budget = float(experiment.default_budget if budget is None else budget)
    if budget <= 0:
        raise ValueError(f"the run length must be positive ({experiment.budget_unit}), got {budget}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) is for the Ray backend only; add --backend ray")
    env_kwargs, algo_kwargs = dict(env_kwargs or {}), dict(algo_kwargs or {})
    check_env_kwargs(experiment.env_id, env_kwargs)  # once, before any run: not one failure per run
    _check_algo_kwargs(algos, algo_kwargs)
    if "preset" in algo_kwargs:
        raise ValueError(
            "a table's rows choose their preset: the thesis's algorithms run preset='thesis', the stable learner's "
            f"rows preset='stable' (--algos {' '.join(STABLE_ROWS)}); --algo-kwargs cannot set it"
        )
    out_dir = Path(out_dir if out_dir is not None else Path("results") / experiment.name)
    files.lock_folder(out_dir)  # one writer per folder, until this function returns
    settings = _settings(experiment, budget, env_kwargs, algo_kwargs)
    records.check_settings(out_dir, settings)
    seeds = list(range(first_seed, first_seed + n_seeds))

    to_run, finished = plan_jobs(experiment, algos, seeds, budget, out_dir, env_kwargs, algo_kwargs)
    _check_finished_runs(finished, out_dir, allow_mixed_versions)
    if finished:
        records.pin_settings(out_dir, settings)
    if backend == "local":
        n_workers = n_workers or os.cpu_count() or 1
    run_jobs(
        to_run,
        n_workers,
        show_progress,
        backend=backend,
        address=address,
        allow_mixed_versions=allow_mixed_versions,
        on_written=lambda job: records.pin_settings(out_dir, settings),
    )

    # this command's rows and seeds, and the finished runs of earlier commands
    rows = _finished_rows(experiment, out_dir, algos, seeds, budget, env_kwargs, algo_kwargs)
    curves = {row: load_curves(experiment, out_dir, row, row_seeds, budget) for row, row_seeds in rows.items()}
    curves = {row: curve for row, curve in curves.items() if curve is not None}
    table = summary_table(experiment, curves, budget)
    seeds_text = _seeds_text(rows)
    plotted = {algo: every for algo, curve in curves.items() if (every := curve.all_runs()).seeds}
    table_csv = files.write_csv(out_dir / "summary.csv", table)

    figures = [
        plot_mean_with_ci(
            {algo: (curve.x, curve.performance) for algo, curve in plotted.items()},
            experiment.x_label,
            experiment.performance_label,
            f"{experiment.title}: mean of {seeds_text.replace('seed', 'run')}, 95% CI",
            out_dir / "learning_curves.png",
        )
    ]
    if experiment.has_falls:
        figures.append(
            plot_mean_with_ci(
                {algo: (curve.x, curve.cumulative_falls) for algo, curve in plotted.items()},
                experiment.x_label,
                "cumulative falls while learning",
                f"{experiment.title}: falls, mean of {seeds_text.replace('seed', 'run')}, 95% CI",
                out_dir / "cumulative_falls.png",
            )
        )
    figures += _per_run_figures(experiment, out_dir, curves, first_seed)
    reading = "".join(f", {name}={value!r}" for name, value in {**env_kwargs, **algo_kwargs}.items())
    length = (
        records.counted(budget, "episode")
        if experiment.protocol == "episodes"
        else f"{budget:g} {experiment.budget_unit}"
    )
    sections = [
        f"# {experiment.title}: {seeds_text}, {length} per run{reading}",
        "",
        markdown_table(experiment, table),
        "",
        experiment.thesis_caption,
        "Averages count every run: a run whose values left the possible returns with its own curve, "
        + (
            "a diverged run as one that learned nothing (the random policy's score throughout"
            + (", its falls going on at its last rate to the end of the run)" if experiment.has_falls else ")")
            if experiment.random_performance is not None
            else "a diverged run not at all (this experiment has no random policy's score to count it by)"
        )
        + "; their counts have rows of their own, and rows marked (inside only) average the runs that stayed inside. "
        "Rise time is measured on the mean curve, to 90 % of its way from its first value to its best; settling time "
        "is its first point within 10 % of its final plateau, so it can come before the rise time.",
        "",
        "Learning wall time per algorithm (sum over its runs): "
        + ", ".join(f"{ALGORITHM_LABELS[algo]} {curve.wall_time_s:.0f} s" for algo, curve in curves.items()),
        "",
        _code_versions_line(out_dir, rows),
    ]
    if experiment.name == "gridworld":
        value_figures, value_section = _gridworld_value_maps(out_dir, first_seed)
        figures += value_figures
        sections += ["", value_section]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(sections) + "\n")
    if THESIS_TABLES.get(experiment.name):
        from sb3_er.experiments.findings import table_findings, write_findings

        write_findings(out_dir, THESIS_TABLES[experiment.name], table_findings(experiment, curves, budget))
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=figures,
        runs_done=len(to_run),
        runs_skipped=len(finished),
        wall_time_s=time.perf_counter() - start,
    )


#: The thesis table each experiment reproduces, whose printed differences become its findings.json.
THESIS_TABLES = {"pendulum": "Table 6.1", "walker": "Table 6.2", "leo": "Table 6.3"}


def _check_algo_kwargs(algos: Sequence[str], algo_kwargs: dict) -> None:
    from sb3_er.experiments.runner import check_algo_kwargs
    from sb3_er.experiments.thesis import row_algorithm
    from sb3_er.zoo import algorithm_classes

    check_algo_kwargs([algorithm_classes()[row_algorithm(algo)[0]] for algo in algos], algo_kwargs)


def _per_run_figures(experiment: Experiment, out_dir: Path, curves: dict, seed: int) -> list[Path]:
    """Figure 4.5 (one seed's learning curve per algorithm, for the walking experiments) and, for the walker, each
    algorithm's learned gait (Figures 4.6 / 6.3, ``gait_<algo>.png``) and animation (``walker_<algo>.gif``) from the
    first seed's final greedy policy."""
    from sb3_er.experiments.gait import GaitTrace, plot_gait
    from sb3_er.experiments.plots import plot_typical_runs
    from sb3_er.experiments.runner import artifact_path, run_csv_path

    figures = []
    if experiment.protocol == "walking":
        runs = {}
        for algo, curve in curves.items():
            if curve is not None and seed in curve.all_runs().seeds and seed not in curve.diverged_seeds:
                frame = read_run_csv(run_csv_path(out_dir, algo, seed))
                runs[ALGORITHM_LABELS[algo]] = (
                    frame[experiment.x_column].to_numpy(),
                    frame[experiment.performance_column].to_numpy(),
                )
        if runs:
            figures.append(
                plot_typical_runs(
                    runs,
                    experiment.x_label,
                    experiment.performance_label,
                    f"{experiment.title}: typical runs (seed {seed})",
                    out_dir / "typical_runs.png",
                )
            )
    for algo in curves:
        csv_path = run_csv_path(out_dir, algo, seed)
        gait_csv, gif = artifact_path(csv_path, "gait.csv"), artifact_path(csv_path, "walker.gif")
        if gait_csv.is_file():
            table = read_run_csv(gait_csv)
            trace = GaitTrace(
                table["time"].to_numpy(),
                table["stance_angle"].to_numpy(),
                table["hip_angle"].to_numpy(),
                table["swing_foot_height"].to_numpy(),
                bool(table["fell"].iloc[-1]),
                float(table["distance"].iloc[-1]) if "distance" in table else 0.0,  # older runs did not record it
            )
            figures.append(
                plot_gait(
                    {ALGORITHM_LABELS[algo]: trace},
                    out_dir / f"gait_{algo}.png",
                    f"{experiment.title}: greedy gait after learning, {ALGORITHM_LABELS[algo]}",
                )
            )
        if gif.is_file():
            figures.append(files.write_atomically(out_dir / f"walker_{algo}.gif", gif.read_bytes()))
    return figures


def _gridworld_value_maps(out_dir: Path, seed: int) -> tuple[list[Path], str]:
    """The value-map study (thesis 5.2-5.4): figures, statistics CSV and a markdown section."""
    import gymnasium as gym

    import sb3_er_envs  # noqa: F401
    from sb3_er.experiments.gridworld import ENV_ID, same_data_value_maps
    from sb3_er.experiments.plots import plot_value_maps

    maps, statistics = same_data_value_maps(seed)
    files.write_csv(out_dir / "value_maps.csv", statistics)
    first_windy_row = gym.make(ENV_ID).unwrapped.first_windy_row
    figures = [
        plot_value_maps(
            cases,
            first_windy_row,
            f"Windy cliff: V = max_a Q, same data and replays per row ({situation})",
            out_dir / f"value_maps_{situation.replace(' ', '_')}.png",
        )
        for situation, cases in maps.items()
    ]
    lines = [
        "## Value functions on the same data and the same replays (thesis Tables 5.1-5.2, Figures 5.2-5.7)",
        "",
        "| Situation | Case | Algorithm | Windy max | Windy mean | Windy cells > 0 | Calm max | Calm min | "
        "Values outside the possible returns |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in statistics.itertuples():
        lines.append(
            f"| {row.situation} | {row.case} | {ALGORITHM_LABELS[row.algorithm]} | {row.windy_max:.1f} | "
            f"{row.windy_mean:.1f} | {row.windy_positive_fraction:.0%} | {row.calm_max:.1f} | {row.calm_min:.1f} | "
            f"{row.values_out_of_range:,} |"
        )
    lines += [
        "",
        "Values outside the possible returns: the targets and Q-values the value watch saw outside them, "
        "counted over the model's learning and replays (the maps are made outside the table's runs).",
    ]
    return figures, "\n".join(lines)

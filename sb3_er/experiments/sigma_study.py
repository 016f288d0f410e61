"""Thesis Appendix B: ER-sigma with each of the five definitions of sigma(s') on the simplest walker.

Every (definition, seed) pair is one run of the walker experiment (:data:`~sb3_er.experiments.specs.EXPERIMENTS`
``"walker"``: ER-sigma with the thesis's walker settings from ``zoo_configs/er_sigma.yml``, the env's default reading
at run time; every 100 s of learning 10 greedy runs of 100 s, 5000 s in all) with ``sigma`` set to the definition.
The runs go through the runner like any reproduction (parallel, resumable, versioned records, Ray); each definition
has its own folder ``runs/er_sigma-<definition>/seed_<n>.csv``, and its record names the definition
(``run``: ``er_sigma-<definition>/seed_<n>``; ``config.algorithm_kwargs.sigma`` and ``resolved.algorithm.sigma``).

A run's score is the thesis's "average of each recorded walking distance": the mean of the distances (m per 100 s,
each the mean of 10 greedy runs) recorded after 100, 200, ..., 5000 s of learning. The evaluation at 0 s, before any
learning, is left out: it is the same for every definition (zero weights, the same evaluation starts). The table
gives per definition the mean score over its runs with the 95 % CI (diverged runs left out and counted), and the
thesis's finding beside it: definition 4 (between the worst case and the average) performs best, and performance
drops greatly towards the best case (Figure B.1; the thesis prints no numbers).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.common.env_ids import check_env_kwargs
from sb3_er.experiments import files
from sb3_er.experiments.analyses import check_request, check_settings, code_line, env_reading, run_analysis_jobs
from sb3_er.experiments.metrics import mean_confidence_interval
from sb3_er.experiments.records import counted
from sb3_er.experiments.runner import RunJob, read_run_csv, run_csv_path
from sb3_er.experiments.specs import ANALYSES

ALGO = "er_sigma"
# name: (the thesis's number in Appendix B, sigma(s'), the thesis's finding). Ordered from the worst case to the best.
DEFINITIONS: dict[str, tuple[int, str, str]] = {
    "worst": (1, "min_a Q/W", "below definition 4"),
    "average_worst": (4, "½ (Σ_a Q / Σ_a W + min_a Q/W)", "best (the thesis's choice)"),
    "average": (2, "Σ_a Q / Σ_a W", "below definition 4"),
    "average_best": (5, "½ (Σ_a Q / Σ_a W + max_a Q/W)", "drops towards the best case"),
    "best": (3, "max_a Q/W", "drops greatly towards the best case"),
}
"""The five sigma definitions of Appendix B (ER's ``sigma`` values), from the worst case to the best case."""
THESIS_BEST = "average_worst"


def run_label(definition: str) -> str:
    """The run folder and key prefix of a definition's runs, e.g. ``"er_sigma-worst"``.

    :param definition: sigma's definition, e.g. "worst".
    """
    return f"{ALGO}-{definition}"


def sigma_jobs(
    out_dir: Path,
    definitions: Sequence[str],
    seeds: Sequence[int],
    budget: float,
    env_kwargs: dict | None = None,
    algo_kwargs: dict | None = None,
) -> list[RunJob]:
    """One walker run of ER-sigma per (definition, seed), ``sigma`` set to the definition on top of `algo_kwargs`.

    :param out_dir: the results folder.
    :param definitions: sigma's definitions.
    :param seeds: the seeds.
    :param budget: learning time per run [s].
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param algo_kwargs: constructor overrides by parameter name (default None: the zoo config's).
    """
    experiment = ANALYSES["sigma"]
    env_items = tuple(sorted((env_kwargs or {}).items()))
    return [
        RunJob(
            experiment,
            ALGO,
            seed,
            budget,
            run_csv_path(out_dir, run_label(definition), seed),
            env_items,
            tuple(sorted({**(algo_kwargs or {}), "sigma": definition}.items())),
            label=run_label(definition),
        )
        for definition in definitions
        for seed in seeds
    ]


def run_score(frame: pd.DataFrame) -> float:
    """The thesis's score of one run: the mean distance of the evaluations after some learning (learning_time_s > 0);
    NaN for a diverged run or one without such evaluations.

    :param frame: one run's CSV.
    """
    if frame.empty or frame["diverged"].any():
        return math.nan
    after = frame[frame["learning_time_s"] > 0]["distance"]
    return float(after.mean()) if len(after) else math.nan


def sigma_table(frames: dict[str, dict[int, pd.DataFrame]]) -> pd.DataFrame:
    """One row per definition (in the given order): the thesis's number and sigma, the mean score over its runs with
    the 95% CI, the runs counted and diverged, the mean final falls with the 95% CI, and the thesis's finding.
    `frames` maps definitions to {seed: run frame}.

    :param frames: see above.
    """
    rows = []
    for definition, runs in frames.items():
        number, formula, finding = DEFINITIONS[definition]
        scores = np.array([run_score(frame) for frame in runs.values()], dtype=float)
        valid = scores[np.isfinite(scores)]
        mean, half = mean_confidence_interval(valid) if valid.size else (math.nan, math.nan)
        falls = np.array(
            [
                frame["cumulative_falls"].iloc[-1]
                for frame in runs.values()
                if not frame.empty and not frame["diverged"].any()
            ],
            dtype=float,
        )
        falls_mean, falls_half = mean_confidence_interval(falls) if falls.size else (math.nan, math.nan)
        rows.append(
            {
                "definition": definition,
                "thesis_number": number,
                "sigma": formula,
                "score": float(mean),
                "ci95": float(half),
                "runs": int(valid.size),
                "diverged": int(len(runs) - valid.size),
                "falls": float(falls_mean),
                "falls_ci95": float(falls_half),
                "thesis_finding": finding,
            }
        )
    return pd.DataFrame(rows)


def _format(value: float, half_width: float) -> str:
    if not math.isfinite(value):
        return "NA"
    return f"{value:.3g}" + (f" ± {half_width:.2g}" if math.isfinite(half_width) else "")


def verdict(table: pd.DataFrame) -> str:
    """Our reading of the table against the thesis's finding, in one paragraph.

    :param table: the table of :func:`sigma_table`.
    """
    scored = table[np.isfinite(table["score"])]
    if scored.empty:
        return "No run finished without diverging: nothing to compare."
    if len(scored) < 2:
        return f"Ours: only {scored['definition'].iloc[0]} has scored runs; nothing to compare."
    order = scored.sort_values("score", ascending=False)["definition"].tolist()
    best = scored.loc[scored["score"].idxmax()]
    text = f"Ours, best first: {' > '.join(order)}. "
    if THESIS_BEST in set(scored["definition"]):
        thesis = scored[scored["definition"] == THESIS_BEST].iloc[0]
        others = scored[scored["definition"] != THESIS_BEST]
        separated = all(thesis["score"] - thesis["ci95"] > row.score + row.ci95 for row in others.itertuples())
        if best["definition"] == THESIS_BEST:
            text += "Definition 4 scores highest" + (
                ", its CI clear of every other's. " if separated else ", the CIs overlapping. "
            )
        else:
            text += f"Definition 4 does not score highest ({best['definition']} does). "
    towards_best = [name for name in ("average", "average_best", "best") if name in set(scored["definition"])]
    if len(towards_best) >= 2:
        values = [float(scored[scored["definition"] == name]["score"].iloc[0]) for name in towards_best]
        falling = all(later < earlier for earlier, later in itertools.pairwise(values))
        text += f"From the average towards the best case ({' → '.join(towards_best)}) the score " + (
            "falls at every step, as in the thesis." if falling else "does not fall at every step."
        )
    return text


def _markdown(table: pd.DataFrame) -> str:
    lines = [
        "| Definition (thesis number) | σ(s') | Score: mean distance [m per 100 s] (± 95 % CI) | Runs | Falls "
        "(± 95 % CI) | Thesis (App. B, Fig. B.1) |",
        "|---|---|---|---|---|---|",
    ]
    for row in table.itertuples():
        runs = f"{row.runs}" + (f" ({row.diverged} diverged)" if row.diverged else "")
        lines.append(
            f"| {row.definition} ({row.thesis_number}) | {row.sigma} | {_format(row.score, row.ci95)} | "
            f"{runs} | {_format(row.falls, row.falls_ci95)} | {row.thesis_finding} |"
        )
    return "\n".join(lines)


@files.holds_folder_locks
def reproduce_sigma(
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
    algo_kwargs: dict | None = None,
    sigmas: Sequence[str] | None = None,
):
    """`sb3-er reproduce sigma`: Appendix B, `n_seeds` walker runs of ER-sigma per definition in `sigmas` (default
    all five, ordered from the worst case to the best).

    `budget` is the learning time per run in seconds (default 5000), `env_kwargs` a walker reading other than its
    defaults, `algo_kwargs` further ER-sigma constructor arguments (not ``sigma``). Writes
    ``runs/er_sigma-<definition>/seed_<n>.csv`` (and ``.json``), ``summary.md``, ``summary.csv``,
    ``sigma_scores.png`` (Figure B.1: scores with 95 % CIs) and ``learning_curves.png`` into `out_dir` (default
    ``results/sigma``). Returns a Reproduction. ValueError for an unknown definition or argument, or a folder holding
    runs of other settings; MixedVersionsError / RunFailure as :func:`sb3_er.experiments.reproduce.reproduce`.

    :param n_seeds: the number of seeds (default 20, the thesis's).
    :param out_dir: the results folder (default None: ``results/<name>``).
    :param budget: learning time per run [s] (default None: 5000).
    :param n_workers: worker processes, or the local Ray instance's CPUs (default None: all CPUs).
    :param first_seed: the first seed; the seeds are ``first_seed, ..., first_seed + n_seeds - 1`` (default 0).
    :param show_progress: show a progress bar (default True).
    :param backend: "local" (default) or "ray".
    :param address: the Ray cluster's address (default None: a new local instance; only with ``backend="ray"``).
    :param allow_mixed_versions: accept finished runs made by other code or settings (default False: refused).
    :param env_kwargs: ``gymnasium.make`` keyword arguments, a reading of the env other than its defaults (default
        None).
    :param algo_kwargs: further ER-sigma constructor arguments, not ``sigma`` (default None).
    :param sigmas: the definitions to compare (default None: all five).
    """
    from sb3_er import ERSigma
    from sb3_er.experiments.plots import plot_mean_with_ci, plot_scores
    from sb3_er.experiments.reproduce import Reproduction
    from sb3_er.experiments.runner import check_algo_kwargs

    start = time.perf_counter()
    experiment = ANALYSES["sigma"]
    budget = float(experiment.default_budget if budget is None else budget)
    check_request(n_seeds, budget, experiment.budget_unit, backend, address)
    definitions = list(dict.fromkeys(sigmas or DEFINITIONS))
    unknown = [name for name in definitions if name not in DEFINITIONS]
    if unknown:
        raise ValueError(f"unknown sigma definitions {unknown}; choose from {', '.join(DEFINITIONS)}")
    definitions = [name for name in DEFINITIONS if name in definitions]  # worst case to best case
    algo_kwargs, env_kwargs = dict(algo_kwargs or {}), dict(env_kwargs or {})
    check_env_kwargs(experiment.env_id, env_kwargs)  # once, before any run: not one failure per run
    if "sigma" in algo_kwargs:
        raise ValueError("the sigma study sets sigma itself; choose definitions with sigmas (--sigmas)")
    check_algo_kwargs([ERSigma], algo_kwargs, who="ER-sigma")
    out_dir = Path(out_dir if out_dir is not None else Path("results") / experiment.name)
    settings = {
        "experiment": experiment.name,
        "env_id": experiment.env_id,
        "budget": budget,
        "env_kwargs": env_kwargs,
        "algo_kwargs": algo_kwargs,
    }
    files.lock_folder(out_dir)  # one writer per folder, until this function returns
    check_settings(out_dir, settings)
    seeds = list(range(first_seed, first_seed + n_seeds))
    jobs = sigma_jobs(out_dir, definitions, seeds, budget, env_kwargs, algo_kwargs)
    done, skipped = run_analysis_jobs(
        jobs, out_dir, n_workers, show_progress, backend, address, allow_mixed_versions, settings={out_dir: settings}
    )

    frames = {
        definition: {
            job.seed: read_run_csv(job.csv_path)
            for job in jobs
            if job.label == run_label(definition) and job.csv_path.is_file()
        }
        for definition in definitions
    }
    table = sigma_table(frames)
    table_csv = files.write_csv(out_dir / "summary.csv", table)
    labels = {definition: f"{definition} ({DEFINITIONS[definition][0]})" for definition in definitions}
    scores = {
        labels[definition]: np.array([score for frame in runs.values() if math.isfinite(score := run_score(frame))])
        for definition, runs in frames.items()
    }
    figures = [
        plot_scores(
            scores,
            "score: mean distance [m per 100 s]",
            f"Simplest walker, ER-σ per σ definition (Figure B.1)\n{counted(n_seeds, 'run')} each of "
            f"{budget:g} s, mean and 95% CI",
            out_dir / "sigma_scores.png",
        )
    ]
    curves = {}
    for definition, runs in frames.items():
        complete = [frame for frame in runs.values() if not frame.empty and not frame["diverged"].any()]
        if complete:
            length = min(len(frame) for frame in complete)
            curves[labels[definition]] = (
                complete[0][experiment.x_column].to_numpy(dtype=float)[:length],
                np.stack([frame["distance"].to_numpy(dtype=float)[:length] for frame in complete]),
            )
    figures.append(
        plot_mean_with_ci(
            curves,
            experiment.x_label,
            experiment.performance_label,
            f"Simplest walker, ER-σ per σ definition: mean of {counted(n_seeds, 'run')}, 95% CI",
            out_dir / "learning_curves.png",
        )
    )
    reading = "".join(f", {name}={value!r}" for name, value in {**env_kwargs, **algo_kwargs}.items())
    sections = [
        f"# {experiment.title}: {counted(n_seeds, 'seed')}, {budget:g} s of learning per run{reading}",
        "",
        "Score of a run: the mean of its recorded walking distances (every 100 s of learning, 10 greedy runs of 100 s; "
        "the evaluation at 0 s, the same for every definition, left out). Mean over runs ± 95 % CI; rows from the "
        "worst case to the best case.",
        "",
        _markdown(table),
        "",
        experiment.thesis_caption,
        "",
        verdict(table),
        "",
        f"Walker reading (env arguments at run time): {env_reading(jobs)}.",
        "",
        code_line(jobs),
    ]
    table_markdown = files.write_atomically(out_dir / "summary.md", "\n".join(sections) + "\n")
    return Reproduction(
        out_dir=out_dir,
        table_markdown=table_markdown,
        table_csv=table_csv,
        figures=figures,
        runs_done=done,
        runs_skipped=skipped,
        wall_time_s=time.perf_counter() - start,
    )

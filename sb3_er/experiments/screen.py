"""Screens of readings on Sarsa(lambda): the readings rule's distance to the thesis's Sarsa(lambda) row.

The rule (README, Readings): a value the thesis prints is the default unless no screened candidate with it brings
Sarsa(lambda) within 50 % of each figure of the thesis's Sarsa(lambda) row; among screened candidates for what the text
leaves open, the default is the one nearest that row. "Nearest" is the sum of the relative errors of rise time, end
performance and falls (where the table has falls), each ``|ours - thesis| / |thesis|``. A figure we cannot measure
(no gait learned, a rise time beyond the run) has an infinite error, so such a candidate ranks last.

A screen is one ``sb3-er reproduce`` folder per candidate (Sarsa(lambda) only), so that every run keeps its version
record; :func:`run_screen` runs or resumes them and :func:`write_screen_summary` writes ``summary.md`` and
``summary.csv`` ranking the candidates.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.experiments import files, records
from sb3_er.experiments.runner import run_csv_path
from sb3_er.experiments.specs import EXPERIMENTS, Experiment
from sb3_er.experiments.summary import load_curves, summarize

CONTROL_ARM = "sarsa_lambda"
FIGURES = ("rise_time", "end_performance", "falls")
WITHIN = 0.5
"""The rule's bound on each figure's relative error for a printed value to stay the default."""
MIN_SEEDS = 10
"""Seeds a candidate needs before the rule weighs it."""
BOOTSTRAP_RESAMPLES = 1000
"""Resamples of the seeds behind each candidate's score interval (:func:`bootstrap_score_interval`)."""


@dataclass(frozen=True)
class Candidate:
    """One reading to screen.

    :param name: the candidate's name, also its folder ``<screen>/<name>``.
    :param env_kwargs: the reading, as ``gymnasium.make`` keyword arguments.
    :param description: a line saying what the candidate tests.
    :param printed: the values the thesis prints that this candidate keeps (labels such as ``"fall: the hip touches
        the ground"``), which the rule's first part weighs (default: none).
    :param check: True when the row checks a printed value that the screen does not vary (e.g. another tile width):
        reported beside the candidates, it chooses nothing (default False).
    :param folder: an existing `sb3-er reproduce` folder of this reading (e.g. a committed reproduction of the
        defaults) to read instead of ``<screen>/<name>``; :func:`run_screen` leaves such a candidate alone (default
        None).
    """

    name: str
    env_kwargs: Mapping
    description: str
    printed: frozenset = frozenset()
    check: bool = False
    folder: Path | None = None

    def run_folder(self, screen_dir: Path) -> Path:
        """Where the candidate's runs live: its own ``folder`` if set, else ``<screen_dir>/<name>``.

        :param screen_dir: the screen's folder.
        """
        return Path(self.folder) if self.folder is not None else Path(screen_dir) / self.name


def relative_error(ours: float | None, thesis: float) -> float:
    """``|ours - thesis| / |thesis|``; infinite when ours is missing or NaN (not measurable in the run).

    :param ours: our figure, None or NaN when not measurable.
    :param thesis: the thesis's figure.
    """
    if not isinstance(thesis, (int, float)) or thesis == 0 or math.isnan(thesis):
        raise ValueError(f"the thesis's figure must be a non-zero number, got {thesis!r}")
    if ours is None or math.isnan(ours):
        return math.inf
    return abs(ours - thesis) / abs(thesis)


def score(figures: Mapping[str, float | None], thesis_row: Mapping[str, tuple]) -> dict[str, float]:
    """Relative error of each figure the thesis row prints (``rise_time``, ``end_performance``, ``falls``), their sum
    (``score``) and whether every error is within the rule's 50 % (``within_50``).

    :param figures: our figures by name (None: not measurable).
    :param thesis_row: the thesis table's row of the algorithm (figure name -> (average, difference)).
    """
    errors = {}
    for figure in FIGURES:
        if figure in thesis_row:
            errors[figure] = relative_error(figures.get(figure), float(thesis_row[figure][0]))
    if not errors:
        raise ValueError(f"the thesis row {dict(thesis_row)} has none of the figures {FIGURES}")
    return {
        **{f"{figure}_error": error for figure, error in errors.items()},
        "score": sum(errors.values()),
        "within_50": all(error <= WITHIN for error in errors.values()),
    }


def bootstrap_score_interval(
    experiment: Experiment,
    curves,
    thesis_row: Mapping[str, tuple],
    resamples: int = BOOTSTRAP_RESAMPLES,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile interval of the score over seeds drawn with replacement (the figures recomputed from each resample's
    mean curve): how far the ranking can be trusted. Resamples with an unmeasurable figure count as infinite.

    :param experiment: the experiment screened.
    :param curves: the candidate's Sarsa(lambda) curves.
    :param thesis_row: the thesis table's row of Sarsa(lambda).
    :param resamples: bootstrap resamples (default 1000).
    :param confidence: the interval's confidence level (default 0.95).
    :param seed: the seed of the resampling (default 0).
    """
    from sb3_er.experiments.metrics import summarize_curves

    rng = np.random.default_rng(seed)
    n_seeds = curves.performance.shape[0]
    scores = np.empty(resamples)
    for k in range(resamples):
        rows = rng.integers(0, n_seeds, size=n_seeds)
        summary = summarize_curves(
            curves.x / experiment.rise_time_scale,
            curves.performance[rows],
            curves.cumulative_falls[rows] if experiment.has_falls else None,
            success_threshold=experiment.success_threshold,
        )
        scores[k] = score(
            {"rise_time": summary.rise_time, "end_performance": summary.end_performance, "falls": summary.falls},
            thesis_row,
        )["score"]
    tail = 100.0 * (1.0 - confidence) / 2.0
    # order statistics, not interpolation: infinite scores (a resample without a gait) must not turn into NaN
    low = np.percentile(scores, tail, method="lower")
    high = np.percentile(scores, 100.0 - tail, method="higher")
    return float(low), float(high)


def _experiment(name: str) -> Experiment:
    if name not in EXPERIMENTS or not EXPERIMENTS[name].thesis_table:
        raise ValueError(f"a screen needs an experiment with a thesis table, got {name!r}")
    return EXPERIMENTS[name]


def _checked_candidates(candidates) -> list[Candidate]:
    candidates = list(candidates)
    names = [candidate.name for candidate in candidates]
    if not candidates or len(set(names)) != len(names):
        raise ValueError(f"candidates need distinct names, got {names}")
    return candidates


def screen_command(
    experiment_name: str, candidates, out_dir: Path, title: str, notes: str, argv: list[str] | None = None
) -> pd.DataFrame:
    """The command line of a screen script: ``[--only NAME ...] [--seeds N] [--summary-only] [--out DIR]``. Runs (or
    resumes) the candidates, seals their records and writes ``summary.md``; prints and returns the ranked table.

    :param experiment_name: the experiment screened ("pendulum", "walker" or "leo").
    :param candidates: the candidate readings (:class:`Candidate`).
    :param out_dir: the screen's folder (a sub-folder per candidate), the default of ``--out``.
    :param title: the summary's title.
    :param notes: text added under the summary's table (default "").
    :param argv: the script's arguments (default None: ``sys.argv[1:]``).
    """
    import argparse

    parser = argparse.ArgumentParser(description=title)
    parser.add_argument("--only", nargs="+", help="screen only these candidates")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--summary-only", action="store_true", help="write summary.md from the finished runs")
    parser.add_argument("--out", type=Path, default=Path(out_dir), help=f"the screen's folder (default {out_dir})")
    arguments = parser.parse_args(argv)
    out_dir = arguments.out
    if not arguments.summary_only:
        run_screen(experiment_name, candidates, out_dir, n_seeds=arguments.seeds, only=arguments.only)
    seal_finished_runs(experiment_name, candidates, out_dir, n_seeds=arguments.seeds)
    table = write_screen_summary(experiment_name, candidates, out_dir, title, notes=notes, n_seeds=arguments.seeds)
    print(table.to_string(index=False))
    return table


def tiling_screen_command(
    description: str,
    candidates: Mapping[str, Mapping[str, dict]],
    run_one,
    summarize,
    out_dir: Path,
    default_seeds=(0,),
    seeds_outermost: bool = False,
    argv: list[str] | None = None,
) -> None:
    """The command line of a tiling screen over env ids (the continuous-action and dm_control screens):
    ``[--envs ID ...] [--candidates NAME ...] [--seeds N ...] [--summarize] [--out DIR]``. Runs every chosen (env,
    candidate, seed) through ``run_one``, which skips a finished run (so the command resumes), or only ``summarize``.

    :param description: the command's description (its script's first docstring paragraph).
    :param candidates: env id -> candidate name -> the candidate's ``policy_kwargs``.
    :param run_one: ``run_one(env_id, candidate_name, seed, out)`` runs one candidate on one seed into the screen's
        folder ``out``, or skips it if finished.
    :param summarize: ``summarize(out)`` writes the summary of the screen's folder ``out`` from its finished runs.
    :param out_dir: the screen's folder, the default of ``--out``.
    :param default_seeds: the seeds run when ``--seeds`` is not given (default (0,)).
    :param seeds_outermost: loop over seeds outermost, so that the first seed of every candidate finishes first
        (default False: env, then candidate, then seed).
    :param argv: the script's arguments (default None: ``sys.argv[1:]``).
    """
    import argparse

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument(
        "--envs",
        nargs="+",
        default=list(candidates),
        choices=list(candidates),
        help="screen only these env ids (default: all)",
    )
    parser.add_argument(
        "--candidates",
        nargs="+",
        default=None,
        metavar="NAME",
        help="screen only these candidates (default: every candidate of each env)",
    )
    parser.add_argument("--seeds", nargs="+", type=int, default=list(default_seeds))
    parser.add_argument("--summarize", action="store_true", help="write the summary from the finished runs")
    parser.add_argument("--out", type=Path, default=Path(out_dir), help=f"the screen's folder (default {out_dir})")
    arguments = parser.parse_args(argv)
    if arguments.summarize:
        summarize(arguments.out)
        return
    chosen = {
        env_id: [name for name in candidates[env_id] if arguments.candidates is None or name in arguments.candidates]
        for env_id in arguments.envs
    }
    unknown = sorted(set(arguments.candidates or ()) - {name for names in chosen.values() for name in names})
    if unknown:
        parser.error(
            f"no candidate named {', '.join(unknown)} for {', '.join(arguments.envs)}; the candidates are "
            + "; ".join(f"{env_id}: {', '.join(candidates[env_id])}" for env_id in arguments.envs)
        )
    pairs = [(env_id, name) for env_id, names in chosen.items() for name in names]
    if seeds_outermost:
        jobs = [(env_id, name, seed) for seed in arguments.seeds for env_id, name in pairs]
    else:
        jobs = [(env_id, name, seed) for env_id, name in pairs for seed in arguments.seeds]
    for env_id, name, seed in jobs:
        run_one(env_id, name, seed, arguments.out)


def run_screen(
    experiment_name: str,
    candidates,
    out_dir: Path,
    n_seeds: int = 10,
    budget: float | None = None,
    n_workers: int = 1,
    only: list[str] | None = None,
) -> None:
    """Run (or resume) Sarsa(lambda) on every candidate in ``out_dir/<candidate>`` with `sb3-er reproduce`.

    :param experiment_name: the experiment screened ("pendulum", "walker" or "leo").
    :param candidates: the candidate readings (:class:`Candidate`).
    :param out_dir: the screen's folder (a sub-folder per candidate).
    :param n_seeds: seeds per candidate (default 10).
    :param budget: run length (default None: the experiment's).
    :param n_workers: worker processes (default 1).
    :param only: names of the candidates to run (default None: all).
    """
    from sb3_er.experiments.reproduce import reproduce

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _experiment(experiment_name)
    for candidate in _checked_candidates(candidates):
        if (only and candidate.name not in only) or candidate.folder is not None:
            continue
        result = reproduce(
            experiment_name,
            n_seeds=n_seeds,
            algos=[CONTROL_ARM],
            out_dir=Path(out_dir) / candidate.name,
            budget=budget,
            n_workers=n_workers,
            show_progress=False,
            env_kwargs=dict(candidate.env_kwargs),
        )
        print(
            f"{candidate.name}: {records.counted(result.runs_done, 'run')} done, {result.runs_skipped} resumed, "
            f"{result.wall_time_s:.0f} s",
            flush=True,
        )


@files.holds_folder_locks
def seal_finished_runs(experiment_name: str, candidates, out_dir: Path, n_seeds: int = 10) -> int:
    """Give the finished runs of every candidate folder (seeds below `n_seeds`) records with checksums, as a resume
    does (:func:`sb3_er.experiments.runner.check_run`: records that predate checksums are checked and sealed once;
    damaged runs are moved aside). Returns how many records were sealed now.

    :param experiment_name: the experiment screened ("pendulum", "walker" or "leo").
    :param candidates: the candidate readings (:class:`Candidate`).
    :param out_dir: the screen's folder (a sub-folder per candidate).
    :param n_seeds: seeds per candidate (default 10).
    """
    import json
    import warnings

    from sb3_er.experiments.runner import plan_jobs

    experiment = _experiment(experiment_name)
    sealed = 0
    for candidate in _checked_candidates(candidates):
        folder = candidate.run_folder(out_dir)
        settings_path = folder / "settings.json"
        if not settings_path.is_file():
            continue
        settings = json.loads(settings_path.read_text())
        files.lock_folder(folder)
        before = {
            seed: (records.read_record(path) or {}).get(records.CHECKSUM_FIELD)
            for seed in range(n_seeds)
            if (path := run_csv_path(folder, CONTROL_ARM, seed)).is_file()
        }
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            plan_jobs(
                experiment,
                [CONTROL_ARM],
                range(n_seeds),
                float(settings["budget"]),
                folder,
                settings.get("env_kwargs", {}),
                settings.get("algo_kwargs", {}),
            )
        sealed += sum(
            checksum is None
            and (records.read_record(run_csv_path(folder, CONTROL_ARM, seed)) or {}).get(records.CHECKSUM_FIELD)
            is not None
            for seed, checksum in before.items()
        )
    return sealed


def screen_table(experiment_name: str, candidates, out_dir: Path, n_seeds: int = 10) -> pd.DataFrame:
    """One row per candidate with finished runs: seeds, rise time, end performance, falls, relative errors, score,
    ranked by score (best first).

    :param experiment_name: the experiment screened ("pendulum", "walker" or "leo").
    :param candidates: the candidate readings (:class:`Candidate`).
    :param out_dir: the screen's folder (a sub-folder per candidate).
    :param n_seeds: seeds per candidate (default 10).
    """
    experiment = _experiment(experiment_name)
    thesis_row = experiment.thesis_table[CONTROL_ARM]
    rows = []
    for candidate in _checked_candidates(candidates):
        curves = load_curves(experiment, candidate.run_folder(out_dir), CONTROL_ARM, range(n_seeds))
        if curves is None:
            continue
        summary = summarize(experiment, curves)
        figures = {"rise_time": math.nan, "end_performance": math.nan, "falls": None}
        if summary is not None:
            figures = {
                "rise_time": summary.rise_time,
                "end_performance": summary.end_performance,
                "falls": summary.falls,
            }
        low, high = (
            bootstrap_score_interval(experiment, curves, thesis_row) if summary is not None else (math.inf, math.inf)
        )
        rows.append(
            {
                "candidate": candidate.name,
                "reading": candidate.description,
                "seeds": len(curves.seeds),
                "diverged": len(curves.diverged_seeds),
                **figures,
                **score(figures, thesis_row),
                "score_low": low,
                "score_high": high,
            }
        )
    table = pd.DataFrame(rows)
    if not table.empty:
        table = table.sort_values("score", kind="stable").reset_index(drop=True)
        table.insert(0, "rank", range(1, len(table) + 1))
    return table


@dataclass(frozen=True)
class Decision:
    """What the rule decides from a screen.

    :param kept: per printed value (its label), the nearest candidate with it within 50 % of every thesis figure, or
        None when there is none (the printed value then does not bind).
    :param winner: the default: the nearest candidate that keeps every printed value that stays, or None.
    """

    kept: dict
    winner: str | None


def decide(table: pd.DataFrame, candidates) -> Decision:
    """Apply the readings rule to :func:`screen_table`'s rows of `candidates` (checks, and candidates with fewer than
    :data:`MIN_SEEDS` seeds, excluded).

    :param table: the rows of :func:`screen_table`.
    :param candidates: the candidate readings.
    """
    by_name = {candidate.name: candidate for candidate in _checked_candidates(candidates)}
    rows = [row for row in table.itertuples() if not by_name[row.candidate].check and row.seeds >= MIN_SEEDS]
    labels = sorted(set().union(*(by_name[row.candidate].printed for row in rows))) if rows else []
    kept = {}
    for label in labels:
        passing = [row for row in rows if label in by_name[row.candidate].printed and row.within_50]
        kept[label] = min(passing, key=lambda row: row.score).candidate if passing else None
    required = {label for label, candidate in kept.items() if candidate is not None}
    eligible = [row for row in rows if required <= by_name[row.candidate].printed]
    winner = min(eligible, key=lambda row: row.score).candidate if eligible else None
    return Decision(kept, winner)


def _decision_lines(decision: Decision, table: pd.DataFrame) -> list[str]:
    lines = ["## The rule's decision", "", f"Candidates with at least {MIN_SEEDS} seeds, checks aside.", ""]
    for label, candidate in decision.kept.items():
        if candidate is None:
            lines.append(
                f'- Printed value "{label}": no screened candidate with it brings Sarsa(λ) within 50 % of '
                "every figure, so it does not bind the choice below."
            )
        else:
            lines.append(f'- Printed value "{label}": stays (`{candidate}` keeps it within 50 % of every figure).')
    if decision.winner is None:
        lines.append("- No candidate has enough seeds: the screen decides nothing yet.")
    else:
        row = table.set_index("candidate").loc[decision.winner]
        lines.append(
            f"- Default: `{decision.winner}` ({row['reading']}), score {_percent(row['score'])} "
            f"({_percent(row['score_low'])} to {_percent(row['score_high'])}): the nearest candidate that "
            "keeps every printed value that stays."
        )
    return lines + [""]


def _number(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "NA"
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    if abs(value) >= 100:
        return f"{value:.0f}"
    return f"{value:.3g}" if abs(value) < 10 else f"{value:.1f}"


def _percent(value: float) -> str:
    return "NA" if math.isinf(value) else f"{100 * value:.0f} %"


def write_screen_summary(
    experiment_name: str, candidates, out_dir: Path, title: str, notes: str = "", n_seeds: int = 10
) -> pd.DataFrame:
    """Write ``out_dir/summary.md`` and ``summary.csv`` (the ranking of :func:`screen_table`) and return the table.

    :param experiment_name: the experiment screened ("pendulum", "walker" or "leo").
    :param candidates: the candidate readings (:class:`Candidate`).
    :param out_dir: the screen's folder (a sub-folder per candidate).
    :param title: the summary's title.
    :param notes: text added under the summary's table (default "").
    :param n_seeds: seeds per candidate (default 10).
    """
    experiment = _experiment(experiment_name)
    out_dir = Path(out_dir)
    table = screen_table(experiment_name, candidates, out_dir, n_seeds)
    thesis_row = experiment.thesis_table[CONTROL_ARM]
    has_falls = "falls" in thesis_row
    header = ["rank", "candidate", "reading", "seeds", f"rise time [{experiment.rise_time_unit}]", "end performance"]
    header += ["falls"] if has_falls else []
    header += ["rise error", "end error"] + (["falls error"] if has_falls else [])
    header += ["score", "score, 95 % bootstrap interval", "all within 50 %"]
    lines = [
        f"# {title}",
        "",
        notes.strip(),
        "",
        "Thesis Sarsa(λ) row: "
        + ", ".join(f"{name.replace('_', ' ')} {value[0]}" for name, value in thesis_row.items())
        + ".",
        "",
    ]
    checks = {candidate.name for candidate in _checked_candidates(candidates) if candidate.check}
    for heading, part in (
        ("Candidates", table[~table["candidate"].isin(checks)]),
        ("Checks of a printed value the candidates keep (they choose nothing)", table[table["candidate"].isin(checks)]),
    ):
        if part.empty:
            continue
        lines += [f"## {heading}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for rank, row in enumerate(part.itertuples(), start=1):
            cells = [
                str(rank),
                row.candidate,
                row.reading.replace("|", "\\|"),
                f"{row.seeds}" + (f" (+{row.diverged} diverged)" if row.diverged else ""),
                _number(row.rise_time),
                _number(row.end_performance),
            ]
            cells += [_number(row.falls)] if has_falls else []
            cells += [_percent(row.rise_time_error), _percent(row.end_performance_error)]
            cells += [_percent(row.falls_error)] if has_falls else []
            cells += [
                _percent(row.score),
                f"{_percent(row.score_low)} to {_percent(row.score_high)}",
                "yes" if row.within_50 else "no",
            ]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += _decision_lines(decide(table, candidates), table)
    lines += [
        "Score: the sum of the relative errors |ours - thesis| / |thesis| of the figures above against the "
        "thesis's Sarsa(λ) row (NA: not measurable in the run, ranked last). Rise time and end performance by "
        "the fixed metrics of thesis 6.1 on the mean curve of the seeds. The interval resamples the seeds "
        f"({BOOTSTRAP_RESAMPLES} draws with replacement, the figures recomputed from each draw's mean curve): "
        "candidates whose intervals overlap are not told apart by these seeds.",
        "",
    ]
    per_candidate = {
        candidate.name: [
            records.read_record(path)
            for seed in range(n_seeds)
            if (path := run_csv_path(candidate.run_folder(out_dir), CONTROL_ARM, seed)).is_file()
        ]
        for candidate in _checked_candidates(candidates)
    }
    mixed = sorted(
        name
        for name, found in per_candidate.items()
        if len({(record or {}).get("code_sha256") for record in found}) > 1
    )
    lines.append(
        "Each candidate's runs were made by one code version."
        if not mixed
        else "Candidates whose runs were made by more than one code version: " + ", ".join(mixed) + "."
    )
    lines.append(records.code_versions_line([record for found in per_candidate.values() for record in found]))
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n")
    table.to_csv(out_dir / "summary.csv", index=False)
    return table

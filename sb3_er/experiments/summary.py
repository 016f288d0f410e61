"""Aggregates per-run CSVs into learning curves and tables in the format of thesis Tables 6.1-6.3."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.experiments.metrics import CurveSummary, relative_difference, summarize_curves
from sb3_er.experiments.runner import read_run_csv, run_csv_path
from sb3_er.experiments.specs import Experiment
from sb3_er.experiments.thesis import ALGORITHM_LABELS

REFERENCE_ALGORITHM = "sarsa_lambda"


@dataclass(frozen=True)
class Curves:
    """Per-seed curves of one algorithm's runs, cut to the shortest complete run (rows: seeds).

    Two sets of rows: the runs whose values stayed inside the possible returns (``performance``, ``seeds``), and every
    run (``all_performance``, ``all_seeds``; :meth:`all_runs`), where a diverged run counts as one that learned
    nothing (:func:`diverged_run_curves`).

    :param x: the common abscissa, shape (n,), in the experiment's x units.
    :param performance: the performance curves of the runs that stayed inside, shape (len(seeds), n).
    :param cumulative_falls: their cumulative falls, shape (len(seeds), n).
    :param seeds: the complete runs whose values stayed within the possible returns (or were not watched).
    :param diverged_seeds: the seeds of the runs whose Q-function diverged (their CSVs end at the divergence).
    :param wall_time_s: the runs' summed wall time in seconds.
    :param out_of_bounds_seeds: the complete runs whose values left the possible returns; default none.
    :param unwatched_seeds: the runs made before the value watch (their CSVs have no ``values_out_of_range`` column),
        counted as inside; None (default): no run was watched.
    :param all_performance: the performance curves of every run, shape (len(all_seeds), n); default None: the runs
        that stayed inside are all.
    :param all_cumulative_falls: their cumulative falls, shape (len(all_seeds), n); default None.
    :param all_seeds: the rows of ``all_performance``; default None (with ``all_performance`` None: the runs that
        stayed inside are all).
    """

    x: np.ndarray
    performance: np.ndarray
    cumulative_falls: np.ndarray
    seeds: tuple[int, ...]
    diverged_seeds: tuple[int, ...]
    wall_time_s: float
    out_of_bounds_seeds: tuple[int, ...] = ()
    unwatched_seeds: tuple[int, ...] | None = None
    all_performance: np.ndarray | None = None
    all_cumulative_falls: np.ndarray | None = None
    all_seeds: tuple[int, ...] | None = None

    @property
    def n_runs(self) -> int:
        return len(self.seeds) + len(self.diverged_seeds) + len(self.out_of_bounds_seeds)

    @property
    def left_out_seeds(self) -> tuple[int, ...]:
        """The runs that are in :meth:`all_runs` and not in the runs that stayed inside."""
        return tuple(seed for seed in self.all_runs().seeds if seed not in self.seeds)

    def all_runs(self) -> Curves:
        """These curves with every run as its rows: the runs whose values left the possible returns with their own
        curves, and the diverged ones as runs that learned nothing (:func:`diverged_run_curves`)."""
        if self.all_performance is None or self.all_seeds is None:
            return self
        seeds = self.all_seeds
        return Curves(
            self.x,
            self.all_performance,
            self.all_cumulative_falls,
            seeds,
            tuple(seed for seed in self.diverged_seeds if seed not in seeds),
            self.wall_time_s,
            (),
            self.unwatched_seeds,
            self.all_performance,
            self.all_cumulative_falls,
            seeds,
        )


def diverged_run_curves(
    experiment: Experiment, frame: pd.DataFrame, x: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """(performance, cumulative falls) on `x` of a run whose Q-function diverged, counted as a run that learned
    nothing: its performance is the random policy's committed score throughout (so it never rises, and ends at that
    score), and its falls are those it recorded, going on at its last rate (the falls of its last recorded interval
    per x unit) to the end of `x`. None when the experiment has no random score (the run cannot be counted).

    :param experiment: the experiment (its random policy's score, its x column).
    :param frame: the diverged run's CSV, cut at the divergence.
    :param x: the abscissa of the other runs, or of the whole budget.
    """
    if experiment.random_performance is None:
        return None
    performance = np.full(x.shape, float(experiment.random_performance))
    recorded_x = frame[experiment.x_column].to_numpy(dtype=float) if not frame.empty else np.zeros(0)
    recorded = frame["cumulative_falls"].to_numpy(dtype=float) if not frame.empty else np.zeros(0)
    if recorded.size == 0:
        return performance, np.zeros(x.shape)
    rate = 0.0
    if recorded.size >= 2 and recorded_x[-1] > recorded_x[-2]:
        rate = (recorded[-1] - recorded[-2]) / (recorded_x[-1] - recorded_x[-2])
    falls = np.interp(x, recorded_x, recorded)  # the recorded falls on the common abscissa
    beyond = x > recorded_x[-1]
    falls[beyond] = recorded[-1] + rate * (x[beyond] - recorded_x[-1])
    return performance, falls


def left_the_bounds(frame: pd.DataFrame) -> bool | None:
    """Whether a run's values left the possible returns (its last ``values_out_of_range`` is positive); None when the
    run was not watched (a CSV made before the watch, or a learner without one: -1).

    :param frame: one run's CSV.
    """
    if "values_out_of_range" not in frame.columns or frame.empty:
        return None
    last = float(frame["values_out_of_range"].iloc[-1])
    return None if last < 0 else last > 0


def budget_abscissa(experiment: Experiment, budget: float) -> np.ndarray:
    """The abscissa of a finished run of `budget`: episodes 1 .. budget, or the evaluations' learning times 0, one
    interval, ..., and the budget itself when it is not a multiple of the interval (the walking protocol's last
    evaluation, :func:`sb3_er.experiments.runner.expected_rows`).

    :param experiment: the experiment (its protocol and evaluation interval).
    :param budget: the run length in episodes or seconds of learning time.
    """
    if experiment.protocol == "episodes":
        return np.arange(1.0, math.floor(float(budget)) + 1.0)
    interval = float(experiment.eval_interval)
    x = interval * np.arange(math.floor(float(budget) / interval + 1e-9) + 1)
    return x if math.isclose(x[-1], float(budget)) else np.append(x, float(budget))


def _abscissa(experiment: Experiment, frames: dict, complete_seeds: list, length: int, budget) -> np.ndarray:
    """The common abscissa: the complete runs' (cut to the shortest); without one, a finished run's of `budget`, or
    the longest diverged run's own when no budget is given."""
    if complete_seeds:
        return frames[complete_seeds[0]][experiment.x_column].iloc[:length].to_numpy(dtype=float)
    if budget is not None:
        return budget_abscissa(experiment, budget)
    return max(frames.values(), key=len)[experiment.x_column].to_numpy(dtype=float)


def load_curves(experiment: Experiment, out_dir: Path, algo: str, seeds, budget: float | None = None) -> Curves | None:
    """The finished runs of `algo` among `seeds`, or None when none has finished.

    :param experiment: the experiment (its units and thesis table).
    :param out_dir: the results folder.
    :param algo: the algorithm's rl-zoo name.
    :param seeds: the seeds to read.
    :param budget: the runs' length, the end of a diverged run's counted curve when no run is complete (default None:
        the longest diverged run's end; a table always gives it).
    """
    frames = {seed: read_run_csv(path) for seed in seeds if (path := run_csv_path(out_dir, algo, seed)).is_file()}
    if not frames:
        return None
    diverged = tuple(seed for seed, frame in sorted(frames.items()) if frame.empty or frame["diverged"].any())
    complete_seeds = [seed for seed in sorted(frames) if seed not in diverged]
    length = min((len(frames[seed]) for seed in complete_seeds), default=0)
    complete = {seed: frames[seed].iloc[:length] for seed in complete_seeds}
    out_of_bounds = tuple(seed for seed in complete_seeds if left_the_bounds(frames[seed]))
    averaged = [seed for seed in complete_seeds if seed not in out_of_bounds]
    x = _abscissa(experiment, frames, complete_seeds, length, budget)
    counted = {seed: diverged_run_curves(experiment, frames[seed], x) for seed in diverged}
    counted = {seed: curves for seed, curves in counted.items() if curves is not None}

    def stacked(column: str, chosen) -> np.ndarray:
        if not chosen:
            return np.zeros((0, x.size))
        return np.stack([complete[seed][column].to_numpy(dtype=float) for seed in chosen])

    every = sorted(complete_seeds + list(counted))

    def every_run(column: str, part: int) -> np.ndarray:
        if not every:
            return np.zeros((0, x.size))
        return np.stack(
            [counted[seed][part] if seed in counted else complete[seed][column].to_numpy(dtype=float) for seed in every]
        )

    return Curves(
        x=x,
        performance=stacked(experiment.performance_column, averaged),
        cumulative_falls=stacked("cumulative_falls", averaged),
        seeds=tuple(averaged),
        diverged_seeds=diverged,
        wall_time_s=float(sum(frame["wall_time_s"].iloc[-1] for frame in frames.values() if not frame.empty)),
        out_of_bounds_seeds=out_of_bounds,
        unwatched_seeds=tuple(
            seed for seed in sorted(frames) if seed not in diverged and left_the_bounds(frames[seed]) is None
        ),
        all_performance=every_run(experiment.performance_column, 0),
        all_cumulative_falls=every_run("cumulative_falls", 1),
        all_seeds=tuple(every),
    )


def summarize(experiment: Experiment, curves: Curves) -> CurveSummary | None:
    """Rise time (in the table's unit), end performance and falls of one algorithm; None without a complete run.

    :param experiment: the experiment (its units and thesis table).
    :param curves: one algorithm's curves.
    """
    if not curves.seeds or curves.x.size == 0:
        return None
    return summarize_curves(
        curves.x / experiment.rise_time_scale,
        curves.performance,
        curves.cumulative_falls if experiment.has_falls else None,
        success_threshold=experiment.success_threshold,
    )


def format_figure(value: float, scale: float | None = None, signed: bool = False, whole: bool = False) -> str:
    """A figure in the notation of the tables: three significant figures from 10,000 on, digits grouped by commas
    (-49,300; 1,200,000) up to a billion and in exponent notation beyond (a diverged value); whole numbers from 100,
    one decimal from 10, two below; NA for a missing one.

    The notation follows `scale`, the largest magnitude shown beside `value`, so that figures shown together share
    it: a difference and its interval, ``format_figure(-700, 2800, signed=True)`` -> ``"-700"`` beside ``"+2800"``.

    :param value: the figure.
    :param scale: the largest magnitude shown beside it (default: its own).
    :param signed: write the sign of a positive figure too (a difference).
    :param whole: the figures shown together are all whole numbers (counts such as episodes): no decimals below
        10,000.
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "NA"
    scale = max(abs(value), abs(scale) if scale is not None else 0.0)
    sign = "+" if signed else ""
    if scale >= 1e9 or not math.isfinite(scale):
        return f"{value:{sign}.3g}"
    if scale >= 1e4:
        return f"{round(value, 2 - math.floor(math.log10(scale))):{sign},.0f}"
    decimals = 0 if whole or scale >= 100 else (1 if scale >= 10 else 2)
    return f"{value:{sign}.{decimals}f}"


def _format_with_ci(value: float, half_width: float | None) -> str:
    text = format_figure(value)
    if half_width is None or math.isnan(half_width) or text == "NA":
        return text
    return f"{text} ± {format_figure(half_width)}"


def _format_difference(value: float, reference: float, algo: str) -> str:
    if algo == REFERENCE_ALGORITHM:
        return "-"
    difference = relative_difference(value, reference)
    return "NA" if math.isnan(difference) else f"{difference:+.0f} %"


def _thesis_number(value) -> tuple[float, str]:
    """A thesis table entry as (number, prefix): ">200" -> (200.0, ">"), None -> (nan, "")."""
    if value is None:
        return float("nan"), ""
    if isinstance(value, str):
        prefix = value[0] if value[0] in "<>" else ""
        return float(value.lstrip("<>")), prefix
    return float(value), ""


def thesis_difference(experiment: Experiment, algo: str, metric: str) -> str:
    """The thesis's difference with Sarsa(lambda): the printed figure where the one computed from its own averages
    (percent of Sarsa(lambda)'s value) agrees with it up to rounding (the findings quote the same), else the computed
    one with the printed figure beside it (e.g. walker falls of vanilla ER: 150 against 74 is +103 %, printed +51 %).

    :param experiment: the experiment (its units and thesis table).
    :param algo: the algorithm's rl-zoo name.
    :param metric: the metric, a key of the thesis table's rows (e.g. "rise_time").
    """
    entry = experiment.thesis_table.get(algo, {}).get(metric)
    reference = experiment.thesis_table.get(REFERENCE_ALGORITHM, {}).get(metric)
    if entry is None:
        return ""
    printed = entry[1]
    if algo == REFERENCE_ALGORITHM or reference is None:
        return printed
    value, prefix = _thesis_number(entry[0])
    base, base_prefix = _thesis_number(reference[0])
    difference = relative_difference(value, base)
    if math.isnan(difference) or base_prefix:
        return printed
    computed = f"{prefix}{difference:+.0f} %"
    printed_number = printed.replace("%", "").replace(" ", "").lstrip("<>")
    try:
        agrees = abs(float(printed_number) - difference) <= 1.5
    except ValueError:
        agrees = False
    return printed if agrees else f"{computed} (printed {printed})"


def _thesis_cells(experiment: Experiment, algo: str, metric: str) -> tuple[str, str]:
    entry = experiment.thesis_table.get(algo, {}).get(metric)
    if entry is None:
        return "", ""
    return thesis_text(entry[0]), thesis_difference(experiment, algo, metric)


def thesis_text(value) -> str:
    """A thesis table's figure as it prints it: -1.673e4 -> "-16730", 12.0 -> "12", ">200" as is, None -> "NA".

    :param value: the figure (a number, a string such as ">200", or None for NA).
    """
    return "NA" if value is None else (value if isinstance(value, str) else f"{value:g}")


#: Rows that count runs: no difference with Sarsa(lambda), no thesis figure.
COUNT_ROWS = ("diverged", "left_bounds")


def _out_of_bounds_row(curve: Curves) -> tuple:
    """("left_bounds", name, count, None, text): how many runs' values left the possible returns, or "not measured"
    for the runs made before the value watch (a diverged run is counted in its own row)."""
    name = "Runs whose values left the possible returns"
    count = len(curve.out_of_bounds_seeds)
    complete = curve.n_runs - len(curve.diverged_seeds)
    unwatched = complete if curve.unwatched_seeds is None else len(curve.unwatched_seeds)
    if complete and unwatched == complete:
        return "left_bounds", name, float("nan"), None, "not measured"
    text = f"{count} of {curve.n_runs}"
    if unwatched:
        text += f" ({unwatched} not measured)"
    return "left_bounds", name, float(count), None, text


def _diverged_row(curve: Curves) -> tuple:
    """("diverged", name, count, None, text): how many runs diverged, and whether they are counted."""
    count = len(curve.diverged_seeds)
    text = f"{count} of {curve.n_runs}"
    if curve.all_runs().diverged_seeds:
        text += " (left out: this experiment has no random policy's score to count them by)"
    return "diverged", "Diverged runs", float(count), None, text


def summary_table(experiment: Experiment, curves: dict[str, Curves], budget: float) -> pd.DataFrame:
    """One row per (algorithm, metric), columns as thesis Tables 6.1-6.3 plus the thesis's own figures.

    Every run is averaged, as the thesis averaged every run it made: a run whose values left the possible returns with
    its own curve, a diverged run as a run that learned nothing (:func:`diverged_run_curves`). Their counts have rows
    of their own ("Diverged runs", "Runs whose values left the possible returns", "not measured" where runs predate
    the value watch). Where some runs left the possible returns or diverged, the rise time, end performance and falls
    of the runs that stayed inside follow, marked "(inside only)", against Sarsa(λ)'s own runs that stayed inside.

    :param experiment: the experiment (its units and thesis table).
    :param curves: the curves by algorithm.
    :param budget: the runs' length.
    """
    summaries = {algo: summarize(experiment, curve.all_runs()) for algo, curve in curves.items()}
    inside = {algo: summarize(experiment, curve) for algo, curve in curves.items()}
    run_end = budget / experiment.rise_time_scale if experiment.protocol == "walking" else budget
    no_run = CurveSummary(float("nan"), float("nan"), float("nan"), None, None, 0)
    rows = []
    for algo, curve in curves.items():
        summary = summaries[algo] or no_run
        label = ALGORITHM_LABELS.get(algo, algo)

        def rise_text(of: CurveSummary) -> str | None:
            whole = float(run_end).is_integer()  # episodes, or seconds
            return f">{format_figure(run_end, whole=whole)}" if math.isnan(of.rise_time) and of.n_seeds else None

        metrics = [
            ("rise_time", f"Rise time [{experiment.rise_time_unit}]", summary.rise_time, None, rise_text(summary)),
            ("settling_time", f"Settling time [{experiment.rise_time_unit}]", summary.settling_time, None, None),
            ("end_performance", "End performance", summary.end_performance, summary.end_performance_ci, None),
        ]
        if experiment.has_falls:
            falls = float("nan") if summary.falls is None else summary.falls
            metrics.append(("falls", "Falls", falls, summary.falls_ci, None))
        if curve.diverged_seeds:
            metrics.append(_diverged_row(curve))
        metrics.append(_out_of_bounds_row(curve))
        if curve.left_out_seeds:
            kept = inside[algo] or no_run
            unit = experiment.rise_time_unit
            metrics.append(
                ("rise_time_inside", f"Rise time [{unit}] (inside only)", kept.rise_time, None, rise_text(kept))
            )
            metrics.append(
                (
                    "end_performance_inside",
                    "End performance (inside only)",
                    kept.end_performance,
                    kept.end_performance_ci,
                    None,
                )
            )
            if experiment.has_falls:
                falls = float("nan") if kept.falls is None else kept.falls
                metrics.append(("falls_inside", "Falls (inside only)", falls, kept.falls_ci, None))
        for key, name, value, half_width, text in metrics:
            of_inside = key.endswith("_inside")  # "(inside only)" rows against the reference's own inside runs
            reference = (inside if of_inside else summaries).get(REFERENCE_ALGORITHM)
            reference_key = key.removesuffix("_inside")
            reference_value = getattr(reference, reference_key, float("nan")) if reference is not None else float("nan")
            thesis_value, thesis_difference = _thesis_cells(experiment, algo, key)
            rows.append(
                {
                    "algorithm": label,
                    "metric": name,
                    "average": value,
                    "ci95": half_width,
                    "average_text": text or _format_with_ci(value, half_width),
                    "difference_with_sarsa_lambda": ""
                    if key in COUNT_ROWS
                    else _format_difference(value, reference_value, algo),
                    "thesis_average": thesis_value,
                    "thesis_difference": thesis_difference,
                    "seeds": (inside[algo] or no_run).n_seeds if of_inside else summary.n_seeds,
                }
            )
    return pd.DataFrame(rows)


def markdown_table(experiment: Experiment, table: pd.DataFrame) -> str:
    """The summary as a markdown table (algorithm named on its first row only, like the thesis's tables).

    :param experiment: the experiment (its units and thesis table).
    :param table: the table of :func:`summary_table`.
    """
    lines = [
        "| Algorithm | Metric | Average (ours, ± 95% CI) | Difference with Sarsa(λ) | Thesis average "
        "| Thesis difference |",
        "|---|---|---|---|---|---|",
    ]
    previous = None
    for row in table.itertuples():
        name = row.algorithm if row.algorithm != previous else ""
        previous = row.algorithm
        lines.append(
            f"| {name} | {row.metric} | {row.average_text} | {row.difference_with_sarsa_lambda or '—'} | "
            f"{row.thesis_average or '—'} | {row.thesis_difference or '—'} |"
        )
    return "\n".join(lines)

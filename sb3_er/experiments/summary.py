"""Aggregates per-run CSVs into learning curves and tables in the format of thesis Tables 6.1-6.3."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sb3_er.experiments.metrics import CurveSummary, relative_difference, summarize_curves
from sb3_er.experiments.runner import run_csv_path
from sb3_er.experiments.specs import Experiment
from sb3_er.experiments.thesis import ALGORITHM_LABELS

REFERENCE_ALGORITHM = "sarsa_lambda"


@dataclass(frozen=True)
class Curves:
    """Per-seed curves of one algorithm's complete runs, cut to the shortest (rows: seeds), and its diverged runs.

    :param x: the common abscissa, shape (n,), in the experiment's x units.
    :param performance: the performance curves, shape (seeds, n).
    :param cumulative_falls: the cumulative falls, shape (seeds, n).
    :param seeds: the seeds of the complete runs, one per row.
    :param diverged_seeds: the seeds of the runs whose Q-function diverged (left out of the curves).
    :param wall_time_s: the runs' summed wall time in seconds.
    """

    x: np.ndarray
    performance: np.ndarray
    cumulative_falls: np.ndarray
    seeds: tuple[int, ...]
    diverged_seeds: tuple[int, ...]
    wall_time_s: float

    @property
    def n_runs(self) -> int:
        return len(self.seeds) + len(self.diverged_seeds)


def load_curves(experiment: Experiment, out_dir: Path, algo: str, seeds) -> Curves | None:
    """The finished runs of `algo` among `seeds`, or None when none has finished."""
    frames = {seed: pd.read_csv(path) for seed in seeds if (path := run_csv_path(out_dir, algo, seed)).is_file()}
    if not frames:
        return None
    diverged = tuple(seed for seed, frame in sorted(frames.items()) if frame.empty or frame["diverged"].any())
    complete = [frame for seed, frame in sorted(frames.items()) if seed not in diverged]
    length = min((len(frame) for frame in complete), default=0)
    complete = [frame.iloc[:length] for frame in complete]

    def stacked(column: str) -> np.ndarray:
        return np.stack([frame[column].to_numpy(dtype=float) for frame in complete]) if complete else np.zeros((0, 0))

    return Curves(
        x=complete[0][experiment.x_column].to_numpy(dtype=float) if complete else np.zeros(0),
        performance=stacked(experiment.performance_column),
        cumulative_falls=stacked("cumulative_falls"),
        seeds=tuple(seed for seed in sorted(frames) if seed not in diverged),
        diverged_seeds=diverged,
        wall_time_s=float(sum(frame["wall_time_s"].iloc[-1] for frame in frames.values() if not frame.empty)),
    )


def summarize(experiment: Experiment, curves: Curves) -> CurveSummary | None:
    """Rise time (in the table's unit), end performance and falls of one algorithm; None without a complete run."""
    if not curves.seeds:
        return None
    return summarize_curves(
        curves.x / experiment.rise_time_scale,
        curves.performance,
        curves.cumulative_falls if experiment.has_falls else None,
        success_threshold=experiment.success_threshold,
    )


def _format_number(value: float) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "NA"
    magnitude = abs(value)
    if magnitude >= 1e4:
        return f"{value:.3g}"
    if magnitude >= 100:
        return f"{value:.0f}"
    if magnitude >= 10:
        return f"{value:.1f}"
    return f"{value:.2f}"


def _format_with_ci(value: float, half_width: float | None) -> str:
    text = _format_number(value)
    if half_width is None or math.isnan(half_width) or text == "NA":
        return text
    return f"{text} ± {_format_number(half_width)}"


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
    """The thesis's difference with Sarsa(lambda), computed from its own averages (percent of Sarsa(lambda)'s value),
    with the printed figure beside it where the two differ by more than rounding (e.g. walker falls of vanilla ER:
    150 against 74 is +103 %, printed +51 %)."""
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
    return computed if agrees else f"{computed} (printed {printed})"


def _thesis_cells(experiment: Experiment, algo: str, metric: str) -> tuple[str, str]:
    entry = experiment.thesis_table.get(algo, {}).get(metric)
    if entry is None:
        return "", ""
    value = entry[0]
    text = "NA" if value is None else (value if isinstance(value, str) else f"{value:g}")
    return text, thesis_difference(experiment, algo, metric)


def summary_table(experiment: Experiment, curves: dict[str, Curves], budget: float) -> pd.DataFrame:
    """One row per (algorithm, metric), columns as thesis Tables 6.1-6.3 plus the thesis's own figures.

    Diverged runs are left out of the averages and counted in a "Diverged runs" row of their algorithm.
    """
    summaries = {algo: summarize(experiment, curve) for algo, curve in curves.items()}
    reference = summaries.get(REFERENCE_ALGORITHM)
    run_end = budget / experiment.rise_time_scale if experiment.protocol == "walking" else budget
    no_run = CurveSummary(float("nan"), float("nan"), float("nan"), None, None, 0)
    rows = []
    for algo, curve in curves.items():
        summary = summaries[algo] or no_run
        label = ALGORITHM_LABELS.get(algo, algo)
        rise = summary.rise_time
        rise_text = f">{_format_number(run_end)}" if math.isnan(rise) and summary.n_seeds else None
        settling = summary.settling_time
        metrics = [
            ("rise_time", f"Rise time [{experiment.rise_time_unit}]", rise, None, rise_text),
            ("settling_time", f"Settling time [{experiment.rise_time_unit}]", settling, None, None),
            ("end_performance", "End performance", summary.end_performance, summary.end_performance_ci, None),
        ]
        if experiment.has_falls:
            falls = float("nan") if summary.falls is None else summary.falls
            metrics.append(("falls", "Falls", falls, summary.falls_ci, None))
        if curve.diverged_seeds:
            share = len(curve.diverged_seeds)
            metrics.append(("diverged", "Diverged runs", share, None, f"{share} of {curve.n_runs}"))
        for key, name, value, half_width, text in metrics:
            reference_value = getattr(reference, key, float("nan")) if reference is not None else float("nan")
            thesis_value, thesis_difference = _thesis_cells(experiment, algo, key)
            rows.append(
                {
                    "algorithm": label,
                    "metric": name,
                    "average": value,
                    "ci95": half_width,
                    "average_text": text or _format_with_ci(value, half_width),
                    "difference_with_sarsa_lambda": "" if key == "diverged" else _format_difference(
                        value, reference_value, algo
                    ),
                    "thesis_average": thesis_value,
                    "thesis_difference": thesis_difference,
                    "seeds": summary.n_seeds,
                }
            )
    return pd.DataFrame(rows)


def markdown_table(experiment: Experiment, table: pd.DataFrame) -> str:
    """The summary as a markdown table (algorithm named on its first row only, like the thesis's tables)."""
    lines = [
        "| Algorithm | Metric | Average (ours, ± 95% CI) | Difference with Sarsa(λ) | Thesis average | Thesis difference |",
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

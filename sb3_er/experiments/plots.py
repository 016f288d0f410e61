"""Figures like the thesis's: mean learning curves with 95% CI bands (Figure 6.1), cumulative falls (Figure 6.2),
typical single runs (Figure 4.5) and grid-world value maps (Figures 5.2-5.5, Tables 5.1-5.2)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sb3_er.experiments import files  # noqa: E402
from sb3_er.experiments.metrics import mean_confidence_interval  # noqa: E402
from sb3_er.experiments.thesis import ALGORITHM_LABELS  # noqa: E402


def plot_mean_with_ci(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]], x_label: str, y_label: str, title: str, path: Path
) -> Path:
    """One line per algorithm (mean over seeds) with a shaded 95% confidence interval of the mean; saved to `path`.

    :param series: per label, (x of shape (P,), samples of shape (S, P)).
    :param x_label: the x axis's label.
    :param y_label: the y axis's label.
    :param title: the figure's title.
    :param path: the image file; its suffix gives the format.
    """
    figure, axes = plt.subplots(figsize=(7.0, 4.2))
    for algo, (x, curves) in series.items():
        mean, half_width = mean_confidence_interval(curves)
        (line,) = axes.plot(x, mean, label=f"{ALGORITHM_LABELS.get(algo, algo)} (n={curves.shape[0]})")
        if np.isfinite(half_width).any():
            axes.fill_between(x, mean - half_width, mean + half_width, color=line.get_color(), alpha=0.2, linewidth=0)
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.set_title(title)
    axes.grid(alpha=0.3)
    axes.legend(fontsize="small")
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path


def plot_typical_runs(
    runs: Mapping[str, tuple[np.ndarray, np.ndarray]], x_label: str, y_label: str, title: str, path: Path
) -> Path:
    """Figure 4.5: one run's learning curve per algorithm (label -> (x, y)), to show how single runs behave (drops in
    performance, runs that find no gait) where the mean curves smooth it away; saved to `path`.

    :param runs: per label, (x, y) of one run.
    :param x_label: the x axis's label.
    :param y_label: the y axis's label.
    :param title: the figure's title.
    :param path: the image file; its suffix gives the format.
    """
    figure, axes = plt.subplots(figsize=(7.0, 4.2))
    for label, (x, y) in runs.items():
        axes.plot(x, y, label=label, linewidth=1.2)
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.set_title(title)
    axes.grid(alpha=0.3)
    axes.legend(fontsize="small")
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path


def _cell_label(value: float) -> str:
    return f"{value:.0f}" if abs(value) < 1000 else f"{value:.0e}"


def plot_value_maps(maps: Mapping[str, Mapping[str, np.ndarray]], first_windy_row: int, title: str, path: Path) -> Path:
    """Grid of value maps, one row per case (e.g. tabular, tile coding) and one column per algorithm.

    Each map is indexed [y, x] with y growing northwards; the wind starts at `first_windy_row` (dashed line, the
    thesis's striped line). Every cell is annotated with its value; each map has its own symmetric colour scale (red
    negative, blue positive) so that a diverged map does not wash out the others.

    :param maps: value maps V[y, x] by case, then by algorithm.
    :param first_windy_row: the first row in the wind.
    :param title: the figure's title.
    :param path: the image file; its suffix gives the format.
    """
    rows = list(maps)
    columns = list(maps[rows[0]])
    figure, axes = plt.subplots(len(rows), len(columns), figsize=(2.9 * len(columns), 2.4 * len(rows)), squeeze=False)
    for row_index, case in enumerate(rows):
        for column_index, algo in enumerate(columns):
            axes_cell = axes[row_index][column_index]
            value_map = maps[case][algo]
            limit = float(np.max(np.abs(value_map))) or 1.0
            axes_cell.imshow(value_map, origin="lower", cmap="RdBu", vmin=-limit, vmax=limit)
            axes_cell.axhline(first_windy_row - 0.5, color="black", linestyle="--", linewidth=1)
            for (y, x), value in np.ndenumerate(value_map):
                axes_cell.text(x, y, _cell_label(value), ha="center", va="center", fontsize=5.5)
            axes_cell.set_xticks([])
            axes_cell.set_yticks([])
            axes_cell.set_title(f"{ALGORITHM_LABELS.get(algo, algo)}, {case}", fontsize="small")
    figure.suptitle(title)
    files.save_figure(figure, path, dpi=120, bbox_inches="tight")
    plt.close(figure)
    return path


def plot_mean_with_error_bars(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]],
    x_label: str,
    y_label: str,
    title: str,
    path: Path,
    references: Mapping[str, float] | None = None,
) -> Path:
    """Figure A.1's style: per series (label -> (x of shape (P,), samples of shape (S, P), rows the seeds)) the mean
    at each x with the 95% CI of the mean as error bars, the series shifted slightly apart along x so that their bars
    do not hide each other; `references` (label -> value) are drawn as dashed horizontal lines. Saved to `path`.

    :param series: per label, (x of shape (P,), samples of shape (S, P)).
    :param x_label: the x axis's label.
    :param y_label: the y axis's label.
    :param title: the figure's title.
    :param path: the image file; its suffix gives the format.
    :param references: horizontal reference lines by label (default None: none).
    """
    figure, axes = plt.subplots(figsize=(7.0, 4.2))
    span = max((float(np.ptp(x)) for x, _ in series.values() if len(x)), default=1.0) or 1.0
    shift = 0.012 * span
    for index, (label, (x, samples)) in enumerate(series.items()):
        samples = np.asarray(samples, dtype=float)
        if samples.size == 0:
            continue
        mean, half_width = mean_confidence_interval(samples)
        offset = (index - (len(series) - 1) / 2.0) * shift
        axes.errorbar(
            np.asarray(x, dtype=float) + offset,
            mean,
            yerr=None if not np.isfinite(half_width).any() else half_width,
            marker="o",
            markersize=4,
            capsize=3,
            linewidth=1.2,
            label=f"{label} (n={samples.shape[0]})",
        )
    for label, value in (references or {}).items():
        axes.axhline(value, color="grey", linestyle="--", linewidth=1, label=label)
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.set_title(title, fontsize="medium")
    axes.grid(alpha=0.3)
    axes.legend(fontsize="small")
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path


def plot_scores(scores: Mapping[str, np.ndarray], y_label: str, title: str, path: Path) -> Path:
    """Figure B.1's style: one category per key (in the given order) with its per-run scores (1-D), the mean and
    the 95% CI of the mean as an error bar, the single runs as faint dots. Saved to `path`.

    :param scores: per category, its per-run scores (1-D).
    :param y_label: the y axis's label.
    :param title: the figure's title.
    :param path: the image file; its suffix gives the format.
    """
    figure, axes = plt.subplots(figsize=(7.0, 4.2))
    for index, values in enumerate(scores.values()):
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.size == 0:
            continue
        mean, half_width = mean_confidence_interval(values)
        axes.scatter(np.full(values.size, index, dtype=float), values, color="grey", alpha=0.35, s=10)
        axes.errorbar(
            [index],
            [mean],
            yerr=None if not np.isfinite(half_width) else [half_width],
            marker="o",
            color="C0",
            capsize=5,
            linewidth=1.5,
        )
    axes.set_xticks(range(len(scores)))
    axes.set_xticklabels(list(scores), fontsize="small")
    axes.set_ylabel(y_label)
    axes.set_title(title, fontsize="medium")
    axes.grid(alpha=0.3, axis="y")
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path

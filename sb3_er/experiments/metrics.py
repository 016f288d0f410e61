"""Learning-curve metrics of the thesis (section 6.1): means with 95% confidence intervals, rise time, end performance.

A learning curve is a 1-D array of performance values at increasing abscissae (episodes or seconds of learning time);
a set of curves from several seeds is a 2-D array with one row per seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


def _as_seed_matrix(curves) -> np.ndarray:
    matrix = np.asarray(curves, dtype=float)
    if matrix.ndim == 1:
        matrix = matrix[np.newaxis, :]
    if matrix.ndim != 2 or matrix.shape[1] == 0:
        raise ValueError(f"curves must be a non-empty (seeds, points) array, got shape {matrix.shape}")
    return matrix


def mean_confidence_interval(samples, confidence: float = 0.95, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and the half-width of its Student-t confidence interval along `axis` (NaN half-width for one sample).

    :param samples: the samples (an array; rows along `axis`).
    :param confidence: the interval's confidence level (default 0.95).
    :param axis: the axis of the samples (default 0).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    values = np.asarray(samples, dtype=float)
    n = values.shape[axis]
    if n == 0:
        raise ValueError("cannot average zero samples")
    mean = values.mean(axis=axis)
    if n < 2:
        return mean, np.full_like(mean, np.nan)
    standard_error = values.std(axis=axis, ddof=1) / np.sqrt(n)
    return mean, stats.t.ppf(0.5 + confidence / 2.0, df=n - 1) * standard_error


def end_performance(mean_curve, success_threshold: float | None = None) -> float:
    """Highest value of the mean curve, the thesis's "highest performance after a successful gait has been learned".

    With a `success_threshold`, a curve that never reaches it has learned no gait: the result is NaN (thesis "NA").

    :param mean_curve: the mean curve over seeds, (P,).
    :param success_threshold: the level a curve must reach to count as learned (default None: any).
    """
    curve = _as_seed_matrix(mean_curve)[0]
    best = float(np.max(curve))
    if success_threshold is not None and best < success_threshold:
        return float("nan")
    return best


def rise_time(abscissa, mean_curve, end: float | None = None, fraction: float = 0.9) -> float:
    """First abscissa at which the mean curve has covered `fraction` of its way from its first value to `end`.

    `end` defaults to the curve's maximum (the end performance). For curves starting at zero, such as walked distance,
    this is the thesis's "time to reach 90% of the end performance"; measuring from the first value also makes it
    meaningful for negative returns (pendulum). NaN when `end` is NaN (no gait learned) or is never reached, and when
    the curve never rises above its first value (a run that learned nothing, such as a diverged run counted at the
    random policy's score, has no rise: its rise is beyond the run, not at its first point).

    :param abscissa: the curve's x values (episodes or seconds), (P,).
    :param mean_curve: the mean curve over seeds, (P,).
    :param end: the value the rise aims at (default None: the curve's maximum).
    :param fraction: the share of the way from the first value to `end` (default 0.9).
    """
    x = np.asarray(abscissa, dtype=float)
    curve = _as_seed_matrix(mean_curve)[0]
    if x.shape != curve.shape:
        raise ValueError(f"abscissa has shape {x.shape} but the curve has shape {curve.shape}")
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must lie in (0, 1], got {fraction}")
    target_end = float(np.max(curve)) if end is None else float(end)
    if np.isnan(target_end) or target_end <= curve[0] or np.max(curve) <= curve[0]:
        return float("nan")
    threshold = curve[0] + fraction * (target_end - curve[0])
    reached = np.flatnonzero(curve >= threshold)
    return float(x[reached[0]]) if reached.size else float("nan")


def settling_time(abscissa, mean_curve, tolerance: float = 0.1, plateau_points: int = 10) -> float:
    """First abscissa at which the mean curve comes within ``tolerance`` of its final plateau (our second rise time).

    The plateau is the mean of the last ``plateau_points`` points. A curve of distances (plateau > 0) has settled at
    the first point >= (1 - tolerance) * plateau; a curve of returns that are costs (plateau < 0) at the first point
    whose cost is <= (1 + tolerance) * the plateau's cost. Unlike the thesis's rise time, it does not measure from the
    first value nor from the best value, so once a run is long enough to reach its plateau, a longer run leaves it
    unchanged (the thesis's rise time moves with the run length whenever the mean curve still creeps up at its end).
    NaN when the plateau is 0, and when the curve never rises above its first value (nothing learned: no settling).

    :param abscissa: the curve's x values (episodes or seconds), (P,).
    :param mean_curve: the mean curve over seeds, (P,).
    :param tolerance: the relative distance to the plateau (default 0.1).
    :param plateau_points: points at the end averaged into the plateau (default 10).
    """
    x = np.asarray(abscissa, dtype=float)
    curve = _as_seed_matrix(mean_curve)[0]
    if x.shape != curve.shape:
        raise ValueError(f"abscissa has shape {x.shape} but the curve has shape {curve.shape}")
    if not 0.0 <= tolerance < 1.0:
        raise ValueError(f"tolerance must lie in [0, 1), got {tolerance}")
    if int(plateau_points) != plateau_points or plateau_points < 1:
        raise ValueError(f"plateau_points must be a positive integer, got {plateau_points}")
    plateau = float(np.mean(curve[-int(plateau_points) :]))
    if plateau == 0.0 or np.isnan(plateau) or np.max(curve) <= curve[0]:
        return float("nan")
    threshold = plateau * (1.0 - tolerance) if plateau > 0 else plateau * (1.0 + tolerance)
    reached = np.flatnonzero(curve >= threshold)
    return float(x[reached[0]]) if reached.size else float("nan")


def relative_difference(value: float, reference: float) -> float:
    """Difference with a reference in percent of the reference's magnitude (the thesis tables' last column).

    :param value: our value.
    :param reference: the reference value.
    """
    if reference == 0 or np.isnan(reference):
        return float("nan")
    return 100.0 * (value - reference) / abs(reference)


@dataclass(frozen=True)
class CurveSummary:
    """Thesis-table figures of one algorithm: rise time, end performance (with its CI), final falls (with CI), and our
    horizon-free settling time (:func:`settling_time`).

    :param rise_time: first abscissa at which the mean curve covers ``fraction`` of its way to the end performance
        (:func:`rise_time`), in the curve's x units (episodes or seconds of learning time).
    :param end_performance: best value of the mean curve, NaN when it never reaches the success threshold.
    :param end_performance_ci: half width of its confidence interval at that point.
    :param falls: mean cumulative falls at the end of learning, None without falls.
    :param falls_ci: half width of their confidence interval, None without falls.
    :param n_seeds: runs (seeds) summarised.
    :param settling_time: :func:`settling_time` of the mean curve, in x units (default NaN).
    """

    rise_time: float
    end_performance: float
    end_performance_ci: float
    falls: float | None
    falls_ci: float | None
    n_seeds: int
    settling_time: float = float("nan")


def summarize_curves(
    abscissa,
    performance,
    cumulative_falls=None,
    success_threshold: float | None = None,
    fraction: float = 0.9,
    confidence: float = 0.95,
) -> CurveSummary:
    """Summarise per-seed learning curves (rows: seeds) the way thesis Tables 6.1-6.3 do.

    :param abscissa: the curves' x values, (P,).
    :param performance: the per-seed curves, (S, P).
    :param cumulative_falls: the per-seed cumulative falls, (S, P) (default None: no falls column).
    :param success_threshold: see :func:`end_performance` (default None).
    :param fraction: see :func:`rise_time` (default 0.9).
    :param confidence: the confidence level of the intervals (default 0.95).
    """
    curves = _as_seed_matrix(performance)
    mean, half_width = mean_confidence_interval(curves, confidence)
    end = end_performance(mean, success_threshold)
    end_ci = float("nan") if np.isnan(end) else float(half_width[int(np.argmax(mean))])
    falls = falls_ci = None
    if cumulative_falls is not None:
        final_falls = _as_seed_matrix(cumulative_falls)[:, -1]
        falls_mean, falls_half = mean_confidence_interval(final_falls, confidence)
        falls, falls_ci = float(falls_mean), float(falls_half)
    return CurveSummary(
        rise_time=rise_time(abscissa, mean, end, fraction),
        settling_time=settling_time(abscissa, mean),
        end_performance=end,
        end_performance_ci=end_ci,
        falls=falls,
        falls_ci=falls_ci,
        n_seeds=curves.shape[0],
    )

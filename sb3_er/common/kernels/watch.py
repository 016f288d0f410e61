"""The value watch in the kernels: every target T and every Q(s_t, a_t) of an update folded into a float64 array of
WATCH_SIZE entries, in place, without allocating or drawing a random number (so results are the same with and
without it); an empty array switches it off. Python sets the bounds [WATCH_LOW, WATCH_HIGH] (the possible returns
widened by a margin, :mod:`sb3_er.common.value_bounds`) and resets the per-period entries after logging them; counts
and the first excursion accumulate for the model's life."""

import numpy as np

from sb3_er.common.kernels._jit import inline, kernel

(
    WATCH_TARGET_MIN,
    WATCH_TARGET_MAX,
    WATCH_Q_MIN,
    WATCH_Q_MAX,  # per logging period
    WATCH_SHIFT_SUM,
    WATCH_SHIFT_COUNT,
    WATCH_RAISED,
    WATCH_LOWERED,  # per logging period: ER-sigma's T_sigma - T
    WATCH_LOW,
    WATCH_HIGH,  # the bounds, set by Python
    WATCH_UPDATES,
    WATCH_OUT_OF_RANGE,  # cumulative: updates watched, values (T or Q) outside the bounds
    WATCH_FIRST_UPDATE,
    WATCH_FIRST_VALUE,  # the first value outside: its update number (-1: none), value
    WATCH_BOUND_LOW,
    WATCH_BOUND_HIGH,  # the possible returns themselves, set by Python
    WATCH_EXCURSION,  # cumulative: the largest distance of a value (T or Q) beyond them, 0 when none
    WATCH_PERIOD_UPDATES,
    WATCH_TRUNCATED,  # per logging period: updates watched, targets whose bootstrapped value was truncated
    WATCH_PROJECTED,  # per logging period: updates whose projection moved a weight back into the bounds
) = range(20)
WATCH_SIZE = 20
WATCH_PERIOD = (
    WATCH_TARGET_MIN,
    WATCH_TARGET_MAX,
    WATCH_Q_MIN,
    WATCH_Q_MAX,
    WATCH_SHIFT_SUM,
    WATCH_SHIFT_COUNT,
    WATCH_RAISED,
    WATCH_LOWERED,
    WATCH_PERIOD_UPDATES,
    WATCH_TRUNCATED,
    WATCH_PROJECTED,
)

#: The watch switched off: kernels given an empty array watch nothing.
NO_WATCH = np.zeros(0, dtype=np.float64)


def new_watch(low: float = -np.inf, high: float = np.inf, margin: float = 0.0) -> np.ndarray:
    """A value watch of the possible returns [low, high], nothing seen yet: a value counts as outside beyond
    ``margin`` on either side.

    :param low: the bounds' lower end (default -inf).
    :param high: their upper end (default +inf).
    :param margin: how far beyond the bounds a value may lie before it counts as outside (default 0).
    """
    watch = np.zeros(WATCH_SIZE, dtype=np.float64)
    reset_watch_period(watch)
    set_watch_bounds(watch, low, high, margin)
    watch[WATCH_FIRST_UPDATE] = -1.0
    watch[WATCH_FIRST_VALUE] = np.nan
    return watch


def set_watch_bounds(watch: np.ndarray, low: float, high: float, margin: float) -> None:
    """Set the possible returns [low, high] and the margin beyond which a value counts as outside.

    :param watch: the value watch (:func:`new_watch`), updated in place.
    :param low: the bounds' lower end.
    :param high: their upper end.
    :param margin: how far beyond the bounds a value may lie before it counts as outside.
    """
    watch[WATCH_BOUND_LOW], watch[WATCH_BOUND_HIGH] = low, high
    watch[WATCH_LOW], watch[WATCH_HIGH] = low - margin, high + margin


def reset_watch_period(watch: np.ndarray) -> None:
    """Start a new logging period: minima +inf, maxima -inf, shift sums and counts 0.

    :param watch: the value watch (:func:`new_watch`), updated in place.
    """
    watch[[WATCH_TARGET_MIN, WATCH_Q_MIN]] = np.inf
    watch[[WATCH_TARGET_MAX, WATCH_Q_MAX]] = -np.inf
    counts = [WATCH_SHIFT_SUM, WATCH_SHIFT_COUNT, WATCH_RAISED, WATCH_LOWERED, WATCH_PERIOD_UPDATES]
    watch[counts + [WATCH_TRUNCATED, WATCH_PROJECTED]] = 0.0


@inline
def watch_update(watch, target, q_sa):
    """Fold one update's target T and Q(s_t, a_t) into the value watch (their extremes, the largest excursion beyond
    the possible returns, the count of values beyond the margin); True when this is the first value the watch ever saw
    outside [watch[WATCH_LOW], watch[WATCH_HIGH]]. Nothing when ``watch`` is empty (the watch switched off).

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param target: the update's target T.
    :param q_sa: Q(s_t, a_t) before the update.
    """
    if watch.shape[0] == 0:
        return False
    watch[WATCH_TARGET_MIN] = min(watch[WATCH_TARGET_MIN], target)
    watch[WATCH_TARGET_MAX] = max(watch[WATCH_TARGET_MAX], target)
    watch[WATCH_Q_MIN] = min(watch[WATCH_Q_MIN], q_sa)
    watch[WATCH_Q_MAX] = max(watch[WATCH_Q_MAX], q_sa)
    watch[WATCH_UPDATES] += 1.0
    watch[WATCH_PERIOD_UPDATES] += 1.0
    bound_low, bound_high = watch[WATCH_BOUND_LOW], watch[WATCH_BOUND_HIGH]
    excess = max(target - bound_high, bound_low - target, q_sa - bound_high, bound_low - q_sa)
    watch[WATCH_EXCURSION] = max(watch[WATCH_EXCURSION], excess)
    low, high = watch[WATCH_LOW], watch[WATCH_HIGH]
    target_out = target < low or target > high
    q_out = q_sa < low or q_sa > high
    if not (target_out or q_out):
        return False
    watch[WATCH_OUT_OF_RANGE] += np.float64(target_out) + np.float64(q_out)
    if watch[WATCH_FIRST_UPDATE] >= 0.0:
        return False
    watch[WATCH_FIRST_UPDATE] = watch[WATCH_UPDATES] - 1.0
    watch[WATCH_FIRST_VALUE] = target if target_out else q_sa
    return True


@inline
def watch_shift(watch, shift):
    """Fold ER-sigma's target shift T_sigma - T (the same transition's target without sigma) into the watch.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param shift: T_sigma - T of one update.
    """
    if watch.shape[0] == 0:
        return
    watch[WATCH_SHIFT_SUM] += shift
    watch[WATCH_SHIFT_COUNT] += 1.0
    watch[WATCH_RAISED] += np.float64(shift > 0.0)
    watch[WATCH_LOWERED] += np.float64(shift < 0.0)


@inline
def watch_truncation(watch):
    """Count one target whose bootstrapped value was truncated to the possible returns.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    if watch.shape[0] > 0:
        watch[WATCH_TRUNCATED] += 1.0


@inline
def watch_projection(watch):
    """Count one update whose projection moved a weight back into the bounds.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    if watch.shape[0] > 0:
        watch[WATCH_PROJECTED] += 1.0


@kernel
def watch_batch(watch, targets, values):
    """Fold a batch of targets T_d and values Q(s_d, a_d) (FQI's and LSPI's sweeps over the database) into the
    watch; True when it saw its first value outside the bounds.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param targets: the targets T_d, (n,).
    :param values: the values Q(s_d, a_d), (n,).
    """
    flagged = False
    for d in range(targets.shape[0]):
        flagged |= watch_update(watch, targets[d], values[d])
    return flagged

"""Continuous (Box) action spaces as joint actions over a few levels per dimension, as the thesis's actuators are.

The thesis learns on continuous actuators by discretising them: 7 pendulum torques from -3 to 3 V, both bounds
included (section 4.2.1), 15 hip accelerations of the simplest walker, 7 voltages per joint of LEO (7^3 = 343 joint
actions). A Box action space is handled the same way here: each of its dimensions gets levels spaced evenly from its
lower to its upper bound, both included, and the agent acts on the joint actions (flattened in C order, like a
MultiDiscrete space), an action index as for LEO, or tiled over the levels with ``action_tile_widths``.

Why not Gymnasium's ``DiscretizeAction`` wrapper: it takes the centres of equal bins, never the bounds (7 bins of
Pendulum-v1's [-2, 2] give +-1.71 as the strongest torques, where the thesis's levels reach the actuator's limit), and
it replaces the env's action space by a Discrete one, so that a model trained through it could not act on the
unwrapped env, and ``evaluate_policy``, rl-zoo and SB3's callbacks would see indices instead of the torques the env
receives. Discretising in the policy keeps the env as it is, the way SB3's continuous algorithms see it: ``predict``
returns actions of the Box's shape and dtype, inside its bounds.
"""

from collections.abc import Sequence

import numpy as np
from gymnasium import spaces

#: Levels per Box action dimension when neither ``action_bins`` nor ``action_values`` is given: the thesis's 7 (its
#: pendulum torques and LEO's voltages per joint), odd so that zero is a level when the bounds are symmetric.
DEFAULT_ACTION_BINS = 7
#: The most joint actions the default levels may make: LEO's 7^3 = 343, so the default covers Box spaces of up to 3
#: dimensions. Beyond, the user chooses: ``action_bins`` (fewer levels per dimension) or ``action_values``.
MAX_DEFAULT_JOINT_ACTIONS = DEFAULT_ACTION_BINS**3
#: Bounds this large in magnitude are placeholders for "unbounded", not a range: MuJoCo's mjMAXVAL (1e10), which
#: dm_control reports for an actuator without a control range (lqr's motors), and +-float32 max. Levels spaced between
#: them would push with forces of order 1e10, and the simulation would blow up.
PLACEHOLDER_BOUND = 1e10


def box_action_levels(
    action_space: spaces.Box,
    action_bins: int | Sequence[int] | None = None,
    action_values: Sequence[Sequence[float]] | None = None,
) -> list[np.ndarray]:
    """The levels of each dimension of a Box action space (flattened in C order), as float64 arrays holding exactly
    the values the env receives in the Box's dtype.

    :param action_space: a Box of a floating-point dtype.
    :param action_bins: levels per dimension, one int for all or one per dimension; each dimension's levels are
        ``linspace(low, high, bins)``, both bounds included (one level, the midpoint, for ``bins=1``).
    :param action_values: explicit levels, each inside the Box's bounds, distinct: one list per dimension, or one
        flat list of numbers for every dimension (``[0.0, 1.0]`` gives each dimension the levels 0 and 1); the only
        way to discretise a dimension with infinite bounds.
    Neither given: ``DEFAULT_ACTION_BINS`` per dimension, if the joint actions stay within
    ``MAX_DEFAULT_JOINT_ACTIONS``. ValueError naming the problem otherwise.
    """
    if not isinstance(action_space, spaces.Box):
        raise ValueError(f"box_action_levels needs a Box action space, got {action_space}")
    if not np.issubdtype(action_space.dtype, np.floating):
        raise ValueError(
            f"A Box action space of dtype {action_space.dtype} is not supported: levels between its "
            "bounds need a floating-point dtype (use a MultiDiscrete space for integer actions)"
        )
    dtype = action_space.dtype
    low = action_space.low.astype(np.float64).reshape(-1)
    high = action_space.high.astype(np.float64).reshape(-1)
    n_dims = low.size
    if n_dims == 0:
        raise ValueError(f"The Box action space {action_space} has no dimensions")
    if action_bins is not None and action_values is not None:
        raise ValueError("Give either action_bins or action_values for a Box action space, not both")
    if action_values is not None:
        return _explicit_levels(action_values, low, high, dtype)
    bounded = (
        np.isfinite(low) & np.isfinite(high) & (np.abs(low) < PLACEHOLDER_BOUND) & (np.abs(high) < PLACEHOLDER_BOUND)
    )
    if not bounded.all():
        bad = np.flatnonzero(~bounded).tolist()
        raise ValueError(
            f"Action dimensions {bad} of {action_space} are unbounded (bounds {low[bad].tolist()} to "
            f"{high[bad].tolist()}; magnitudes of 1e10 or more, such as MuJoCo's 1e10 for an actuator without a "
            "control range, count as unbounded): levels cannot be spaced between "
            "them. Give the levels: policy_kwargs=dict(action_values=[[...], ...]), one list per action dimension"
        )
    bins = _check_bins(action_bins, n_dims, low, high)
    levels = []
    for j in range(n_dims):
        if bins[j] == 1:
            values = np.array([0.5 * (low[j] + high[j])])
        else:
            values = np.linspace(low[j], high[j], bins[j])  # endpoints are exactly low and high
        levels.append(
            np.clip(values.astype(dtype), action_space.low.reshape(-1)[j], action_space.high.reshape(-1)[j]).astype(
                np.float64
            )
        )
    return levels


def _check_bins(action_bins, n_dims: int, low: np.ndarray, high: np.ndarray) -> list[int]:
    if action_bins is None:
        if DEFAULT_ACTION_BINS**n_dims > MAX_DEFAULT_JOINT_ACTIONS:
            raise ValueError(
                f"A Box action space of {n_dims} dimensions would get {DEFAULT_ACTION_BINS}^{n_dims} = "
                f"{DEFAULT_ACTION_BINS**n_dims} joint actions by default, more than the default's cap of "
                f"{MAX_DEFAULT_JOINT_ACTIONS} ({DEFAULT_ACTION_BINS}^3, LEO's). Choose the levels: "
                "policy_kwargs=dict(action_bins=3) (or one count per dimension), or action_values=[[...], ...]"
            )
        bins = [DEFAULT_ACTION_BINS] * n_dims
    else:
        bins = [action_bins] * n_dims if np.ndim(action_bins) == 0 else list(action_bins)
        if len(bins) != n_dims:
            raise ValueError(f"action_bins has {len(bins)} entries for a Box action space of {n_dims} dimensions")
        for count in bins:
            if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
                raise ValueError(f"action_bins must be positive integers, got {action_bins!r}")
        bins = [int(count) for count in bins]
    constant = [j for j in range(n_dims) if low[j] == high[j] and bins[j] > 1]
    if constant:
        raise ValueError(
            f"Action dimensions {constant} have equal bounds: they hold one level, give action_bins 1 for them"
        )
    return bins


def levels_per_dimension(action_values, n_dims: int) -> list[np.ndarray]:
    """``action_values`` as one float64 array of levels per action dimension: a list of lists gives each dimension
    its own levels, a flat list of numbers the same levels to every dimension (as one int of ``action_bins`` gives
    every dimension that many levels). ValueError naming the problem for anything else (a mix of numbers and lists,
    non-numbers, or a list of lists whose count differs from ``n_dims``).

    :param action_values: a flat list of numbers, or one list of numbers per action dimension.
    :param n_dims: the number of action dimensions.
    """
    usage = "one list of numbers per action dimension, or one flat list of numbers for every dimension"
    problem = ValueError(f"action_values must be {usage}, got {action_values!r}")
    sequence = isinstance(action_values, (list, tuple)) or (
        isinstance(action_values, np.ndarray) and action_values.ndim >= 1
    )
    if not sequence:
        raise problem
    entries = list(action_values)
    is_number = [not isinstance(v, (list, tuple, np.ndarray, str, bytes)) for v in entries]
    try:
        if entries and all(is_number):
            shared = np.asarray(entries, dtype=np.float64)
            return [shared.copy() for _ in range(n_dims)]
        if any(is_number):
            raise problem
        values = [np.asarray(v, dtype=np.float64) for v in entries]
    except (TypeError, ValueError):
        raise problem from None
    if any(v.ndim != 1 for v in values):
        raise problem
    if len(values) != n_dims:
        raise ValueError(
            f"action_values has {len(values)} lists for an action space of {n_dims} dimensions (give one list per "
            "dimension, or one flat list for every dimension)"
        )
    return values


def _explicit_levels(action_values, low: np.ndarray, high: np.ndarray, dtype) -> list[np.ndarray]:
    values = levels_per_dimension(action_values, low.size)
    levels = []
    for j, v in enumerate(values):
        if v.size == 0 or not np.all(np.isfinite(v)):
            raise ValueError(f"action_values[{j}] must be finite numbers, at least one, got {v.tolist()}")
        cast = v.astype(dtype).astype(np.float64)
        if np.any(cast < low[j]) or np.any(cast > high[j]):
            raise ValueError(f"action_values[{j}] = {v.tolist()} leave the action space's bounds [{low[j]}, {high[j]}]")
        if np.unique(cast).size != cast.size:
            raise ValueError(f"action_values[{j}] = {v.tolist()} repeat a level (in the space's dtype {dtype})")
        levels.append(cast)
    return levels

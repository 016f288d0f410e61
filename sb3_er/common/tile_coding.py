"""Binary tile coding of (state, action) pairs into a hashed weight memory (thesis section 2.7.2), and the default
tilings: sb3-er's tilings for known env ids (package data) and the generic rule for other bounded observations."""

import functools
import importlib.resources
import inspect
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import yaml
from gymnasium import spaces

from sb3_er.common import kernels
from sb3_er.common.action_levels import levels_per_dimension

#: The generic rule: at most this many tiles per bounded dimension (the rule of sb3-er before budgets), at least 2.
DEFAULT_TILES_PER_DIMENSION = 10
MIN_DEFAULT_TILES_PER_DIMENSION = 2
#: The generic rule's cells per tiling, spread over the non-constant dimensions; 2^14 gives Acrobot's 6 dimensions 5
#: tiles each and MountainCar's 2 the cap of 10. Measured on these bounded tasks (the documentation's "Your own
#: environment" and "Classic control" pages; 16 tilings, 100,000 steps, seeds 0-4): with 5 tiles per dimension
#: ER-sigma's median greedy returns on Acrobot were -130 to -145, where 10 (1e6 cells per tiling) never reached the
#: goal; MountainCar learned with 8 and with 10.
DEFAULT_CELL_BUDGET = 2**14
#: sb3-er's tilings for known env ids (package data, shipped in the wheel).
PACKAGE_TILINGS = ("sb3_er", "data/tilings.yml")
#: Observation bounds this large in magnitude are placeholders for "unbounded", not a range: +-float32 max, and MuJoCo's
#: mjMAXVAL (1e10), its stand-in for "no limit".
PLACEHOLDER_BOUND = 1e10

WEIGHTS_PER_CACHE_LINE = 8  # float64 weights in a 64-byte cache line: a state tile's row starts on a line boundary
#: The distinct state tiles per tiling a run is assumed to visit when the observation space holds more (or is
#: unbounded), for the expected collision rate of a table: 4,096 per tiling, 65,536 at 16 tilings. sb3-er's thesis runs
#: visit about as many: 64,982 on the pendulum, 29,569 to 46,347 on the simplest walker (16 tilings;
#: ``results/measured/table_size``).
REFERENCE_TILES_PER_TILING = 4096
#: Above this expected collision rate at the reference tile count, building a policy warns. In the measurements of
#: ``results/measured/table_size`` the pendulum and the walker learned as well at 53 % and 63 % collisions as at 6 %,
#: and worse at 87 % and 91 %.
COLLISION_WARNING_RATE = 0.5
#: The collision rate the warning's suggested memory_size keeps under (the default table's on the pendulum: 6 %).
SUGGESTED_COLLISION_RATE = 0.1


class HashCollisionWarning(UserWarning):
    """The hashed weight table has too few state-tile slots for the tiles a run is likely to visit: different states
    would share weights (see :meth:`TileCoder.expected_collision_rate`)."""


def tiling_offsets(n_tilings: int, n_dims: int) -> np.ndarray:
    """Displacement of tiling k in dimension d, in tile widths: k (1 + 2d) / N (Eq. 2.9 with 0-based k and d).

    These are the asymmetric offsets of Miller et al. (1990) and Sutton's tiles: tiling k is displaced by
    (1, 3, 5, ...) * k / N tile widths along dimensions (0, 1, 2, ...).

    :param n_tilings: the number of tilings N.
    :param n_dims: the number of state dimensions D.
    """
    k = np.arange(n_tilings, dtype=np.float64)[:, None]
    d = np.arange(n_dims, dtype=np.float64)[None, :]
    return k * (1.0 + 2.0 * d) / n_tilings


class TileCoder:
    """Tile coding with N displaced tilings, hashed into ``memory_size`` weights.

    phi(s, a) has exactly N ones (Eq. 2.8): one tile per tiling. States are tiled with per-dimension ``tile_widths``
    (optionally periodic with ``wrap_periods``; the width is then rounded so that a whole number of tiles fills one
    period). Actions either index the feature (no generalisation across actions, the default) or, given
    ``action_tile_widths``, are tiled like further state dimensions over their ``action_values`` (LEO's original setup
    tiled its voltages). The weights of all actions of one (tiling, state tile) are adjacent: weight index =
    slot * stride + action column, with the slot a hash of (tiling, state-tile coordinates) into a power-of-two table
    and the stride the row length rounded up to whole cache lines, so that Q(s, .) reads as few lines as possible.

    :param tile_widths: tile width per observation dimension, in observation units.
    :param action_nvec: number of choices per action dimension (``[n]`` for Discrete(n)).
    :param n_tilings: N, the number of tilings.
    :param memory_size: upper bound on the number of weights; the table uses the largest power of two of state-tile
        slots that fits.
    :param wrap_periods: per dimension a period (e.g. 2 pi for an angle) or None.
    :param action_values: per action dimension the value of each choice (defaults to the choice index); one flat list
        gives every dimension the same values.
    :param action_tile_widths: per action dimension a tile width over ``action_values``; None keeps actions apart.
    """

    def __init__(
        self,
        tile_widths: Sequence[float],
        action_nvec: Sequence[int],
        n_tilings: int = 16,
        memory_size: int = 2**22,
        wrap_periods: Sequence[float | None] | None = None,
        action_values: Sequence[Sequence[float]] | None = None,
        action_tile_widths: Sequence[float] | None = None,
    ):
        self.tile_widths = np.asarray(tile_widths, dtype=np.float64).reshape(-1)
        self.n_dims = self.tile_widths.shape[0]
        self.action_nvec = np.asarray(action_nvec, dtype=np.int64).reshape(-1)
        for name, value in (("n_tilings", n_tilings), ("memory_size", memory_size)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, np.integer, float))
                or value != int(value)
                or value < 1
            ):
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        self.n_tilings = int(n_tilings)
        self.n_actions = int(np.prod(self.action_nvec))
        with np.errstate(divide="ignore", over="ignore"):
            inverse = 1.0 / self.tile_widths
        if (
            not np.all(np.isfinite(self.tile_widths))
            or np.any(self.tile_widths <= 0)
            or not np.all(np.isfinite(inverse))
        ):
            raise ValueError(
                f"tile_widths must be finite and positive (and not subnormal), got {self.tile_widths.tolist()}"
            )
        self.wrap_periods = self._check_wrap_periods(wrap_periods)
        self.wrap_tiles = np.zeros(self.n_dims, dtype=np.int64)
        self.inv_widths = 1.0 / self.tile_widths
        for d, period in enumerate(self.wrap_periods):
            if period is not None:
                if not period / self.tile_widths[d] < kernels.MAX_TILE_COORDINATE:
                    raise ValueError(
                        f"wrap period {period} of dimension {d} holds too many tiles of width "
                        f"{self.tile_widths[d]} (at most 2^62)"
                    )
                self.wrap_tiles[d] = max(1, int(round(period / self.tile_widths[d])))
                self.inv_widths[d] = self.wrap_tiles[d] / period
        self.offsets = tiling_offsets(self.n_tilings, self.n_dims)
        self.action_values = self._check_action_values(action_values)
        self.action_tile_widths = None if action_tile_widths is None else np.asarray(action_tile_widths, np.float64)
        self.action_columns = self._action_columns()
        self.stride = -(-(int(self.action_columns.max()) + 1) // WEIGHTS_PER_CACHE_LINE) * WEIGHTS_PER_CACHE_LINE
        n_slots = 1 << int(np.floor(np.log2(max(memory_size // self.stride, 1))))
        if n_slots * self.stride > memory_size:
            raise ValueError(
                f"memory_size={memory_size} cannot hold even one state tile of {self.stride} action weights"
            )
        self.n_slots = n_slots
        self.slot_mask = n_slots - 1
        self.memory_size = int(memory_size)
        self.n_weights = n_slots * self.stride
        self.layout = kernels.make(
            kernels.TileLayout,
            inv_widths=self.inv_widths,
            offsets=self.offsets,
            wrap_tiles=self.wrap_tiles,
            slot_mask=self.slot_mask,
            stride=self.stride,
            action_columns=self.action_columns,
            columns_are_actions=self.columns_are_actions,
        )
        """The coder as the kernels read it (a :class:`~sb3_er.common.kernels.bundles.TileLayout`)."""

    def _check_wrap_periods(self, wrap_periods) -> list[float | None]:
        if wrap_periods is None:
            return [None] * self.n_dims
        periods = list(wrap_periods)
        if len(periods) != self.n_dims:
            raise ValueError(f"wrap_periods has {len(periods)} entries for {self.n_dims} observation dimensions")
        for period in periods:
            if period is not None and not (np.isfinite(period) and period > 0):
                raise ValueError(f"wrap periods must be positive and finite or None, got {periods}")
        return [None if p is None else float(p) for p in periods]

    def _check_action_values(self, action_values) -> list[np.ndarray]:
        if action_values is None:
            return [np.arange(n, dtype=np.float64) for n in self.action_nvec]
        values = levels_per_dimension(action_values, len(self.action_nvec))
        if [len(v) for v in values] != self.action_nvec.tolist():
            raise ValueError(
                f"action_values sizes {[len(v) for v in values]} do not match the action space {self.action_nvec}"
            )
        return values

    def _action_columns(self) -> np.ndarray:
        """Column of each action within a state tile's row, per tiling: (N, A)."""
        flat = np.arange(self.n_actions)
        if self.action_tile_widths is None:
            return np.tile(flat, (self.n_tilings, 1)).astype(np.int64)
        if self.action_tile_widths.shape != (len(self.action_nvec),):
            raise ValueError(
                f"action_tile_widths needs one width per action dimension ({len(self.action_nvec)}), "
                f"got {self.action_tile_widths.tolist()}"
            )
        if not np.all(np.isfinite(self.action_tile_widths)) or np.any(self.action_tile_widths <= 0):
            raise ValueError(f"action_tile_widths must be finite and positive, got {self.action_tile_widths.tolist()}")
        if not all(np.all(np.isfinite(v)) for v in self.action_values):
            raise ValueError("action_values must be finite")
        choice = np.stack(np.unravel_index(flat, self.action_nvec), axis=1)
        values = np.stack([self.action_values[j][choice[:, j]] for j in range(len(self.action_nvec))], axis=1)
        offsets = tiling_offsets(self.n_tilings, self.n_dims + len(self.action_nvec))[:, self.n_dims :]
        columns = np.empty((self.n_tilings, self.n_actions), dtype=np.int64)
        for k in range(self.n_tilings):
            coords = np.floor(values / self.action_tile_widths + offsets[k]).astype(np.int64)
            _, columns[k] = np.unique(coords, axis=0, return_inverse=True)
        return columns

    @property
    def columns_are_actions(self) -> bool:
        """True when actions are not tiled: column a of a row is action a."""
        return self.action_tile_widths is None

    def config(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this exact coder."""
        return {
            "tile_widths": self.tile_widths.tolist(),
            "action_nvec": self.action_nvec.tolist(),
            "n_tilings": self.n_tilings,
            "memory_size": self.memory_size,
            "wrap_periods": list(self.wrap_periods),
            "action_values": [v.tolist() for v in self.action_values],
            "action_tile_widths": None if self.action_tile_widths is None else self.action_tile_widths.tolist(),
        }

    def bad_observation_message(self, obs: np.ndarray, where: str = "") -> str:
        """Why ``obs`` cannot be tiled: NaN or infinite entries, or entries so far out that a tile coordinate would
        overflow (|x / width| >= 2^62).

        :param obs: the observation, (D,).
        :param where: where it came from, for the message (default "").
        """
        obs = np.asarray(obs, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(obs)):
            problem = f"NaN or infinite values in dimensions {np.flatnonzero(~np.isfinite(obs)).tolist()}"
        else:
            huge = np.flatnonzero(~(np.abs(obs * self.inv_widths) < kernels.MAX_TILE_COORDINATE))
            problem = (
                f"values too large for their tile widths in dimensions {huge.tolist()} "
                f"(|x / width| must stay below 2^62)"
            )
        return f"Observation {obs.tolist()}{where} cannot be tiled: {problem}"

    def coordinates(self, obs: np.ndarray) -> np.ndarray:
        """Integer tile coordinates (N, D) of one observation, before hashing.

        :param obs: one observation, (D,).
        """
        obs = np.asarray(obs, dtype=np.float64).reshape(self.n_dims)
        coords = np.floor(obs * self.inv_widths + self.offsets).astype(np.int64)
        wrapped = self.wrap_tiles > 0
        coords[:, wrapped] %= self.wrap_tiles[wrapped]
        return coords

    def slots(self, obs: np.ndarray) -> np.ndarray:
        """Hashed state-tile slot (N,) of one observation.

        :param obs: one observation, (D,).
        """
        out = np.empty(self.n_tilings, dtype=np.int64)
        obs = np.ascontiguousarray(obs, dtype=np.float64).reshape(self.n_dims)
        if not kernels.state_slots(obs, self.layout, out):
            raise ValueError(self.bad_observation_message(obs))
        return out

    def feature_indices(self, obs: np.ndarray, action: int) -> np.ndarray:
        """Weight indices (N,) of the active features of phi(s, a); repeated indices mean a hash collision.

        :param obs: one observation, (D,).
        :param action: the flat action index.
        """
        return self.slots(obs) * self.stride + self.action_columns[:, int(action)]

    def memory_report(self, observations: np.ndarray) -> dict[str, float]:
        """How well the hashed memory holds the state tiles of these observations.

        distinct_tiles: distinct (tiling, state tile) pairs; slots_used: distinct slots they occupy; collision_rate:
        share of distinct tiles sharing a slot with another tile; fill: slots_used / slots in the table.

        :param observations: the states to tile, (n, D).
        """
        observations = np.asarray(observations, dtype=np.float64).reshape(-1, self.n_dims)
        keys = set()
        slots = set()
        for obs in observations:
            coords = self.coordinates(obs)
            keys.update((k, *coords[k].tolist()) for k in range(self.n_tilings))
            slots.update(self.slots(obs).tolist())
        distinct = len(keys)
        return {
            "distinct_tiles": float(distinct),
            "slots_used": float(len(slots)),
            "collision_rate": 0.0 if distinct == 0 else 1.0 - len(slots) / distinct,
            "fill": len(slots) / self.n_slots,
        }

    def expected_collision_rate(self, n_tiles: float) -> float:
        """The collision rate :meth:`memory_report` would measure after ``n_tiles`` distinct state tiles, hashed
        uniformly into the table's S slots: 1 - E[slots used] / n_tiles, with E[slots used] = S (1 - (1 - 1/S)^n_tiles)
        (the share of tiles that find their slot taken by another).

        :param n_tiles: the number of distinct (tiling, state tile) pairs, at least 1.
        """
        if not n_tiles >= 1:
            raise ValueError(f"n_tiles must be at least 1, got {n_tiles!r}")
        return expected_collision_rate(float(n_tiles), self.n_slots)

    def state_tiles_in_box(self, low: Sequence[float], high: Sequence[float]) -> float:
        """The number of distinct (tiling, state tile) pairs that cover the box [low, high] of observations: per
        tiling the product over dimensions of the tiles spanned between the bounds (at most the period's tiles for a
        wrapped dimension), summed over the tilings; infinity when a bound is infinite.

        :param low: the lower bound of each observation dimension.
        :param high: the upper bound of each observation dimension.
        """
        low = np.asarray(low, dtype=np.float64).reshape(self.n_dims)
        high = np.asarray(high, dtype=np.float64).reshape(self.n_dims)
        total = 0.0
        with np.errstate(invalid="ignore", over="ignore"):
            spans = np.floor(high * self.inv_widths + self.offsets) - np.floor(low * self.inv_widths + self.offsets) + 1
        wrapped = self.wrap_tiles > 0
        spans[:, wrapped] = np.fmin(spans[:, wrapped], self.wrap_tiles[wrapped])  # any bounds: one period's tiles
        if not np.all(np.isfinite(spans[:, ~wrapped])):
            return math.inf
        for row in spans:
            total += math.prod(float(count) for count in row)
        return total

    def slots_for(self, n_tiles: float, collision_rate: float) -> int:
        """The fewest state-tile slots (a power of two) whose expected collision rate after ``n_tiles`` distinct state
        tiles is at most ``collision_rate``; ``slots_for(...) * stride`` is the memory_size that gives them.

        :param n_tiles: the number of distinct state tiles, at least 1.
        :param collision_rate: the largest acceptable expected collision rate, in (0, 1).
        """
        if not 0.0 < collision_rate < 1.0:
            raise ValueError(f"collision_rate must lie in (0, 1), got {collision_rate!r}")
        slots = 1
        while expected_collision_rate(float(n_tiles), slots) > collision_rate:
            slots *= 2
        return slots

    def __repr__(self) -> str:
        return (
            f"TileCoder(n_tilings={self.n_tilings}, tile_widths={self.tile_widths.tolist()}, "
            f"actions={self.n_actions}, stride={self.stride}, slots={self.n_slots}, weights={self.n_weights})"
        )


def expected_collision_rate(n_tiles: float, n_slots: int) -> float:
    """1 - E[slots used] / n_tiles for ``n_tiles`` distinct keys hashed uniformly into ``n_slots`` slots, with
    E[slots used] = n_slots (1 - (1 - 1 / n_slots)^n_tiles): the share of keys that find their slot taken.

    :param n_tiles: the number of distinct keys, at least 1.
    :param n_slots: the number of slots, at least 1.
    """
    used = -n_slots * math.expm1(n_tiles * math.log1p(-1.0 / n_slots)) if n_slots > 1 else 1.0
    return max(0.0, 1.0 - used / n_tiles)


def collision_warning(coder: TileCoder, observation_space: spaces.Box) -> str | None:
    """The message of a :class:`HashCollisionWarning` when ``coder``'s actions leave its table too few state-tile rows
    for the state tiles a run on ``observation_space`` is likely to visit, else None.

    It speaks when more than ``COLLISION_WARNING_RATE`` of those tiles are expected to share a row, and rows of one
    cache line (at most 8 action columns) would have kept under it: a long row is what a user may not see coming. A
    memory_size too small for any action set is left to the user who chose it (``memory_report`` measures it).

    The tiles counted are those covering the observation space (:meth:`TileCoder.state_tiles_in_box`), at most
    ``REFERENCE_TILES_PER_TILING`` per tiling; the message gives the expected collision rate at that count, the
    memory_size that would keep it under ``SUGGESTED_COLLISION_RATE`` and the ways to shorten a state tile's row.

    :param coder: the tile coder of a policy.
    :param observation_space: the policy's (flat) Box observation space.
    """
    reference = REFERENCE_TILES_PER_TILING * coder.n_tilings
    n_tiles = min(coder.state_tiles_in_box(observation_space.low, observation_space.high), reference)
    n_tiles = max(n_tiles, 1.0)
    rate = coder.expected_collision_rate(n_tiles)
    one_line_slots = 1 << int(np.floor(np.log2(max(coder.memory_size // WEIGHTS_PER_CACHE_LINE, 1))))
    if rate <= COLLISION_WARNING_RATE or expected_collision_rate(n_tiles, one_line_slots) > COLLISION_WARNING_RATE:
        return None  # enough rows, or a memory_size too small for any action set: the user's choice, not the actions'
    slots = coder.slots_for(n_tiles, SUGGESTED_COLLISION_RATE)
    memory = slots * coder.stride
    counted = (
        "the state tiles covering the observation space"
        if n_tiles < reference
        else f"{REFERENCE_TILES_PER_TILING:,} per tiling, about what sb3-er's pendulum and walker runs visit"
    )
    mebibytes = memory * 8 / 2**20
    size = f"{mebibytes / 1024:,.1f} GiB" if mebibytes >= 1024 else f"{mebibytes:,.0f} MiB"
    return (
        f"The weight table holds {coder.n_slots:,} state-tile slots: memory_size={coder.memory_size} weights in rows "
        f"of {coder.stride:,} (one weight per action column; {coder.n_actions:,} actions). A run that visits "
        f"{n_tiles:,.0f} distinct state tiles ({counted}) would find about {100 * rate:.0f} % of them sharing a slot, "
        f"and so weights, with another state. memory_size={memory} ({slots:,} slots, {size} of float64 weights) "
        f"keeps this under {100 * SUGGESTED_COLLISION_RATE:.0f} %; or use fewer actions (action_bins, action_values) "
        "or tile the actions (action_tile_widths), which shortens the rows. TileCoder.memory_report(observations) "
        "measures the rate on the observations of a run."
    )


def default_tiles_per_dimension(n_dims: int, cell_budget: int = DEFAULT_CELL_BUDGET) -> int:
    """Tiles per dimension of the generic rule: min(10, floor(cell_budget^(1/n_dims))), at least 2.

    A cell budget per tiling spread evenly over the dimensions keeps a tiling's cell count near ``cell_budget``
    whatever the dimension, where a fixed 10 per dimension gives 10^D cells (Acrobot's 6 dimensions: 10^6 cells per
    tiling, which 100,000 steps cannot fill). The root is taken in integers, so 5^6 = 15,625 cells give exactly 5.

    :param n_dims: the number of tiled dimensions D (at least 1).
    :param cell_budget: the cells per tiling to aim at (default 16,384).
    """
    if int(n_dims) != n_dims or n_dims < 0:
        raise ValueError(f"n_dims must be a non-negative integer, got {n_dims!r}")
    if int(cell_budget) != cell_budget or cell_budget < 1:
        raise ValueError(f"cell_budget must be a positive integer, got {cell_budget!r}")
    if n_dims == 0:
        return DEFAULT_TILES_PER_DIMENSION
    k = math.floor(cell_budget ** (1.0 / n_dims))
    while (k + 1) ** n_dims <= cell_budget:  # floating-point roots can fall short of an exact integer root
        k += 1
    while k > 1 and k**n_dims > cell_budget:
        k -= 1
    return max(MIN_DEFAULT_TILES_PER_DIMENSION, min(DEFAULT_TILES_PER_DIMENSION, k))


def varying_dimensions(observation_space: spaces.Box) -> int:
    """The number of observation dimensions whose bounds differ (the generic rule's D; a constant needs no tiles).

    :param observation_space: a Box observation space.
    """
    return int(np.count_nonzero(observation_space.high.astype(np.float64) > observation_space.low.astype(np.float64)))


def default_tile_widths(
    observation_space: spaces.Box, tiles_per_dimension: int | None = None, cell_budget: int = DEFAULT_CELL_BUDGET
) -> list[float]:
    """Tile widths splitting each bounded observation dimension into equal tiles.

    ``tiles_per_dimension`` tiles per dimension if given; otherwise the generic rule,
    ``default_tiles_per_dimension(D, cell_budget)`` with D the number of non-constant dimensions (at most 10, at
    least 2 tiles each, ``cell_budget`` cells per tiling). Bounds that are infinite, or placeholders for infinity
    (magnitude >= 1e10, such as +-float32 max), cannot be split: those dimensions need explicit widths and the
    ValueError names them. A dimension whose bounds coincide (a constant) gets width 1, one tile for its only value.

    :param observation_space: a Box observation space with finite bounds.
    :param tiles_per_dimension: tiles per dimension (default None: the generic rule).
    :param cell_budget: the generic rule's cells per tiling (default 16,384).
    """
    if tiles_per_dimension is not None and (
        isinstance(tiles_per_dimension, bool)
        or int(tiles_per_dimension) != tiles_per_dimension
        or tiles_per_dimension < 1
    ):
        raise ValueError(f"tiles_per_dimension must be a positive integer, got {tiles_per_dimension!r}")
    low, high = observation_space.low.astype(np.float64), observation_space.high.astype(np.float64)
    bounded = (
        np.isfinite(low) & np.isfinite(high) & (np.abs(low) < PLACEHOLDER_BOUND) & (np.abs(high) < PLACEHOLDER_BOUND)
    )
    unbounded = np.flatnonzero(~bounded)
    if unbounded.size:
        raise ValueError(
            f"Observation dimensions {unbounded.tolist()} are unbounded (bounds {low[unbounded].tolist()} to "
            f"{high[unbounded].tolist()}; magnitudes of 1e10 or more, such as +-float32 max, count as unbounded) and "
            "no tile widths were given: pass policy_kwargs=dict(tile_widths=[...]) or give the env a `tile_widths` "
            "attribute"
        )
    if tiles_per_dimension is None:
        tiles_per_dimension = default_tiles_per_dimension(varying_dimensions(observation_space), cell_budget)
    widths = (high - low).reshape(-1) / tiles_per_dimension
    return np.where(widths > 0.0, widths, 1.0).tolist()


@functools.lru_cache(maxsize=1)
def package_tilings() -> dict[str, dict[str, Any]]:
    """sb3-er's tilings for known env ids, from the package data file ``sb3_er/data/tilings.yml`` (each entry:
    ``observation_shape``, ``source`` and TileQ settings such as ``n_tilings`` and ``tile_widths``; for a Dict
    observation, ``observation_keys``: ``[key, size]`` pairs in the order ``FlattenObservation`` lays them out)."""
    package, path = PACKAGE_TILINGS
    with importlib.resources.files(package).joinpath(path).open("r", encoding="utf-8") as stream:
        entries = yaml.safe_load(stream)
    for env_id, entry in entries.items():
        missing = {"observation_shape", "source", "tile_widths"} - set(entry)
        if missing or len(entry["tile_widths"]) != int(np.prod(entry["observation_shape"])):
            raise ValueError(
                f"{path}: the entry of {env_id} needs observation_shape, source and one tile width per "
                f"observation dimension, got {entry}"
            )
        keys = entry.get("observation_keys")
        if keys is not None and sum(size for _, size in keys) != int(np.prod(entry["observation_shape"])):
            raise ValueError(
                f"{path}: the observation_keys of {env_id} ({keys}: [key, size] in flattening order) do "
                f"not add up to its observation_shape {entry['observation_shape']}"
            )
    return entries


#: The env attributes a tiling setting can come from (each the TileQPolicy argument of the same name).
ENV_TILING_ATTRIBUTES = ("tile_widths", "wrap_periods", "action_values", "action_tile_widths", "memory_size")


def _to_builtin(value: Any) -> Any:
    """Arrays and tuples (possibly nested) as lists of Python numbers, so settings pickle and print plainly."""
    if isinstance(value, (np.ndarray, list, tuple)):
        return [_to_builtin(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def resolve_tiling(
    policy_kwargs: dict[str, Any],
    env_attribute: Callable[[str], Any],
    observation_space: spaces.Box,
    action_space: spaces.Space,
    policy_class: type,
    dict_space: Callable[[], spaces.Dict | None] = lambda: None,
    verbose: int = 0,
) -> dict[str, Any]:
    """The tile-coding settings of a model, explicit, so that save/load rebuilds the same coder.

    Each setting comes from the first of: ``policy_kwargs``; the env's attribute of that name
    (:data:`ENV_TILING_ATTRIBUTES`); sb3-er's tiling for the env's id (:func:`package_tilings`, or for a task of
    dm_control's suite its domain's or a derived tiling: ``dm_control_tilings.tiling_for_env``; only when neither
    ``policy_kwargs`` (``tile_widths`` or ``tiles_per_dimension``) nor the env give tile widths, and the observation
    has the entry's shape); for tile widths, the generic rule (:func:`default_tile_widths`: ``tiles_per_dimension`` if
    given, else a cell budget per tiling). At ``verbose >= 1`` the tiling in use is printed with where it came from.

    :param policy_kwargs: the model's policy_kwargs (``tiles_per_dimension`` is consumed here).
    :param env_attribute: an optional attribute of the (first) env by name, None when absent.
    :param observation_space: the (flat Box) observation space.
    :param action_space: the action space (a derived dm_control tiling acts with its levels).
    :param policy_class: the policy class (for its default number of tilings, printed).
    :param dict_space: the Dict space the env flattens into its observation, None when out of reach: checked against
        the key order a package tiling assumes.
    :param verbose: print the tiling at 1 or more (default 0).
    """
    kwargs = dict(policy_kwargs)
    tiles_per_dimension = kwargs.pop("tiles_per_dimension", None)
    origins = {name: "policy_kwargs" for name, value in kwargs.items() if value is not None}
    for name in ENV_TILING_ATTRIBUTES:
        if (
            kwargs.get(name) is None
            and not (name == "tile_widths" and tiles_per_dimension is not None)
            and not (name == "action_values" and kwargs.get("action_bins") is not None)
        ):
            kwargs[name] = env_attribute(name)
            if kwargs[name] is not None:
                origins[name] = f"the env's {name} attribute"
    notes = []
    if kwargs.get("tile_widths") is None and tiles_per_dimension is None:
        from sb3_er.common.dm_control_tilings import tiling_for_env  # it reads this module's package tilings

        spec = env_attribute("spec")
        env_id = getattr(spec, "id", None)
        entry = tiling_for_env(spec, action_space, kwargs)  # by id; dm_control's suite: by domain or derived
        shape = tuple(observation_space.shape)
        if entry is not None and tuple(entry["observation_shape"]) != shape:
            notes.append(
                f"sb3-er's tiling for {env_id} is for observations of shape "
                f"{tuple(entry['observation_shape'])}, not {shape}: not used"
            )
        elif entry is not None:
            notes.extend(_check_observation_keys(env_id, entry, dict_space()))
            for name, value in entry.items():
                if name not in ("observation_shape", "observation_keys", "source") and kwargs.get(name) is None:
                    kwargs[name] = value
                    origins[name] = f"sb3-er's tiling for {env_id} ({entry['source']})"
    if kwargs.get("tile_widths") is None:
        if tiles_per_dimension is None:
            tiles_per_dimension = default_tiles_per_dimension(varying_dimensions(observation_space))
            origins["tile_widths"] = (
                f"the generic rule: {tiles_per_dimension} tiles per bounded dimension, "
                f"min(10, floor({DEFAULT_CELL_BUDGET} cells ^ (1/D))), at least 2"
            )
        else:
            origins["tile_widths"] = f"policy_kwargs: {tiles_per_dimension} tiles per bounded dimension"
        kwargs["tile_widths"] = default_tile_widths(observation_space, tiles_per_dimension)
    resolved = {k: _to_builtin(v) for k, v in kwargs.items() if v is not None}
    if verbose >= 1:
        print(_describe_tiling(resolved, origins, notes, policy_class))
    return resolved


def _check_observation_keys(env_id: str, entry: dict[str, Any], space: spaces.Dict | None) -> list[str]:
    """Compare the key order and sizes sb3-er's tiling for ``env_id`` assumes (``observation_keys``) with the Dict
    the env's ``FlattenObservation`` flattens: a ValueError when they differ (its tile widths would fall on the
    wrong arrays). Returns a note when the env's Dict cannot be seen."""
    from sb3_er.common.dict_observations import observation_keys

    expected = entry.get("observation_keys")
    if expected is None:
        return []
    if space is None:
        return [
            f"the key order of {env_id}'s Dict observation is not checked against sb3-er's tiling "
            f"{expected}: the env's FlattenObservation is out of reach"
        ]
    actual = observation_keys(space)
    if actual != [list(pair) for pair in expected]:
        raise ValueError(
            f"sb3-er's tiling for {env_id} assumes the Dict observation {expected} ([key, size] in flattening "
            f"order), but the env flattens {actual}: its tile widths would fall on the wrong arrays. Give "
            "policy_kwargs=dict(tile_widths=[...]) for this env"
        )
    return []


def _describe_tiling(resolved: dict[str, Any], origins: dict[str, str], notes: list[str], policy_class: type) -> str:
    """The tiling in use and where each setting came from, e.g. ``Tile coding: 8 tilings, tile widths [0.225,
    0.0175] from sb3-er's tiling for MountainCar-v0 (...)``."""
    n_tilings = resolved.get("n_tilings")
    if n_tilings is None:
        n_tilings = inspect.signature(policy_class).parameters["n_tilings"].default
        origins["n_tilings"] = f"{policy_class.__name__}'s default"
    widths = [float(f"{w:.4g}") for w in resolved["tile_widths"]]
    if origins["n_tilings"] == origins["tile_widths"]:
        line = f"Tile coding: {n_tilings} tilings, tile widths {widths} from {origins['tile_widths']}"
    else:
        line = (
            f"Tile coding: {n_tilings} tilings from {origins['n_tilings']}; tile widths {widths} from "
            f"{origins['tile_widths']}"
        )
    others = [
        f"{name}={resolved[name]} from {origins[name]}"
        for name in resolved
        if name not in ("n_tilings", "tile_widths") and name in origins
    ]
    return "\n  ".join([line, *others, *[f"({note})" for note in notes]])

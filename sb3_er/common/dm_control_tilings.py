"""Tilings for every task of dm_control's suite by id: a domain's shipped tiling for its other tasks, else one derived
from the observation ranges of a short random rollout.

The suite declares every observation unbounded, so the generic rule (``default_tile_widths``, which splits bounds)
cannot tile it. A model built on a ``dm_control/`` id without tile widths (``policy_kwargs`` or an env attribute) looks
its tiling up here (:func:`tiling_for_env`, called where the model resolves its tile coding), in this order:

1. the id's own entry of ``sb3_er/data/tilings.yml`` (screened by learning: cart-pole, pendulum and acrobot swing-up);
2. the entry of another task of the same domain whose observation has the same layout (the same Dict keys and sizes
   in flattening order, ``observation_keys``): ``cartpole-balance`` observes what ``cartpole-swingup`` does, so it gets
   its tiling; ``cartpole-two_poles``, with more poles, does not;
3. a derived tiling, with a :class:`DerivedTilingWarning` that states it and how to pin it. A separate env of the same
   id and keyword arguments runs :data:`ROLLOUT_EPISODES` episodes of at most :data:`ROLLOUT_EPISODE_STEPS` steps
   (lqr's episodes never end), seeded (:data:`ROLLOUT_SEED`), each step a uniformly random level of each action
   dimension among the model's own levels (what an untrained epsilon-greedy learner does). Each flattened dimension
   gets k tiles over the range it covered, k the generic rule's ``default_tiles_per_dimension(D)`` for the D
   dimensions that moved (the count of tiles the package gives a bounded dimension, so a derived tiling has about
   the generic rule's 16,384 cells per tiling); a dimension that never moved gets width 1, one tile for its value.
   Widths keep 4 significant digits, so the printed widths pinned by the user rebuild the same coder.

Random actions cover less than a learned policy reaches (a swing-up learner spins faster than random torques do):
observations beyond the measured range still fall into tiles (tiling is unbounded; only resolution is set here), but
a derived tiling is a starting point, not a screened one. It is computed once per process for an id, its keyword
arguments and the action levels.

The model asks for the action levels before deriving, so a task it cannot act on by default keeps the policy's clear
error and runs no rollout: more than 3 action dimensions (the default 7 levels stop at 7^3 joint actions: give
``action_bins`` or ``action_values``) and unlimited actuators (lqr's motors, bounded only by MuJoCo's 1e10: give
``action_values``).
"""

from __future__ import annotations

import copy
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_er.common.action_levels import box_action_levels
from sb3_er.common.dict_observations import observation_keys, suite_task
from sb3_er.common.tile_coding import default_tiles_per_dimension, package_tilings

#: Episodes of the rollout a derived tiling measures.
ROLLOUT_EPISODES = 3
#: The most steps of one rollout episode (the suite's episodes last 1,000 steps; lqr's never end).
ROLLOUT_EPISODE_STEPS = 1_000
#: The seed of the rollout's resets (episode i resets with ROLLOUT_SEED + i) and of its actions.
ROLLOUT_SEED = 0
#: Significant digits a derived width keeps.
WIDTH_DIGITS = 4

_DERIVED: dict[tuple[Any, ...], dict[str, Any]] = {}


class DerivedTilingWarning(UserWarning):
    """A model tiles a dm_control task with widths derived from a random rollout (no shipped tiling covers it)."""


def tiling_for_env(spec: Any, action_space: spaces.Space, policy_kwargs: dict[str, Any]) -> dict[str, Any] | None:
    """sb3-er's tiling for the env of ``spec``: an entry of ``sb3_er/data/tilings.yml`` by id, or for a task of
    dm_control's suite without one, its domain's entry for the same observation layout or a derived entry (module
    docstring). None when nothing covers the env (the generic rule applies). An entry holds ``observation_shape``,
    ``source``, ``tile_widths``, ``observation_keys`` for a Dict observation, and other TileQ settings.

    Raises the policy's ValueError for a suite task whose actions cannot be discretised by ``policy_kwargs``
    (``action_bins``, ``action_values``) before any rollout.

    :param spec: the env's ``EnvSpec`` (or None).
    :param action_space: the model's action space.
    :param policy_kwargs: the model's policy keyword arguments (``action_bins`` and ``action_values`` are read).
    """
    env_id = getattr(spec, "id", None)
    if not isinstance(env_id, str):
        return None
    entry = package_tilings().get(env_id)
    task = None if entry is not None else suite_task(env_id)
    if task is None:
        return entry
    if isinstance(action_space, spaces.Box):
        levels = box_action_levels(action_space, policy_kwargs.get("action_bins"), policy_kwargs.get("action_values"))
    else:
        levels = None
    env_kwargs = {key: value for key, value in (spec.kwargs or {}).items() if key != "render_mode"}
    key = (env_id, repr(sorted(env_kwargs.items())), None if levels is None else tuple(map(tuple, levels)))
    if key not in _DERIVED:
        _DERIVED[key] = _domain_tiling(env_id, task[0], env_kwargs) or _derived_tiling(
            env_id, env_kwargs, action_space, levels
        )
    entry = _DERIVED[key]
    if entry.get("derived"):
        warnings.warn(_derived_message(env_id, entry), DerivedTilingWarning, stacklevel=2)
    return copy.deepcopy({name: value for name, value in entry.items() if name != "derived"})  # the cache stays


def _make(env_id: str, env_kwargs: dict[str, Any]) -> gym.Env:
    return gym.wrappers.FlattenObservation(gym.make(env_id, **env_kwargs))


def _domain_tiling(env_id: str, domain: str, env_kwargs: dict[str, Any]) -> dict[str, Any] | None:
    """The shipped entry of another task of ``domain`` whose ``observation_keys`` are the task's, or None."""
    prefix = f"dm_control/{domain}-"
    candidates = {other: entry for other, entry in package_tilings().items() if other.startswith(prefix)}
    if not candidates:
        return None
    env = gym.make(env_id, **env_kwargs)
    layout = observation_keys(env.observation_space) if isinstance(env.observation_space, spaces.Dict) else None
    env.close()
    for other, entry in sorted(candidates.items()):
        if layout is not None and [list(pair) for pair in entry.get("observation_keys", [])] == layout:
            return {
                **entry,
                "source": f"{other}'s tiling, the same domain and observation layout: {entry['source']}",
            }
    return None


def _derived_tiling(
    env_id: str, env_kwargs: dict[str, Any], action_space: spaces.Space, levels: list[np.ndarray] | None
) -> dict[str, Any]:
    """Widths from the observation ranges of a seeded random rollout (module docstring)."""
    env = _make(env_id, env_kwargs)
    layout = observation_keys(env.env.observation_space) if isinstance(env.env.observation_space, spaces.Dict) else None
    rng = np.random.default_rng(ROLLOUT_SEED)
    sampler = copy.deepcopy(action_space)  # the model's own space keeps its random state
    sampler.seed(ROLLOUT_SEED)
    rows = []
    for episode in range(ROLLOUT_EPISODES):
        observation, _ = env.reset(seed=ROLLOUT_SEED + episode)
        rows.append(observation)
        for _ in range(ROLLOUT_EPISODE_STEPS):
            if levels is None:
                action = sampler.sample()
            else:
                action = np.array([rng.choice(values) for values in levels], dtype=action_space.dtype)
                action = action.reshape(action_space.shape)
            observation, _, terminated, truncated, _ = env.step(action)
            rows.append(observation)
            if terminated or truncated:
                break
    env.close()
    observations = np.asarray(rows, dtype=np.float64)
    low, high = observations.min(axis=0), observations.max(axis=0)
    moved = high > low
    tiles = default_tiles_per_dimension(int(np.count_nonzero(moved)))
    widths = np.where(moved, (high - low) / tiles, 1.0)
    entry = {
        "observation_shape": list(observations.shape[1:]),
        "tile_widths": [float(f"{width:.{WIDTH_DIGITS}g}") for width in widths],
        "source": (
            f"derived from a random rollout: {tiles} tiles over each range observed in {len(observations)} "
            f"observations of {ROLLOUT_EPISODES} seeded episodes"
        ),
        "derived": {"low": low.tolist(), "high": high.tolist(), "tiles": tiles, "steps": len(observations)},
    }
    if layout is not None:
        entry["observation_keys"] = layout
    return entry


def _derived_message(env_id: str, entry: dict[str, Any]) -> str:
    derived = entry["derived"]
    ranges = ", ".join(f"[{lo:.3g}, {hi:.3g}]" for lo, hi in zip(derived["low"], derived["high"], strict=True))
    still = [d for d, (lo, hi) in enumerate(zip(derived["low"], derived["high"], strict=True)) if hi <= lo]
    return (
        f"sb3-er has no tiling for {env_id}: its tile widths {entry['tile_widths']} are derived from "
        f"{derived['steps']} observations of random actions ({ROLLOUT_EPISODES} episodes, seed {ROLLOUT_SEED}), "
        f"{derived['tiles']} tiles over each observed range {ranges} (flattened dimensions in the order of "
        f"{entry.get('observation_keys')})"
        + (f"; dimensions {still} never moved and get width 1" if still else "")
        + ". A learned policy may reach beyond these ranges. Pin this tiling, or your own, with "
        f"policy_kwargs=dict(tile_widths={entry['tile_widths']})"
    )

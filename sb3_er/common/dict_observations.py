"""dm_control's suite through Gymnasium (Farama's shimmy bindings), and Dict observations made flat for tile coding.

shimmy exposes every task of the dm_control suite as ``dm_control/<domain>-<task>-v0``. Its ids exist once shimmy is
imported (importing it imports dm_control and MuJoCo, a few seconds), so sb3-er imports it only when such an id is
used: a model built from the id (``SarsaLambda("TileQ", "dm_control/cartpole-swingup-v0")``), ``sb3-er train --env
dm_control/...``, or :func:`register_dm_control_envs` called by the user before ``gymnasium.make``. ``import sb3_er``
imports neither shimmy nor dm_control.

The suite observes a Dict of named arrays (cart-pole: ``position`` (3) and ``velocity`` (2)). A model given a single
env with a Dict observation flattens it with Gymnasium's ``FlattenObservation`` (the arrays one after another, in the
Dict space's key order); a VecEnv of Dict observations is refused with the wrapper to use. sb3-er's tilings for the
suite (``sb3_er/data/tilings.yml``) record the key order and sizes their tile widths assume (``observation_keys``), and
a model checks them against the env. Pixel observations (an image in the Dict, e.g. ``pixels`` of shape (84, 84, 3))
are refused: tile coding needs the low-dimensional state.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

#: The namespace of shimmy's dm_control ids.
DM_CONTROL_NAMESPACE = "dm_control"


def is_dm_control_id(env_id: Any) -> bool:
    """Whether ``env_id`` is a Gymnasium id in shimmy's ``dm_control`` namespace (a ``module:`` prefix allowed).

    :param env_id: anything given where an env or env id is expected.
    """
    if not isinstance(env_id, str):
        return False
    name = env_id.rpartition(":")[2]
    return name.startswith(DM_CONTROL_NAMESPACE + "/")


def register_dm_control_envs() -> None:
    """Register shimmy's ``dm_control/<domain>-<task>-v0`` ids with Gymnasium (by importing shimmy), once, with
    entry points that pickle (:class:`RegisteredEntryPoint`), so that a ``SubprocVecEnv`` worker can send an env's
    ``spec`` back; and for subprocesses: a forkserver that starts afterwards imports
    :mod:`sb3_er.common.register_dm_control` before it starts ``SubprocVecEnv`` workers (see
    :mod:`sb3_er.common.env_ids`).

    Raises ModuleNotFoundError naming the ``dmc`` extra when shimmy or dm_control is missing.
    """
    if "dm_control/cartpole-swingup-v0" not in gym.registry:
        _import_shimmy()
    _make_entry_points_picklable()
    from sb3_er_envs import preload_in_subprocesses

    preload_in_subprocesses("sb3_er.common.register_dm_control")


def _import_shimmy() -> None:
    try:
        if "dm_control" not in sys.modules:
            # dm_control picks its OpenGL backend once, at import: choose it as LEO does (sb3_er_envs.leo._gl), so that
            # a suite env imported first does not leave a backend (GLFW without a display) that aborts LEO's rendering.
            from sb3_er_envs.leo import _gl

            user_choice = os.environ.get("MUJOCO_GL")
            _gl.prepare_backend()
            import dm_control._render  # noqa: F401  (the backend is chosen here)

            if user_choice is None:
                os.environ.pop("MUJOCO_GL", None)
        import dm_control  # noqa: F401  (shimmy registers its suite only when dm_control imports)
        import shimmy  # noqa: F401  (importing shimmy registers the ids)
    except ModuleNotFoundError as error:
        raise ModuleNotFoundError(
            f"The dm_control/<domain>-<task>-v0 ids need shimmy and dm-control ({error.name} is missing), which the "
            "dmc extra installs: pip install 'sb3-er[dmc]'",
            name=error.name,
        ) from error
    if "dm_control/cartpole-swingup-v0" not in gym.registry:
        raise RuntimeError(
            "shimmy was imported but registered no dm_control/ ids: its dm_control bindings failed "
            "to load (import shimmy.dm_control_compatibility to see why)"
        )


#: shimmy's own entry point of each ``dm_control/`` id, in this process (filled by register_dm_control_envs).
_SHIMMY_ENTRY_POINTS: dict[str, Any] = {}


class RegisteredEntryPoint:
    """The entry point of a ``dm_control/`` id: shimmy's, called by the id.

    shimmy registers its ids with functions defined inside its registering function, which cannot be pickled: a
    ``SubprocVecEnv`` worker asked for such an env's ``spec`` (as a model asks, to look up the env's tiling) dies
    sending it, and the VecEnv raises a bare ``EOFError``. This stand-in pickles as the id alone and, called in a
    process that has not registered the ids yet, registers them first.

    :param env_id: the ``dm_control/`` id.
    """

    def __init__(self, env_id: str):
        self.env_id = env_id

    def __call__(self, **kwargs: Any) -> gym.Env:
        if self.env_id not in _SHIMMY_ENTRY_POINTS:
            register_dm_control_envs()
        return _SHIMMY_ENTRY_POINTS[self.env_id](**kwargs)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RegisteredEntryPoint) and other.env_id == self.env_id

    def __hash__(self) -> int:
        return hash((RegisteredEntryPoint, self.env_id))

    def __repr__(self) -> str:
        return f"RegisteredEntryPoint({self.env_id!r})"


def _make_entry_points_picklable() -> None:
    """Replace every ``dm_control/`` id's entry point that is not a string by a :class:`RegisteredEntryPoint`."""
    for env_id, spec in list(gym.registry.items()):
        if not env_id.startswith(DM_CONTROL_NAMESPACE + "/") or isinstance(
            spec.entry_point, (str, RegisteredEntryPoint)
        ):
            continue
        _SHIMMY_ENTRY_POINTS[env_id] = spec.entry_point
        gym.registry[env_id] = dataclasses.replace(spec, entry_point=RegisteredEntryPoint(env_id))


def observation_keys(space: spaces.Dict) -> list[list[Any]]:
    """``[[key, size], ...]`` of a Dict space in the order ``FlattenObservation`` lays its arrays out.

    :param space: a Dict observation space.
    """
    return [[key, int(spaces.flatdim(subspace))] for key, subspace in space.spaces.items()]


#: A two-dimensional Dict entry of floats is an image when both its sides are at least this long.
IMAGE_SIDE = 16


def is_image(space: spaces.Box) -> bool:
    """Whether a Box holds an image rather than state: three or more dimensions (height, width, channels), or two
    dimensions of an integer dtype (a grayscale image) or with both sides of at least :data:`IMAGE_SIDE` pixels. A
    small two-dimensional array of floats is state (manipulator's ``arm_pos``: the cos and sin of 8 joints, (8, 2)).

    :param space: a Box space.
    """
    shape = space.shape
    if len(shape) >= 3:
        return True
    return len(shape) == 2 and (np.issubdtype(space.dtype, np.integer) or min(shape) >= IMAGE_SIDE)


def check_flat_dict(space: spaces.Dict) -> None:
    """Refuse a Dict observation whose flattening tile coding cannot use: pixels (an image, :func:`is_image`), nested
    Dicts and non-Box entries; a ValueError naming the key. Arrays of state are flattened in C order.

    :param space: a Dict observation space.
    """
    for key, subspace in space.spaces.items():
        if not isinstance(subspace, spaces.Box):
            raise ValueError(
                f"The observation's key {key!r} is a {type(subspace).__name__} space ({subspace}): "
                "sb3-er flattens Dict observations of Box arrays only"
            )
        if is_image(subspace):
            raise ValueError(
                f"The observation's key {key!r} holds pixels (an image) of shape {subspace.shape} ({subspace.dtype}): "
                "tile coding needs low-dimensional state observations, and flattening it would make one tiled "
                "dimension per pixel. Use the task's state observations (dm_control's suite without a pixels "
                "wrapper, shimmy's default) or extract low-dimensional features first"
            )


#: Where the suite's rewards lie: every task's reward is in the unit interval, on terminating transitions too
#: (Tassa et al. 2018, "DeepMind Control Suite", arXiv:1801.00690), so its returns lie in [0, 1 / (1 - gamma)]. Each
#: domain's ``get_reward`` (dm_control/suite/<domain>.py) keeps to it: products and averages of ``rewards.tolerance``
#: terms (each in [0, 1]) or 0/1 indicators. The exceptions are in :data:`DM_CONTROL_DOMAIN_REWARD_BOUNDS`.
DM_CONTROL_REWARD_BOUNDS = {"step": (0.0, 1.0), "terminal": (0.0, 1.0)}

#: The suite's domains whose rewards leave the unit interval. lqr's reward is 1 - (|q|^2 / 2 + 0.1 |u|^2 / 2)
#: (dm_control/suite/lqr.py: a quadratic state and control cost subtracted from 1), at most 1 (at rest, no force) and
#: unbounded below: its undamped springs and unlimited actuators bound neither the positions nor the forces.
DM_CONTROL_DOMAIN_REWARD_BOUNDS = {"lqr": {"step": (-math.inf, 1.0), "terminal": (-math.inf, 1.0)}}


def suite_task(env_id: Any) -> tuple[str, str] | None:
    """``(domain, task)`` of a ``dm_control/<domain>-<task>-v0`` id of dm_control's suite (``suite.ALL_TASKS``), or
    None for any other id (shimmy's locomotion and manipulation ids included). Imports dm_control's suite: call it
    only for a ``dm_control/`` id.

    :param env_id: an env id (a ``module:`` prefix allowed).
    """
    if not is_dm_control_id(env_id):
        return None
    name = env_id.rpartition(":")[2][len(DM_CONTROL_NAMESPACE) + 1 :]
    name, _, version = name.rpartition("-v")
    domain, _, task = name.partition("-")
    from dm_control import suite

    return (domain, task) if version.isdigit() and (domain, task) in suite.ALL_TASKS else None


def dm_control_reward_bounds(env_id: Any) -> dict[str, tuple[float, float]] | None:
    """The reward bounds of a suite task's id (:data:`DM_CONTROL_REWARD_BOUNDS`, or its domain's entry of
    :data:`DM_CONTROL_DOMAIN_REWARD_BOUNDS`); None for an id outside dm_control's suite, whose rewards nothing
    declares.

    :param env_id: an env id.
    """
    task = suite_task(env_id)
    if task is None:
        return None
    return DM_CONTROL_DOMAIN_REWARD_BOUNDS.get(task[0], DM_CONTROL_REWARD_BOUNDS)


class FlattenSuiteObservation(gym.wrappers.FlattenObservation):
    """Gymnasium's ``FlattenObservation`` of a dm_control suite task, declaring the task's ``reward_bounds`` to the
    value watch (:func:`dm_control_reward_bounds`), which would otherwise bound the values by the rewards observed
    so far: near zero for the many steps before a swing-up task first pays, so that possible values would be
    reported as impossible. An env outside the suite (or without a spec) declares nothing (``reward_bounds`` None).

    rl-zoo's ``env_wrapper: sb3_er.common.dict_observations.FlattenSuiteObservation`` uses it for each env of a VecEnv.

    :param env: a dm_control suite task with a Dict observation of Box arrays (shimmy's ``dm_control/`` ids).
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.reward_bounds = dm_control_reward_bounds(getattr(env.spec, "id", None))

    @property
    def dict_observation_space(self) -> spaces.Dict:
        """The Dict space it flattens (read by the model's key-order check, across processes too)."""
        return self.env.observation_space


def flatten_dict_observation(env: gym.Env) -> gym.Env:
    """``env`` with its Dict observation flattened by Gymnasium's ``FlattenObservation`` (for a ``dm_control/`` id,
    :class:`FlattenSuiteObservation`, which declares the suite's reward bounds); other envs unchanged.

    Raises ValueError for pixel observations (:func:`check_flat_dict`).

    :param env: a Gymnasium env.
    """
    if not isinstance(env.observation_space, spaces.Dict):
        return env
    check_flat_dict(env.observation_space)
    if is_dm_control_id(getattr(env.spec, "id", None)):
        return FlattenSuiteObservation(env)
    return gym.wrappers.FlattenObservation(env)


def flattened_dict_space(env: gym.Env) -> spaces.Dict | None:
    """The Dict space the outermost ``FlattenObservation`` among ``env``'s wrappers flattens, or None.

    :param env: a Gymnasium env (wrapped or not).
    """
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.FlattenObservation) and isinstance(env.env.observation_space, spaces.Dict):
            return env.env.observation_space
        env = env.env
    return None


def dict_vec_env_message(space: spaces.Dict) -> str:
    """The refusal of a VecEnv of Dict observations, naming the wrapper to use.

    :param space: the VecEnv's Dict observation space.
    """
    check_flat_dict(space)  # pixels get their own message
    return (
        f"Tile coding needs a flat Box observation, and this VecEnv observes a Dict {observation_keys(space)} "
        "([key, size] pairs). A single env is flattened for you; for a VecEnv, flatten each env with "
        "gymnasium.wrappers.FlattenObservation (make_vec_env(..., wrapper_class=FlattenObservation), rl-zoo's "
        "`env_wrapper: gymnasium.wrappers.FlattenObservation`); for a task of dm_control's suite, with "
        "sb3_er.common.dict_observations.FlattenSuiteObservation, which also declares the task's reward bounds"
    )


def vec_observation_keys(vec_env) -> list[list[Any]] | None:
    """``[[key, size], ...]`` of the Dict observation the (first) env of a VecEnv flattens (:func:`observation_keys`),
    or None when it flattens none or it cannot be seen: a DummyVecEnv's env is read directly, envs in subprocesses
    through their ``dict_observation_space`` attribute (:class:`FlattenSuiteObservation` has one).

    :param vec_env: a VecEnv, possibly wrapped.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper

    level = vec_env
    while isinstance(level, VecEnvWrapper):
        level = level.venv
    if isinstance(level, DummyVecEnv):
        space = flattened_dict_space(level.envs[0])
    elif level.has_attr("dict_observation_space"):
        space = level.get_attr("dict_observation_space", indices=0)[0]
    else:
        space = None
    return None if space is None else observation_keys(space)

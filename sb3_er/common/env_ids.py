"""Gymnasium ids that register themselves when a model or the zoo is given one, in this process and in the
``SubprocVecEnv`` workers it starts afterwards.

SB3 makes an env id with ``gymnasium.make`` inside ``BaseAlgorithm``, so an id's namespace must be registered before
that: ``sb3_er/...`` (this package's environments, :mod:`sb3_er_envs`, whose registering imports no environment
module) and ``dm_control/...`` (shimmy's suite, the ``dmc`` extra, registered only when such an id is used). So
``ERSigma("TileQ", "sb3_er/SimplestWalker-v0")`` works without ``import sb3_er_envs`` first, as it does after it.

A ``SubprocVecEnv`` makes its envs in worker processes, each with a registry of its own: ``make_vec_env(env_id,
vec_env_cls=SubprocVecEnv)`` calls ``gymnasium.make(env_id)`` there. Its default start method on Linux and macOS is
``forkserver``, whose workers import the modules listed by ``multiprocessing.set_forkserver_preload`` (the main
script by default) before they run. Registering a namespace here adds the module that registers it there
(``sb3_er_envs``, :mod:`sb3_er.common.register_dm_control`), so workers started by a forkserver that starts
afterwards know the ids (``sb3-er train --vec-env subproc`` relies on it). Under the ``spawn`` start method, or a
forkserver already running, register where the workers import it too: at the top level of the main script
(``import sb3_er_envs``, ``register_dm_control_envs()``), or with Gymnasium's ``module:id`` form
(``make_vec_env("sb3_er_envs:sb3_er/Leo-v0", ...)``).

:func:`check_env_kwargs` checks the keyword arguments a command line gives an env id before any run starts.
"""

import inspect
import types
import typing
from typing import Any

from sb3_er.common.dict_observations import is_dm_control_id, register_dm_control_envs

#: The namespace of this package's environment ids.
SB3_ER_NAMESPACE = "sb3_er"


def register_env_id(env_id: Any) -> None:
    """Register the namespace of ``env_id`` (``sb3_er/`` or ``dm_control/``, a ``module:`` prefix allowed) with
    Gymnasium if it is not yet, here and for the forkserver's later subprocesses (module docstring); anything else
    (an env, None, another id) is left to Gymnasium.

    :param env_id: an env id, an env or None.
    """
    if not isinstance(env_id, str):
        return
    if env_id.rpartition(":")[2].startswith(SB3_ER_NAMESPACE + "/"):
        import sb3_er_envs  # noqa: F401  (registers the ids; their entry points are strings)
    elif is_dm_control_id(env_id):
        register_dm_control_envs()


#: Keyword arguments ``gymnasium.make`` takes itself rather than passing them to the env's constructor.
MAKE_KEYWORDS = ("max_episode_steps", "disable_env_checker", "autoreset", "apply_api_compatibility", "render_mode")


def _type_problem(value: Any, annotation: Any) -> str | None:
    """What is wrong with ``value`` for a parameter annotated ``annotation``, or None when it fits or the annotation is
    not one of the plain types this check reads (bool, int, float, str, None, Literal and unions of them)."""
    import numpy as np  # here, so that the command line's parser stays light

    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(annotation)
        problems = [_type_problem(value, option) for option in options]
        if any(problem is None for problem in problems):
            return None
        return " or ".join(problems)
    if origin is typing.Literal:
        choices = typing.get_args(annotation)
        return None if value in choices else f"one of {', '.join(repr(c) for c in choices)}"
    if annotation is type(None):
        return None if value is None else "None"
    if annotation is bool:
        return None if isinstance(value, (bool, np.bool_)) else "a bool (true or false)"
    if annotation is int:
        ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
        return None if ok else "an integer"
    if annotation is float:
        ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
        return None if ok else "a number"
    if annotation is str:
        return None if isinstance(value, str) else "a string"
    return None


def check_env_kwargs(env_id: str, env_kwargs: dict[str, Any], given_as: str = "--env-kwargs") -> None:
    """ValueError naming the problem, before any run starts, when ``gymnasium.make(env_id, **env_kwargs)`` would not
    make the env: a name its constructor does not take (the names it takes are listed), a value whose type its
    annotation refuses (``step_reward:abc`` for a float), or anything the constructor itself refuses (the env is made
    once, then closed).

    :param env_id: a registered Gymnasium id (``sb3_er/`` and ``dm_control/`` ids register themselves).
    :param env_kwargs: the keyword arguments to check.
    :param given_as: how the user gave them, for the message (default "--env-kwargs").
    """
    import gymnasium as gym

    if not env_kwargs:
        return
    register_env_id(env_id)
    shown = ", ".join(f"{name}={value!r}" for name, value in env_kwargs.items())
    try:
        spec = gym.spec(env_id)
        creator = spec.entry_point
        if isinstance(creator, str):
            creator = gym.envs.registration.load_env_creator(creator)
    except Exception as error:  # an unknown id or an entry point that does not import
        raise ValueError(f"{given_as}: the env {env_id} cannot be found ({error})") from None
    target = creator.__init__ if inspect.isclass(creator) else creator
    try:
        signature = inspect.signature(target)
        hints = typing.get_type_hints(target)
    except (TypeError, ValueError, NameError):
        signature, hints = None, {}
    if signature is not None:
        parameters = {
            name: parameter
            for name, parameter in signature.parameters.items()
            if name != "self" and parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY)
        }
        open_ended = any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values())
        unknown = [name for name in env_kwargs if name not in parameters and name not in MAKE_KEYWORDS]
        if unknown and not open_ended:
            raise ValueError(
                f"{given_as}: {env_id} takes no argument {', '.join(unknown)}; its arguments are "
                f"{', '.join(parameters)}"
            )
        for name, value in env_kwargs.items():
            problem = _type_problem(value, hints[name]) if name in hints else None
            if problem is not None:
                raise ValueError(
                    f"{given_as}: {env_id}'s {name} must be {problem}, got {value!r} ({type(value).__name__})"
                )
    try:
        env = gym.make(env_id, **env_kwargs)
    except Exception as error:
        raise ValueError(f"{given_as}: {env_id} refuses {shown}: {type(error).__name__}: {error}") from None
    env.close()

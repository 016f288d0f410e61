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
"""

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

"""sb3-er environments. Importing this package registers their Gymnasium ids.

The entry points are strings, so registering imports no environment module (and neither dm_control nor MuJoCo):

* ``sb3_er/WindyCliff-v0``: windy cliff grid world (thesis 5.1), :class:`sb3_er_envs.windy_cliff.WindyCliffEnv`
* ``sb3_er/PendulumSwingup-v0``: pendulum swing-up (thesis 4.2.1), :class:`sb3_er_envs.pendulum.PendulumSwingupEnv`
* ``sb3_er/SimplestWalker-v0``: simplest walker (thesis 4.2.2), :class:`sb3_er_envs.simplest_walker.SimplestWalkerEnv`
* ``sb3_er/CompassWalker-v0``: the same walker in GRL's walk task (a peer's setup, for cross-checks),
  :class:`sb3_er_envs.compass_walker.CompassWalkerEnv`
* ``sb3_er/Leo-v0``: the LEO biped in MuJoCo (thesis 4.2.3, needs the ``dmc`` extra), :class:`sb3_er_envs.leo.LeoEnv`

Every environment ends its own episodes at its time limit and reports it as ``truncated``, so none is registered with
``max_episode_steps``; change a limit through the environment's keyword arguments in ``gymnasium.make``.

Importing the package also names it among the modules a forkserver imports before it starts a subprocess
(:func:`preload_in_subprocesses`), so that the workers of a ``SubprocVecEnv`` started afterwards (its default start
method on Linux and macOS) know the ids too.
"""

import multiprocessing

from gymnasium.envs.registration import register, registry


def preload_in_subprocesses(module: str) -> None:
    """Add ``module`` to the modules the forkserver imports before it starts subprocesses
    (``multiprocessing.set_forkserver_preload``; the main script, ``__main__``, stays first), so that a module whose
    import registers Gymnasium ids registers them in ``SubprocVecEnv`` workers too. Takes effect for a forkserver
    that starts afterwards; nothing where there is no forkserver.

    :param module: an importable module name.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return
    from multiprocessing import forkserver

    preloaded = list(getattr(forkserver._forkserver, "_preload_modules", None) or ["__main__"])
    if module not in preloaded:
        multiprocessing.set_forkserver_preload([*preloaded, module])


def discrete_action_index(action, n_actions: int) -> int:
    """``action`` as a Python int in ``[0, n_actions)``; a ValueError naming the action for anything else.

    :param action: the action as given (a Python or NumPy integer, or a one-element array).
    :param n_actions: the number of actions.
    """
    try:
        index = int(action)
    except (TypeError, ValueError):
        index = None
    if index is None or index != action or not 0 <= index < n_actions:
        raise ValueError(f"action must be an integer in [0, {n_actions - 1}], got {action!r}")
    return index


ENV_IDS = {
    "sb3_er/WindyCliff-v0": "sb3_er_envs.windy_cliff:WindyCliffEnv",
    "sb3_er/PendulumSwingup-v0": "sb3_er_envs.pendulum:PendulumSwingupEnv",
    "sb3_er/SimplestWalker-v0": "sb3_er_envs.simplest_walker:SimplestWalkerEnv",
    "sb3_er/CompassWalker-v0": "sb3_er_envs.compass_walker:CompassWalkerEnv",
    "sb3_er/Leo-v0": "sb3_er_envs.leo:LeoEnv",
}

for _env_id, _entry_point in ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point=_entry_point)

preload_in_subprocesses(__name__)

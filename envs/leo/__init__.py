"""LEO, the Delft biped of thesis section 4.2.3, in MuJoCo through dm_control (needs the ``dmc`` extra).

* :class:`LeoEnv`: the Gymnasium environment ``sb3_er/Leo-v0``;
* :mod:`sb3_er_envs.leo.leo`: the dm_control domain (``Physics``, the ``LeoWalk`` task, ``walk()``) and ``leo.xml``;
* :class:`ObservingGait`: Erik Schuitema's hand-made gait, a working walking policy to compare with;
* :func:`save_episode_video`: write an episode as a GIF or MP4 to look at a gait;
* :class:`RenderingUnavailable`: what rendering raises on a machine without a working OpenGL backend.

dm_control and MuJoCo are imported on first use of any of these names, so that ``import sb3_er_envs`` works without
them; a missing installation raises an ImportError that names the extra to install.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "LeoEnv": "gym_env",
    "LeoWalk": "leo",
    "Physics": "leo",
    "walk": "leo",
    "ObservingGait": "gait",
    "save_episode_video": "video",
    "RenderingUnavailable": "_gl",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        module = importlib.import_module(f".{_EXPORTS[name]}", __name__)
    except ImportError as error:
        if error.name and error.name.split(".")[0] in ("dm_control", "mujoco", "dm_env"):
            raise ImportError(
                f"LEO needs dm_control and MuJoCo ({error.name} is missing): pip install 'sb3-er[dmc]'"
            ) from error
        raise
    return getattr(module, name)

"""Gymnasium ids that register themselves when a model or the zoo is given one.

SB3 makes an env id with ``gymnasium.make`` inside ``BaseAlgorithm``, so an id's namespace must be registered before
that: ``sb3_er/...`` (this package's environments, :mod:`sb3_er_envs`, whose registering imports no environment
module) and ``dm_control/...`` (shimmy's suite, the ``dmc`` extra, registered only when such an id is used). So
``ERSigma("TileQ", "sb3_er/SimplestWalker-v0")`` works without ``import sb3_er_envs`` first, as it does after it.
"""

from typing import Any

from sb3_er.common.dict_observations import register_if_dm_control_id

#: The namespace of this package's environment ids.
SB3_ER_NAMESPACE = "sb3_er"


def register_env_id(env_id: Any) -> None:
    """Register the namespace of ``env_id`` (``sb3_er/`` or ``dm_control/``, a ``module:`` prefix allowed) with
    Gymnasium if it is not yet; anything else (an env, None, another id) is left to Gymnasium.

    :param env_id: an env id, an env or None.
    """
    if not isinstance(env_id, str):
        return
    if env_id.rpartition(":")[2].startswith(SB3_ER_NAMESPACE + "/"):
        import sb3_er_envs  # noqa: F401  (registers the ids; their entry points are strings)
    register_if_dm_control_id(env_id)

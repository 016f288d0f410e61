"""Importing this module registers shimmy's ``dm_control/`` ids with Gymnasium
(:func:`~sb3_er.common.dict_observations.register_dm_control_envs`).

It exists for subprocesses: :func:`sb3_er.common.env_ids.register_env_id` names it among the modules a forkserver
imports before it starts ``SubprocVecEnv`` workers, so that a worker knows the ids the parent process used.
"""

from sb3_er.common.dict_observations import register_dm_control_envs

register_dm_control_envs()

"""How the learning loop steps the envs of a VecEnv: one of two steppers, chosen once per ``learn()``.

Each stepper's ``step(actions)`` takes the N envs' flat action indices and returns what SB3's ``VecEnv.step`` returns,
in the form the loop reads per env: ``(new_obs, env_obs, rewards, dones, infos)``, where ``new_obs`` is the stacked
(N, ...) array after the resets of finished envs, ``env_obs[i]`` env i's row of it, ``rewards`` a list of N floats,
``dones`` a list of N bools, and ``infos`` the N info dicts with "TimeLimit.truncated" and, where done,
"terminal_observation". Lists, because the loop reads them per env, where numpy scalars and views cost.

* :class:`DirectStepper`: a plain ``DummyVecEnv``'s envs, stepped directly: what its ``step`` does, without its
  per-step deep copy of ``info`` and with the env's float64 reward (DummyVecEnv's buffer would round it to float32).
* :class:`VecEnvStepper`: any other VecEnv (``SubprocVecEnv``, a wrapper such as ``VecMonitor``), through its
  ``step``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv


class VecEnvStepper:
    """Any VecEnv, through its ``step``.

    :param vec_env: the VecEnv.
    :param to_env_actions: the policy's map from flat action indices (an array) to the env's actions.
    :param env_actions: each flat action in the env's format.
    :param copy_action: whether an env action must be copied before a step (an array an env could change in place).
    """

    def __init__(self, vec_env: VecEnv, to_env_actions, env_actions: list[Any], copy_action: bool) -> None:
        self.vec_env, self.to_env_actions = vec_env, to_env_actions
        self.env_actions, self.copy_action = env_actions, copy_action

    def step(self, actions: list[int]) -> tuple[Any, Any, list[float], list[bool], list[dict[str, Any]]]:
        """Step every env with its flat action (see the module's docstring for what it returns).

        :param actions: each env's flat action index.
        """
        new_obs, rewards, dones, infos = self.vec_env.step(self.to_env_actions(np.array(actions)))
        rewards, dones = np.asarray(rewards, dtype=np.float64).tolist(), np.asarray(dones, dtype=bool).tolist()
        return new_obs, new_obs, rewards, dones, list(infos)


class DirectStepper(VecEnvStepper):
    """A plain ``DummyVecEnv``'s envs, stepped directly (one env, the common case, without the loop over envs).

    :param vec_env: the DummyVecEnv.
    :param to_env_actions: the policy's map from flat action indices (an array) to the env's actions.
    :param env_actions: each flat action in the env's format.
    :param copy_action: whether an env action must be copied before a step (an array an env could change in place).
    """

    def __init__(self, vec_env: DummyVecEnv, to_env_actions, env_actions: list[Any], copy_action: bool) -> None:
        super().__init__(vec_env, to_env_actions, env_actions, copy_action)
        self.envs = vec_env.envs
        if len(self.envs) == 1:
            self.step = self._step_one

    def _step_one(self, actions: list[int]) -> tuple[Any, Any, list[float], list[bool], list[dict[str, Any]]]:
        env_action = self.env_actions[actions[0]]
        obs, reward, terminated, truncated, info = self.envs[0].step(
            env_action.copy() if self.copy_action else env_action
        )
        done = bool(terminated or truncated)
        info["TimeLimit.truncated"] = bool(truncated and not terminated)
        if done:
            info["terminal_observation"] = obs
            obs, self.vec_env.reset_infos[0] = self.envs[0].reset()
        return np.asarray(obs)[np.newaxis], (obs,), [float(reward)], [done], [info]

    def step(self, actions: list[int]) -> tuple[Any, Any, list[float], list[bool], list[dict[str, Any]]]:
        """Step every env with its flat action (see the module's docstring for what it returns).

        :param actions: each env's flat action index.
        """
        observations, rewards, dones, infos = [], [], [], []
        env_actions, copy_action, reset_infos = self.env_actions, self.copy_action, self.vec_env.reset_infos
        for i, env in enumerate(self.envs):
            env_action = env_actions[actions[i]].copy() if copy_action else env_actions[actions[i]]
            obs, reward, terminated, truncated, info = env.step(env_action)
            done = bool(terminated or truncated)
            info["TimeLimit.truncated"] = bool(truncated and not terminated)
            if done:
                info["terminal_observation"] = obs
                obs, reset_infos[i] = env.reset()
            observations.append(obs)
            rewards.append(float(reward))
            dones.append(done)
            infos.append(info)
        return np.stack(observations), observations, rewards, dones, infos


def make_stepper(vec_env: VecEnv, to_env_actions, env_actions: list[Any], copy_action: bool) -> VecEnvStepper:
    """The stepper for ``vec_env``: direct for a plain DummyVecEnv, else its ``step`` (a subclass or a wrapper may
    change what a step does, so only the exact class is bypassed).

    :param vec_env: the VecEnv.
    :param to_env_actions: the policy's map from flat action indices (an array) to the env's actions.
    :param env_actions: each flat action in the env's format.
    :param copy_action: whether an env action must be copied before a step.
    """
    if type(vec_env) is DummyVecEnv:
        return DirectStepper(vec_env, to_env_actions, env_actions, copy_action)
    return VecEnvStepper(vec_env, to_env_actions, env_actions, copy_action)

"""Simplest walker throughput: the numba kernel, ``env.step`` on the bare env and through ``gymnasium.make``.

Usage: ``python benchmarks/walker_speed.py [--steps 200000] [--options]``. Rates are per second of the process's CPU
time (robust to other jobs on the machine). Two policies: zero hip acceleration (passive walking, a heel strike about
every 19 control steps, episodes truncated at 500 steps) and uniformly random actions (falls after about 45 steps, so
resets are included). The default options are always measured; ``--options`` adds the bare env under each other
reading (``reward="literal"``, ``fall="angles"``, ``observation="grl"``) and CompassWalkerEnv (GRL's task: 20 RK4
substeps instead of 10, so slower by construction).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er_envs.compass_walker import CompassWalkerEnv
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT, OUTCOME_SIZE, SimplestWalkerEnv, simulate_control_step


def kernel_rate(steps: int) -> float:
    """Control steps per second of :func:`simulate_control_step` alone, walking passively from the fixed point."""
    state, outcome = GARCIA_FIXED_POINT.copy(), np.zeros(OUTCOME_SIZE)
    simulate_control_step(state, 0.0, 0.004, 0.2, 10, outcome)
    start = time.process_time()
    for _ in range(steps):
        simulate_control_step(state, 0.0, 0.004, 0.2, 10, outcome)
    return steps / (time.process_time() - start)


def env_rate(env: gym.Env, actions: np.ndarray) -> tuple[float, int, int]:
    """(env steps per second including resets, footsteps, falls) over the given actions."""
    env.reset(seed=0)
    footsteps = falls = 0
    start = time.process_time()
    for action in actions:
        _, _, terminated, truncated, info = env.step(action)
        footsteps += info["footstep"]
        if terminated or truncated:
            falls += terminated
            env.reset()
    return len(actions) / (time.process_time() - start), footsteps, falls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000, help="control steps per measurement")
    parser.add_argument("--options", action="store_true", help="also measure the reading options and CompassWalkerEnv")
    args = parser.parse_args()
    print(f"kernel simulate_control_step: {kernel_rate(args.steps):>10,.0f} steps/s")
    rng = np.random.default_rng(0)
    policies = {"zero action": np.full(args.steps, 7), "random actions": rng.integers(0, 15, args.steps)}
    for policy, actions in policies.items():
        envs = {"SimplestWalkerEnv": SimplestWalkerEnv(), "gymnasium.make": gym.make("sb3_er/SimplestWalker-v0")}
        if args.options:
            envs["literal reward"] = SimplestWalkerEnv(reward="literal")
            envs["fall angles"] = SimplestWalkerEnv(fall="angles")
            envs["GRL observation"] = SimplestWalkerEnv(observation="grl")
        for label, env in envs.items():
            env_rate(env, actions[:1000])
            rate, footsteps, falls = env_rate(env, actions)
            print(f"{label:>17} env.step, {policy:<14}: {rate:>10,.0f} steps/s ({footsteps} footsteps, {falls} falls)")
    if args.options:
        compass = {"zero action": np.full(args.steps, 1), "random actions": rng.integers(0, 3, args.steps)}
        for policy, actions in compass.items():
            env = CompassWalkerEnv()
            env_rate(env, actions[:1000])
            rate, footsteps, falls = env_rate(env, actions)
            label = "CompassWalkerEnv"
            print(f"{label:>17} env.step, {policy:<14}: {rate:>10,.0f} steps/s ({footsteps} footsteps, {falls} falls)")


if __name__ == "__main__":
    main()

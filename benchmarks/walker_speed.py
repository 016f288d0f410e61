"""Simplest walker throughput: the numba kernel, ``env.step`` on the bare env and through ``gymnasium.make``.

Usage: ``python benchmarks/walker_speed.py [--steps 200000]``. Two policies: zero hip acceleration (passive walking, a
heel strike about every 19 control steps, episodes truncated at 500 steps) and uniformly random actions (falls after
about 45 steps, so resets are included).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT, OUTCOME_SIZE, SimplestWalkerEnv, simulate_control_step


def kernel_rate(steps: int) -> float:
    """Control steps per second of :func:`simulate_control_step` alone, walking passively from the fixed point."""
    state, outcome = GARCIA_FIXED_POINT.copy(), np.zeros(OUTCOME_SIZE)
    simulate_control_step(state, 0.0, 0.004, 0.2, 10, outcome)
    start = time.perf_counter()
    for _ in range(steps):
        simulate_control_step(state, 0.0, 0.004, 0.2, 10, outcome)
    return steps / (time.perf_counter() - start)


def env_rate(env: gym.Env, actions: np.ndarray) -> tuple[float, int, int]:
    """(env steps per second including resets, footsteps, falls) over the given actions."""
    env.reset(seed=0)
    footsteps = falls = 0
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, info = env.step(action)
        footsteps += info["footstep"]
        if terminated or truncated:
            falls += terminated
            env.reset()
    return len(actions) / (time.perf_counter() - start), footsteps, falls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000, help="control steps per measurement")
    args = parser.parse_args()
    print(f"kernel simulate_control_step: {kernel_rate(args.steps):>10,.0f} steps/s")
    rng = np.random.default_rng(0)
    policies = {"zero action": np.full(args.steps, 7), "random actions": rng.integers(0, 15, args.steps)}
    for policy, actions in policies.items():
        envs = {"SimplestWalkerEnv": SimplestWalkerEnv(), "gymnasium.make": gym.make("sb3_er/SimplestWalker-v0")}
        for label, env in envs.items():
            env_rate(env, actions[:1000])
            rate, footsteps, falls = env_rate(env, actions)
            print(f"{label:>17} env.step, {policy:<14}: {rate:>10,.0f} steps/s ({footsteps} footsteps, {falls} falls)")


if __name__ == "__main__":
    main()

"""Control steps per second of ``sb3_er/Leo-v0`` (target: at least 1,000, i.e. a 25 s episode in under a second).

Usage: ``python benchmarks/leo_speed.py [--episodes N] [--seed S]``

Prints, for uniformly random voltage levels (episodes end early at falls) and for Erik's hand-made gait (full 25 s
episodes), the control steps per second through ``gymnasium.make`` and the wall time of one 25 s episode, plus the
share of the time spent inside MuJoCo's physics steps.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import sb3_er_envs  # noqa: F401  (registers sb3_er/Leo-v0)
from sb3_er_envs.leo import ObservingGait
from sb3_er_envs.leo.leo import PHYSICS_SUBSTEPS


def run(env, episodes: int, seed: int, policy_name: str) -> tuple[int, float]:
    """Total control steps and wall time of ``episodes`` episodes under the named policy."""
    rng = np.random.default_rng(seed)
    gait = ObservingGait()
    steps, start = 0, time.perf_counter()
    for episode in range(episodes):
        observation, info = env.reset(seed=seed + episode)
        gait.reset()
        done = False
        while not done:
            if policy_name == "gait":
                action = gait.action(observation, info)
            else:
                action = rng.integers(0, 7, size=3)
            observation, _, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
    return steps, time.perf_counter() - start


def physics_share(env, steps: int = 750) -> float:
    """Wall time of ``steps`` control steps' worth of bare MuJoCo substeps."""
    physics = env.unwrapped.physics
    start = time.perf_counter()
    for _ in range(steps):
        physics.step(PHYSICS_SUBSTEPS)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=5, help="episodes per policy (default 5)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    env = gym.make("sb3_er/Leo-v0")
    run(env, 1, args.seed, "gait")  # warm-up
    print(f"sb3_er/Leo-v0, {PHYSICS_SUBSTEPS} physics substeps per 1/30 s control step")
    for policy_name in ("random", "gait"):
        steps, seconds = run(env, args.episodes, args.seed, policy_name)
        rate = steps / seconds
        print(f"{policy_name:>6} policy: {steps:6d} steps in {seconds:6.2f} s = {rate:7.0f} control steps/s"
              f" (a 25 s episode = 750 steps in {750 / rate:.2f} s)")
    env.reset(seed=args.seed)
    bare = physics_share(env)
    print(f"bare MuJoCo: 750 control steps of physics in {bare:.2f} s = {750 / bare:.0f} steps/s")
    env.close()


if __name__ == "__main__":
    main()

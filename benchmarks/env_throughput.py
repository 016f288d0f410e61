"""Environment steps per second of the registered sb3-er environments, raw and through ``gymnasium.make``.

Random actions (drawn beforehand from a seeded generator, so sampling is not timed), resets included whenever an episode
ends. The simplest walker has a target of 50,000 steps/s: its environment must never dominate a learning run.

    python benchmarks/env_throughput.py [--steps 200000] [--repeats 3] [--ids sb3_er/WindyCliff-v0 ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import gymnasium
import numpy as np
from gymnasium.envs.registration import load_env_creator

import sb3_er_envs

TARGETS = {"sb3_er/SimplestWalker-v0": 50_000.0}
NEEDS = {"sb3_er/Leo-v0": "dm_control"}


def steps_per_second(env: gymnasium.Env, steps: int, seed: int) -> float:
    """Steps per second over ``steps`` random-action steps, resetting at every episode end."""
    actions = np.random.default_rng(seed).integers(0, env.action_space.n, size=steps).tolist()
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def best_of(make_env, steps: int, repeats: int) -> float:
    """The fastest of ``repeats`` timed runs, after a short warm-up that triggers any JIT compilation."""
    env = make_env()
    steps_per_second(env, min(steps, 1000), seed=0)
    rate = max(steps_per_second(env, steps, seed=repeat + 1) for repeat in range(repeats))
    env.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=200_000, help="steps per timed run (default 200,000)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per variant; the best counts (default 3)")
    parser.add_argument("--ids", nargs="+", default=list(sb3_er_envs.ENV_IDS), help="env ids (default: all registered)")
    args = parser.parse_args()
    if args.steps < 1 or args.repeats < 1:
        parser.error("--steps and --repeats must be positive")
    unknown = sorted(set(args.ids) - set(sb3_er_envs.ENV_IDS))
    if unknown:
        parser.error(f"unknown env ids {unknown}; registered: {sorted(sb3_er_envs.ENV_IDS)}")

    print(f"{'env id':<28} {'raw env':>14} {'gymnasium.make':>15}  target")
    for env_id in args.ids:
        needed = NEEDS.get(env_id)
        if needed and importlib.util.find_spec(needed) is None:
            print(f"{env_id:<28} skipped: needs {needed} (pip install 'sb3-er[dmc]')")
            continue
        spec = gymnasium.spec(env_id)
        raw = best_of(lambda: load_env_creator(spec.entry_point)(**spec.kwargs), args.steps, args.repeats)
        made = best_of(lambda: gymnasium.make(env_id), args.steps, args.repeats)
        target = TARGETS.get(env_id)
        verdict = "" if target is None else f"{target:,.0f} steps/s {'met' if raw >= target else 'NOT met'}"
        print(f"{env_id:<28} {raw:>12,.0f}/s {made:>13,.0f}/s  {verdict}", flush=True)


if __name__ == "__main__":
    main()

"""Environment steps per second of the registered sb3-er environments, raw and through ``gymnasium.make``.

Random actions (drawn beforehand from a seeded generator, so sampling is not timed), resets included whenever an episode
ends; each variant is timed ``--repeats`` times for at least ``--seconds`` and the best run counts. The simplest walker
has a target of 50,000 steps/s: its environment must never dominate a learning run.

    python benchmarks/env_throughput.py [--seconds 2] [--repeats 3] [--ids sb3_er/WindyCliff-v0 ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import load_env_creator

import sb3_er_envs

CHUNK = 1000
TARGETS = {"sb3_er/SimplestWalker-v0": 50_000.0}
NEEDS = {"sb3_er/Leo-v0": "dm_control"}


def random_actions(action_space: gymnasium.Space, count: int, seed: int) -> list:
    """``count`` uniformly random actions of a Discrete or MultiDiscrete space."""
    rng = np.random.default_rng(seed)
    if isinstance(action_space, spaces.Discrete):
        return (action_space.start + rng.integers(0, action_space.n, size=count)).tolist()
    return list(rng.integers(0, action_space.nvec, size=(count, len(action_space.nvec))))


def steps_per_second(env: gymnasium.Env, seconds: float, seed: int) -> float:
    """Steps per second over chunks of random-action steps, at least one and at least ``seconds`` long; resets at
    every episode end are included."""
    actions = random_actions(env.action_space, CHUNK, seed)
    env.reset(seed=seed)
    steps = 0
    start = time.perf_counter()
    while True:
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        steps += CHUNK
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return steps / elapsed


def best_of(make_env, seconds: float, repeats: int) -> float:
    """The fastest of ``repeats`` timed runs, after a one-chunk warm-up that triggers any JIT compilation."""
    env = make_env()
    steps_per_second(env, 0.0, seed=0)
    rate = max(steps_per_second(env, seconds, seed=repeat + 1) for repeat in range(repeats))
    env.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=2.0, help="least duration of a timed run (default 2 s)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per variant; the best counts (default 3)")
    parser.add_argument("--ids", nargs="+", default=list(sb3_er_envs.ENV_IDS), help="env ids (default: all registered)")
    args = parser.parse_args()
    if not args.seconds > 0 or args.repeats < 1:
        parser.error("--seconds and --repeats must be positive")
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
        raw = best_of(lambda spec=spec: load_env_creator(spec.entry_point)(**spec.kwargs), args.seconds, args.repeats)
        made = best_of(lambda env_id=env_id: gymnasium.make(env_id), args.seconds, args.repeats)
        target = TARGETS.get(env_id)
        verdict = "" if target is None else f"{target:,.0f} steps/s {'met' if raw >= target else 'NOT met'}"
        print(f"{env_id:<28} {raw:>12,.0f}/s {made:>13,.0f}/s  {verdict}", flush=True)


if __name__ == "__main__":
    main()

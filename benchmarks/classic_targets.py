"""Issue 12's targets for the shipped defaults on Gymnasium's classic control, seed by seed.

    python benchmarks/classic_targets.py [--algos sarsa_lambda er_sigma] [--envs ...] [--seeds 0 1 2 3 4]

Each run is exactly what a new user writes: ``Algo("TileQ", env_id, seed=seed).learn(100_000)``, nothing else passed
(so the class defaults and sb3-er's tilings for the id, sb3_er/data/tilings.yml). Then 20 greedy episodes
(``evaluate_policy(deterministic=True)``) on a fresh env reset with seed 1000 + seed. Printed per seed: the median and
mean of the 20 returns, whether the median reaches the issue's level (CartPole-v1 450, MountainCar-v0 -140,
Acrobot-v1 -120), learning CPU seconds and episodes, and what the value watch saw over the whole run: the largest
Q(s, a) and target it saw updated, the possible returns' upper end and how many values fell outside the possible
returns (widened by the watch's 5 % tolerance); then a markdown table. Runs go one after another in this process; CPU
time is this process's. With ``--out DIR`` the printout is also written to DIR/summary.md (atomically), with the
command and the code version.
"""

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import gymnasium as gym
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er.experiments import records
from sb3_er.zoo import algorithm_classes

#: Issue 12's level for the median greedy return of each seed.
TARGETS = {"CartPole-v1": 450.0, "MountainCar-v0": -140.0, "Acrobot-v1": -120.0}
STEPS = 100_000
EVAL_EPISODES = 20


def run(algo: str, env_id: str, seed: int) -> dict:
    cpu = time.process_time()
    model = algorithm_classes()[algo]("TileQ", env_id, seed=seed).learn(STEPS)
    cpu = time.process_time() - cpu
    env = Monitor(gym.make(env_id))
    env.reset(seed=1000 + seed)
    returns, _ = evaluate_policy(
        model, env, n_eval_episodes=EVAL_EPISODES, deterministic=True, return_episode_rewards=True
    )
    # No logger writes during these runs, so the watch's logging period is the whole run.
    watch = model._watch.period_figures()
    return {
        "median": statistics.median(returns),
        "mean": statistics.fmean(returns),
        "cpu": cpu,
        "episodes": model._episode_num,
        "q_max": max(watch["q_max"], watch["target_max"]),
        "bound_high": watch["value_bound_high"],
        "out_of_range": model.values_out_of_range,
    }


def _value(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else str(value)


def main(argv=None, targets: dict = TARGETS, description: str = __doc__) -> None:
    """Run and print every (env, algorithm, seed) of ``targets`` (env id -> level of the median greedy return)."""
    parser = argparse.ArgumentParser(description=description.split("\n\n")[0])
    parser.add_argument("--algos", nargs="+", default=["sarsa_lambda", "er_sigma"])
    parser.add_argument("--envs", nargs="+", default=list(targets), choices=list(targets))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--out", type=Path, default=None, help="also write the printout to OUT/summary.md")
    args = parser.parse_args(argv)
    printed = []
    rows = [
        "| env | algorithm | median greedy return per seed | median over seeds | seeds at the level | "
        "learn CPU s per seed | largest Q(s, a) or target the watch saw, per seed (possible returns up to) | "
        "values outside the possible returns, per seed |",
        "|---|---|---|---:|---:|---|---|---|",
    ]
    for env_id in args.envs:
        level = targets[env_id]
        for algo in args.algos:
            results = []
            for seed in args.seeds:
                result = run(algo, env_id, seed)
                results.append(result)
                line = (
                    f"{env_id} {algo} seed {seed}: median {result['median']:.1f}, mean {result['mean']:.1f}, "
                    f"{'reaches' if result['median'] >= level else 'misses'} {level:g}, "
                    f"{result['cpu']:.1f} CPU s, {result['episodes']} episodes; largest value "
                    f"{_value(result['q_max'])} (returns up to {result['bound_high']:.4g}), "
                    f"{result['out_of_range']} values outside"
                )
                printed.append(line)
                print(line, flush=True)
            medians = [r["median"] for r in results]
            reached = sum(m >= level for m in medians)
            cpus = ", ".join(f"{r['cpu']:.1f}" for r in results)
            largest = ", ".join(_value(r["q_max"]) for r in results)
            bound = max(r["bound_high"] for r in results)
            outside = ", ".join(f"{r['out_of_range']:,}" for r in results)
            rows.append(
                f"| {env_id} (>= {level:g}) | {algo} | {', '.join(f'{m:g}' for m in medians)} | "
                f"{statistics.median(medians):g} | {reached}/{len(results)} | {cpus} | {largest} "
                f"({bound:.4g}) | {outside} |"
            )
    print("\n".join(rows))
    if args.out is not None:
        command = "python " + " ".join([Path(sys.argv[0]).as_posix(), *(sys.argv[1:] if argv is None else argv)])
        text = "\n".join(
            [
                f"Regenerate: `{command}` (seeds {', '.join(map(str, args.seeds))}, one after another).",
                "",
                *rows,
                "",
                "Per seed:",
                "",
                "```text",
                *printed,
                "```",
                "",
                records.code_versions_line([records.code_version()]),
                "",
            ]
        )
        args.out.mkdir(parents=True, exist_ok=True)
        partial = args.out / "summary.md.partial"
        partial.write_text(text, encoding="utf-8")
        partial.replace(args.out / "summary.md")


if __name__ == "__main__":
    main()

"""What the size of the hashed weight table costs and saves in the thesis reproductions (issue 11, part 4).

The replay kernels run about 3.1M updates/s when the weight table fits in the L2 cache and 1.2-1.9M at the default
2**22 weights (``benchmarks/replay_throughput.py``), while the grid world, the pendulum and the walker touch only a
few thousand state tiles. This script learns one reproduction run (the experiment's protocol, the zoo config's
hyperparameters, one seed) with the weight table at each ``--memory-sizes`` and prints, per size: the CPU seconds of
the run, the state-tile slots and the collision rate of the states the run visited (``TileCoder.memory_report`` on
every stored observation: the share of distinct tiles that share a slot with another), and the run's performance at its
end (the walker: the last greedy evaluation in metres per 100 s; the episodic tasks: the mean return of the last 10
learning episodes). A smaller table changes which tiles collide, so a run's numbers change with the size even at a zero
collision rate (the hash spreads tiles differently); the collision rate says whether it changes the function class.

    python benchmarks/table_size.py                                   # pendulum and walker, vanilla ER, seed 0
    python benchmarks/table_size.py --experiments gridworld --algo er_sigma --memory-sizes 22 16 12
"""

from __future__ import annotations

import argparse
import time

EXPERIMENT_BUDGETS = {"gridworld": 100, "pendulum": 100, "walker": 5000.0}


def run(experiment_name: str, algo: str, log2_size: int, budget: float, seed: int) -> dict:
    """Learn one run of `experiment_name` with ``memory_size = 2**log2_size`` and return its figures."""
    import gymnasium as gym
    import torch

    import sb3_er_envs  # noqa: F401  (registers the environment ids)
    from sb3_er import DivergenceError
    from sb3_er.experiments.runner import build_protocol
    from sb3_er.experiments.specs import EXPERIMENTS
    from sb3_er.zoo import algorithm_classes, model_kwargs

    torch.set_num_threads(1)
    experiment = EXPERIMENTS[experiment_name]
    env = gym.make(experiment.env_id)
    kwargs = model_kwargs(algo, experiment.env_id)
    kwargs["policy_kwargs"] = {**kwargs.get("policy_kwargs", {}), "memory_size": 2**log2_size}
    model = algorithm_classes()[algo]("TileQ", env, seed=seed, **kwargs)
    callback, total_timesteps = build_protocol(experiment, env, budget, seed)
    start = time.process_time()
    try:
        model.learn(total_timesteps=total_timesteps, callback=callback)
        diverged = False
    except DivergenceError:
        diverged = True
    cpu_s = time.process_time() - start
    buffer = model.replay_buffer
    rows = buffer.observations[: min(buffer.n_transitions + buffer.open_length, buffer.capacity)]
    report = model.policy.tile_coder.memory_report(rows)
    records = callback.records
    if "distance" in records[-1]:
        performance = records[-1]["distance"]  # the last greedy evaluation, metres per 100 s
    else:
        performance = sum(record["return"] for record in records[-10:]) / len(records[-10:])
    for used_env in [env, *getattr(callback, "eval_envs", [])]:
        used_env.close()
    return {
        "cpu_s": cpu_s,
        "slots": model.policy.tile_coder.n_slots,
        "weights": model.policy.tile_coder.n_weights,
        "table_mb": model.policy.tile_coder.n_weights * 8 / 2**20,
        "performance": performance,
        "diverged": diverged,
        **report,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiments", nargs="+", default=["pendulum", "walker"], choices=list(EXPERIMENT_BUDGETS))
    parser.add_argument("--algo", default="er")
    parser.add_argument(
        "--memory-sizes",
        nargs="+",
        type=int,
        default=[22, 18, 16],
        metavar="LOG2",
        help="log2 of memory_size (default 22 18 16; 22 is the default table)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=None,
        help="run length (default: the experiment's own, episodes or seconds of learning time)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    print(
        "| experiment | memory_size | weights (MB) | CPU s of the run | speed-up | distinct state tiles | "
        "collision rate | fill | performance at the end |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.experiments:
        budget = EXPERIMENT_BUDGETS[name] if args.budget is None else args.budget
        run(name, args.algo, args.memory_sizes[0], 2, args.seed)  # compiles the kernels outside the measurement
        reference = None
        for log2_size in args.memory_sizes:
            figures = run(name, args.algo, log2_size, budget, args.seed)
            reference = reference or figures["cpu_s"]
            performance = "diverged" if figures["diverged"] else f"{figures['performance']:.4g}"
            print(
                f"| {name} ({args.algo}, {budget:g}) | 2^{log2_size} | {figures['table_mb']:.1f} | "
                f"{figures['cpu_s']:.1f} | {reference / figures['cpu_s']:.2f}x | {figures['distinct_tiles']:,.0f} | "
                f"{100 * figures['collision_rate']:.2f} % | {100 * figures['fill']:.2f} % | {performance} |",
                flush=True,
            )


if __name__ == "__main__":
    main()

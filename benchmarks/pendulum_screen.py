"""Screen pendulum readings on Sarsa(lambda), ER and ER-sigma: one process, runs one after another; one CSV per
(candidate, algorithm, seed).

    nice -n 10 python benchmarks/pendulum_screen.py [--candidates ...] [--algos sarsa_lambda er]
        [--seeds 5] [--episodes 50] [--out DIR]
    python benchmarks/pendulum_screen.py --summarize [--out DIR]

Each run is ``Algo("TileQ", env, seed=seed, **<the zoo's hyperparameters for the pendulum>)`` on the candidate's
env keyword arguments, learning ``--episodes`` episodes and recording each one's return
(:class:`sb3_er.experiments.EpisodeReturnProtocol`) in ``<out>/runs/<candidate>/<algo>/seed_<n>.csv`` (default out:
results/measured/pendulum_screen); a finished run is skipped, so the command resumes. ``--summarize`` prints a row per
(candidate, algorithm) of the mean curve (``rise``: rise time in episodes; ``best``, ``r1``, ``r10``, ``r20``, ``r50``
and ``last10``: the best, the 1st, 10th, 20th and 50th and the mean of the last 10 mean returns; ``goal_frac``: the
share of episodes that reached the goal) into ``<out>/summary_runs.csv``, and ER's and ER-sigma's best against
Sarsa(lambda)'s in % of its magnitude.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import torch  # noqa: E402

import sb3_er_envs  # noqa: E402, F401  (registers the environment ids)
from sb3_er.experiments import EpisodeReturnProtocol  # noqa: E402
from sb3_er.experiments.metrics import rise_time  # noqa: E402
from sb3_er.zoo import algorithm_classes, model_kwargs  # noqa: E402
from sb3_er_envs.pendulum import DCSC_MOPS  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "measured" / "pendulum_screen"
ENV_ID = "sb3_er/PendulumSwingup-v0"
CANDIDATES = {
    # name: env kwargs
    "pivot_w0.33": dict(inertia_about="pivot", velocity_tile_width=0.33),
    "pivot_w1.0": dict(inertia_about="pivot", velocity_tile_width=1.0),
    "pivot_w3.3": dict(inertia_about="pivot", velocity_tile_width=3.3),
    "com_w0.33": dict(velocity_tile_width=0.33),
    "com_w1.0": dict(velocity_tile_width=1.0),
    "com_w3.3": dict(velocity_tile_width=3.3),
    "com_w3.3_u0.3": dict(velocity_tile_width=3.3, max_torque=0.3),
    "com_w0.33_u0.3": dict(velocity_tile_width=0.33, max_torque=0.3),
    "com_w3.3_u0.8": dict(velocity_tile_width=3.3, max_torque=0.8),
    "com_w0.33_u0.8": dict(velocity_tile_width=0.33, max_torque=0.8),
    "com_w3.3_nogoal": dict(velocity_tile_width=3.3, terminate_at_goal=False),
    "dcsc_w0.33": dict(DCSC_MOPS, velocity_tile_width=0.33),
    "dcsc_w3.3": dict(DCSC_MOPS, velocity_tile_width=3.3),
}


def run(candidate: str, algo: str, seed: int, episodes: int, runs: Path) -> None:
    path = runs / candidate / algo / f"seed_{seed}.csv"
    if path.is_file():
        return
    torch.set_num_threads(1)
    env = gym.make(ENV_ID, **CANDIDATES[candidate])
    cpu0, wall0 = time.process_time(), time.perf_counter()
    model = algorithm_classes()[algo]("TileQ", env, seed=seed, **model_kwargs(algo, ENV_ID))
    callback = EpisodeReturnProtocol(episodes)
    model.learn(total_timesteps=episodes * env.unwrapped.max_episode_steps, callback=callback)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    frame = pd.DataFrame(callback.records)
    frame["cpu_s"], frame["wall_s"] = cpu, wall
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(path, index=False)
    last5 = frame["return"].tail(5).mean()
    print(f"{candidate} {algo} seed {seed}: cpu {cpu:.1f}s wall {wall:.1f}s last5 {last5:.0f}", flush=True)


def summarize(runs: Path) -> pd.DataFrame:
    rows = []
    for candidate_dir in sorted(p for p in runs.iterdir() if p.is_dir()):
        for algo_dir in sorted(p for p in candidate_dir.iterdir() if p.is_dir()):
            frames = [pd.read_csv(f) for f in sorted(algo_dir.glob("seed_*.csv"))]
            if not frames:
                continue
            n = min(len(f) for f in frames)
            curves = np.array([f["return"].to_numpy()[:n] for f in frames])
            mean = curves.mean(0)
            episode = np.arange(1, n + 1)
            goal = np.mean([f["goal_reached"].to_numpy()[:n].mean() for f in frames])
            rows.append(
                dict(
                    candidate=candidate_dir.name,
                    algo=algo_dir.name,
                    seeds=len(frames),
                    episodes=n,
                    rise=rise_time(episode, mean),
                    best=mean.max(),
                    r1=mean[0],
                    r10=mean[9] if n >= 10 else np.nan,
                    r20=mean[19] if n >= 20 else np.nan,
                    r50=mean[49] if n >= 50 else np.nan,
                    last10=mean[-10:].mean(),
                    goal_frac=goal,
                    cpu_s=np.mean([f["cpu_s"].iloc[0] for f in frames]),
                    wall_s=np.mean([f["wall_s"].iloc[0] for f in frames]),
                )
            )
    table = pd.DataFrame(rows)
    pd.set_option("display.width", 200)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.0f}" if abs(x) >= 10 else f"{x:.2f}"))
    table.to_csv(runs.parent / f"summary_{runs.name}.csv", index=False)
    # ER's and ER-sigma's best against Sarsa(lambda)'s, in % of |Sarsa(lambda)'s|
    best = table.pivot(index="candidate", columns="algo", values="best")
    for algo in ("er", "er_sigma"):
        if algo in best:
            best[f"{algo}_vs_sarsa_%"] = 100 * (best[algo] - best["sarsa_lambda"]) / best["sarsa_lambda"].abs()
    print(best.round(0).to_string())
    return table


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--candidates", nargs="+", default=list(CANDIDATES), choices=list(CANDIDATES))
    parser.add_argument("--algos", nargs="+", default=["sarsa_lambda", "er"], choices=list(algorithm_classes()))
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0 to N-1 (default 5)")
    parser.add_argument("--episodes", type=int, default=50, help="learning episodes per run (default 50)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"the screen's folder (default {OUT})")
    parser.add_argument("--summarize", action="store_true", help="write summary_runs.csv from the finished runs")
    arguments = parser.parse_args(argv)
    if arguments.summarize:
        summarize(arguments.out / "runs")
        return
    for candidate in arguments.candidates:
        for algo in arguments.algos:
            for seed in range(arguments.seeds):
                run(candidate, algo, seed, arguments.episodes, arguments.out / "runs")


if __name__ == "__main__":
    main()

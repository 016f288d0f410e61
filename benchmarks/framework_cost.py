"""Per-episode cost of Dyna, FQI and LSPI (thesis chapter 3) on the pendulum swing-up, beside Sarsa(lambda).

    python benchmarks/framework_cost.py [--episodes 100] [--seed 0] [--algos sarsa_lambda dyna fqi lspi]

Each algorithm runs one seed of the thesis's pendulum protocol (sb3_er/PendulumSwingup-v0, episodes of up to 1500
steps) with its settings from zoo_configs/<algo>.yml. Printed per algorithm: the CPU seconds of the whole run and per
episode in three windows of the run (the cost grows with the stored data), the share spent in fits (FQI, LSPI) or
model fits and planning (Dyna), the mean return of the last 10 episodes, and the size figures (touched features,
model error). CPU time is this process's (single-threaded), so other load on the machine does not count; a 20-seed
run costs about 20 times the total.
"""

import argparse
import time

import gymnasium as gym
import numpy as np

import sb3_er_envs  # noqa: F401  (registers the env ids)
from sb3_er.experiments.protocols import EpisodeReturnProtocol
from sb3_er.zoo import algorithm_classes, model_kwargs

ENV_ID = "sb3_er/PendulumSwingup-v0"


class EpisodeClock(EpisodeReturnProtocol):
    """The pendulum protocol, plus the CPU time at the end of every episode."""

    def _on_training_start(self) -> None:
        super()._on_training_start()
        self.cpu = [time.process_time()]

    def _on_step(self) -> bool:
        episodes = len(self.records)
        keep_going = super()._on_step()
        if len(self.records) > episodes:
            self.cpu.append(time.process_time())
        return keep_going


def run(algo: str, episodes: int, seed: int) -> None:
    model = algorithm_classes()[algo]("TileQ", gym.make(ENV_ID), seed=seed, **model_kwargs(algo, ENV_ID))
    clock = EpisodeClock(episodes)
    model.learn(10**9, callback=clock)
    per_episode = np.diff(clock.cpu)
    total = clock.cpu[-1] - clock.cpu[0]
    windows = [(0, 10), (episodes // 2 - 5, episodes // 2 + 5), (episodes - 10, episodes)]
    window_text = ", ".join(f"episodes {a + 1}-{b}: {per_episode[a:b].mean():.3f} s" for a, b in windows if a >= 0)
    returns = [r["return"] for r in clock.records]
    print(
        f"{algo}: {total:.1f} CPU s for {len(per_episode)} episodes ({model.num_timesteps} steps); per episode "
        f"{window_text}; mean return of the last 10 episodes {np.mean(returns[-10:]):.0f}"
    )
    if hasattr(model, "fit_seconds"):
        stats = model._fit_stats
        print(
            f"    {model.fits} fits, {model.fit_seconds:.1f} s in fits ({model.fit_seconds / total:.0%}); last fit: "
            + ", ".join(f"{k} {v:.4g}" for k, v in stats.items())
        )
    if hasattr(model, "planning_updates"):
        print(f"    {model.planning_updates} planning updates, {model.model_fits} model fits")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--algos", nargs="+", default=["sarsa_lambda", "dyna", "fqi", "lspi"])
    args = parser.parse_args()
    for algo in args.algos:
        run(algo, args.episodes, args.seed)


if __name__ == "__main__":
    main()

"""Pendulum learning runs of ER, ER-sigma and the residual variants (taken/next, zeta 1/0.5) on the same seeds,
with the mechanism measured at chosen replay phases (instrument.py, on copies). One process, runs in sequence,
one CSV per run (resumable).

Usage (the README's residual paragraph):
    python benchmarks/residual_mechanism/run_pendulum.py --seeds 0 1 2 3 4 --episodes 100 --out DIR
    python benchmarks/residual_mechanism/analyse.py DIR
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import pandas as pd
import torch
from instrument import instrumented_phase, summarize

import sb3_er_envs  # noqa: F401
from sb3_er import ER, DivergenceError
from sb3_er.experiments import files
from sb3_er.experiments.protocols import EpisodeReturnProtocol
from sb3_er.zoo import model_kwargs

ENV_ID = "sb3_er/PendulumSwingup-v0"
VARIANTS = {
    "er": ("er", {}),
    "er_sigma": ("er_sigma", {}),
    "res_taken_z1": ("residual_er", {"residual_action": "taken", "residual_zeta": 1.0}),
    "res_taken_z0.5": ("residual_er", {"residual_action": "taken", "residual_zeta": 0.5}),
    "res_next_z1": ("residual_er", {"residual_action": "next", "residual_zeta": 1.0}),
    "res_next_z0.5": ("residual_er", {"residual_action": "next", "residual_zeta": 0.5}),
    "ressig_taken_z1": ("residual_er_sigma", {"residual_action": "taken", "residual_zeta": 1.0}),
    "ressig_taken_z0.5": ("residual_er_sigma", {"residual_action": "taken", "residual_zeta": 0.5}),
    "ressig_next_z1": ("residual_er_sigma", {"residual_action": "next", "residual_zeta": 1.0}),
    "ressig_next_z0.5": ("residual_er_sigma", {"residual_action": "next", "residual_zeta": 0.5}),
}
CHECKPOINTS = (1, 5, 20, 50, 100)
MAX_INSTRUMENTED_TRAJECTORIES = 20


class Instrumented(ER):
    """ER whose replay phases at CHECKPOINTS are first measured on copies (instrument.py); learning is unchanged."""

    instrument_at: tuple = ()
    measurements: list  # set per model in build()

    def replay(self, n_trajectories):
        phase = self.replay_phases + 1
        if phase in self.instrument_at and self.replay_buffer.n_trajectories > 0 and n_trajectories > 0:
            t0 = time.perf_counter()
            res = instrumented_phase(self, min(n_trajectories, MAX_INSTRUMENTED_TRAJECTORIES), seed=10_000 + phase)
            summary = summarize(res)
            summary.update(phase=phase, instrument_s=time.perf_counter() - t0)
            self.measurements.append(summary)
        return super().replay(n_trajectories)


def build(variant: str, seed: int, instrument: bool):
    algo, overrides = VARIANTS[variant]
    kwargs = model_kwargs(algo, ENV_ID)
    if algo == "er_sigma":
        kwargs["sigma"] = "average_worst"
    if algo == "residual_er":
        kwargs["residual_zeta"] = 1.0
    if algo == "residual_er_sigma":
        kwargs.update(sigma="average_worst", residual_zeta=1.0)
    kwargs.update(overrides)
    env = gym.make(ENV_ID)
    model = Instrumented("TileQ", env, seed=seed, **kwargs)
    model.instrument_at = CHECKPOINTS if (instrument and kwargs.get("sigma") is None) else ()
    model.measurements = []
    return model, env, kwargs


def run(variant: str, seed: int, episodes: int, out: Path, instrument: bool = True) -> None:
    csv = out / variant / f"seed_{seed}.csv"
    if csv.exists():
        return
    csv.parent.mkdir(parents=True, exist_ok=True)
    model, env, kwargs = build(variant, seed, instrument)
    callback = EpisodeReturnProtocol(episodes)
    t0 = time.perf_counter()
    diverged = False
    try:
        model.learn(total_timesteps=episodes * env.unwrapped.max_episode_steps, callback=callback)
    except DivergenceError:
        diverged = True
    frame = pd.DataFrame(callback.records, columns=list(callback.COLUMNS))
    frame["diverged"] = diverged
    wall = time.perf_counter() - t0
    meta = {
        "variant": variant,
        "seed": seed,
        "kwargs": kwargs,
        "wall_s": wall,
        "diverged": diverged,
        "replay_updates": model.replay_updates,
        "env": {
            k: getattr(env.unwrapped, k)
            for k in ("inertia_about", "velocity_tile_width", "actuation", "max_torque", "terminate_at_goal")
        },
    }
    files.write_atomically(csv.with_suffix(".json"), json.dumps(meta, default=str, indent=1))
    if model.measurements:
        files.write_csv(csv.with_name(f"seed_{seed}_mechanism.csv"), pd.DataFrame(model.measurements))
    files.write_csv(csv, frame)  # last: a run whose CSV exists is finished
    print(
        f"{variant} seed {seed}: {wall:.0f} s, diverged={diverged}, last10={frame['return'].tail(10).mean():.0f}",
        flush=True,
    )
    env.close()


def main():
    torch.set_num_threads(1)
    parser = argparse.ArgumentParser()
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS))
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--out", default="runs")
    parser.add_argument("--no-instrument", action="store_true")
    args = parser.parse_args()
    out = Path(args.out)
    for seed in args.seeds:
        for variant in args.variants:
            run(variant, seed, args.episodes, out, instrument=not args.no_instrument)


if __name__ == "__main__":
    main()

"""Screen pendulum readings (issue 10): one process, runs one after another; one CSV per (candidate, algo, seed)."""
import argparse, os, time
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
from pathlib import Path
import gymnasium as gym, pandas as pd, torch
import sb3_er_envs  # noqa: F401
from sb3_er.zoo import algorithm_classes, model_kwargs
from sb3_er.experiments import EpisodeReturnProtocol
from sb3_er_envs.pendulum import DCSC_MOPS

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

def run(candidate, algo, seed, episodes, out):
    path = out / candidate / algo / f"seed_{seed}.csv"
    if path.is_file():
        return
    torch.set_num_threads(1)
    env = gym.make(ENV_ID, **CANDIDATES[candidate])
    cpu0, wall0 = time.process_time(), time.perf_counter()
    model = algorithm_classes()[algo]("TileQ", env, seed=seed, **model_kwargs(algo, ENV_ID))
    cb = EpisodeReturnProtocol(episodes)
    model.learn(total_timesteps=episodes * env.unwrapped.max_episode_steps, callback=cb)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    frame = pd.DataFrame(cb.records)
    frame["cpu_s"], frame["wall_s"] = cpu, wall
    path.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(path, index=False)
    print(f"{candidate} {algo} seed {seed}: cpu {cpu:.1f}s wall {wall:.1f}s last5 {frame['return'].tail(5).mean():.0f}",
          flush=True)

if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--candidates", nargs="+", default=list(CANDIDATES))
    p.add_argument("--algos", nargs="+", default=["sarsa_lambda", "er"])
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--out", default="/work/scratch/pendulum/runs")
    a = p.parse_args()
    for c in a.candidates:
        for algo in a.algos:
            for s in range(a.seeds):
                run(c, algo, s, a.episodes, Path(a.out))

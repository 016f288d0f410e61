"""Control steps per wall second of learn() with one env and with N envs in subprocesses (SubprocVecEnv): where the
env's step dominates (LEO's MuJoCo), envs in subprocesses use more cores.

    python benchmarks/several_envs.py                          # LEO (needs the dmc extra), SarsaLambda and ERSigma
    python benchmarks/several_envs.py --env sb3_er/SimplestWalker-v0 --n-envs 2 4

Per (learner, number of envs): the model is built on ``make_vec_env(env, n_envs, vec_env_cls=SubprocVecEnv)`` (one env:
a DummyVecEnv, stepped in this process), learns a warm-up of 2,000 control steps, then ``--steps`` more, timed by the
wall clock; printed: control steps per wall second (every env's steps counted) and its ratio to one env. Measure on a
quiet machine: the figure is wall time, and other load takes the cores the subprocesses need. ER's replay phases run
in the learner's process between steps, so with replay the gain shrinks as replay's share of the time grows.
"""

from __future__ import annotations

import argparse
import time
import warnings


def steps_per_second(algo: str, env_id: str, n_envs: int, steps: int, kwargs: dict) -> float:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import sb3_er
    import sb3_er_envs  # noqa: F401  (registers the ids)

    cls = DummyVecEnv if n_envs == 1 else SubprocVecEnv
    env = make_vec_env(env_id, n_envs=n_envs, seed=0, vec_env_cls=cls)
    try:
        model = getattr(sb3_er, algo)("TileQ", env, seed=0, value_bound_action="ignore", **kwargs)
        model.learn(2_000)
        start = time.perf_counter()
        model.learn(steps, reset_num_timesteps=False)
        return steps / (time.perf_counter() - start)
    finally:
        env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="sb3_er/Leo-v0")
    parser.add_argument("--n-envs", nargs="+", type=int, default=[2])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--algos", nargs="+", default=["SarsaLambda", "ERSigma"])
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    print(f"{'learner':12s} {'envs':>5s} {'steps/wall s':>13s} {'vs one env':>11s}", flush=True)
    for algo in args.algos:
        kwargs = {"trace_lambda": 0.859} if algo == "SarsaLambda" else {}
        one = steps_per_second(algo, args.env, 1, args.steps, kwargs)
        print(f"{algo:12s} {1:5d} {one:13,.0f} {1.0:10.2f}x", flush=True)
        for n in args.n_envs:
            rate = steps_per_second(algo, args.env, n, args.steps, kwargs)
            print(f"{algo:12s} {n:5d} {rate:13,.0f} {rate / one:10.2f}x", flush=True)


if __name__ == "__main__":
    main()

"""Control steps per wall second of learn() with one env and with N envs in subprocesses (SubprocVecEnv): where the
env's step dominates (LEO's MuJoCo), envs in subprocesses use more cores.

    python benchmarks/several_envs.py                          # LEO (needs the dmc extra), SarsaLambda and ERSigma
    python benchmarks/several_envs.py --env sb3_er/SimplestWalker-v0 --n-envs 2 4

Per (learner, number of envs): the model is built on ``make_vec_env(env, n_envs, vec_env_cls=SubprocVecEnv)`` (one env:
a DummyVecEnv, stepped in this process), learns a warm-up of 2,000 control steps, then ``--steps`` more, timed by the
wall clock; printed: control steps per wall second (every env's steps counted) and its ratio to one env. Measure on a
quiet machine: the figure is wall time, and other load takes the cores the subprocesses need. ER's replay phases run
in the learner's process between steps, so with replay the gain shrinks as replay's share of the time grows.

Then the same without a learner (``--no-env-only`` skips it): the env's steps per wall second under uniformly random
actions, in this process (a DummyVecEnv), in one subprocess (a SubprocVecEnv of one env: the pipes' round trip and
the worker's own pace, with no parallelism to gain) and in N subprocesses. These bound what any learner can get from
subprocesses on the machine.
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


def env_steps_per_second(env_id: str, n_envs: int, subprocesses: bool, steps: int) -> float:
    """Env steps per wall second under uniformly random actions (every env's steps counted), no learner."""
    import numpy as np
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import sb3_er_envs  # noqa: F401  (registers the ids)

    env = make_vec_env(env_id, n_envs=n_envs, seed=0, vec_env_cls=SubprocVecEnv if subprocesses else DummyVecEnv)
    try:
        env.action_space.seed(0)
        env.reset()

        def actions():
            return np.array([env.action_space.sample() for _ in range(n_envs)])

        for _ in range(500):  # warm-up
            env.step(actions())
        calls = max(1, steps // n_envs)
        start = time.perf_counter()
        for _ in range(calls):
            env.step(actions())
        return calls * n_envs / (time.perf_counter() - start)
    finally:
        env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="sb3_er/Leo-v0")
    parser.add_argument("--n-envs", nargs="+", type=int, default=[2])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--algos", nargs="+", default=["SarsaLambda", "ERSigma"])
    parser.add_argument("--no-env-only", action="store_true", help="skip the env's own rates without a learner")
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
    if args.no_env_only:
        return
    print(f"\nthe env alone, random actions\n{'where':28s} {'envs':>5s} {'steps/wall s':>13s} {'vs one env':>11s}")
    here = env_steps_per_second(args.env, 1, False, args.steps)
    print(f"{'this process':28s} {1:5d} {here:13,.0f} {1.0:10.2f}x", flush=True)
    for n in [1, *args.n_envs]:
        rate = env_steps_per_second(args.env, n, True, args.steps)
        print(f"{'subprocesses':28s} {n:5d} {rate:13,.0f} {rate / here:10.2f}x", flush=True)


if __name__ == "__main__":
    main()

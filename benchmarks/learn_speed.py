"""learn() end to end: steps per CPU second of SarsaLambda and ERSigma on CartPole-v1, MountainCar-v0 and the
simplest walker, against another checkout in alternating rounds; and two models learning in two threads against one
after the other (the kernels release the GIL).

    python benchmarks/learn_speed.py                                   # this checkout only
    python benchmarks/learn_speed.py --baseline-python OTHER/.venv/bin/python --rounds 9
    python benchmarks/learn_speed.py --threads
    python benchmarks/learn_speed.py --learners SarsaLambda              # only these learners' cases

Each figure is measured in a fresh subprocess of a Python (this one, or the baseline checkout's venv, which imports
that checkout's package): the model is built and learns a warm-up of 2,000 steps (compilation, caches), then the
timed ``learn(steps, reset_num_timesteps=False)``; the rate is steps per CPU second of that process, so other load on
the machine counts less. With ``--baseline-python`` the two alternate round by round and the ``vs baseline`` column is
the median of the per-round ratios, current over baseline, which the machine's drift affects far less than either
rate. Only the public API is used, so any version of the package can be the baseline.

``--threads``: two ERSigma models on CartPole-v1 learn 30,000 steps each, in two threads at once and one after the
other, in one process; wall seconds of each (on two free cores the threads take about as long as one model alone).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

CASES = (
    ("SarsaLambda", "CartPole-v1", 50_000, {}),
    ("SarsaLambda", "MountainCar-v0", 50_000, {}),
    ("SarsaLambda", "sb3_er/SimplestWalker-v0", 25_000, {}),
    ("ERSigma", "CartPole-v1", 20_000, {}),
    ("ERSigma", "sb3_er/SimplestWalker-v0", 5_000, {"replay_trigger": "segment"}),
)
WORKER = "--worker"


def worker(case: str) -> None:
    """Print the steps per CPU second of one case (a JSON list: class, env id, steps, kwargs)."""
    import warnings

    import sb3_er
    import sb3_er_envs  # noqa: F401  (registers the ids)

    warnings.simplefilter("ignore")
    class_name, env_id, steps, kwargs = json.loads(case)
    model = getattr(sb3_er, class_name)("TileQ", env_id, seed=0, **kwargs)
    model.learn(2_000)
    start = time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    print(json.dumps(steps / (time.process_time() - start)))


def rate(python: str, case: tuple) -> float:
    result = subprocess.run(
        [python, str(Path(__file__).resolve()), WORKER, json.dumps(case)], capture_output=True, text=True, check=True
    )
    return float(result.stdout.strip().splitlines()[-1])


def threads(steps: int = 30_000) -> tuple[float, float]:
    """(wall seconds of two models learning one after the other, of the same two in two threads at once)."""
    import threading
    import warnings

    from sb3_er import ERSigma

    warnings.simplefilter("ignore")

    def model(seed):
        built = ERSigma("TileQ", "CartPole-v1", seed=seed, value_bound_action="ignore")
        built.learn(1_000)  # compiled and warm
        return built

    first, second = model(0), model(1)
    start = time.perf_counter()
    first.learn(steps, reset_num_timesteps=False)
    second.learn(steps, reset_num_timesteps=False)
    sequential = time.perf_counter() - start
    first, second = model(0), model(1)
    runners = [
        threading.Thread(target=m.learn, args=(steps,), kwargs={"reset_num_timesteps": False}) for m in (first, second)
    ]
    start = time.perf_counter()
    for runner in runners:
        runner.start()
    for runner in runners:
        runner.join()
    return sequential, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline-python", help="the python of another checkout's venv, to alternate with")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds per case (default 5)")
    parser.add_argument("--threads", action="store_true", help="also the two-thread figure")
    parser.add_argument(
        "--learners", nargs="+", choices=sorted({case[0] for case in CASES}), help="only these learners' cases"
    )
    args = parser.parse_args()
    header = f"{'learner':12s} {'env':28s} {'steps/CPU s':>12s}"
    print(header + (f" {'baseline':>12s} {'vs baseline':>11s}" if args.baseline_python else ""), flush=True)
    for case in CASES:
        if args.learners and case[0] not in args.learners:
            continue
        current, baseline, ratios = [], [], []
        for _ in range(args.rounds):
            current.append(rate(sys.executable, case))
            if args.baseline_python:
                baseline.append(rate(args.baseline_python, case))
                ratios.append(current[-1] / baseline[-1])
        line = f"{case[0]:12s} {case[1]:28s} {statistics.median(current):12,.0f}"
        if args.baseline_python:
            line += f" {statistics.median(baseline):12,.0f} {statistics.median(ratios):10.2f}x"
        print(line, flush=True)
    if args.threads:
        sequential, together = threads()
        print(
            f"\ntwo ERSigma models, 30,000 steps each: {sequential:.2f} s one after the other, {together:.2f} s in "
            f"two threads ({sequential / together:.2f}x)"
        )


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == WORKER:
        worker(sys.argv[2])
    else:
        main()

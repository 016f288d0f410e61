"""The uniformly random policy's score on the thesis's tasks, in each table's own metric.

    python benchmarks/random_policy.py [--runs 100] [--leo-runs 20] [--out results/measured/random_policy]

A run that learned nothing is worth what a policy that knows nothing does. Per task, episodes of the uniformly random
policy (every action drawn from the env's action space, seeded) scored as Tables 6.1-6.3 score a learner
(:func:`sb3_er.experiments.random_policy.random_policy_scores`): the pendulum swing-up's undiscounted episode return,
the simplest walker's distance in one 100 s evaluation run, LEO's in one 25 s run. Printed per task: the mean ± the
half-width of its 95 % Student-t interval, the median, the extremes and the CPU seconds; written (atomically) to
``--out``/scores.json with the command and the code version. The experiments' specs carry the means
(``Experiment.random_performance``), checked against this file by a test.
"""

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

from scipy import stats

import sb3_er_envs  # noqa: F401  (registers the thesis's env ids)
from sb3_er.experiments import files, records
from sb3_er.experiments.random_policy import METRICS, random_policy_scores
from sb3_er.experiments.specs import EXPERIMENTS

TASKS = ("pendulum", "walker", "leo")
OUT = Path(__file__).resolve().parent.parent / "results" / "measured" / "random_policy"


def measure(name: str, n_runs: int, seed: int) -> dict:
    """The random policy's scores on experiment `name`: mean, 95 % half-width, median, extremes, CPU seconds."""
    start = time.process_time()
    scores = random_policy_scores(EXPERIMENTS[name], n_runs, seed=seed)
    half = float(stats.t.ppf(0.975, n_runs - 1) * scores.std(ddof=1) / math.sqrt(n_runs)) if n_runs > 1 else None
    return {
        "experiment": name,
        "env_id": EXPERIMENTS[name].env_id,
        "metric": METRICS[EXPERIMENTS[name].protocol],
        "runs": n_runs,
        "seed": seed,
        "mean": float(scores.mean()),
        "ci95": half,
        "median": float(statistics.median(scores)),
        "min": float(scores.min()),
        "max": float(scores.max()),
        "cpu_s": time.process_time() - start,
        "scores": [float(score) for score in scores],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100, help="episodes on the pendulum and the walker (default 100)")
    parser.add_argument("--leo-runs", type=int, default=20, help="episodes on LEO (default 20)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=OUT, help="where scores.json goes (default: the results folder)")
    args = parser.parse_args(argv)
    results = [measure(name, args.leo_runs if name == "leo" else args.runs, args.seed) for name in TASKS]
    print("| task | metric | runs | mean ± 95 % CI | median | min | max | CPU s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for r in results:
        print(
            f"| {r['env_id']} | {r['metric']} | {r['runs']} | {r['mean']:.4g} ± {r['ci95']:.2g} | {r['median']:.4g} "
            f"| {r['min']:.4g} | {r['max']:.4g} | {r['cpu_s']:.1f} |"
        )
    command = "python benchmarks/random_policy.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:])
    )
    data = {"command": command, "code_version": records.code_version(), "tasks": {r["experiment"]: r for r in results}}
    args.out.mkdir(parents=True, exist_ok=True)
    path = files.write_json(args.out / "scores.json", data)
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

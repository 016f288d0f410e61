"""Wall time of the thesis reproductions (grid world, pendulum, walker; LEO on request) and where it goes.

Runs ``sb3-er reproduce <experiment>`` for each experiment into a fresh temporary folder (nothing is resumed) with
``--jobs`` worker processes, and prints, per experiment, the wall time of the whole reproduction and the summed run
time of each algorithm (each run's own ``wall_time_s`` column: its learning and evaluation, the share of the work each
algorithm takes). The issue's target is grid world + pendulum + walker, all five algorithms x 20 seeds, in under
15 minutes on this project's 2-core machine.

    python benchmarks/reproduce_wall_time.py                      # 20 seeds, gridworld pendulum walker, 2 jobs
    python benchmarks/reproduce_wall_time.py --seeds 2 --experiments walker
    python benchmarks/reproduce_wall_time.py --from-results results/measured   # report finished reproductions only

``--from-results DIR`` reads finished reproductions (``DIR/<experiment>/runs/*/*.csv``) instead of running them:
the sum of run times divided by the jobs is then a lower bound of the wall time, since it ignores the summary,
figures and idle workers at the end.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import pandas as pd

from sb3_er.experiments.reproduce import ALL_ALGORITHMS, reproduce

DEFAULT_EXPERIMENTS = ("gridworld", "pendulum", "walker")
TARGET_S = 15 * 60


def run_times(out_dir: Path) -> dict[str, tuple[int, float]]:
    """(number of runs, summed ``wall_time_s`` of their last row) per algorithm of a reproduction folder."""
    times = {}
    for algo_dir in sorted((out_dir / "runs").iterdir()):
        csvs = [path for path in algo_dir.glob("seed_*.csv") if path.stem.split("_")[-1].isdigit()]
        if csvs:
            times[algo_dir.name] = (len(csvs), sum(float(pd.read_csv(path)["wall_time_s"].iloc[-1]) for path in csvs))
    return times


def report(name: str, wall_s: float | None, times: dict[str, tuple[int, float]], jobs: int) -> float:
    total_runs = sum(seconds for _, seconds in times.values())
    wall = wall_s if wall_s is not None else total_runs / jobs
    label = f"{wall:,.0f} s" if wall_s is not None else f">= {wall:,.0f} s (run times / {jobs} jobs)"
    print(f"{name}: {label}")
    for algo, (n_runs, seconds) in times.items():
        share = 100 * seconds / total_runs if total_runs else 0.0
        print(f"  {algo:18s} {n_runs:3d} runs  {seconds:8,.0f} s of runs  {seconds / n_runs:6.1f} s per run  {share:5.1f} %")
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiments", nargs="+", default=list(DEFAULT_EXPERIMENTS),
                        choices=["gridworld", "pendulum", "walker", "leo"])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--algos", nargs="+", default=list(ALL_ALGORITHMS), choices=list(ALL_ALGORITHMS))
    parser.add_argument("--from-results", type=Path, default=None,
                        help="report finished reproductions in DIR/<experiment> instead of running them")
    args = parser.parse_args()

    total = 0.0
    for experiment in args.experiments:
        if args.from_results is not None:
            folder = args.from_results / experiment
            if not (folder / "runs").is_dir():
                print(f"{experiment}: no finished runs in {folder}")
                continue
            total += report(experiment, None, run_times(folder), args.jobs)
            continue
        with tempfile.TemporaryDirectory(prefix=f"sb3er_{experiment}_") as tmp:
            start = time.perf_counter()
            reproduce(experiment, n_seeds=args.seeds, algos=args.algos, out_dir=Path(tmp), n_workers=args.jobs,
                      show_progress=False)
            wall = time.perf_counter() - start
            total += report(experiment, wall, run_times(Path(tmp)), args.jobs)
    verdict = "within" if total <= TARGET_S else "over"
    print(f"all: {total:,.0f} s ({total / 60:.1f} min), {verdict} the {TARGET_S // 60}-minute target "
          f"({args.seeds} seeds, {args.jobs} jobs)")


if __name__ == "__main__":
    main()

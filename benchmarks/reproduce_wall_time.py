"""Wall time of the thesis reproductions (grid world, pendulum, walker; LEO on request) and where it goes.

Runs ``sb3-er reproduce <experiment>`` for each experiment into a fresh temporary folder (nothing is resumed) with
``--jobs`` worker processes, and prints, per experiment, the wall time of the whole reproduction and the summed run
time of each algorithm (each run's own ``wall_time_s`` column: its learning and evaluation, the share of the work each
algorithm takes). The issue's target is grid world + pendulum + walker, all five algorithms x 20 seeds, in under
15 minutes on this project's 2-core machine.

    python benchmarks/reproduce_wall_time.py                      # 20 seeds, gridworld pendulum walker, 2 jobs
    python benchmarks/reproduce_wall_time.py --seeds 2 --experiments walker
    python benchmarks/reproduce_wall_time.py --from-results results/measured   # report finished reproductions only

``--cpu-estimate`` is for a machine that is not quiet: it runs each reproduction with ``--seeds`` seeds (say 2) in
this process, one run after another, and measures its CPU time (this process and its children), which other jobs on
the machine barely change (a short warm-up run first takes the imports and kernel compiles out); scaled to 20 seeds
(the summary and figures too, so the estimate leans high) and divided by ``--jobs`` it estimates the wall time of the
full reproduction on an otherwise idle machine with that many cores.

    python benchmarks/reproduce_wall_time.py --cpu-estimate --seeds 2

``--from-results DIR`` reads finished reproductions (``DIR/<experiment>/runs/*/*.csv``) instead of running them:
the sum of run times divided by the jobs is then a lower bound of the wall time, since it ignores the summary,
figures and idle workers at the end.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import pandas as pd

from sb3_er.experiments.reproduce import ALL_ALGORITHMS, reproduce
from sb3_er.experiments.thesis import LITERAL_LABELS

DEFAULT_EXPERIMENTS = ("gridworld", "pendulum", "walker")
TARGET_S = 15 * 60
FULL_SEEDS = 20


def cpu_seconds() -> float:
    """CPU time (user + system) of this process and its finished children."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


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
        print(
            f"  {algo:18s} {n_runs:3d} runs  {seconds:8,.0f} s of runs  "
            f"{seconds / n_runs:6.1f} s per run  {share:5.1f} %"
        )
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--experiments",
        nargs="+",
        default=list(DEFAULT_EXPERIMENTS),
        choices=["gridworld", "pendulum", "walker", "leo"],
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    # the target is for the thesis's five algorithms; the stable learner's rows are extra work
    parser.add_argument("--algos", nargs="+", default=list(LITERAL_LABELS), choices=list(ALL_ALGORITHMS))
    parser.add_argument(
        "--cpu-estimate",
        action="store_true",
        help="run --seeds seeds one after another and estimate the 20-seed wall time from CPU time",
    )
    parser.add_argument(
        "--from-results",
        type=Path,
        default=None,
        help="report finished reproductions in DIR/<experiment> instead of running them",
    )
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
        if args.cpu_estimate:
            with tempfile.TemporaryDirectory(
                prefix=f"sb3er_{experiment}_warmup_"
            ) as tmp:  # imports and kernel compiles
                reproduce(
                    experiment,
                    n_seeds=1,
                    algos=args.algos,
                    out_dir=Path(tmp),
                    n_workers=1,
                    budget=2,
                    show_progress=False,
                )
            with tempfile.TemporaryDirectory(prefix=f"sb3er_{experiment}_") as tmp:
                start = cpu_seconds()
                reproduce(
                    experiment,
                    n_seeds=args.seeds,
                    algos=args.algos,
                    out_dir=Path(tmp),
                    n_workers=1,
                    show_progress=False,
                )
                cpu = cpu_seconds() - start
                estimate = cpu * FULL_SEEDS / args.seeds / args.jobs
                print(
                    f"{experiment}: {cpu:,.0f} CPU s for {args.seeds} seeds -> {cpu * FULL_SEEDS / args.seeds:,.0f} "
                    f"CPU s for {FULL_SEEDS} seeds -> about {estimate:,.0f} s on {args.jobs} idle cores"
                )
                report(experiment, None, run_times(Path(tmp)), args.jobs)
                total += estimate
            continue
        with tempfile.TemporaryDirectory(prefix=f"sb3er_{experiment}_") as tmp:
            start = time.perf_counter()
            reproduce(
                experiment,
                n_seeds=args.seeds,
                algos=args.algos,
                out_dir=Path(tmp),
                n_workers=args.jobs,
                show_progress=False,
            )
            wall = time.perf_counter() - start
            total += report(experiment, wall, run_times(Path(tmp)), args.jobs)
    verdict = "within" if total <= TARGET_S else "over"
    seeds = f"estimated for {FULL_SEEDS} seeds from {args.seeds}" if args.cpu_estimate else f"{args.seeds} seeds"
    print(
        f"all: {total:,.0f} s ({total / 60:.1f} min), {verdict} the {TARGET_S // 60}-minute target "
        f"({seeds}, {args.jobs} jobs)"
    )


if __name__ == "__main__":
    main()

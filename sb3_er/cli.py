"""The `sb3-er` command: `reproduce` the thesis's experiments, and rl-zoo `train`, `enjoy` and `optimize`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from sb3_er.experiments.specs import EXPERIMENTS
from sb3_er.experiments.thesis import ALGORITHM_LABELS

ZOO_COMMANDS = ("train", "enjoy", "optimize")


def _reproduce_parser() -> argparse.ArgumentParser:
    budgets = ", ".join(f"{name} {spec.default_budget:g} {spec.budget_unit}" for name, spec in EXPERIMENTS.items())
    parser = argparse.ArgumentParser(
        prog="sb3-er reproduce",
        description="Run a thesis experiment for every (algorithm, seed) pair in parallel, resume finished runs, and "
        "write per-run CSVs, a summary table beside the thesis's numbers and figures.",
    )
    parser.add_argument("experiment", choices=list(EXPERIMENTS), help="which thesis experiment")
    parser.add_argument("--seeds", type=int, default=20, help="number of seeds per algorithm (default 20)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument(
        "--algos", nargs="+", default=list(ALGORITHM_LABELS), choices=list(ALGORITHM_LABELS),
        help="algorithms (default: all five)",
    )
    parser.add_argument("--out", default=None, help="output folder (default results/<experiment>)")
    parser.add_argument(
        "--budget", type=float, default=None,
        help=f"run length: episodes for gridworld and pendulum, seconds of learning time for walker and leo "
        f"(defaults: {budgets})",
    )
    parser.add_argument("--jobs", type=int, default=None, help="worker processes (default: number of CPUs)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


def reproduce_command(argv: Sequence[str]) -> None:
    """`sb3-er reproduce EXPERIMENT [--seeds N] [--algos ...] [--out DIR] [--budget B] [--jobs J]`."""
    from sb3_er.experiments.reproduce import reproduce

    args = _reproduce_parser().parse_args(argv)
    result = reproduce(
        args.experiment,
        n_seeds=args.seeds,
        algos=args.algos,
        out_dir=args.out,
        budget=args.budget,
        n_workers=args.jobs,
        first_seed=args.first_seed,
        show_progress=not args.no_progress,
    )
    print(result.table_markdown.read_text())
    print(f"{result.runs_done} runs done, {result.runs_skipped} already finished, {result.wall_time_s:.0f} s wall time")
    print(f"table:   {result.table_markdown}  and  {result.table_csv}")
    for figure in result.figures:
        print(f"figure:  {figure}")
    print(f"per-run CSVs: {result.out_dir / 'runs'}")


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the `sb3-er` console script."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    commands = ("reproduce", *ZOO_COMMANDS)
    if not arguments or arguments[0] in ("-h", "--help") or arguments[0] not in commands:
        print(
            "usage: sb3-er {reproduce,train,enjoy,optimize} ...\n\n"
            "  reproduce EXPERIMENT   run a thesis experiment (gridworld, pendulum, walker, leo); see reproduce -h\n"
            "  train --algo A --env E rl-zoo training with the thesis hyperparameters from zoo_configs/\n"
            "  enjoy --algo A --env E rl-zoo enjoy of a trained agent (-f FOLDER, --no-render)\n"
            "  optimize --algo A --env E  rl-zoo optuna search (--n-trials N, --n-timesteps T)\n\n"
            f"algorithms: {', '.join(ALGORITHM_LABELS)}"
        )
        if arguments and arguments[0] not in ("-h", "--help"):
            raise SystemExit(f"sb3-er: unknown command {arguments[0]!r}")
        raise SystemExit(0 if arguments else 2)
    command, rest = arguments[0], arguments[1:]
    if command == "reproduce":
        reproduce_command(rest)
    else:
        from sb3_er import zoo

        zoo.COMMANDS[command](rest)


if __name__ == "__main__":
    main()

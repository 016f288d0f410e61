"""The `sb3-er` command: `reproduce` the thesis's experiments, and rl-zoo `train`, `enjoy` and `optimize`.

:func:`build_parser` is the command's one parser tree (the documentation's CLI reference is generated from it). The
rl-zoo commands hand every argument after their name to rl_zoo3, whose own ``-h`` lists its options.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from sb3_er.experiments.specs import ANALYSES, EXPERIMENTS
from sb3_er.experiments.thesis import ALGORITHM_LABELS
from sb3_er.zoo import ALL_ALGORITHM_NAMES

ZOO_COMMANDS = ("train", "enjoy", "optimize")
# The analyses, and the framework experiment (thesis Table 3.1, sb3_er.experiments.framework), which runs three envs.
ANALYSIS_NAMES = (*ANALYSES, "framework", "sigma-regime")
FRAMEWORK_PROBLEMS = ("gridworld", "pendulum", "mountaincar")
FRAMEWORK_METHODS = ("sarsa_lambda", "er", "er_prioritized", "er_sigma", "dyna", "fqi", "lspi")
SIGMA_REGIME_READINGS = (
    "gridworld",
    "pendulum-0.33",
    "pendulum-3.3",
    "walker",
    "walker-earlier",
    "walker-optimistic",
    "leo",
)
SIGMA_REGIME_LEARNERS = ("er_sigma", "er_sigma_stable")  # sigma_regime.LEARNERS (a test checks)


def _name_value(text: str) -> tuple[str, object]:
    """``NAME:VALUE`` with VALUE read as YAML (``3`` -> 3, ``angles`` -> "angles", ``[1, 2]`` -> [1, 2])."""
    import yaml

    name, separator, value = text.partition(":")
    if not separator or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME:VALUE, got {text!r}")
    return name, yaml.safe_load(value)


REPRODUCE_DESCRIPTION = (
    "Run a thesis experiment for every (algorithm, seed) pair in parallel, resume finished runs, and write per-run "
    "CSVs, a summary table beside the thesis's numbers and figures."
)
ZOO_DESCRIPTIONS = {
    "train": "rl-zoo training (rl_zoo3 train) with the thesis's hyperparameters of zoo_configs/<algo>.yml, the env "
    "package sb3_er_envs and TensorBoard logs under <log folder>/tensorboard filled in",
    "enjoy": "rl-zoo enjoy (rl_zoo3 enjoy) of an agent trained by sb3-er train: the latest run in the folder train "
    "writes (-f, default logs, as train's), e.g. --no-render -n 5000; nothing is downloaded",
    "optimize": "rl-zoo's optuna hyperparameter search (rl_zoo3 train --optimize-hyperparameters) with sb3-er's "
    "search spaces, e.g. --n-trials N --n-timesteps T",
}


def build_parser() -> argparse.ArgumentParser:
    """The parser tree of the `sb3-er` command: ``reproduce`` with its options, and the rl-zoo commands."""
    parser = argparse.ArgumentParser(
        prog="sb3-er",
        description="Reproduce the thesis's experiments, or train, watch and tune sb3-er's algorithms with rl-zoo.",
        epilog=f"reproduce --algos (the thesis's tables): {', '.join(ALGORITHM_LABELS)}; train, enjoy and optimize "
        f"--algo: {', '.join(ALL_ALGORITHM_NAMES)}",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="{reproduce,train,enjoy,optimize}")
    reproduce = commands.add_parser(
        "reproduce",
        help="run a thesis experiment (gridworld, pendulum, walker, leo) or "
        "analysis (replay-order, sigma, pessimistic, framework, sigma-regime)",
        description=REPRODUCE_DESCRIPTION,
    )
    _add_reproduce_arguments(reproduce)
    for name, description in ZOO_DESCRIPTIONS.items():
        zoo_command = commands.add_parser(name, help=description, description=description, add_help=False)
        zoo_command.add_argument(
            "zoo_arguments",
            nargs=argparse.REMAINDER,
            metavar="--algo ALGO --env ENV ...",
            help=f"rl_zoo3 {'enjoy' if name == 'enjoy' else 'train'} options, passed through "
            f"(sb3-er {name} -h lists them)",
        )
    return parser


def reproduce_parser() -> argparse.ArgumentParser:
    """The parser of `sb3-er reproduce` on its own (the ``reproduce`` branch of :func:`build_parser`)."""
    parser = argparse.ArgumentParser(prog="sb3-er reproduce", description=REPRODUCE_DESCRIPTION)
    _add_reproduce_arguments(parser)
    return parser


def _add_reproduce_arguments(parser: argparse.ArgumentParser) -> None:
    budgets = ", ".join(f"{name} {spec.default_budget:g} {spec.budget_unit}" for name, spec in EXPERIMENTS.items())
    parser.add_argument(
        "experiment",
        choices=[*EXPERIMENTS, *ANALYSIS_NAMES],
        help="which thesis experiment, or analysis: replay-order (Appendix A), sigma (Appendix B), pessimistic "
        "(Figure 5.5), framework (Table 3.1: the sample re-use methods on the grid world, pendulum and MountainCar), "
        "sigma-regime (which way ER-sigma moves its targets, per env and reading)",
    )
    parser.add_argument("--seeds", type=int, default=20, help="number of seeds per algorithm (default 20)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument(
        "--algos",
        nargs="+",
        default=None,
        choices=list(ALGORITHM_LABELS),
        help="the table's rows (default: all nine, the thesis's five algorithms and the stable learner's rows "
        "er_stable, er_sigma_stable, residual_er_stable and residual_er_sigma_stable: each ER class with "
        "preset='stable'; not for the analyses)",
    )
    parser.add_argument("--out", default=None, help="output folder (default results/<experiment>)")
    parser.add_argument(
        "--budget",
        type=float,
        default=None,
        help=f"run length: episodes for gridworld and pendulum, seconds of learning time for walker and leo "
        f"(defaults: {budgets}); replay-order: the horizon in replayed updates (default 300000); sigma: seconds of "
        "learning time (default 5000); pessimistic: long-replay phases (default 30); framework: learning episodes "
        "of every problem (defaults: gridworld 100, pendulum 100, mountaincar 200); sigma-regime: episodes or "
        "seconds of the chosen --readings, which must share a unit, so --budget needs --readings of one unit "
        "(defaults: gridworld and pendulum 100 episodes, walker 5000 s, leo 12000 s)",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="worker processes, or the CPUs of the local Ray instance with --backend ray (default: number of CPUs)",
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="hide the progress bar (it is shown only when standard error is a terminal)",
    )
    parser.add_argument(
        "--backend",
        choices=["local", "ray"],
        default="local",
        help="local: worker processes on this machine (default); ray: one Ray task per run, on a local Ray instance "
        "or the cluster at --address (needs pip install 'sb3-er[ray]')",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to run on: 'auto' (the cluster this machine belongs to) or HOST:PORT of its head node; "
        "default: start a local Ray instance",
    )
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        default=[],
        metavar="NAME:VALUE",
        type=_name_value,
        help="a reading of the env other than its defaults, as gymnasium.make keyword arguments, e.g. "
        "--env-kwargs n_actions:3 fall:angles (values read as YAML: 3 is a number, angles a string); checked against "
        "the env's constructor before any run starts",
    )
    parser.add_argument(
        "--algo-kwargs",
        nargs="+",
        default=[],
        metavar="NAME:VALUE",
        type=_name_value,
        help="constructor arguments overriding zoo_configs/<algo>.yml for every chosen algorithm that has them, e.g. "
        "--algo-kwargs replay_unit:segment (for the analyses: sigma only, on top of its sigma definitions)",
    )
    analyses = parser.add_argument_group("analyses")
    analyses.add_argument(
        "--database-episodes",
        type=int,
        default=None,
        help="replay-order: Sarsa(lambda) episodes per database (default 200)",
    )
    analyses.add_argument(
        "--eval-every",
        type=int,
        default=None,
        help="replay-order: replayed updates between greedy evaluations (default 75000)",
    )
    analyses.add_argument(
        "--sigmas",
        nargs="+",
        default=None,
        metavar="SIGMA",
        help="sigma: the definitions to run (default all five: worst average_worst average average_best best)",
    )
    analyses.add_argument(
        "--initial-value",
        type=float,
        default=None,
        help="pessimistic: the pessimistic initial Q (default -50, the cliff's reward)",
    )
    analyses.add_argument(
        "--problems",
        nargs="+",
        default=None,
        choices=FRAMEWORK_PROBLEMS,
        help="framework: the problems to run (default all three)",
    )
    analyses.add_argument(
        "--methods",
        nargs="+",
        default=None,
        choices=FRAMEWORK_METHODS,
        help="framework: the methods to run (default all seven)",
    )
    analyses.add_argument(
        "--readings",
        nargs="+",
        default=None,
        choices=SIGMA_REGIME_READINGS,
        help="sigma-regime: the env readings to run (default all seven)",
    )
    analyses.add_argument(
        "--learners",
        nargs="+",
        default=None,
        choices=SIGMA_REGIME_LEARNERS,
        help="sigma-regime: the learners to run, ER-sigma under the thesis's preset (er_sigma) and under the stable "
        "one (er_sigma_stable) (default both)",
    )
    parser.add_argument(
        "--allow-mixed-versions",
        action="store_true",
        help="resume next to finished runs made by other code (version, git commit) or another configuration; "
        "without it such a resume is refused",
    )


# Options of one analysis: option name (argparse dest) -> keyword of its reproduce function.
ANALYSIS_OPTIONS = {
    "replay-order": {"database_episodes": "database_episodes", "eval_every": "eval_every"},
    "sigma": {"sigmas": "sigmas", "algo_kwargs": "algo_kwargs"},
    "pessimistic": {"initial_value": "initial_value"},
    "framework": {"problems": "problems", "methods": "methods"},
    "sigma-regime": {"readings": "readings", "learners": "learners"},
}


def _analysis_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, object]:
    """The keyword arguments of the chosen analysis's own options; a parser error (exit 2) for an option given to an
    experiment or analysis that has no use for it."""
    own = ANALYSIS_OPTIONS.get(args.experiment, {"algo_kwargs": "algo_kwargs"})
    given = {
        dest: value
        for dest in (
            "database_episodes",
            "eval_every",
            "sigmas",
            "initial_value",
            "algo_kwargs",
            "problems",
            "methods",
            "readings",
            "learners",
        )
        if (value := getattr(args, dest)) not in (None, [])
    }
    if args.experiment in ANALYSIS_NAMES and args.algos is not None:
        given["algos"] = args.algos
    foreign = sorted(f"--{dest.replace('_', '-')}" for dest in given if dest not in own)
    if foreign:
        hint = " (it chooses its learners with --learners)" if args.experiment == "sigma-regime" else ""
        parser.error(f"{', '.join(foreign)} does not apply to {args.experiment}{hint}")
    if args.experiment not in ANALYSIS_NAMES:
        return {}
    return {
        keyword: dict(given[dest]) if dest == "algo_kwargs" else given[dest]
        for dest, keyword in own.items()
        if dest in given
    }


def _check_env_kwargs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A parser error (exit 2) before any run starts for --env-kwargs the experiment's env does not take, or takes with
    values of another type or that it refuses (:func:`sb3_er.common.env_ids.check_env_kwargs`), and for --env-kwargs
    given to an analysis that runs several envs with their own settings."""
    if not args.env_kwargs:
        return
    spec = {**EXPERIMENTS, **ANALYSES}.get(args.experiment)
    if spec is None:
        parser.error(f"--env-kwargs does not apply to {args.experiment}: it runs each env with its own settings")
    from sb3_er.common.env_ids import check_env_kwargs

    try:
        check_env_kwargs(spec.env_id, dict(args.env_kwargs))
    except ValueError as error:
        parser.error(str(error))


def reproduce_command(argv: Sequence[str]) -> None:
    """`sb3-er reproduce EXPERIMENT [--seeds N] [--algos ...] [--out DIR] [--budget B] [--jobs J] [--backend ray ...]`.

    Bad option combinations, requests the command refuses (ValueError), a missing import (ray), version conflicts
    with finished runs, a folder another command is writing and a damaged settings or record file exit with the
    message (status 2). SIGTERM (a scheduler's time
    limit, ``timeout``) ends the command as Ctrl-C does: its worker processes and the Ray instance it started end
    with it, and the runs written so far stay for a resume.

    :param argv: the arguments after ``reproduce`` (the experiment's name first).
    """
    import signal
    import threading

    from sb3_er.experiments.files import DamagedFileError, FolderLockedError
    from sb3_er.experiments.records import MixedVersionsError, counted
    from sb3_er.experiments.reproduce import reproduce
    from sb3_er.experiments.runner import RUNNER_ARGUMENTS

    def terminate(signum, frame):
        raise SystemExit(128 + signum)

    parser = reproduce_parser()
    args = parser.parse_args(argv)
    if args.address is not None and args.backend != "ray":
        parser.error("--address needs --backend ray")
    if args.address is not None and args.jobs is not None:
        parser.error("--jobs sets the CPUs of a local Ray instance; a cluster at --address uses its own CPUs")
    if args.jobs is not None and args.jobs < 1:
        parser.error(f"--jobs must be at least 1, got {args.jobs}")
    options = _analysis_options(parser, args)
    _check_env_kwargs(parser, args)
    reserved = [name for name, _ in args.algo_kwargs if name in RUNNER_ARGUMENTS]
    if reserved:
        parser.error("--algo-kwargs cannot set " + "; ".join(f"{name}: {RUNNER_ARGUMENTS[name]}" for name in reserved))
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if in_main_thread else None
    try:
        if args.experiment in ANALYSIS_NAMES:
            from sb3_er.experiments.analyses import command

            result = command(args.experiment)(
                n_seeds=args.seeds,
                out_dir=args.out,
                budget=args.budget,
                n_workers=args.jobs,
                first_seed=args.first_seed,
                show_progress=not args.no_progress,
                backend=args.backend,
                address=args.address,
                allow_mixed_versions=args.allow_mixed_versions,
                env_kwargs=dict(args.env_kwargs),
                **options,
            )
        else:
            result = reproduce(
                args.experiment,
                n_seeds=args.seeds,
                algos=args.algos if args.algos is not None else list(ALGORITHM_LABELS),
                out_dir=args.out,
                budget=args.budget,
                n_workers=args.jobs,
                first_seed=args.first_seed,
                show_progress=not args.no_progress,
                backend=args.backend,
                address=args.address,
                allow_mixed_versions=args.allow_mixed_versions,
                env_kwargs=dict(args.env_kwargs),
                algo_kwargs=dict(args.algo_kwargs),
            )
    except (ImportError, MixedVersionsError, FolderLockedError, DamagedFileError, ValueError) as error:
        # ValueError: a request the command refuses before any run (an argument no algorithm takes, a preset set
        # over the table's rows, a budget of the wrong unit), named in its message
        parser.exit(2, f"sb3-er reproduce: error: {error}\n")
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    print(result.table_markdown.read_text())
    findings = result.out_dir / "findings.json"
    if findings.is_file():  # the thesis's findings of this table, judged by the rule (sb3_er.experiments.findings)
        from sb3_er.experiments.files import read_json

        data = read_json(findings, "run the same command again: it rewrites findings.json from the finished runs")
        words = {True: "holds", False: "does not hold", None: "inconclusive"}
        print(f"The findings of thesis {data['thesis']} on these runs ({data['rule']}):")
        for finding in data["findings"]:
            print(f"  {words[finding['holds']]:>14}: {finding['claim']}; {finding['evidence']}")
        print()
    print(
        f"{counted(result.runs_done, 'run')} done, {result.runs_skipped} already finished, "
        f"{result.wall_time_s:.0f} s wall time"
    )
    print(f"table:     {result.table_markdown}  and  {result.table_csv}")
    for figure in result.figures:
        print(f"{'animation:' if figure.suffix == '.gif' else 'figure:   '} {figure}")
    runs = result.out_dir / "runs"
    print(f"per-run CSVs: {runs if runs.is_dir() else result.out_dir / '<problem>' / 'runs'}")


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of the `sb3-er` console script.

    :param argv: the command line without the program's name (default None: ``sys.argv[1:]``).
    """
    arguments = list(sys.argv[1:] if argv is None else argv)
    commands = ("reproduce", *ZOO_COMMANDS)
    if not arguments or arguments[0] in ("-h", "--help") or arguments[0] not in commands:
        build_parser().print_help()
        if arguments and arguments[0] not in ("-h", "--help"):
            raise SystemExit(f"sb3-er: unknown command {arguments[0]!r}")
        raise SystemExit(0 if arguments else 2)
    command, rest = arguments[0], arguments[1:]
    try:
        if command == "reproduce":
            reproduce_command(rest)
        else:
            from sb3_er import zoo

            zoo.run_command(command, rest)
    except ModuleNotFoundError as error:
        extra = EXTRAS.get((error.name or "").partition(".")[0])
        if extra is None:
            raise
        raise SystemExit(
            f"sb3-er {command} needs {error.name}, which the {extra} extra installs: "
            f"pip install 'sb3-er[{extra}]' (or 'sb3-er[all]')"
        ) from error


#: The optional packages the commands import, and the extra of pyproject.toml that installs each.
EXTRAS = {
    "rl_zoo3": "zoo",
    "optuna": "zoo",
    "pandas": "plots",
    "matplotlib": "plots",
    "ray": "ray",
    "dm_control": "dmc",
    "mujoco": "dmc",
    "imageio": "dmc",
    "shimmy": "dmc",
}


if __name__ == "__main__":
    main()

"""What a run is: :class:`RunJob` (an algorithm on an experiment with one seed) and what follows from it alone, the
model's constructor arguments and the run's files. Both the runner (:mod:`sb3_er.experiments.runner`, which executes
jobs) and the version records (:mod:`sb3_er.experiments.records`, which describe them) use this module, so neither
imports the other for it."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sb3_er.common.docstrings import accepted_parameters
from sb3_er.experiments.specs import Experiment


@dataclass(frozen=True)
class RunJob:
    """One learning run: an algorithm on an experiment with one seed, for `budget` episodes or seconds.

    `csv_path` is where the driver writes the run's CSV; the run itself never touches it. `env_kwargs` and
    `algo_kwargs` (sorted ``(name, value)`` pairs) are a reading to run instead of the defaults: keyword arguments of
    ``gymnasium.make`` and overrides of the zoo config's constructor arguments (see :func:`job_model_kwargs`).
    `figure_run` asks the run for the data of its per-run figures (the walker's gait and animation).
    `label` names the run in place of `algo` (its key ``<label>/seed_<seed>``), so that several runs of one algorithm
    with different `algo_kwargs` (the sigma study's definitions) are told apart by the driver and in their records.

    :param experiment: the experiment (or analysis) the run belongs to.
    :param algo: the algorithm's rl-zoo name.
    :param seed: the run's seed.
    :param budget: run length in the experiment's unit (episodes or seconds of learning time).
    :param csv_path: where the driver writes the run's CSV.
    :param env_kwargs: ``gymnasium.make`` keyword arguments as sorted ``(name, value)`` pairs (default none).
    :param algo_kwargs: constructor overrides as sorted ``(name, value)`` pairs (default none).
    :param figure_run: whether the run returns the data of its per-run figures (default False).
    :param label: the run's name in place of `algo` (default "": `algo`).
    """

    experiment: Experiment
    algo: str
    seed: int
    budget: float
    csv_path: Path
    env_kwargs: tuple = ()
    algo_kwargs: tuple = ()
    figure_run: bool = False
    label: str = ""

    @property
    def key(self) -> str:
        return f"{self.label or self.algo}/seed_{self.seed}"


RUNNER_ARGUMENTS = {
    "self": "a method's own object",
    "policy": "the runner passes the policy, 'TileQ'",
    "env": "the runner makes each run's env (give its arguments with --env-kwargs)",
    "seed": "the runner passes each run's seed (choose them with --seeds and --first-seed)",
    "_init_setup_model": "the runner needs the model set up",
    "tensorboard_log": "the runner's workers keep no logs; train with `sb3-er train` for TensorBoard",
    "verbose": "the runner's workers report through the progress bar",
}
"""Constructor arguments that the runner sets itself (or that are no setting of a run), with why: ``--algo-kwargs``
refuses them (:func:`check_algo_kwargs`)."""


def check_algo_kwargs(algorithm_classes: Iterable[type], algo_kwargs: dict[str, Any], who: str | None = None) -> None:
    """ValueError naming the problem when `algo_kwargs` sets an argument the runner sets itself (RUNNER_ARGUMENTS)
    or one that none of `algorithm_classes` has; `who` names the one algorithm in the message (default: "no chosen
    algorithm").

    :param algorithm_classes: the classes of the chosen algorithms.
    :param algo_kwargs: the settings by parameter name.
    :param who: the one algorithm's name for the message (default None: several).
    """
    reserved = [name for name in algo_kwargs if name in RUNNER_ARGUMENTS]
    if reserved:
        raise ValueError(
            "--algo-kwargs cannot set " + "; ".join(f"{name}: {RUNNER_ARGUMENTS[name]}" for name in reserved)
        )
    accepted = set().union(*map(accepted_parameters, algorithm_classes)) - set(RUNNER_ARGUMENTS)
    unknown = sorted(set(algo_kwargs) - accepted)
    if unknown:
        if who is None:
            raise ValueError(f"no chosen algorithm has the parameters {unknown}; they take {sorted(accepted)}")
        raise ValueError(f"{who} has no parameters {unknown}; it takes {sorted(accepted)}")


def job_model_kwargs(job: RunJob) -> dict[str, Any]:
    """The constructor keyword arguments of `job`'s model: its zoo config entry, overridden by ``job.algo_kwargs``
    where the algorithm has such a parameter (``replay_unit`` reaches the ER family, not Sarsa(lambda)). An ER class
    gets ``preset="thesis"`` unless the config or ``job.algo_kwargs`` give another: the reproductions run the thesis's
    algorithms whatever the class default is. A replay volume given in ``job.algo_kwargs`` (``n_replays``,
    ``replays_per_stored_trajectory`` or ``replay_ratio``) replaces the config's as a whole, as it replaces a preset's.

    :param job: the run.
    """
    from sb3_er.er import REPLAY_VOLUME
    from sb3_er.zoo import algorithm_classes, model_kwargs

    kwargs = model_kwargs(job.algo, job.experiment.env_id) if job.experiment.zoo_configs else {}
    accepted = set(accepted_parameters(algorithm_classes()[job.algo]))
    if "preset" in accepted:
        kwargs.setdefault("preset", "thesis")
    given = {name: value for name, value in job.algo_kwargs if name in accepted and name not in RUNNER_ARGUMENTS}
    if any(name in REPLAY_VOLUME for name in given):
        for name in REPLAY_VOLUME:
            kwargs.pop(name, None)
    kwargs.update(given)
    return kwargs


def run_csv_path(out_dir: Path, algo: str, seed: int) -> Path:
    """Where the CSV of one run lives (its version record is beside it, ``.json``).

    :param out_dir: the results folder.
    :param algo: the run's name (its algorithm, or its label).
    :param seed: the run's seed.
    """
    return Path(out_dir) / "runs" / algo / f"seed_{seed}.csv"

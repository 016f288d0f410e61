"""rl-baselines3-zoo integration: our algorithms in rl_zoo3's registries, and `sb3-er train|enjoy|optimize`.

``register_algorithms()`` adds ``sarsa_lambda``, ``er``, ``er_sigma``, ``residual_er`` and ``residual_er_sigma`` to
``rl_zoo3.ALGOS`` and to its optuna sampler and converter tables. The commands then run rl_zoo3's own ``train`` and
``enjoy`` with our defaults filled in: the thesis's hyperparameters from ``zoo_configs/<algo>.yml`` (package data of
``sb3_er.zoo_configs``, installed with the wheel as rl_zoo3 installs its ``hyperparams/``), the environment
package ``sb3_er_envs`` (and shimmy's ids for a ``dm_control/`` env, registered before rl_zoo3 makes it) and
TensorBoard logs under ``<log folder>/tensorboard``. Every other rl_zoo3 option passes
through unchanged. ``python -m sb3_er.zoo train ...`` is the same as ``sb3-er train ...``.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib.resources
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

from sb3_er.common.env_ids import register_env_id

ALGORITHM_NAMES = ("sarsa_lambda", "er", "er_sigma", "residual_er", "residual_er_sigma")
# The other sample re-use methods of thesis chapter 3 (Dyna, FQI, LSPI): trainable through rl-zoo, not in the thesis's
# experiments (their zoo configs hold our settings, not the thesis's).
FRAMEWORK_ALGORITHM_NAMES = ("dyna", "fqi", "lspi")
ALL_ALGORITHM_NAMES = ALGORITHM_NAMES + FRAMEWORK_ALGORITHM_NAMES
# The repository's top-level zoo_configs/, mapped into the package in pyproject.toml.
CONFIG_PACKAGE = "sb3_er.zoo_configs"
ENV_PACKAGE = "sb3_er_envs"
# rl_zoo3 keys that configure the run rather than the algorithm's constructor.
ZOO_ONLY_KEYS = ("n_timesteps", "n_envs", "policy", "normalize", "env_wrapper", "frame_stack", "callback", "env_kwargs")


def sigma_definitions() -> tuple[str, ...]:
    """The definitions of sigma (thesis Appendix B, numbered 1-5 in this order), as ERSigma's ``sigma`` names them.
    (sb3_er.er is imported here, not with this module, so that the command line's parser stays light.)"""
    from sb3_er.er import SIGMAS

    return tuple(name for name in SIGMAS if name is not None)


def replay_orders() -> tuple[str, ...]:
    """The replay orders ER's ``replay_order`` accepts (thesis Appendix A and section 3.2)."""
    from sb3_er.er import REPLAY_ORDERS

    return tuple(REPLAY_ORDERS)


def algorithm_classes() -> dict[str, type]:
    """Our algorithm classes under their rl-zoo names (:data:`ALL_ALGORITHM_NAMES`, in its order)."""
    from sb3_er import ER, FQI, LSPI, Dyna, ERSigma, ResidualER, ResidualERSigma, SarsaLambda

    classes = (SarsaLambda, ER, ERSigma, ResidualER, ResidualERSigma, Dyna, FQI, LSPI)
    return dict(zip(ALL_ALGORITHM_NAMES, classes, strict=True))


_EXTRACTED = contextlib.ExitStack()  # config files extracted from a zipped install, removed at exit
atexit.register(_EXTRACTED.close)


def config_path(algo: str) -> Path:
    """The rl-zoo YAML file holding the thesis's hyperparameters of `algo` (``zoo_configs/<algo>.yml``), read through
    ``importlib.resources`` from the installed package, so that an installed wheel finds it as a checkout does.

    Raises ValueError for an algorithm sb3-er does not have and FileNotFoundError when the installation lacks the file
    (a broken install: reinstall sb3-er, or pass ``--conf-file`` explicitly).

    :param algo: the algorithm's rl-zoo name, e.g. "er_sigma".
    """
    if algo not in ALL_ALGORITHM_NAMES:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {', '.join(ALL_ALGORITHM_NAMES)}")
    resource = importlib.resources.files(CONFIG_PACKAGE).joinpath(f"{algo}.yml")
    if not resource.is_file():
        raise FileNotFoundError(
            f"{resource} not found: this installation of sb3-er lacks its package data {CONFIG_PACKAGE}/{algo}.yml "
            "(reinstall sb3-er, or pass --conf-file explicitly)"
        )
    if isinstance(resource, Path):
        return resource
    # rl_zoo3 opens --conf-file by name: a zipped install's file is extracted for the life of the process.
    return _EXTRACTED.enter_context(importlib.resources.as_file(resource))


def load_hyperparameters(algo: str, env_id: str) -> dict[str, Any]:
    """The YAML entry of `env_id` in `zoo_configs/<algo>.yml`, as rl_zoo3 reads it.

    :param algo: the algorithm's rl-zoo name, e.g. "er_sigma".
    :param env_id: the Gymnasium env id, e.g. "sb3_er/SimplestWalker-v0".
    """
    with open(config_path(algo)) as stream:
        entries = yaml.safe_load(stream)
    if env_id not in entries:
        raise KeyError(f"zoo_configs/{algo}.yml has no entry for {env_id!r}; it has {', '.join(entries)}")
    return dict(entries[env_id])


def model_kwargs(algo: str, env_id: str) -> dict[str, Any]:
    """Constructor keyword arguments of `algo` for `env_id` from its zoo config (the run-level keys removed).

    :param algo: the algorithm's rl-zoo name, e.g. "er_sigma".
    :param env_id: the Gymnasium env id, e.g. "sb3_er/SimplestWalker-v0".
    """
    hyperparameters = load_hyperparameters(algo, env_id)
    for key in ZOO_ONLY_KEYS:
        hyperparameters.pop(key, None)
    return hyperparameters


def _sample_common(trial) -> dict[str, Any]:
    return {
        "learning_rate": trial.suggest_float("learning_rate", 0.02, 0.6, log=True),
        "gamma": trial.suggest_categorical("gamma", [0.95, 0.98, 0.99, 0.995, 0.999]),
        "exploration_rate": trial.suggest_float("exploration_rate", 0.01, 0.2, log=True),
    }


def _sample_stabilizers(trial, averager: bool = True) -> dict[str, Any]:
    """The replay stabilizers every ER class takes (``truncate_targets``, ``target_copy``, ``step_size_bound``,
    ``averager``, ``project_weights`` and ``replay_ratio``): each one on or off, and the replay volume as a ratio of
    updates per new transition (None: the volume of the config or the preset). Each is sampled explicitly, so
    ``preset``, which only fills what is not given, is not searched. A sampled ratio replaces the config's volume,
    which rl-zoo merges under the sampled values (the grid world's replays_per_stored_trajectory, the walker's
    n_replays).

    :param trial: the optuna trial that suggests the values.
    :param averager: sample the averager too (the semi-gradient classes); False for the residual classes, whose
        direction has no averager form (it is then off).
    """
    sampled = {
        "truncate_targets": trial.suggest_categorical("truncate_targets", [False, True]),
        "target_copy": trial.suggest_categorical("target_copy", [False, True]),
        "step_size_bound": trial.suggest_categorical("step_size_bound", [False, True]),
        "averager": trial.suggest_categorical("averager", [False, True]) if averager else False,
        "project_weights": trial.suggest_categorical("project_weights", [False, True]),
        "replay_ratio": trial.suggest_categorical("replay_ratio", [None, 1, 4, 16, 64, 256]),
    }
    if sampled["replay_ratio"] is not None:
        sampled.update(n_replays=None, replays_per_stored_trajectory=None)
    return sampled


def sample_sarsa_lambda_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of Sarsa(lambda): alpha, gamma, epsilon and the trace decay lambda.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {**_sample_common(trial), "trace_lambda": trial.suggest_float("trace_lambda", 0.5, 0.99)}


def sample_er_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of vanilla ER: alpha, gamma, epsilon, the replay order (every order ER has: reversed,
    forward and uniform of thesis Appendix A, and prioritized sweeping of section 3.2) and the replay stabilizers.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {
        **_sample_common(trial),
        "replay_order": trial.suggest_categorical("replay_order", list(replay_orders())),
        **_sample_stabilizers(trial),
    }


def sample_er_sigma_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of ER-sigma: alpha, gamma, epsilon, the definition of sigma (thesis Appendix B) and the
    replay stabilizers.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {
        **_sample_common(trial),
        "sigma": trial.suggest_categorical("sigma", list(sigma_definitions())),
        **_sample_stabilizers(trial),
    }


def sample_residual_er_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of residual ER: alpha, gamma, epsilon, the residual weight zeta (thesis Eq. 5.9) and the
    replay stabilizers.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {
        **_sample_common(trial),
        "residual_zeta": trial.suggest_float("residual_zeta", 0.0, 1.0),
        **_sample_stabilizers(trial, averager=False),
    }


def sample_residual_er_sigma_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of residual ER-sigma: the sigma definition, zeta and the replay stabilizers.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {
        **sample_residual_er_params(trial, n_actions, n_envs, additional_args),
        "sigma": trial.suggest_categorical("sigma", list(sigma_definitions())),
    }


def sample_dyna_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of Dyna: alpha, gamma, epsilon, the planning updates per step and the model's k.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {
        **_sample_common(trial),
        "planning_steps": trial.suggest_categorical("planning_steps", [1, 5, 10, 20, 50]),
        "target": trial.suggest_categorical("target", ["q_learning", "sarsa"]),
        "n_neighbors": trial.suggest_categorical("n_neighbors", [1, 3, 5, 10]),
    }


def _sample_fitted(trial) -> dict[str, Any]:
    return {
        "gamma": trial.suggest_categorical("gamma", [0.95, 0.98, 0.99, 0.995, 0.999]),
        "exploration_rate": trial.suggest_float("exploration_rate", 0.01, 0.2, log=True),
        "fit_every": trial.suggest_categorical("fit_every", [1, 2, 5, 10]),
        "ridge": trial.suggest_float("ridge", 1e-4, 10.0, log=True),
    }


def sample_fqi_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of FQI: gamma, epsilon, the fit schedule, the ridge term and the sweeps per fit.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return {**_sample_fitted(trial), "n_iterations": trial.suggest_categorical("n_iterations", [5, 10, 20, 50])}


def sample_lspi_params(trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """Optuna search space of LSPI: gamma, epsilon, the fit schedule and the ridge term.

    :param trial: the optuna trial that suggests the values.
    :param n_actions: actions of the env (rl_zoo3's sampler signature; unused).
    :param n_envs: parallel envs of the run (rl_zoo3's sampler signature; unused).
    :param additional_args: rl_zoo3's extra sampler arguments (unused).
    """
    return _sample_fitted(trial)


SAMPLERS: dict[str, Callable[..., dict[str, Any]]] = {
    "sarsa_lambda": sample_sarsa_lambda_params,
    "er": sample_er_params,
    "er_sigma": sample_er_sigma_params,
    "residual_er": sample_residual_er_params,
    "residual_er_sigma": sample_residual_er_sigma_params,
    "dyna": sample_dyna_params,
    "fqi": sample_fqi_params,
    "lspi": sample_lspi_params,
}


def _sampled_params_as_kwargs(params: dict[str, Any]) -> dict[str, Any]:
    """Our samplers name optuna parameters after constructor arguments, so a stored trial needs no conversion."""
    return dict(params)


def register_algorithms() -> None:
    """Add our algorithms to rl_zoo3's ALGOS, HYPERPARAMS_SAMPLER and HYPERPARAMS_CONVERTER (idempotent)."""
    from rl_zoo3 import hyperparams_opt, utils

    utils.ALGOS.update(algorithm_classes())
    hyperparams_opt.HYPERPARAMS_SAMPLER.update(SAMPLERS)
    hyperparams_opt.HYPERPARAMS_CONVERTER.update({name: _sampled_params_as_kwargs for name in ALL_ALGORITHM_NAMES})


#: The log folder rl_zoo3's ``train`` writes to by default (its ``-f/--log-folder``), which ``sb3-er enjoy`` reads by
#: default too (rl_zoo3's own ``enjoy`` reads ``rl-trained-agents`` and downloads missing models from a model hub).
LOG_FOLDER = "logs"


def _has_option(argv: Sequence[str], *names: str) -> bool:
    return any(arg == name or arg.startswith(name + "=") for arg in argv for name in names)


def _known_arguments(argv: Sequence[str], command: str) -> argparse.Namespace:
    """The options our defaults depend on (--algo, --env and the log folder), parsed as the command's own."""
    parser = argparse.ArgumentParser(prog=f"sb3-er {command}", add_help=False)
    parser.add_argument("--algo", required=True, choices=ALL_ALGORITHM_NAMES)
    parser.add_argument("--env", default="CartPole-v1")  # rl_zoo3's default env
    parser.add_argument("-f", "--log-folder", "--folder", dest="folder", default=LOG_FOLDER)
    known, _ = parser.parse_known_args(argv)
    return known


def _with_defaults(argv: Sequence[str], command: str) -> list[str]:
    """rl_zoo3 arguments with our defaults: the env package; for training the config file and TensorBoard folder; for
    enjoy the folder training writes (:data:`LOG_FOLDER`). ``-h`` passes through to rl_zoo3's own help."""
    arguments = list(argv)
    if not _has_option(arguments, "--gym-packages"):
        arguments += ["--gym-packages", ENV_PACKAGE]
    if _has_option(arguments, "-h", "--help"):
        return arguments
    known = _known_arguments(argv, command)
    training = command in ("train", "optimize")
    if training and not _has_option(arguments, "-conf", "--conf-file"):
        arguments += ["--conf-file", str(config_path(known.algo))]
    if training and not _has_option(arguments, "-tb", "--tensorboard-log"):
        arguments += ["--tensorboard-log", str(Path(known.folder) / "tensorboard")]
    if not training:
        # rl_zoo3's enjoy spells the folder -f/--folder only; train's --log-folder is accepted here as well
        arguments = [
            "--folder" if arg == "--log-folder" else arg.replace("--log-folder=", "--folder=", 1) for arg in arguments
        ]
        if not _has_option(arguments, "-f", "--folder"):
            arguments += ["--folder", LOG_FOLDER]
    return arguments


def _check_env_kwargs(program: str, env_id: str | None, argv: Sequence[str]) -> None:
    """Exit with one message before rl_zoo3 starts when ``--env-kwargs`` or ``--eval-env-kwargs`` (read as rl_zoo3
    reads them: each value a Python expression) do not make the env (:func:`sb3_er.common.env_ids.check_env_kwargs`).

    :param program: the command's name, for the message.
    :param env_id: the ``--env`` given (None: rl_zoo3 reports it missing).
    :param argv: the command's arguments.
    """
    from rl_zoo3.utils import StoreDict

    from sb3_er.common.env_ids import check_env_kwargs

    parser = argparse.ArgumentParser(add_help=False, allow_abbrev=False)  # --env is not --env-kwargs
    for option in ("--env-kwargs", "--eval-env-kwargs"):
        parser.add_argument(option, type=str, nargs="+", action=StoreDict, default=None)
    try:
        known, _ = parser.parse_known_args(argv)
    except Exception as error:  # StoreDict evaluates each value as Python: NameError, SyntaxError, ...
        raise SystemExit(
            f"{program}: error: --env-kwargs: rl_zoo3 reads each NAME:VALUE's value as a Python expression ({error}); "
            "write a string quoted, e.g. --env-kwargs \"fall:'angles'\""
        ) from None
    for option, env_kwargs in (("--env-kwargs", known.env_kwargs), ("--eval-env-kwargs", known.eval_env_kwargs)):
        if env_kwargs and env_id is not None:
            try:
                check_env_kwargs(env_id, env_kwargs, given_as=option)
            except ValueError as error:
                raise SystemExit(f"{program}: error: {error}") from None


def _env_id(argv: Sequence[str]) -> str | None:
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--env", default=None)
    known, _ = parser.parse_known_args(argv)
    return known.env


def _run_zoo_script(
    script: Callable[[], None], program: str, argv: Sequence[str], check_env_kwargs: bool = True
) -> None:
    register_algorithms()
    env_id = _env_id(argv)
    register_env_id(env_id)  # sb3_er/ and shimmy's dm_control/ ids, in this process, before rl_zoo3 makes it
    if check_env_kwargs:
        _check_env_kwargs(program, env_id, argv)  # one message, before any env or run exists
    saved = sys.argv
    sys.argv = [program, *argv]
    try:
        script()
    finally:
        sys.argv = saved


def train(argv: Sequence[str]) -> None:
    """`sb3-er train --algo ALGO --env ENV [rl_zoo3 train options]`: rl_zoo3 training with our defaults.

    :param argv: the arguments after ``train`` (rl_zoo3's train options).
    """
    from rl_zoo3.train import train as zoo_train

    _run_zoo_script(zoo_train, "sb3-er train", _with_defaults(argv, "train"))


def optimize(argv: Sequence[str]) -> None:
    """`sb3-er optimize --algo ALGO --env ENV [--n-trials N ...]`: rl_zoo3's optuna search with our samplers.

    :param argv: the arguments after ``optimize`` (rl_zoo3's train options with ``--optimize``).
    """
    arguments = list(argv)
    if not _has_option(arguments, "-optimize", "--optimize-hyperparameters", "-h", "--help"):
        arguments.append("--optimize-hyperparameters")
    from rl_zoo3.train import train as zoo_train

    _run_zoo_script(zoo_train, "sb3-er optimize", _with_defaults(arguments, "optimize"))


class ModelNotFoundError(FileNotFoundError):
    """``sb3-er enjoy`` found no trained model where it looked."""


def find_trained_model(argv: Sequence[str]) -> Path:
    """The model file ``sb3-er enjoy`` (rl_zoo3's enjoy) loads for these arguments, found as rl_zoo3 finds it (the
    latest run ``<folder>/<algo>/<env>_<N>`` unless ``--exp-id``, its ``<env>.zip`` unless ``--load-best`` or a
    checkpoint is asked for), without rl_zoo3's fallback of downloading from a model hub.

    Raises ModelNotFoundError saying where it looked and which ``sb3-er train`` command writes there.

    :param argv: ``sb3-er enjoy``'s arguments with our defaults (:func:`_with_defaults`).
    """
    import io

    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_model_path

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo", required=True)
    parser.add_argument("--env", default="CartPole-v1")
    parser.add_argument("-f", "--folder", default=LOG_FOLDER)
    parser.add_argument("--exp-id", type=int, default=0)
    parser.add_argument("--load-best", action="store_true")
    parser.add_argument("--load-checkpoint", type=int, default=None)
    parser.add_argument("--load-last-checkpoint", action="store_true")
    known, _ = parser.parse_known_args(argv)
    env_name = EnvironmentName(known.env)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # rl_zoo3 prints "Loading latest experiment"; enjoy will too
            _, model_path, _ = get_model_path(
                known.exp_id,
                known.folder,
                known.algo,
                env_name,
                known.load_best,
                known.load_checkpoint,
                known.load_last_checkpoint,
            )
    except (AssertionError, ValueError) as error:
        folder = Path(known.folder)
        run = folder / known.algo / f"{env_name}_<N>"
        wanted = (
            f"{run}/best_model.zip (written by train's evaluation, --eval-freq)"
            if known.load_best
            else f"{run}/rl_model_<steps>_steps.zip (written with train's --save-freq)"
            if known.load_checkpoint is not None or known.load_last_checkpoint
            else f"{run}/{env_name}.zip"
        )
        reason = str(error)
        folder_option = "" if known.folder == LOG_FOLDER else f" -f {known.folder}"
        raise ModelNotFoundError(
            f"no trained {known.algo} model for {known.env} in {folder}/ ({folder.resolve()}): "
            f"{reason[:1].lower() + reason[1:]}. Enjoy loads {wanted}, the latest run N (or --exp-id N), which "
            f"`sb3-er train --algo {known.algo} --env {known.env}{folder_option}` writes. For a model trained with "
            f"-f FOLDER, give enjoy the same -f FOLDER (both commands default to -f {LOG_FOLDER})"
        ) from error
    return Path(model_path)


def enjoy(argv: Sequence[str]) -> None:
    """`sb3-er enjoy --algo ALGO --env ENV [-f FOLDER --no-render ...]`: rl_zoo3's enjoy of a model trained by
    ``sb3-er train``: by default the latest run in ``logs/`` (:data:`LOG_FOLDER`), where ``sb3-er train`` writes. A
    missing model is a ModelNotFoundError naming the place looked in and the train command that writes there; nothing
    is downloaded.

    :param argv: the arguments after ``enjoy`` (rl_zoo3's enjoy options).
    """
    from rl_zoo3.enjoy import enjoy as zoo_enjoy

    arguments = _with_defaults(argv, "enjoy")
    if not _has_option(arguments, "-h", "--help"):
        register_algorithms()
        env_id = _env_id(arguments)
        register_env_id(env_id)
        _check_env_kwargs("sb3-er enjoy", env_id, arguments)  # the user's settings first, then where the model is
        find_trained_model(arguments)
    _run_zoo_script(zoo_enjoy, "sb3-er enjoy", arguments, check_env_kwargs=False)


COMMANDS = {"train": train, "enjoy": enjoy, "optimize": optimize}


def run_command(command: str, argv: Sequence[str]) -> None:
    """Run `command` ("train", "enjoy" or "optimize") with `argv`; a model enjoy cannot find ends the program with the
    message alone (no traceback).

    :param command: one of :data:`COMMANDS`.
    :param argv: the arguments after the command's name.
    """
    try:
        COMMANDS[command](argv)
    except ModelNotFoundError as error:
        raise SystemExit(f"sb3-er {command}: error: {error}") from error


def main(argv: Sequence[str] | None = None) -> None:
    """`python -m sb3_er.zoo {train,enjoy,optimize} ...`.

    :param argv: the verb and its arguments (default None: ``sys.argv[1:]``).
    """
    arguments = list(sys.argv[1:] if argv is None else argv)
    if not arguments or arguments[0] not in COMMANDS:
        raise SystemExit(f"usage: python -m sb3_er.zoo {{{','.join(COMMANDS)}}} --algo ALGO --env ENV [options]")
    run_command(arguments[0], arguments[1:])


if __name__ == "__main__":
    main()

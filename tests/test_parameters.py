"""What an algorithm accepts is what its constructor takes: the one `accepted_parameters`, which the API pages list and
the runner passes ``--algo-kwargs`` and zoo settings through, agrees with calling the constructor."""

from __future__ import annotations

import inspect

import pytest

import sb3_er_envs  # noqa: F401  (registers the environment ids)
from sb3_er.common.docstrings import accepted_parameters
from sb3_er.experiments.jobs import RUNNER_ARGUMENTS, RunJob, check_algo_kwargs, job_model_kwargs
from sb3_er.experiments.specs import EXPERIMENTS
from sb3_er.zoo import algorithm_classes

ALGORITHMS = algorithm_classes()
ENV = "sb3_er/WindyCliff-v0"
SET_BY_THE_TEST = {"self", "policy", "env", "_init_setup_model"}


def signature_parameters(cls: type) -> dict[str, inspect.Parameter]:
    """Every named parameter of every ``__init__`` of sb3-er's classes up `cls`'s MRO (read with inspect alone, the
    nearest class's default first): the candidates a caller might pass."""
    found: dict[str, inspect.Parameter] = {}
    for klass in cls.__mro__:
        if "__init__" in vars(klass) and klass.__module__.startswith("sb3_er"):
            for name, parameter in inspect.signature(vars(klass)["__init__"]).parameters.items():
                if parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY):
                    found.setdefault(name, parameter)
    return found


def constructs(cls: type, name: str, value) -> bool:
    """Whether ``cls("TileQ", env, name=value)`` is a call the constructor takes (no TypeError about its arguments)."""
    try:
        cls("TileQ", ENV, _init_setup_model=False, **{name: value})
    except TypeError as error:
        if "argument" in str(error):
            return False
        raise
    return True


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_every_accepted_parameter_is_taken_and_every_other_is_refused(algo):
    cls = ALGORITHMS[algo]
    candidates = signature_parameters(cls)
    accepted = accepted_parameters(cls)
    assert set(accepted) <= set(candidates), f"{algo}: accepted names that no constructor has"
    for name, parameter in candidates.items():
        if name in SET_BY_THE_TEST or parameter.default is inspect.Parameter.empty:
            continue
        assert constructs(cls, name, parameter.default) == (name in accepted), (
            f"{cls.__name__}({name}=...) {'fails' if name in accepted else 'works'}, but accepted_parameters says "
            f"{'it is' if name in accepted else 'it is not'} accepted"
        )


def test_er_refuses_the_trace_lambda_it_sets_itself():
    er, sarsa = ALGORITHMS["er"], ALGORITHMS["sarsa_lambda"]
    assert "trace_lambda" not in accepted_parameters(er) and "online_lambda" in accepted_parameters(er)
    assert "trace_lambda" in accepted_parameters(sarsa)
    with pytest.raises(ValueError, match=r"er has no parameters \['trace_lambda'\]"):
        check_algo_kwargs([er], {"trace_lambda": 0.5}, who="er")
    check_algo_kwargs([er, sarsa], {"trace_lambda": 0.5})  # Sarsa(lambda) of the two takes it
    job = RunJob(EXPERIMENTS["gridworld"], "er", 0, 5, csv_path=None, algo_kwargs=(("trace_lambda", 0.5),))
    kwargs = job_model_kwargs(job)
    assert "trace_lambda" not in kwargs
    er("TileQ", ENV, _init_setup_model=False, **kwargs)  # what the runner builds is a call ER takes


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_a_job_passes_every_accepted_parameter_the_runner_does_not_set(algo):
    cls = ALGORITHMS[algo]
    defaults = {name: parameter.default for name, parameter in signature_parameters(cls).items()}
    settable = [name for name in accepted_parameters(cls) if name not in RUNNER_ARGUMENTS]
    algo_kwargs = tuple(sorted((name, defaults[name]) for name in settable))
    check_algo_kwargs([cls], dict(algo_kwargs), who=algo)
    job = RunJob(EXPERIMENTS["gridworld"], algo, 0, 5, csv_path=None, algo_kwargs=algo_kwargs)
    kwargs = job_model_kwargs(job)
    assert set(settable) <= set(kwargs)
    cls("TileQ", ENV, _init_setup_model=False, **kwargs)


@pytest.mark.parametrize("volume", [("n_replays", 5), ("replay_ratio", 4.0)])
def test_a_replay_volume_given_to_a_job_replaces_the_configs(volume):
    """The grid world's entry replays 10 trajectories per one stored; --algo-kwargs n_replays:5 (or a replay ratio)
    replaces that volume, where passing both would be refused."""
    assert (
        job_model_kwargs(RunJob(EXPERIMENTS["gridworld"], "er", 0, 5, csv_path=None))["replays_per_stored_trajectory"]
        == 10.0
    )
    kwargs = job_model_kwargs(RunJob(EXPERIMENTS["gridworld"], "er", 0, 5, csv_path=None, algo_kwargs=(volume,)))
    assert "replays_per_stored_trajectory" not in kwargs and kwargs[volume[0]] == volume[1]
    name, value = volume
    assert ALGORITHMS["er"]("TileQ", ENV, **kwargs).stabilizers[name] == value


@pytest.mark.parametrize("zoo_configs", [True, False])
@pytest.mark.parametrize("experiment", ["gridworld", "pendulum", "walker", "leo"])
def test_a_reproduction_runs_the_thesis_preset_unless_told_otherwise(experiment, zoo_configs):
    """Every reproduction passes preset="thesis" to the ER classes, with or without the zoo configs, so that a later
    class default cannot change the thesis's runs; ``--algo-kwargs preset:stable`` chooses the other; Sarsa(λ) takes
    no preset."""
    import dataclasses

    spec = dataclasses.replace(EXPERIMENTS[experiment], zoo_configs=zoo_configs)
    for algo in ("er", "er_sigma", "residual_er", "residual_er_sigma"):
        assert job_model_kwargs(RunJob(spec, algo, 0, 5, csv_path=None))["preset"] == "thesis"
        job = RunJob(spec, algo, 0, 5, csv_path=None, algo_kwargs=(("preset", "stable"),))
        assert job_model_kwargs(job)["preset"] == "stable"
    assert "preset" not in job_model_kwargs(RunJob(spec, "sarsa_lambda", 0, 5, csv_path=None))

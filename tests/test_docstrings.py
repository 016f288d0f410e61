"""Every public class documents every parameter its constructor accepts and every public function and method every
parameter it takes (the API pages and help() are complete), and inherit_parameters repeats a base's documentation per
class with this class's defaults."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import sb3_er
import sb3_er_envs
from sb3_er.common.docstrings import (
    accepted_parameters,
    documented_parameters,
    inherit_parameters,
    parameter_fields,
    undocumented_parameters,
)


def public_modules() -> list:
    modules = []
    for package in (sb3_er, sb3_er_envs):
        found = pkgutil.walk_packages(package.__path__, package.__name__ + ".")
        names = [package.__name__] + [
            info.name for info in found if not any(part.startswith("_") for part in info.name.split(".")[1:])
        ]
        modules += [importlib.import_module(name) for name in names]
    return modules


def public_classes() -> list[type]:
    classes = [
        obj
        for module in public_modules()
        for key, obj in vars(module).items()
        if inspect.isclass(obj) and not key.startswith("_") and obj.__module__ == module.__name__
    ]
    return sorted(set(classes), key=lambda cls: f"{cls.__module__}.{cls.__qualname__}")


CLASSES = public_classes()


def _overrides_a_foreign_method(cls: type, name: str) -> bool:
    """Whether `name` overrides a method of a base class outside sb3-er (gymnasium's ``step``, dm_control's
    ``get_reward``), whose docstring documents it when the override has none of its own."""
    return any(name in vars(base) for base in cls.__mro__[1:] if not base.__module__.startswith("sb3_er"))


def public_functions() -> dict[str, object]:
    """Every public function of the public modules (numba kernels by their Python function) and every public method
    (static and class methods included) of the public classes, by qualified name; a method without a docstring of
    its own that overrides a method of a base outside sb3-er is left out (the base documents it)."""
    functions = {}
    for module in public_modules():
        for key, obj in vars(module).items():
            obj = getattr(obj, "py_func", obj)  # a numba dispatcher
            if key.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
                continue
            if inspect.isfunction(obj):
                functions[f"{module.__name__}.{key}"] = obj
    for cls in CLASSES:
        for key, member in vars(cls).items():
            member = member.__func__ if isinstance(member, (staticmethod, classmethod)) else member
            if key.startswith("_") or not inspect.isfunction(member):
                continue
            if member.__doc__ is None and _overrides_a_foreign_method(cls, key):
                continue
            functions[f"{cls.__module__}.{cls.__qualname__}.{key}"] = member
    return dict(sorted(functions.items()))


FUNCTIONS = public_functions()


def test_the_public_classes_are_found():
    names = {cls.__name__ for cls in CLASSES}
    assert {
        "ER",
        "ERSigma",
        "ResidualER",
        "ResidualERSigma",
        "SarsaLambda",
        "Dyna",
        "FQI",
        "LSPI",
        "TileCoder",
        "TileQPolicy",
        "TrajectoryReplayBuffer",
        "WindyCliffEnv",
        "PendulumSwingupEnv",
        "SimplestWalkerEnv",
        "LeoEnv",
    } <= names


@pytest.mark.parametrize("cls", CLASSES, ids=[f"{cls.__module__}.{cls.__qualname__}" for cls in CLASSES])
def test_every_constructor_parameter_is_documented(cls):
    missing = [name for name in accepted_parameters(cls) if name not in documented_parameters(cls.__doc__)]
    assert not missing, f"{cls.__module__}.{cls.__qualname__} does not document {missing}"


def test_the_public_functions_are_found():
    assert {
        "sb3_er.common.tile_coding.default_tile_widths",
        "sb3_er.common.kernels.replay.replay_phase",
        "sb3_er.common.policies.TileQPolicy.q_values",
        "sb3_er.common.base_class.TileQAlgorithm.learn",
        "sb3_er_envs.windy_cliff.WindyCliffEnv.reset",
        "sb3_er.zoo.config_path",
    } <= set(FUNCTIONS)
    assert "sb3_er_envs.pendulum.PendulumSwingupEnv.step" not in FUNCTIONS  # gymnasium's docstring documents it


@pytest.mark.parametrize("name", list(FUNCTIONS))
def test_every_function_parameter_is_documented(name):
    missing = undocumented_parameters(FUNCTIONS[name])
    assert not missing, f"{name} does not document {missing} (add :param name: fields to its docstring)"


def test_a_parameter_described_only_in_prose_counts_as_undocumented():
    def prose(path, remedy="rerun"):
        """Read `path`; `remedy` says what to do."""

    def fields(path, remedy="rerun"):
        """Read a file.

        :param path: the file.
        :param remedy: what to do.
        """

    assert undocumented_parameters(prose) == ["path", "remedy"]
    assert undocumented_parameters(fields) == []


@pytest.mark.parametrize(
    "cls",
    [
        sb3_er.SarsaLambda,
        sb3_er.ER,
        sb3_er.ERSigma,
        sb3_er.ResidualER,
        sb3_er.ResidualERSigma,
        sb3_er.Dyna,
        sb3_er.FQI,
        sb3_er.LSPI,
    ],
)
def test_algorithms_state_every_default(cls):
    fields = parameter_fields(cls.__doc__)
    for name in inspect.signature(cls).parameters:
        if name in fields:
            assert "default" in fields[name].lower(), (cls.__name__, name, fields[name])
    assert "as in TileQAlgorithm" not in cls.__doc__


def test_er_sigma_lists_the_parameters_of_er_and_its_base_with_its_own_defaults():
    fields = parameter_fields(sb3_er.ERSigma.__doc__)
    assert {"sigma", "n_replays", "replay_order", "learning_rate", "gamma", "exploration_rate", "seed"} <= set(fields)
    assert "trace_lambda" not in fields  # ER sets it from online_lambda; ERSigma(trace_lambda=...) is no option
    assert '"average_worst" (default' in fields["sigma"]
    assert "0.99" in fields["gamma"] and "0.05" in fields["exploration_rate"]


def test_inherit_parameters_by_hand():
    class Base:
        """Base.

        :param a: the a, in metres.
        :param b: the b (default 2).
        """

        def __init__(self, a=1.0, b=2, c=None):
            pass

    Base.__module__ = "sb3_er.tests"

    @inherit_parameters(hidden=("b",))
    class Child(Base):
        """Child.

        :param d: the d.
        """

        def __init__(self, d=4, a=5.0, **kwargs):
            super().__init__(a=a, **kwargs)

    Child.__module__ = "sb3_er.tests"
    Child = inherit_parameters(hidden=("b",))(Child)  # again, now that the module says it is ours
    assert accepted_parameters(Child) == ["d", "a", "c"]
    fields = parameter_fields(Child.__doc__)
    assert fields["d"] == ":param d: the d. Default: ``4``."
    assert fields["a"] == ":param a: the a, in metres. Default: ``5.0``."  # the child's default, not the base's
    assert "b" not in fields and "c" not in fields  # hidden; and c is documented nowhere
    assert documented_parameters(Child.__doc__) == {"d", "a"}


def test_numpy_parameter_sections_count_as_documentation():
    doc = """Env.

    Parameters
    ----------
    width, height:
        Grid size.
    wind_probability:
        Probability.

    Other text.
    """
    assert documented_parameters(doc) == {"width", "height", "wind_probability"}

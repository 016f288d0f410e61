"""Every public class documents every parameter its constructor accepts (the API pages are complete), and
inherit_parameters repeats a base's documentation per class with this class's defaults."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import sb3_er
import sb3_er_envs
from sb3_er.common.docstrings import accepted_parameters, documented_parameters, inherit_parameters, parameter_fields


def public_classes() -> list[type]:
    classes = []
    for package in (sb3_er, sb3_er_envs):
        modules = pkgutil.walk_packages(package.__path__, package.__name__ + ".")
        names = [package.__name__] + [info.name for info in modules
                                      if not any(part.startswith("_") for part in info.name.split(".")[1:])]
        for name in names:
            module = importlib.import_module(name)
            classes += [obj for key, obj in vars(module).items() if inspect.isclass(obj) and not key.startswith("_")
                        and obj.__module__ == module.__name__]
    return sorted(set(classes), key=lambda cls: f"{cls.__module__}.{cls.__qualname__}")


CLASSES = public_classes()


def test_the_public_classes_are_found():
    names = {cls.__name__ for cls in CLASSES}
    assert {"ER", "ERSigma", "ResidualER", "ResidualERSigma", "SarsaLambda", "Dyna", "FQI", "LSPI", "TileCoder",
            "TileQPolicy", "TrajectoryReplayBuffer", "WindyCliffEnv", "PendulumSwingupEnv", "SimplestWalkerEnv",
            "LeoEnv"} <= names


@pytest.mark.parametrize("cls", CLASSES, ids=[f"{cls.__module__}.{cls.__qualname__}" for cls in CLASSES])
def test_every_constructor_parameter_is_documented(cls):
    missing = [name for name in accepted_parameters(cls) if name not in documented_parameters(cls.__doc__)]
    assert not missing, f"{cls.__module__}.{cls.__qualname__} does not document {missing}"


@pytest.mark.parametrize("cls", [sb3_er.SarsaLambda, sb3_er.ER, sb3_er.ERSigma, sb3_er.ResidualER,
                                 sb3_er.ResidualERSigma, sb3_er.Dyna, sb3_er.FQI, sb3_er.LSPI])
def test_algorithms_state_every_default(cls):
    fields = parameter_fields(cls.__doc__)
    for name, parameter in inspect.signature(cls).parameters.items():
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

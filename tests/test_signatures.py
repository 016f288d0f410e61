"""Every public class spells out its constructor (``help()``, ``inspect.signature``, IDEs and the API pages show every
parameter with its default), its signature and its documentation agree, and an algorithm's constructor takes every
parameter of its bases and hands each value on to the model."""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path

import pytest

import sb3_er
import sb3_er_envs  # noqa: F401  (registers the environment ids)
from sb3_er.common.base_class import TileQAlgorithm
from sb3_er.common.docstrings import NOT_STATED, documented_default, documented_parameters, parameter_fields

DOCS = Path(__file__).resolve().parents[1] / "docs"
ENV = "sb3_er/WindyCliff-v0"
NAMED = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)


def _documented_classes() -> dict[str, type]:
    """The classes the API pages document: ``autoclass`` entries and the classes an ``automodule``'s ``:members:``
    names (all of the module's public classes for an empty list)."""
    classes = {}
    for page in [DOCS / "api.md", *sorted((DOCS / "algorithms").glob("*.md"))]:
        text = page.read_text(encoding="utf-8")
        for match in re.finditer(r"\.\. auto(class|module):: (\S+)((?:\n +:[\w-]+:.*)*)", text):
            kind, name, options = match.groups()
            if kind == "class":
                module, _, attribute = name.rpartition(".")
                classes[name] = getattr(importlib.import_module(module), attribute)
                continue
            members = re.search(r":members:(.*)", options)
            if members is None:
                continue
            module = importlib.import_module(name)
            names = [m.strip() for m in members.group(1).split(",") if m.strip()] or [
                key for key in vars(module) if not key.startswith("_")
            ]
            for key in names:
                obj = getattr(module, key)
                if inspect.isclass(obj) and obj.__module__ == module.__name__:
                    classes[f"{name}.{key}"] = obj
    return classes


def public_classes() -> dict[str, type]:
    """sb3_er's exports and the classes of the API pages, less exceptions and warnings (their signature is
    Python's)."""
    classes = {f"sb3_er.{name}": getattr(sb3_er, name) for name in sb3_er.__all__}
    classes.update(_documented_classes())
    found = {}
    for cls in classes.values():
        if inspect.isclass(cls) and not issubclass(cls, BaseException):
            found.setdefault(f"{cls.__module__}.{cls.__qualname__}", cls)
    return dict(sorted(found.items()))


CLASSES = public_classes()
ALGORITHMS = {
    name: cls for name, cls in CLASSES.items() if issubclass(cls, TileQAlgorithm) and cls is not TileQAlgorithm
}


def named_parameters(cls: type) -> dict[str, inspect.Parameter]:
    """The parameters a caller names, from ``inspect.signature(cls)``: private ones (``_init_setup_model``) left out."""
    return {
        name: parameter
        for name, parameter in inspect.signature(cls).parameters.items()
        if parameter.kind in NAMED and not name.startswith("_")
    }


def test_the_public_classes_are_found():
    names = {cls.__name__ for cls in CLASSES.values()}
    assert {
        "SarsaLambda",
        "ER",
        "ERSigma",
        "ResidualER",
        "ResidualERSigma",
        "Dyna",
        "FQI",
        "LSPI",
        "TileQAlgorithm",
        "TileQPolicy",
        "TrajectoryReplayBuffer",
        "TileCoder",
        "RewardBounds",
        "TileFeatures",
        "NearestNeighbourModel",
        "EpisodeReturnProtocol",
    } <= names
    assert {cls.__name__ for cls in ALGORITHMS.values()} == {
        "SarsaLambda",
        "ER",
        "ERSigma",
        "ResidualER",
        "ResidualERSigma",
        "Dyna",
        "FQI",
        "LSPI",
    }


@pytest.mark.parametrize("name", list(CLASSES))
def test_the_signature_spells_out_every_parameter(name):
    """No ``*args``/``**kwargs`` left for a parameter to hide in (a wrapper's single ``env`` is its own)."""
    hidden = [
        parameter.name
        for parameter in inspect.signature(CLASSES[name]).parameters.values()
        if parameter.kind in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    ]
    assert not hidden, f"{name}'s signature hides parameters in {hidden}: list each one with its default"


@pytest.mark.parametrize("name", list(CLASSES))
def test_the_signature_and_the_documented_parameters_agree(name):
    cls = CLASSES[name]
    signature = named_parameters(cls)
    documented = documented_parameters(cls.__doc__)
    assert not set(signature) - documented, f"{name} does not document {sorted(set(signature) - documented)}"
    assert not documented - set(signature), f"{name} documents {sorted(documented - set(signature))}, no parameter"
    for parameter, field in parameter_fields(cls.__doc__).items():
        stated = documented_default(field)
        if stated is NOT_STATED:
            continue
        default = signature[parameter].default
        assert default is not inspect.Parameter.empty, f"{name}: {parameter} has no default, its docs state {stated!r}"
        assert stated == default and isinstance(stated, bool) == isinstance(default, bool), (
            f"{name}: the docs state {parameter}'s default as {stated!r}, the signature has {default!r}"
        )


@pytest.mark.parametrize("name", list(ALGORITHMS))
def test_an_algorithm_states_every_default(name):
    """The algorithms' pages are where users read their defaults: every field states one that the test above reads."""
    cls = ALGORITHMS[name]
    fields = parameter_fields(cls.__doc__)
    unread = [parameter for parameter in named_parameters(cls) if documented_default(fields[parameter]) is NOT_STATED]
    assert not unread, f"{name}: no default that documented_default reads in the fields of {unread}"


def _own_fields(cls: type) -> set[str]:
    """The parameters that `cls`'s own docstring documents (before inherit_parameters completed it)."""
    return set(parameter_fields(vars(cls).get("__original_doc__", cls.__doc__)))


def _hidden(cls: type) -> set[str]:
    return {name for klass in cls.__mro__ for name in vars(klass).get("hidden_parameters", ())}


@pytest.mark.parametrize("name", list(ALGORITHMS))
def test_an_algorithm_takes_every_parameter_of_its_bases(name):
    """A parameter added to a base (``TileQAlgorithm``, ``ER``) must be added to every algorithm built on it: this
    names each algorithm whose signature lacks it or gives it another default without documenting its own."""
    cls = ALGORITHMS[name]
    signature = inspect.signature(cls).parameters
    for base in cls.__mro__[1:]:
        if "__init__" not in vars(base) or not base.__module__.startswith("sb3_er"):
            continue
        for parameter in list(inspect.signature(vars(base)["__init__"]).parameters.values())[1:]:
            if parameter.kind not in NAMED or parameter.name in _hidden(cls) or parameter.name in ("policy", "env"):
                continue
            assert parameter.name in signature, (
                f"{cls.__name__}.__init__ lacks {parameter.name!r} of {base.__name__}: add it to its signature and "
                "its super().__init__ call"
            )
            own = next(
                (klass for klass in cls.__mro__ if parameter.name in _own_fields(klass) and klass is not base), None
            )
            if own is None or not issubclass(own, base):
                assert signature[parameter.name].default == parameter.default, (
                    f"{cls.__name__}'s default of {parameter.name} is {signature[parameter.name].default!r}, "
                    f"{base.__name__}'s {parameter.default!r}; a class that changes a default documents the parameter"
                )


class _Marker:
    """A value no code path makes by itself: found on the model only if the constructor handed it on."""

    def __repr__(self) -> str:
        return "<marker>"


#: Arguments the base acts on in the constructor (a marker would not do): a value to pass and how to see it arrived.
_OBSERVED = {
    "verbose": (2, lambda model: model.verbose == 2),
    "seed": (12345, lambda model: model.seed == 12345),
}


def _arrived(model, name: str, value) -> bool:
    """Whether `value` is kept on `model` under the parameter's name (SB3's convention, which saving relies on), or
    its private form (``_stats_window_size``)."""
    return any(getattr(model, attribute, None) is value for attribute in (name, f"_{name}"))


@pytest.mark.parametrize(
    "name, parameter",
    [
        (name, parameter)
        for name, cls in ALGORITHMS.items()
        for parameter in named_parameters(cls)
        if parameter not in ("policy", "env")  # every construction here passes them and builds on them
    ],
)
def test_every_argument_reaches_the_model(name, parameter):
    """An argument a subclass takes and forgets to hand to its base would be silently replaced by the base's
    default: each one given must be on the model."""
    cls = ALGORITHMS[name]
    if parameter == "device":
        with pytest.raises(RuntimeError, match="device"):  # SB3 hands it to torch.device, which refuses it
            cls("TileQ", ENV, device="no-such-device", _init_setup_model=False)
        return
    value, arrived = _OBSERVED.get(parameter, (_Marker(), None))
    model = cls("TileQ", ENV, _init_setup_model=False, **{parameter: value})
    assert "policy" not in vars(model), f"{name} did not hand on _init_setup_model=False"
    assert arrived(model) if arrived else _arrived(model, parameter, value), (
        f"{name}({parameter}=...) does not reach the model: hand it to super().__init__"
    )


@pytest.mark.parametrize(
    "field, default",
    [
        (":param gamma: discount factor (default 0.99, thesis 4.2).", 0.99),
        (":param buffer_size: transitions kept (default 1,000,000); the oldest are evicted.", 1_000_000),
        (':param replay_order: "reversed" (default, the thesis\'s), "forward" or "uniform".', "reversed"),
        (":param online_lambda: lambda between replays, or None (default) to act only.", None),
        (":param residual_zeta: zeta in [0, 1]: 1 (default) is the residual gradient.", 1),
        (":param prune_threshold: the share of covered samples; default 0.9.", 0.9),
        (":param n_iterations: steps per fit (>= 1; default 10).", 10),
        (":param solver_tolerance: CG stops there. Default: ``1e-06``.", 1e-6),
        (":param device: \"cpu\". Default: ``'cpu'``.", "cpu"),
        (":param memory_size: the table's size (default 2**22).", 4_194_304),
        (":param action_bins: levels per dimension; default 7 per dimension while at most 343 actions.", NOT_STATED),
        (":param value_watch: watch every value. It defaults to watching.", NOT_STATED),
        (":param tile_widths: tile width per observation dimension.", NOT_STATED),
    ],
)
def test_documented_default_reads_the_forms_the_docs_use(field, default):
    stated = documented_default(field)
    assert stated is default if default is NOT_STATED or default is None else stated == default


def test_a_field_with_two_defaults_is_refused():
    with pytest.raises(ValueError, match="several defaults"):
        documented_default(":param policy_kwargs: tile coding (``n_tilings``, default 16); default None: the env's.")
    assert documented_default(":param ridge: lambda (> 0, default 1). Default: ``1.0``.") == 1  # 1 and 1.0 agree

"""Parameter documentation repeated per class, as sb3-contrib repeats it, from one written source per parameter.

An algorithm passes most of its constructor's parameters on to its base through ``**kwargs`` (``ERSigma`` to ``ER``,
``ER`` to ``TileQAlgorithm``). :func:`inherit_parameters` completes such a class's docstring with the ``:param:``
fields of every parameter it accepts and does not document itself, taken from the classes it passes them to, so that
``help(ERSigma)`` and the API pages list every parameter of ``ERSigma`` with its meaning, unit and default.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Iterable

_FIELD = re.compile(r"^:param (\w+):")
_NAMED = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)


def parameter_fields(docstring: str | None) -> dict[str, str]:
    """The ``:param name:`` fields of `docstring`, each with its indented continuation lines, by parameter name.

    :param docstring: the docstring (None reads as empty).
    """
    fields: dict[str, list[str]] = {}
    name = None
    for line in inspect.cleandoc(docstring or "").splitlines():
        match = _FIELD.match(line)
        if match:
            name = match.group(1)
            fields[name] = [line]
        elif name is not None and line[:1].isspace() and line.strip():
            fields[name].append(line)
        else:
            name = None
    return {name: "\n".join(lines) for name, lines in fields.items()}


def documented_parameters(docstring: str | None) -> set[str]:
    """Every parameter name `docstring` documents: its ``:param name:`` fields, and the entries of a NumPy-style
    ``Parameters`` section (``name:`` or ``name, other:`` lines followed by an indented description).

    :param docstring: the docstring (None reads as empty).
    """
    names = set(parameter_fields(docstring))
    lines = inspect.cleandoc(docstring or "").splitlines()
    for index, line in enumerate(lines[:-1]):
        if line.strip() == "Parameters" and set(lines[index + 1].strip()) == {"-"}:
            for entry in lines[index + 2 :]:
                if entry.strip() and not entry[:1].isspace():
                    match = re.fullmatch(r"([\w*]+(?:,\s*[\w*]+)*)\s*(?::.*)?", entry.strip())
                    if not match:
                        break
                    names.update(name.strip().lstrip("*") for name in match.group(1).split(","))
    return names


def undocumented_parameters(function, docstring: str | None = None) -> list[str]:
    """The named parameters of `function` (not ``self``, ``cls`` or private ones) that its docstring does not document
    (:func:`documented_parameters`), in signature order: a parameter described only in prose counts as undocumented.

    :param function: a function or method (a numba kernel by its ``py_func``).
    :param docstring: the docstring to read instead of the function's own (a class's, for its ``__init__``); default
        None: the function's.
    :return: the names, empty when every parameter has its field.
    """
    names = [
        parameter.name
        for parameter in inspect.signature(function).parameters.values()
        if parameter.kind in (inspect.Parameter.POSITIONAL_ONLY, *_NAMED)
        and parameter.name not in ("self", "cls")
        and not parameter.name.startswith("_")
    ]
    documented = documented_parameters(function.__doc__ if docstring is None else docstring)
    return [name for name in names if name not in documented]


def accepted_parameters(cls: type) -> list[str]:
    """The keyword arguments `cls(...)` accepts, in order: the named parameters of its ``__init__`` and, while an
    ``__init__`` takes ``**kwargs``, those of the next class up the MRO that defines one (within sb3_er), less the
    names a class passes on itself (its ``hidden_parameters``: ``ER`` passes ``trace_lambda=online_lambda``, so
    ``ER(trace_lambda=...)`` is no call it takes). Private names (``_init_setup_model``) are left out.

    The one source of what an algorithm accepts: the API pages list these parameters, and the runner passes a zoo
    config's and ``--algo-kwargs``' settings through to a model only when they are among them
    (:func:`sb3_er.experiments.jobs.job_model_kwargs`).

    :param cls: the class, e.g. ``ERSigma``.
    :return: the parameter names, in the order the constructors declare them.
    """
    hidden: set[str] = set()
    for klass in cls.__mro__:
        hidden.update(vars(klass).get("hidden_parameters", ()))
    names: list[str] = []
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        if not klass.__module__.startswith(("sb3_er", "sb3_er_envs")):
            break
        parameters = list(inspect.signature(klass.__init__).parameters.values())[1:]
        for parameter in parameters:
            if parameter.kind in _NAMED and not parameter.name.startswith("_") and parameter.name not in names:
                names.append(parameter.name)
        if not any(parameter.kind is inspect.Parameter.VAR_KEYWORD for parameter in parameters):
            break
    return [name for name in names if name not in hidden or name in _own_signature(cls)]


def _own_signature(cls: type) -> set[str]:
    init = vars(cls).get("__init__")
    return set(inspect.signature(init).parameters) if init is not None else set()


def parameter_defaults(cls: type) -> dict[str, object]:
    """The default of every parameter :func:`accepted_parameters` lists, from the first ``__init__`` up the MRO that
    names it (a subclass's own default wins: ERSigma's ``sigma="average_worst"``, not ER's None)."""
    defaults: dict[str, object] = {}
    for klass in cls.__mro__:
        init = vars(klass).get("__init__")
        if init is None or not klass.__module__.startswith(("sb3_er", "sb3_er_envs")):
            continue
        for parameter in list(inspect.signature(init).parameters.values())[1:]:
            if parameter.kind in _NAMED and parameter.default is not inspect.Parameter.empty:
                defaults.setdefault(parameter.name, parameter.default)
    return defaults


def _with_default(field: str, name: str, defaults: dict[str, object]) -> str:
    """`field`, with this class's default of `name` appended when the field does not state its default."""
    if "default" in field.lower() or name not in defaults:
        return field
    return f"{field} Default: ``{defaults[name]!r}``."


def inherit_parameters(cls: type | None = None, *, hidden: Iterable[str] = ()):
    """Class decorator: complete the class's docstring so that it documents every parameter it accepts
    (:func:`accepted_parameters`): the ``:param:`` field of each one it does not document is appended from the nearest
    base class that does, and each field that does not state its default gets this class's default appended.

    :param cls: the class (when used as ``@inherit_parameters``).
    :param hidden: parameters of the bases that this class sets itself and does not accept (e.g. ``ER`` passes
        ``trace_lambda=online_lambda``), inherited by its subclasses.
    """

    def decorate(klass: type) -> type:
        klass.hidden_parameters = tuple(hidden)
        defaults = parameter_defaults(klass)
        own = inspect.cleandoc(klass.__doc__ or "")
        documented = parameter_fields(own)
        for name, field in documented.items():
            own = own.replace(field, _with_default(field, name, defaults), 1)
        missing = []
        for name in accepted_parameters(klass):
            if name in documented:
                continue
            for base in klass.__mro__[1:]:
                field = parameter_fields(vars(base).get("__original_doc__", vars(base).get("__doc__"))).get(name)
                if field is not None:
                    missing.append(_with_default(field, name, defaults))
                    break
        klass.__original_doc__ = inspect.cleandoc(klass.__doc__ or "")
        if missing:
            lines = own.splitlines()
            ends_with_field = (
                bool(documented) and bool(lines) and (lines[-1].startswith(":param") or lines[-1][:1].isspace())
            )
            own = own + ("\n" if ends_with_field else "\n\n") + "\n".join(missing)
        klass.__doc__ = own + "\n"
        return klass

    return decorate(cls) if cls is not None else decorate

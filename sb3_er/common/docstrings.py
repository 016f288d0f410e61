"""Parameter documentation repeated per class, as sb3-contrib repeats it, from one written source per parameter.

Every public class spells out its whole constructor signature, as sb3-contrib's algorithms do, so that ``help()``,
``inspect.signature``, IDEs and the API pages show each parameter with its default; a parameter's documentation is
written once, in the ``:param:`` field of the class that introduces it (``gamma`` in ``TileQAlgorithm``,
``n_replays`` in ``ER``). :func:`inherit_parameters` completes a class's docstring with the fields of every parameter
it accepts and does not document itself, taken from its bases, with this class's default appended where a field does
not state one, so that ``help(ERSigma)`` and the API pages list every parameter of ``ERSigma`` with its meaning, unit
and default. A class documents a base's parameter again only where the parameter means more there or its default
differs (``ERSigma``'s ``sigma="average_worst"``).

Adding a parameter to a class: put it in that class's ``__init__`` (signature, attribute, check in
``_check_hyperparameters``) with its ``:param:`` field, then in the signature and the ``super().__init__`` call of every
public subclass (``tests/test_signatures.py`` names each subclass whose signature or call lacks it). A parameter of
``TileQAlgorithm`` so goes into the eight algorithms, one of ``ER`` into its three presets.
"""

from __future__ import annotations

import ast
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
    """`field`, with this class's default of `name` appended when the field does not state its default
    (:func:`documented_default`)."""
    if name not in defaults or documented_default(field) is not NOT_STATED:
        return field
    return f"{field} Default: ``{defaults[name]!r}``."


NOT_STATED = object()
"""What :func:`documented_default` returns for a field that states no default."""

#: A default as the docs write it: a quoted string, a number (``1,000,000``, ``1e-06``, ``2**22``), None, True or False.
_LITERAL = "(?:{})".format(
    "|".join(
        (
            r'"[^"]*"',
            r"'[^']*'",
            r"-?\d{1,3}(?:,\d{3})+(?:\.\d+)?",
            r"-?\d+(?:\.\d+)?(?:e-?\d+)?(?:\*\*\d+)?",
            "None",
            "True",
            "False",
        )
    )
)
_STATED_DEFAULTS = (
    # the form inherit_parameters appends: "Default: ``0.2``."
    re.compile(r"Default: ``(?P<value>[^`]+)``"),
    # a literal followed by "(default": "None (default) acts ...", '"reversed" (default, the thesis's)'
    re.compile(rf"(?:^|(?<=[\s(]))(?P<value>{_LITERAL}) \(default\b"),
    # "default" followed by a literal: "(default 0.2, ...)", "; default None."
    re.compile(rf"(?:\(|[;,.] )[Dd]efault (?P<value>{_LITERAL})(?=[,;:).]|$)"),
)


def _literal(text: str) -> object:
    """A default as the docs write it, as a value: ``1,000,000`` and ``2**22`` read as numbers."""
    text = text.strip()
    if re.fullmatch(r"-?\d{1,3}(?:,\d{3})+(?:\.\d+)?", text):
        text = text.replace(",", "")
    power = re.fullmatch(r"(\d+)\*\*(\d+)", text)
    if power:
        return int(power.group(1)) ** int(power.group(2))
    return ast.literal_eval(text)


def documented_default(field: str) -> object:
    """The default a ``:param:`` field states, as a value, or :data:`NOT_STATED`.

    A field states its default as ``Default: ``0.2``.`` (what :func:`inherit_parameters` appends), as a literal
    followed by ``(default`` (``"reversed" (default, the thesis's)``, ``None (default) acts ...``), or as
    ``default`` followed by a literal and a ``,``, ``;``, ``:``, ``)`` or ``.`` after an opening parenthesis or a
    ``,``, ``;`` or ``.`` (``(default 0.2, ...)``, ``; default None.``); a default given in words (``default 7 per
    dimension``) states none. ``1,000,000`` and ``2**22`` read as numbers.

    :param field: the field, as :func:`parameter_fields` returns it.
    :return: the stated default; ValueError when the field states two different ones.
    """
    text = " ".join(field.split())
    values = [_literal(match.group("value")) for pattern in _STATED_DEFAULTS for match in pattern.finditer(text)]
    if not values:
        return NOT_STATED
    if any(_differ(value, values[0]) for value in values[1:]):
        raise ValueError(f"the field states several defaults, {values}: {text}")
    return values[0]


def _differ(a: object, b: object) -> bool:
    """Whether two defaults differ (1 and 1.0 do not; True and 1 do)."""
    return a != b or isinstance(a, bool) != isinstance(b, bool)


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

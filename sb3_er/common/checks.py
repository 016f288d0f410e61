"""Hyperparameter checks shared by every algorithm: each failure is a ValueError naming the parameter."""

import math
from typing import Any

import numpy as np


def is_real(value: Any) -> bool:
    """A real number (Python or NumPy int or float), not a bool, string, tuple or array.

    :param value: the value to test.
    """
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def check_number(
    name: str,
    value: Any,
    low: float,
    high: float = math.inf,
    *,
    low_open: bool = False,
    high_open: bool = False,
    optional: bool = False,
    unit: str = "",
) -> None:
    """``value`` must be a finite real number in the interval from ``low`` to ``high`` (open ends as given), or None
    if ``optional``; the ValueError names the parameter, the interval and the value given.

    :param name: the parameter's name, for the message.
    :param value: the value given.
    :param low: the interval's lower end.
    :param high: its upper end (default infinity).
    :param low_open: exclude ``low`` itself (default False).
    :param high_open: exclude ``high`` itself (default False).
    :param optional: accept None too (default False).
    :param unit: unit named in the message (default none).
    """
    if optional and value is None:
        return
    if is_real(value) and math.isfinite(value):
        above = value > low if low_open else value >= low
        below = value < high if high_open else value <= high
        if above and below:
            return
    if high == math.inf:
        interval = f"> {low}" if low_open else f">= {low}"
    else:
        interval = f"in {'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
    raise ValueError(f"{name} must be a finite number {interval}{unit}{' or None' if optional else ''}, got {value!r}")


def check_integer(name: str, value: Any, minimum: int, unit: str = "", optional: bool = False) -> None:
    """``value`` must be an integer (Python or NumPy, not a bool) of at least ``minimum``, or None if ``optional``.

    :param name: the parameter's name, for the message.
    :param value: the value given.
    :param minimum: the least value allowed.
    :param unit: unit named in the message (default none).
    :param optional: accept None too (default False).
    """
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(
            f"{name} must be an integer of at least {minimum}{unit}{' or None' if optional else ''}, got {value!r}"
        )


def check_choice(name: str, value: Any, options) -> None:
    """``value`` must be one of ``options`` (compared by equality; unhashable values are refused, never raised on).

    :param name: the parameter's name, for the message.
    :param value: the value given.
    :param options: the allowed values (any iterable).
    """
    try:
        found = value in options
    except TypeError:
        found = False
    if not found:
        raise ValueError(f"{name} must be one of {list(options)}, got {value!r}")


def check_bool(name: str, value: Any, optional: bool = False) -> None:
    """``value`` must be True or False (Python or NumPy bool, not 0 or 1); the ValueError names the parameter.

    :param name: the parameter's name, for the message.
    :param value: the value given.
    :param optional: None is allowed too (default False).
    """
    if optional and value is None:
        return
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")

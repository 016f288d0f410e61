"""A C function that returns 0.0, for MuJoCo's ``mjcb_time`` while LEO steps (see ``Physics.step_control``).

MuJoCo 3.17 reads the system clock for its profiling timers (``data.timer``) at every stage of every substep when no
``mjcb_time`` callback is installed, about 10 % of a LEO substep on this project's machine. A ``mjcb_time`` that
returns a constant turns those reads into a trivial call; the timers then stay at 0 and nothing else changes.
Compiled by numba (a core dependency) on first use and cached on disk.
"""

from __future__ import annotations

import numba


@numba.cfunc("float64()", cache=True)
def zero_clock() -> float:
    """MuJoCo timer callback: always 0.0 [s]."""
    return 0.0

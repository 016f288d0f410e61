"""Which OpenGL backend MuJoCo may render with, decided before dm_control is imported.

dm_control picks its rendering backend once, when it is imported, from ``MUJOCO_GL``: ``glfw`` (a display), ``egl``
(a GPU or Mesa's EGL) or ``osmesa`` (Mesa's CPU renderer, Debian's ``libosmesa6``). Two of its behaviours break LEO on
machines that cannot render at all (a GPU node without libOSMesa, a slim Docker image):

* a ``MUJOCO_GL`` naming a backend whose library is missing makes ``import dm_control`` itself fail (for OSMesa with
  "'NoneType' object has no attribute 'glGetError'"), although simulating needs no OpenGL;
* with ``MUJOCO_GL`` unset it takes GLFW whenever the ``glfw`` wheel imports, display or not, and rendering then fails.

:func:`prepare_backend` therefore checks, without creating any context, that the libraries of the requested backend
can be loaded (or, when none is requested, picks the first of GLFW (only with a display), EGL and OSMesa whose
libraries load) and otherwise imports dm_control with rendering disabled. Simulation then always works; a render call
raises :class:`RenderingUnavailable` with the reason, naming the missing library and ``MUJOCO_GL``. The package never
overrides a backend whose libraries are present: the user's choice stands.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: Libraries each backend loads through PyOpenGL or the glfw wheel: for each, one of the alternatives must load.
BACKEND_LIBRARIES = {
    "egl": (("EGL",), ("OpenGL", "GL")),
    "osmesa": (("OSMesa",),),
}
BACKEND_HINTS = {
    "egl": "libEGL with libOpenGL or libGL, from a GPU driver or Mesa (Debian: apt install libegl1 libgl1)",
    "osmesa": "libOSMesa (Debian: apt install libosmesa6)",
    "glfw": "a display (DISPLAY or WAYLAND_DISPLAY)",
}
_DISABLED = ("off", "disable", "disabled", "false", "0")
_GLFW_NAMES = ("glfw", "on", "enable", "enabled", "true", "1", "")


class RenderingUnavailable(RuntimeError):
    """MuJoCo cannot render on this machine; the message says why and how to choose a backend."""


def _loadable(name: str) -> bool:
    path = ctypes.util.find_library(name)
    for candidate in (path, f"lib{name}.so", f"lib{name}.so.1", f"lib{name}.so.8"):
        if not candidate:
            continue
        try:
            ctypes.CDLL(candidate)
            return True
        except OSError:
            continue
    return False


def _has_display() -> bool:
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def missing_libraries(backend: str) -> str | None:
    """What ``backend`` lacks on this machine (a description), or None when its libraries load."""
    if backend == "glfw":
        return None if _has_display() else "no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    missing = [
        " or ".join(f"lib{name}" for name in names)
        for names in BACKEND_LIBRARIES[backend]
        if not any(_loadable(name) for name in names)
    ]
    return ", ".join(missing) + " not found" if missing else None


def prepare_backend() -> str | None:
    """Set ``MUJOCO_GL`` so that importing dm_control works; return why rendering is unavailable, or None.

    Call before the first ``import dm_control``. A user's ``MUJOCO_GL`` is kept when its backend's libraries load.
    """
    if "dm_control" in sys.modules:
        return None  # dm_control is imported already: its backend is chosen and we must not touch it
    requested = os.environ.get("MUJOCO_GL")
    if requested is not None:
        name = requested.strip().lower()
        if name in _DISABLED:
            return f"rendering is disabled (MUJOCO_GL={requested})"
        backend = "glfw" if name in _GLFW_NAMES else name
        if backend not in ("glfw", *BACKEND_LIBRARIES):
            return None  # dm_control reports an unknown name itself
        problem = missing_libraries(backend)
        if problem is None:
            return None
        os.environ["MUJOCO_GL"] = "disable"
        os.environ.pop("PYOPENGL_PLATFORM", None)
        return f"MUJOCO_GL={requested} asks for the {backend} backend, but {problem}"
    for backend in ("glfw", "egl", "osmesa"):
        if missing_libraries(backend) is None:
            os.environ["MUJOCO_GL"] = backend
            return None
    os.environ["MUJOCO_GL"] = "disable"
    return "no OpenGL backend is available: no display for glfw, " + "; ".join(
        f"{backend}: {missing_libraries(backend)}" for backend in BACKEND_LIBRARIES
    )


def rendering_error(reason: str, error: BaseException | None = None) -> RenderingUnavailable:
    """The error a render call raises, with the reason and how to pick a working backend."""
    detail = f" ({type(error).__name__}: {error})" if error is not None else ""
    needs = "; ".join(f"{backend} needs {hint}" for backend, hint in BACKEND_HINTS.items())
    return RenderingUnavailable(
        f"MuJoCo cannot render here: {reason}{detail}. Simulation works without rendering. To render, set MUJOCO_GL "
        f"before starting Python to a backend this machine has: {needs}."
    )

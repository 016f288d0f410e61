"""Gait figures of the simplest walker (thesis Figures 4.6 and 6.3) and walker animations.

Figures 4.6 and 6.3 plot, for a learned greedy policy of each algorithm, the stance leg's angle, the hip angle and the
height of the swing foot against time: how high a policy lifts its foot before the heel strike shows how safe its gait
is. :func:`gait_trace` records those three signals at every control step (0.2 model time units, the resolution the
agent sees), :func:`plot_gait` draws them in three stacked panels with one line per algorithm, and
:func:`save_walker_gif` writes the walk as an animated GIF from the env's ``rgb_array`` render.

Works with :class:`~sb3_er_envs.simplest_walker.SimplestWalkerEnv` under any options and with
:class:`~sb3_er_envs.compass_walker.CompassWalkerEnv` (anything with the walker's ``state``, ``dt`` and
``info["swing_foot_height"]``), bare or wrapped; ``model`` is anything with SB3's ``predict``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_er.experiments import files
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT


@dataclass(frozen=True)
class GaitTrace:
    """Signals of one greedy walk, sampled at the start and after every control step (arrays of shape (n,)).

    :param time: time in model time units (the thesis's seconds).
    :param stance_angle: phi_st in rad.
    :param hip_angle: phi_h in rad, wrapped into [-pi, pi).
    :param swing_foot_height: in leg lengths above the slope (negative while the foot scuffs through it at
        mid-stance).
    :param fell: whether the walk ended in a fall.
    :param distance: the walker's progress, the sum of its step lengths, in leg lengths.
    :param distances: the progress at each sample, in leg lengths (default None: not recorded).
    """

    time: np.ndarray
    stance_angle: np.ndarray
    hip_angle: np.ndarray
    swing_foot_height: np.ndarray
    fell: bool
    distance: float
    distances: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.time)


def _walker(env: gym.Env) -> Any:
    base = env.unwrapped
    if not (hasattr(base, "state") and hasattr(base, "dt")):
        raise ValueError(f"need a simplest-walker env (with `state` and `dt`), got {type(base).__name__}")
    return base


def _greedy_walk(model, env: gym.Env, seconds: float, start_state, seed: int | None, on_step) -> None:
    """Run the greedy policy from ``start_state`` (None: the env's own start) for ``seconds`` or until the episode
    ends; calls ``on_step(info)`` after the reset and after every control step."""
    if not (np.isfinite(seconds) and seconds > 0.0):
        raise ValueError(f"seconds must be a positive finite number, got {seconds}")
    base = _walker(env)
    options = None if start_state is None else {"state": np.asarray(start_state, dtype=np.float64)}
    observation, info = env.reset(seed=seed, options=options)
    on_step(info, False)
    for _ in range(max(1, round(seconds / base.dt))):
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(int(np.asarray(action).reshape(-1)[0]))
        on_step(info, terminated)
        if terminated or truncated:
            break


def gait_trace(
    model, env: gym.Env, seconds: float = 10.0, start_state=GARCIA_FIXED_POINT, seed: int | None = None
) -> GaitTrace:
    """Walk greedily with ``model`` in ``env`` for ``seconds`` (or until a fall or the episode's time limit) and record
    time, stance angle, hip angle, swing-foot height and distance walked at every control step.

    ``start_state`` is a state ``[phi_st, phi_h, phi_st', phi_h']`` (default Garcia's fixed point, so that traces of
    different algorithms start alike), or None for the env's random start drawn with ``seed``.

    :param model: the trained model (acts greedily).
    :param env: a simplest-walker env.
    :param seconds: how long to walk [s of model time] (default 10).
    :param start_state: the start (see above; default Garcia's fixed point).
    :param seed: the seed of a random start (default None).
    """
    base = _walker(env)
    rows: list[tuple[float, float, float, float]] = []
    outcome = {"fell": False, "distance": 0.0}

    def record(info, terminated):
        stance, hip = float(base.state[0]), float(base.state[1])
        outcome["fell"] = bool(terminated)
        outcome["distance"] = float(info.get("distance", 0.0))
        rows.append((stance, hip, float(info["swing_foot_height"]), outcome["distance"]))

    _greedy_walk(model, env, seconds, start_state, seed, record)
    values = np.array(rows)
    return GaitTrace(
        time=base.dt * np.arange(len(rows)),
        stance_angle=values[:, 0],
        hip_angle=values[:, 1],
        swing_foot_height=values[:, 2],
        fell=outcome["fell"],
        distance=outcome["distance"],
        distances=values[:, 3],
    )


def plot_gait(traces: Mapping[str, GaitTrace], path: str | Path, title: str | None = None) -> Path:
    """Figures 4.6 / 6.3: stance angle, hip angle and swing-foot height against time in three stacked panels, one line
    per label (e.g. per algorithm); a cross marks a fall. Saved to ``path`` (format from its suffix).

    :param traces: the traces by label.
    :param path: the image file.
    :param title: the figure's title (default None: none).
    """
    if not traces:
        raise ValueError("plot_gait needs at least one trace")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    figure, axes = plt.subplots(3, 1, sharex=True, figsize=(7.0, 6.5))
    panels = (
        ("stance_angle", r"stance leg $\phi_{st}$ [rad]"),
        ("hip_angle", r"hip $\phi_h$ [rad]"),
        ("swing_foot_height", "swing foot height [leg lengths]"),
    )
    for label, trace in traces.items():
        for axis, (field, _) in zip(axes, panels, strict=True):
            values = getattr(trace, field)
            (line,) = axis.plot(trace.time, values, label=label, linewidth=1.2)
            if trace.fell:
                axis.plot(trace.time[-1], values[-1], "x", color=line.get_color(), markersize=8)
    for axis, (_, y_label) in zip(axes, panels, strict=True):
        axis.set_ylabel(y_label)
        axis.grid(alpha=0.3)
    axes[2].axhline(0.0, color="0.4", linewidth=0.8)
    axes[2].set_xlabel("time [s]")
    axes[0].legend(fontsize="small")
    axes[0].set_title(title or "Simplest walker: greedy gait")
    figure.tight_layout()
    files.save_figure(figure, path, dpi=120)
    plt.close(figure)
    return path


def save_walker_gif(
    model,
    path: str | Path,
    seconds: float = 10.0,
    fps: float = 5.0,
    env: gym.Env | None = None,
    start_state=GARCIA_FIXED_POINT,
    seed: int | None = None,
) -> Path:
    """Write a greedy walk of ``model`` as an animated GIF, one frame per control step.

    ``fps`` frames per second of playback: 5 (= 1 / dt) plays in model time. ``env`` must render ``rgb_array``;
    None makes ``sb3_er/SimplestWalker-v0`` with its default options (pass your own env for other options or
    CompassWalker-v0). Needs ``imageio`` (the ``dmc`` extra).

    :param model: the trained model (acts greedily).
    :param path: the GIF file.
    :param seconds: how long to walk [s of model time] (default 10).
    :param fps: frames per second of playback (default 5).
    :param env: the env to walk in (default None: see above).
    :param start_state: the start state (default Garcia's fixed point; None: the env's random start).
    :param seed: the seed of the env's reset (default None).
    """
    if not (np.isfinite(fps) and fps > 0.0):
        raise ValueError(f"fps must be a positive finite number, got {fps}")
    try:
        import imageio.v2 as imageio
    except ImportError as error:  # pragma: no cover - depends on the installed extras
        raise ImportError("save_walker_gif needs imageio: pip install 'sb3-er[dmc]' or pip install imageio") from error
    if env is None:
        import sb3_er_envs  # noqa: F401  (registers the ids)

        env = gym.make("sb3_er/SimplestWalker-v0", render_mode="rgb_array")
    if getattr(env, "render_mode", None) != "rgb_array":
        raise ValueError("save_walker_gif needs an env made with render_mode='rgb_array'")
    frames: list[np.ndarray] = []
    _greedy_walk(model, env, seconds, start_state, seed, lambda info, terminated: frames.append(env.render()))
    path = Path(path)
    with files.atomic_output(path) as temporary:
        imageio.mimsave(temporary, frames, duration=1000.0 / fps, loop=0)
    return path

"""Save a LEO episode as a GIF or MP4, to look at a gait."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from .gait import ObservingGait
from .gym_env import LeoEnv


def save_episode_video(
    path: str | Path,
    policy: Callable | None = None,
    env: LeoEnv | None = None,
    seed: int | None = None,
    fps: float = 15.0,
    max_steps: int | None = None,
) -> dict:
    """Run one episode and write its frames to ``path`` (``.gif``, or ``.mp4`` with the ``imageio-ffmpeg`` package).

    ``policy`` maps ``(observation, info)`` to an action of ``env``; an object with ``predict`` (a Stable-Baselines3
    model) is run greedily; ``None`` walks with Erik's hand-made gait. ``env`` defaults to a new ``LeoEnv`` rendering
    RGB frames. Frames are taken every ``round(30 / fps)`` control steps. Returns the episode's ``steps``, ``distance``,
    ``footsteps``, ``fell`` and ``return``.

    :param path: the file to write (``.gif`` or ``.mp4``).
    :param policy: what acts (see above; default None: Erik's gait).
    :param env: the env to run (default None: a new ``LeoEnv`` rendering RGB frames).
    :param seed: the seed of the env's reset (default None).
    :param fps: frames per second of the video (default 15).
    :param max_steps: the most control steps to run (default None: the whole episode).
    """
    import imageio.v2 as imageio

    path = Path(path)
    if path.suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"video path must end in .gif or .mp4, got {path.name!r}")
    if not fps > 0.0:
        raise ValueError(f"fps must be positive, got {fps}")
    own_env = env is None
    env = LeoEnv(render_mode="rgb_array") if own_env else env
    if env.render_mode != "rgb_array":
        raise ValueError("the environment must be created with render_mode='rgb_array'")
    act = _as_policy(policy)
    every = max(1, round(1.0 / (env.dt * fps)))
    observation, info = env.reset(seed=seed)
    frames = [env.render()]
    total, steps, done = 0.0, 0, False
    while not done and (max_steps is None or steps < max_steps):
        observation, reward, terminated, truncated, info = env.step(act(observation, info))
        total += reward
        steps += 1
        done = terminated or truncated
        if steps % every == 0 or done:
            frames.append(env.render())
    path.parent.mkdir(parents=True, exist_ok=True)
    frame_rate = 1.0 / (env.dt * every)
    if path.suffix.lower() == ".gif":
        imageio.mimsave(path, frames, duration=1000.0 / frame_rate, loop=0)
    else:
        try:
            imageio.mimsave(path, frames, fps=frame_rate)
        except (ImportError, ValueError) as error:
            raise RuntimeError(
                f"writing MP4 needs the imageio-ffmpeg package ({error}); save a .gif instead"
            ) from error
    if own_env:
        env.close()
    return {
        "steps": steps,
        "distance": info["distance"],
        "footsteps": info["footsteps"],
        "fell": info["fell"],
        "return": total,
    }


def _as_policy(policy) -> Callable:
    if policy is None:
        gait = ObservingGait()
        gait.reset()
        return gait.action
    if hasattr(policy, "predict"):
        return lambda observation, info: np.asarray(policy.predict(observation, deterministic=True)[0])
    if callable(policy):
        return policy
    raise TypeError(f"policy must be callable, have predict(), or be None; got {type(policy).__name__}")

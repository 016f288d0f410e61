"""Gymnasium face of the LEO walking task: ``sb3_er/Leo-v0``."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import leo as leo_domain
from ._gl import rendering_error
from .leo import CONTROL_TIMESTEP, PHYSICS_SUBSTEPS, TIME_LIMIT, VOLTAGE_LEVELS, LeoWalk, load_physics

#: Tile widths of Table 4.3 in observation order (angle, rate per joint).
TILE_WIDTHS = (0.14, 5.0, 0.28, 10.0, 0.28, 10.0, 0.28, 10.0, 0.28, 10.0)
#: LEO's original setup also tiled its voltages, 6.67 V wide (about two adjacent levels).
ACTION_TILE_WIDTHS = (6.67, 6.67, 6.67)
#: Declared observation bounds: +-pi for angles, +-10 pi rad/s for rates (Erik's state ranges).
OBSERVATION_BOUND = np.array([math.pi, 10.0 * math.pi] * 5)
_BOUNDS = OBSERVATION_BOUND.tolist()
_LEVEL_VOLTAGES = VOLTAGE_LEVELS.tolist()


def _voltages_of_levels(action) -> list[float]:
    """The voltages [V] of LeoEnv's action (3 integer levels 0..6); anything else raises ValueError.

    An integer array of shape (3,), as SB3 and the gait give, takes a fast path; other sequences go through NumPy."""
    if isinstance(action, np.ndarray) and action.dtype.kind in "iu" and action.shape == (3,):
        levels = action.tolist()
        if 0 <= min(levels) and max(levels) < 7:
            return [_LEVEL_VOLTAGES[level] for level in levels]
    else:
        levels = np.asarray(action)
        indices = levels.astype(np.int64, copy=False)
        if levels.shape == (3,) and np.all(indices == levels) and 0 <= indices.min() and indices.max() < 7:
            return [_LEVEL_VOLTAGES[level] for level in indices.tolist()]
    raise ValueError(f"LEO's action is 3 voltage levels in 0..6 (stance hip, swing hip, swing knee), got {action!r}")


class LeoEnv(gym.Env):
    """LEO walking on its boom (thesis 4.2.3), simulated in MuJoCo through dm_control.

    Observation (Eq. 4.6): torso angle and rate, then angle and rate of the stance hip, swing hip, stance knee and swing
    knee [rad, rad/s]; angles about -y, so hip > 0 is the thigh forward, knee < 0 a bent knee and a positive torso
    angle leans backward. Joint rates are low-pass filtered like Erik's (``filter_rates``). The observation is clipped
    to the declared bounds.

    Action: ``MultiDiscrete([7, 7, 7])``, the voltage level of the stance hip, swing hip and swing knee; level ``k``
    applies ``action_values[joint][k]`` volts (Erik's levels {0, +-3.564, +-7.128, +-10.692} V, level 3 is 0 V).

    Reward per 1/30 s step: -1, -3 per joule of the hip and knee motors' electrical energy, +300 per metre the swing
    ankle gains on the stance ankle, -125 at a fall. A fall (``|torso| > 1`` or ``|torso + stance hip| > 0.36 pi``)
    terminates; after ``time_limit`` seconds (25) the episode is truncated.

    ``info``: ``footstep`` (a change of stance leg happened in this step), ``footstep_length`` [m], ``footsteps`` (net
    count, a backward step counts -1), ``distance`` (hip travel since the start [m]), ``fell``, ``energy`` (J of this
    step), ``stance_leg`` and ``stance_contact``.

    Parameters
    ----------
    render_mode:
        ``None`` or ``"rgb_array"``. Simulating needs no OpenGL; rendering needs a backend this machine has (EGL,
        OSMesa or a display for GLFW, chosen automatically or by ``MUJOCO_GL``), else ``render()`` raises
        :class:`sb3_er_envs.leo.RenderingUnavailable` naming the missing library.
    start_noise:
        Half-width [rad] of the uniform start-pose variation (torso, hips, swing knee); 0 gives Erik's exact pose.
    filter_rates:
        Observe Erik's 10 Hz Butterworth-filtered joint rates (default) or the raw ones.
    floor_parallel_ankles:
        Hold the feet at 3.72 degrees to the floor (about parallel, as the thesis describes) instead of Erik's
        default 3.72 degrees between foot and shank.
    time_limit:
        Episode length in seconds before truncation (25).
    render_size:
        ``(height, width)`` of rendered frames.
    camera:
        Name of the model camera to render from (``"side"`` or ``"back"``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": round(1.0 / CONTROL_TIMESTEP)}

    def __init__(
        self,
        render_mode: str | None = None,
        start_noise: float = 0.05,
        filter_rates: bool = True,
        floor_parallel_ankles: bool = False,
        time_limit: float = TIME_LIMIT,
        render_size: tuple[int, int] = (480, 640),
        camera: str = "side",
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not time_limit > 0.0:
            raise ValueError(f"time_limit must be positive, got {time_limit}")
        self.render_mode = render_mode
        self.physics = load_physics()
        if camera not in [self.physics.model.id2name(i, "camera") for i in range(self.physics.model.ncam)]:
            raise ValueError(f"unknown camera {camera!r}; LEO's model has 'side' and 'back'")
        self.task = LeoWalk(
            random=np.random.RandomState(),
            start_noise=start_noise,
            filter_rates=filter_rates,
            floor_parallel_ankles=floor_parallel_ankles,
        )
        self.max_episode_steps = int(round(time_limit / CONTROL_TIMESTEP))
        self.render_size = tuple(render_size)
        self.camera = camera
        self.dt = CONTROL_TIMESTEP
        self.observation_space = spaces.Box(-OBSERVATION_BOUND, OBSERVATION_BOUND, dtype=np.float64)
        self.action_space = spaces.MultiDiscrete([len(VOLTAGE_LEVELS)] * 3)
        self.tile_widths = np.array(TILE_WIDTHS)
        self.wrap_periods = None  # no periodic dimension: a fall ends the episode long before an angle wraps
        self.memory_size = 2**25  # tile-coding weights: 262,144 state-tile slots of 128 voltage-tile columns
        self.action_values = [VOLTAGE_LEVELS.copy() for _ in range(3)]
        self.action_tile_widths = np.array(ACTION_TILE_WIDTHS)
        self._steps = 0
        self._closed = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.task.random.seed(int(self.np_random.integers(2**32)))
        self.physics.reset_for(self.task)
        self._steps = 0
        return self._observation(), self.task.info(self.physics)

    @property
    def reward_bounds(self) -> dict:
        """Where the rewards lie (the value watch of sb3-er reads it): -1, minus 3 per joule (energy >= 0, unbounded
        above: the lower bound is -inf), plus 300 per metre the swing ankle gains, at most twice the largest
        ankle-to-ankle distance 2 (thigh + shank) in one step; a fall adds -125. The upper bound is loose: a step
        gains millimetres, not the 0.88 m it allows."""
        gain = 2.0 * 2.0 * (leo_domain.THIGH_LENGTH + leo_domain.SHANK_LENGTH)
        high = leo_domain.REWARD_TIME + leo_domain.REWARD_PROGRESS * gain
        return {"step": (-math.inf, high), "terminal": (-math.inf, high + leo_domain.REWARD_FALL)}

    def step(self, action):
        self.task.apply_voltages(*_voltages_of_levels(action), self.physics)
        self.physics.step_control(PHYSICS_SUBSTEPS)
        self.task.after_step(self.physics)
        self._steps += 1
        terminated = self.task.fell
        truncated = not terminated and self._steps >= self.max_episode_steps
        return self._observation(), self.task.reward, terminated, truncated, self.task.info(self.physics)

    def _observation(self) -> np.ndarray:
        values = self.task.stance_values()
        return np.array(
            [
                bound if value > bound else -bound if value < -bound else value
                for value, bound in zip(values, _BOUNDS, strict=True)
            ]
        )

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if leo_domain.RENDERING_UNAVAILABLE is not None:
            raise rendering_error(leo_domain.RENDERING_UNAVAILABLE)
        height, width = self.render_size
        try:
            return self.physics.render(height=height, width=width, camera_id=self.camera)
        except Exception as error:  # noqa: BLE001  (dm_control raises several kinds when no GL context can be made)
            raise rendering_error(f"the {leo_domain.RENDER_BACKEND} backend failed", error) from error

    def close(self):
        if not self._closed:
            self.physics.free()
            self._closed = True

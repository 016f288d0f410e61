"""Pendulum swing-up of thesis section 4.2.1 with the model of Table 4.1, in our reading (DESIGN.md section 7).

State ``s = [theta, theta_dot]``: ``theta = 0`` points up, ``theta = +-pi`` hangs down; ``theta`` is wrapped into
``[-pi, pi)``. The dynamics are

    J * theta'' = m * g * l * sin(theta) - b * theta' + u

with Table 4.1's values m = 1.113 kg, J = 3.773e-3 kg m^2, g = 9.81 m/s^2, l = 8.5e-2 m, and viscous damping b = 0 (the
thesis names none). We read J as the inertia about the pivot, as the equation needs. Table 4.1's J is smaller than
m * l^2 = 8.04e-3 kg m^2, so if it was meant about the centre of mass, pass ``inertia=3.773e-3 + 1.113 * 0.085**2``.

The torque ``u`` takes 7 evenly spaced values in ``[-max_torque, max_torque]``; the default limit 0.6 N m lies below
m * g * l = 0.928 N m, so the pendulum cannot be lifted directly and has to swing (the thesis's motivation). Each control
step holds ``u`` for ``dt = 0.01`` s, integrated by ``substeps`` classical Runge-Kutta (RK4) steps. The angular rate is
clipped to ``[-max_velocity, max_velocity]`` after each control step, which keeps the observation bounded; the clip
never binds in a swing-up (from rest hanging down, the upright position is passed at about 31 rad/s).

The reward of thesis Eq. 4.1 is taken at the state reached by the step,

    r = -5 * theta^2 - 0.1 * theta'^2 - u^2.

Every episode starts hanging down at rest. It ends (``terminated``, ``info["goal_reached"]``) when the pendulum reaches
the goal ``|theta| < goal_angle`` (0.1 rad) and ``|theta'| < goal_velocity`` (1 rad/s), and is ``truncated`` after
``episode_seconds`` (15 s, i.e. 1500 steps). ``info["fell"]`` is always False: reaching the goal is no fall.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numba
import numpy as np
from gymnasium import spaces

from sb3_er_envs import discrete_action_index

_IMAGE_PIXELS = 128


@numba.njit(cache=True)
def _angular_acceleration(theta, velocity, torque, gravity_torque, damping, inertia):
    """theta'' of the pendulum, J * theta'' = m g l sin(theta) - b theta' + u (thesis 4.2.1)."""
    return (gravity_torque * math.sin(theta) - damping * velocity + torque) / inertia


@numba.njit(cache=True)
def pendulum_rk4_step(theta, velocity, torque, gravity_torque, damping, inertia, dt, substeps):
    """Advance (theta, theta') by ``dt`` seconds with ``substeps`` RK4 steps at constant torque; no wrapping here.

    ``gravity_torque`` is m * g * l, so the equation integrated is J * theta'' = m g l sin(theta) - b theta' + u.
    """
    h = dt / substeps
    for _ in range(substeps):
        k1_theta = velocity
        k1_velocity = _angular_acceleration(theta, velocity, torque, gravity_torque, damping, inertia)
        k2_theta = velocity + 0.5 * h * k1_velocity
        k2_velocity = _angular_acceleration(
            theta + 0.5 * h * k1_theta, k2_theta, torque, gravity_torque, damping, inertia
        )
        k3_theta = velocity + 0.5 * h * k2_velocity
        k3_velocity = _angular_acceleration(
            theta + 0.5 * h * k2_theta, k3_theta, torque, gravity_torque, damping, inertia
        )
        k4_theta = velocity + h * k3_velocity
        k4_velocity = _angular_acceleration(theta + h * k3_theta, k4_theta, torque, gravity_torque, damping, inertia)
        theta += h / 6.0 * (k1_theta + 2.0 * k2_theta + 2.0 * k3_theta + k4_theta)
        velocity += h / 6.0 * (k1_velocity + 2.0 * k2_velocity + 2.0 * k3_velocity + k4_velocity)
    return theta, velocity


def wrap_angle(theta: float) -> float:
    """``theta`` wrapped into ``[-pi, pi)``."""
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


class PendulumSwingupEnv(gym.Env):
    """Under-actuated pendulum swing-up (thesis 4.2.1, Table 4.1, reward Eq. 4.1) with 7 discrete torques.

    Parameters
    ----------
    max_torque:
        Torque limit in N m (0.6); must lie below m * g * l so that the task needs swinging.
    n_torques:
        Number of evenly spaced torques in ``[-max_torque, max_torque]`` (7, odd so that zero torque is one of them).
    goal_angle, goal_velocity:
        The episode terminates when ``|theta| < goal_angle`` (0.1 rad) and ``|theta'| < goal_velocity`` (1 rad/s).
    episode_seconds:
        Simulated seconds after which the episode is truncated (15).
    dt, substeps:
        Control period in seconds (0.01) and RK4 steps per control period (5).
    mass, inertia, length, gravity, damping:
        Model parameters (Table 4.1; damping 0 N m s/rad).
    max_velocity:
        Clip and observation bound of the angular rate in rad/s (40).
    render_mode:
        ``None`` or ``"rgb_array"``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}

    def __init__(
        self,
        max_torque: float = 0.6,
        n_torques: int = 7,
        goal_angle: float = 0.1,
        goal_velocity: float = 1.0,
        episode_seconds: float = 15.0,
        dt: float = 0.01,
        substeps: int = 5,
        mass: float = 1.113,
        inertia: float = 3.773e-3,
        length: float = 8.5e-2,
        gravity: float = 9.81,
        damping: float = 0.0,
        max_velocity: float = 40.0,
        render_mode: str | None = None,
    ) -> None:
        for name, value in (
            ("mass", mass),
            ("inertia", inertia),
            ("length", length),
            ("gravity", gravity),
            ("dt", dt),
            ("goal_angle", goal_angle),
            ("goal_velocity", goal_velocity),
            ("max_velocity", max_velocity),
            ("episode_seconds", episode_seconds),
        ):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value}")
        if not (math.isfinite(damping) and damping >= 0.0):
            raise ValueError(f"damping must be a non-negative finite number, got {damping}")
        gravity_torque = mass * gravity * length
        if not 0.0 < max_torque < gravity_torque:
            raise ValueError(
                f"max_torque must lie in (0, m*g*l) = (0, {gravity_torque:.4g}) N m so that the pendulum has to swing "
                f"up, got {max_torque}"
            )
        if int(n_torques) != n_torques or n_torques < 2:
            raise ValueError(f"n_torques must be an integer of at least 2, got {n_torques}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")

        self.max_torque = float(max_torque)
        self.torques = tuple(float(u) for u in np.linspace(-max_torque, max_torque, int(n_torques)))
        self.goal_angle = float(goal_angle)
        self.goal_velocity = float(goal_velocity)
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.max_episode_steps = max(1, round(episode_seconds / dt))
        self.mass = float(mass)
        self.inertia = float(inertia)
        self.length = float(length)
        self.gravity = float(gravity)
        self.damping = float(damping)
        self.gravity_torque = float(gravity_torque)
        self.max_velocity = float(max_velocity)
        self.render_mode = render_mode

        self.tile_widths = np.array([0.33, 0.33])
        self.wrap_periods = (2.0 * math.pi, None)
        self.observation_space = spaces.Box(
            low=np.array([-math.pi, -self.max_velocity]), high=np.array([math.pi, self.max_velocity]), dtype=np.float64
        )
        self.action_space = spaces.Discrete(len(self.torques))

        self.theta = -math.pi
        self.velocity = 0.0
        self._steps = 0
        self._last_torque = 0.0

    def energy(self) -> float:
        """Mechanical energy J theta'^2 / 2 + m g l cos(theta) in J (zero potential at the horizontal)."""
        return 0.5 * self.inertia * self.velocity**2 + self.gravity_torque * math.cos(self.theta)

    def reward(self, theta: float, velocity: float, torque: float) -> float:
        """Thesis Eq. 4.1: r = -5 theta^2 - 0.1 theta'^2 - u^2."""
        return -5.0 * theta * theta - 0.1 * velocity * velocity - torque * torque

    def set_state(self, theta: float, velocity: float) -> None:
        """Place the pendulum at angle ``theta`` (wrapped) with angular rate ``velocity`` (within the bound)."""
        if not (math.isfinite(theta) and abs(velocity) <= self.max_velocity):
            raise ValueError(
                f"theta must be finite and |velocity| <= max_velocity = {self.max_velocity}, got ({theta}, {velocity})"
            )
        self.theta = wrap_angle(float(theta))
        self.velocity = float(velocity)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.theta = -math.pi
        self.velocity = 0.0
        self._steps = 0
        self._last_torque = 0.0
        return self._observation(), {"goal_reached": False, "fell": False}

    def step(self, action):
        torque = self.torques[discrete_action_index(action, len(self.torques))]
        theta, velocity = pendulum_rk4_step(
            self.theta,
            self.velocity,
            torque,
            self.gravity_torque,
            self.damping,
            self.inertia,
            self.dt,
            self.substeps,
        )
        self.theta = wrap_angle(theta)
        self.velocity = min(max(velocity, -self.max_velocity), self.max_velocity)
        self._last_torque = torque
        self._steps += 1
        goal_reached = abs(self.theta) < self.goal_angle and abs(self.velocity) < self.goal_velocity
        truncated = not goal_reached and self._steps >= self.max_episode_steps
        reward = self.reward(self.theta, self.velocity, torque)
        return self._observation(), reward, goal_reached, truncated, {"goal_reached": goal_reached, "fell": False}

    def render(self) -> np.ndarray | None:
        """An RGB image: the rod from the pivot (up is theta = 0), the bob coloured by the applied torque."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; pass render_mode='rgb_array' to PendulumSwingupEnv")
            return None
        size = _IMAGE_PIXELS
        centre = size / 2.0
        reach = 0.4 * size
        rows, columns = np.mgrid[0:size, 0:size].astype(np.float64)
        tip_column = centre + reach * math.sin(self.theta)
        tip_row = centre - reach * math.cos(self.theta)
        along = ((columns - centre) * (tip_column - centre) + (rows - centre) * (tip_row - centre)) / reach**2
        along = np.clip(along, 0.0, 1.0)
        distance_to_rod = np.hypot(
            columns - centre - along * (tip_column - centre), rows - centre - along * (tip_row - centre)
        )
        image = np.full((size, size, 3), 255, dtype=np.uint8)
        image[np.hypot(columns - centre, rows - centre - reach) < 2.0] = (200, 200, 200)
        image[distance_to_rod < 2.5] = (60, 60, 60)
        push = self._last_torque / self.max_torque
        bob = (int(120 + 100 * max(push, 0.0)), 80, int(120 + 100 * max(-push, 0.0)))
        image[np.hypot(columns - tip_column, rows - tip_row) < 0.08 * size] = bob
        image[np.hypot(columns - centre, rows - centre) < 3.0] = (0, 0, 0)
        return image

    def _observation(self) -> np.ndarray:
        return np.array((self.theta, self.velocity), dtype=np.float64)

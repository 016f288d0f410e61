"""Pendulum swing-up of thesis section 4.2.1 (Table 4.1, Eq. 4.1), with every uncertain reading an option.

State ``s = [theta, theta_dot]``: ``theta = 0`` points up, ``theta = +-pi`` hangs down; ``theta`` is wrapped into
``[-pi, pi)``. The dynamics are

    J_pivot * theta'' = m * g * l * sin(theta) - b * theta' + tau

with Table 4.1's m = 1.113 kg, J = 3.773e-3 kg m^2, g = 9.81 m/s^2, l = 8.5e-2 m, and viscous damping b = 0 (the
thesis names none). Each control step holds the action for ``dt = 0.01`` s (thesis 4.2.1: "the sampling period is 0.01
seconds"), integrated by ``substeps`` classical Runge-Kutta (RK4) steps. The reward of thesis Eq. 4.1 is taken at the
state reached by the step, with ``a`` the action in its own unit (N m, or V for ``actuation="voltage"``):

    r = -5 * theta^2 - 0.1 * theta'^2 - a^2.

Every episode starts hanging down at rest and is ``truncated`` after ``episode_seconds`` (15 s, thesis 4.2.1).

Readings (the thesis does not settle these; each is an option, with the printed value always available):

* Inertia, ``inertia_about``. Table 4.1 prints J = 3.773e-3 kg m^2 without saying about which axis. About the pivot
  it would be smaller than m * l^2 = 8.04e-3 kg m^2 (the point-mass inertia of the same mass at l), which no rigid body
  can be. The thesis simulated the pendulum in ODE (MatODE), and an ODE body takes its inertia tensor about its centre
  of mass. ``"center_of_mass"`` (default, the physical reading) uses J_pivot = J + m * l^2 = 1.1814e-2 kg m^2 (parallel
  axis theorem); ``"pivot"`` uses J_pivot = J (the reading before issue 10). GRL (github wcaarls/grl) is itself split:
  its hand-written DCSC pendulum (``base/src/environments/pendulum.cpp``) integrates J theta'' = ..., J about the pivot,
  while its RBDL model of the same pendulum (``addons/rbdl/cfg/pendulum.lua``) gives J as the body's inertia about a
  centre of mass at l. For the DCSC values, J = 1.91e-4 > m l^2 = 9.7e-5, so there the pivot reading is physical.
* Velocity tile width, ``velocity_tile_width`` (``tile_widths = [0.33, velocity_tile_width]``). The thesis prints
  "a tile width of 0.33 rad and 0.33 rad/s", the default. ``velocity_tile_width=3.3`` is the earlier default, which
  read a dropped digit: every tile-coded pendulum in GRL (``cfg/pendulum/sarsa_tc.yaml`` and its siblings) tiles the
  rate ten times wider than the angle, [0.31415 rad, 3.1415 rad/s]. A swing-up spans about +-18 rad/s
  (centre-of-mass inertia) or +-31 rad/s (pivot): 0.33 rad/s cuts that range into 100-200 tiles, against 19 for the
  angle.
* Actuation, ``actuation``. ``"torque"`` (default): ``n_actions`` torques evenly spaced in ``[-max_torque, max_torque]``
  N m; the thesis gives "7 actions" but no range, and says only that the torque "is not strong enough to directly rotate
  the pendulum to its up position", so the limit must lie below m g l = 0.928 N m; 0.6 N m is our choice.
  ``"voltage"``: the action is a motor voltage u in ``[-max_voltage, max_voltage]`` V driving a DC motor,
  tau = (K / R) * (u - K * theta'), the model of the Delft DCSC pendulum (MOPS) whose reward Eq. 4.1 is: GRL's
  ``dynamics/pendulum`` has K = 0.0536 N m/A, R = 9.5 Ohm, u in +-3 V, with J = 1.91e-4 kg m^2 (pivot), m = 0.055 kg,
  l = 0.042 m, b = 3e-6 N m s/rad (``DCSC_MOPS`` below). Table 4.1 gives no motor constants: on Table 4.1's pendulum the
  DCSC motor's stall torque of 0.017 N m is 2 % of m g l, and 15 s of bang-bang pumping at 3 V lift it only 1.5 rad
  (centre-of-mass inertia) or 2.7 rad (pivot) from hanging. The voltage reading is meant for the whole DCSC model,
  ``PendulumSwingupEnv(**DCSC_MOPS)``.
* Goal, ``terminate_at_goal``. The thesis says only that "an episode lasts 15 seconds or when the goal is reached"; it
  defines no goal. Ours: the episode ends (``terminated``, ``info["goal_reached"]``) when ``|theta| < goal_angle``
  (0.2 rad) and ``|theta'| < goal_velocity`` (2 rad/s), the goal nearest the thesis's Sarsa(lambda) row in a screen
  of goals (0.05 rad & 0.5 rad/s, 0.1 rad & 1 rad/s, the earlier default, pointing up at any rate with
  ``goal_velocity=None``, and none). GRL's swing-up task has no goal at all: it never marks a state absorbing and
  ends every episode at its timeout (2.99 s of 0.03 s steps, 100 steps); ``terminate_at_goal=False`` runs every
  episode for ``episode_seconds``, as GRL does.

* Reward units, ``reward_units``. Eq. 4.1 prints no units; ``"radians"`` (default) or ``"degrees"`` (theta in
  degrees, theta' in degrees/s: 3283 times the angle and rate costs).
* Integration, ``integrator`` and ``substeps``. The thesis simulated in ODE (MatODE) and names no scheme; ``"rk4"``
  (default) takes ``substeps`` classical Runge-Kutta steps per control step, ``"euler"`` semi-implicit Euler steps
  (rate first, then the angle with the new rate), the scheme of ODE's ``dWorldStep``.

The angular rate is clipped to ``[-max_velocity, max_velocity]`` (40 rad/s) after each control step, which keeps the
observation bounded; the clip never binds in a swing-up (from rest hanging down, upright is passed at about 18 rad/s
with the centre-of-mass inertia, 31 rad/s with J about the pivot, 22 rad/s in the DCSC model). ``info["fell"]`` is
always False: reaching the goal is no fall.
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

INERTIA_AXES = ("center_of_mass", "pivot")
ACTUATIONS = ("torque", "voltage")
REWARD_UNITS = ("radians", "degrees")
INTEGRATORS = ("rk4", "euler")
_DEGREES_PER_RADIAN = 180.0 / math.pi

# Table 4.1 of the thesis.
TABLE_4_1 = {"mass": 1.113, "inertia": 3.773e-3, "length": 8.5e-2, "gravity": 9.81}

# The Delft DCSC pendulum (MOPS) as GRL models it: base/src/environments/pendulum.cpp (PendulumDynamics::configure:
# J, m, l, b, K, R; PendulumSwingupTask: actions clipped to +-3 V). J is the inertia about the pivot there.
DCSC_MOPS = {
    "mass": 0.055,
    "inertia": 1.91e-4,
    "inertia_about": "pivot",
    "length": 0.042,
    "damping": 3e-6,
    "actuation": "voltage",
    "max_voltage": 3.0,
    "motor_constant": 0.0536,
    "motor_resistance": 9.5,
}

# Defaults of the actuation-specific parameters (None in the signature means "this default, if it applies").
_DEFAULT_MAX_TORQUE = 0.6
_DEFAULT_MAX_VOLTAGE = DCSC_MOPS["max_voltage"]
_DEFAULT_MOTOR_CONSTANT = DCSC_MOPS["motor_constant"]
_DEFAULT_MOTOR_RESISTANCE = DCSC_MOPS["motor_resistance"]


@numba.njit(cache=True)
def _angular_acceleration(theta, velocity, torque, gravity_torque, damping, inertia):
    """theta'' of the pendulum, J_pivot * theta'' = m g l sin(theta) - b theta' + u (thesis 4.2.1)."""
    return (gravity_torque * math.sin(theta) - damping * velocity + torque) / inertia


@numba.njit(cache=True)
def pendulum_rk4_step(theta, velocity, torque, gravity_torque, damping, inertia, dt, substeps):
    """Advance (theta, theta') by ``dt`` seconds with ``substeps`` RK4 steps at constant torque; no wrapping here.

    ``gravity_torque`` is m * g * l and ``inertia`` the inertia about the pivot, so the equation integrated is
    J_pivot * theta'' = m g l sin(theta) - b theta' + u.

    :param theta: the angle [rad], 0 upright.
    :param velocity: the angular rate [rad/s].
    :param torque: the applied torque u [N m], constant over the step.
    :param gravity_torque: m g l [N m].
    :param damping: the viscous friction b [N m s/rad].
    :param inertia: the inertia about the pivot J [kg m^2].
    :param dt: the step's duration [s].
    :param substeps: the number of integration steps within it.
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


@numba.njit(cache=True)
def pendulum_euler_step(theta, velocity, torque, gravity_torque, damping, inertia, dt, substeps):
    """Advance (theta, theta') by ``dt`` seconds with ``substeps`` semi-implicit (symplectic) Euler steps.

    Each step of length h first updates the rate, theta' += h * theta'', then the angle with the new rate, theta += h *
    theta': the first-order scheme of ODE's ``dWorldStep``, in which MatODE simulated the thesis's pendulum (4.2.1).

    :param theta: the angle [rad], 0 upright.
    :param velocity: the angular rate [rad/s].
    :param torque: the applied torque u [N m], constant over the step.
    :param gravity_torque: m g l [N m].
    :param damping: the viscous friction b [N m s/rad].
    :param inertia: the inertia about the pivot J [kg m^2].
    :param dt: the step's duration [s].
    :param substeps: the number of integration steps within it.
    """
    h = dt / substeps
    for _ in range(substeps):
        velocity += h * _angular_acceleration(theta, velocity, torque, gravity_torque, damping, inertia)
        theta += h * velocity
    return theta, velocity


def wrap_angle(theta: float) -> float:
    """``theta`` wrapped into ``[-pi, pi)``.

    :param theta: an angle [rad].
    """
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


def _positive_finite(name: str, value) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if isinstance(value, bool) or not (math.isfinite(number) and number >= np.finfo(np.float64).tiny):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return number


class PendulumSwingupEnv(gym.Env):
    """Under-actuated pendulum swing-up (thesis 4.2.1, Table 4.1, reward Eq. 4.1) with 7 discrete actions.

    See the module docstring for the source of every value and the readings behind the options.

    Parameters
    ----------
    actuation:
        ``"torque"`` (default): the action is a joint torque in N m. ``"voltage"``: a DC-motor voltage in V, torque
        (K / R) * (u - K * theta') (the DCSC pendulum's motor, from GRL).
    max_torque:
        Torque limit in N m, ``actuation="torque"`` only (default 0.6, our choice: the thesis gives none). Must lie
        below m * g * l so that the task needs swinging (thesis 4.2.1).
    max_voltage, motor_constant, motor_resistance:
        ``actuation="voltage"`` only: voltage limit in V (3), motor constant K in N m/A (0.0536) and winding resistance
        R in Ohm (9.5), GRL's DCSC values. The stall torque K * max_voltage / R must lie below m * g * l.
    n_actions:
        Number of evenly spaced actions in ``[-max, max]`` (7, thesis 4.2.1; odd keeps zero among them).
    inertia, inertia_about:
        Table 4.1's J = 3.773e-3 kg m^2, read about ``"center_of_mass"`` (default: the pivot inertia is J + m l^2) or
        about the ``"pivot"`` (J itself, though Table 4.1's J is smaller than m l^2).
    velocity_tile_width:
        Tile width of the angular rate in rad/s that the env recommends (``tile_widths``): 0.33 (default, as printed
        in thesis 4.2.1); 3.3 is the earlier default (GRL tiles the rate 10 times wider than the angle).
    terminate_at_goal, goal_angle, goal_velocity:
        With ``terminate_at_goal`` (default, thesis 4.2.1 "or when the goal is reached") the episode terminates when
        ``|theta| < goal_angle`` (0.2 rad) and ``|theta'| < goal_velocity`` (2 rad/s): the screened goal nearest the
        thesis's Sarsa(lambda) row (the earlier default: 0.1 rad and 1 rad/s); the thesis defines none.
        ``goal_velocity=None`` sets no condition on the rate: the goal is pointing up (the task of 4.2.1, "to move the
        pendulum from the initial position to pointing up"), passing through upright included.
        ``terminate_at_goal=False`` runs every episode to its time limit, as GRL's swing-up task does.
    reward_units:
        Units of theta and theta' in Eq. 4.1: ``"radians"`` (default, rad and rad/s) or ``"degrees"`` (degrees and
        degrees/s; the thesis prints no unit for the reward).
    episode_seconds:
        Simulated seconds after which the episode is truncated (15, thesis 4.2.1).
    dt, substeps, integrator:
        Control period in seconds (0.01, thesis 4.2.1), integration steps per control period (5) and the scheme:
        ``"rk4"`` (default, classical Runge-Kutta) or ``"euler"`` (semi-implicit Euler, the first-order scheme of ODE's
        ``dWorldStep`` in which the thesis's MatODE model ran).
    mass, length, gravity, damping:
        m in kg, l (pivot to centre of mass) in m and g in m/s^2 from Table 4.1; viscous damping b in N m s/rad (0).
    max_velocity:
        Clip and observation bound of the angular rate in rad/s (40).
    render_mode:
        ``None`` or ``"rgb_array"``.

    ``PendulumSwingupEnv(**DCSC_MOPS)`` is the DCSC pendulum of GRL with this env's task (7 voltages, dt, goal, 15 s).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 100}

    def __init__(
        self,
        max_torque: float | None = None,
        n_actions: int = 7,
        goal_angle: float = 0.2,
        goal_velocity: float | None = 2.0,
        episode_seconds: float = 15.0,
        dt: float = 0.01,
        substeps: int = 5,
        mass: float = TABLE_4_1["mass"],
        inertia: float = TABLE_4_1["inertia"],
        length: float = TABLE_4_1["length"],
        gravity: float = TABLE_4_1["gravity"],
        damping: float = 0.0,
        max_velocity: float = 40.0,
        render_mode: str | None = None,
        *,
        inertia_about: str = "center_of_mass",
        velocity_tile_width: float = 0.33,
        actuation: str = "torque",
        max_voltage: float | None = None,
        motor_constant: float | None = None,
        motor_resistance: float | None = None,
        terminate_at_goal: bool = True,
        reward_units: str = "radians",
        integrator: str = "rk4",
    ) -> None:
        values = {}
        for name, value in (
            ("mass", mass),
            ("inertia", inertia),
            ("length", length),
            ("gravity", gravity),
            ("dt", dt),
            ("goal_angle", goal_angle),
            ("max_velocity", max_velocity),
            ("episode_seconds", episode_seconds),
            ("velocity_tile_width", velocity_tile_width),
        ):
            values[name] = _positive_finite(name, value)
        if isinstance(damping, bool) or not (math.isfinite(float(damping)) and damping >= 0.0):
            raise ValueError(f"damping must be a non-negative finite number, got {damping!r}")
        if inertia_about not in INERTIA_AXES:
            raise ValueError(f"inertia_about must be one of {INERTIA_AXES}, got {inertia_about!r}")
        if actuation not in ACTUATIONS:
            raise ValueError(f"actuation must be one of {ACTUATIONS}, got {actuation!r}")
        if reward_units not in REWARD_UNITS:
            raise ValueError(f"reward_units must be one of {REWARD_UNITS}, got {reward_units!r}")
        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")
        if not isinstance(terminate_at_goal, (bool, np.bool_)):
            raise ValueError(f"terminate_at_goal must be True or False, got {terminate_at_goal!r}")
        if isinstance(n_actions, bool) or int(n_actions) != n_actions or n_actions < 2:
            raise ValueError(f"n_actions must be an integer of at least 2, got {n_actions!r}")
        if isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")

        mass, length, gravity = values["mass"], values["length"], values["gravity"]
        gravity_torque = mass * gravity * length
        if actuation == "torque":
            for name, value in (
                ("max_voltage", max_voltage),
                ("motor_constant", motor_constant),
                ("motor_resistance", motor_resistance),
            ):
                if value is not None:
                    raise ValueError(f"{name} applies to actuation='voltage' only; got {name}={value!r} with 'torque'")
            max_action = _positive_finite("max_torque", _DEFAULT_MAX_TORQUE if max_torque is None else max_torque)
            torque_per_unit, back_emf_damping = 1.0, 0.0
            stall_torque = max_action
            if not stall_torque < gravity_torque:
                raise ValueError(
                    f"max_torque must lie in (0, m*g*l) = (0, {gravity_torque:.4g}) N m so that the pendulum has to "
                    f"swing up, got {max_torque}"
                )
        else:
            if max_torque is not None:
                raise ValueError(
                    f"max_torque applies to actuation='torque' only; with 'voltage' set max_voltage, got {max_torque!r}"
                )
            max_action = _positive_finite("max_voltage", _DEFAULT_MAX_VOLTAGE if max_voltage is None else max_voltage)
            constant = _positive_finite(
                "motor_constant", _DEFAULT_MOTOR_CONSTANT if motor_constant is None else motor_constant
            )
            resistance = _positive_finite(
                "motor_resistance", _DEFAULT_MOTOR_RESISTANCE if motor_resistance is None else motor_resistance
            )
            torque_per_unit, back_emf_damping = constant / resistance, constant * constant / resistance
            stall_torque = torque_per_unit * max_action
            if not stall_torque < gravity_torque:
                raise ValueError(
                    f"the stall torque motor_constant * max_voltage / motor_resistance = {stall_torque:.4g} N m must "
                    f"lie below m*g*l = {gravity_torque:.4g} N m so that the pendulum has to swing up"
                )

        self.actuation = actuation
        self.action_unit = "N m" if actuation == "torque" else "V"
        self.max_action = float(max_action)
        self.action_levels = tuple(float(a) for a in np.linspace(-max_action, max_action, int(n_actions)))
        # The torque of each action at rest (theta' = 0): the action itself, or K/R times the voltage.
        self.torques = tuple(torque_per_unit * a for a in self.action_levels)
        self.max_torque = float(stall_torque)
        self.torque_per_unit = float(torque_per_unit)
        self.motor_constant = None if actuation == "torque" else float(constant)
        self.motor_resistance = None if actuation == "torque" else float(resistance)
        self.terminate_at_goal = bool(terminate_at_goal)
        self.reward_units = reward_units
        self._reward_scale = _DEGREES_PER_RADIAN if reward_units == "degrees" else 1.0
        self.integrator = integrator
        self._integrate = pendulum_rk4_step if integrator == "rk4" else pendulum_euler_step
        self.goal_angle = values["goal_angle"]
        # None: the goal is "pointing up" (|theta| < goal_angle) at any rate
        self.goal_velocity = math.inf if goal_velocity is None else _positive_finite("goal_velocity", goal_velocity)
        self.dt = values["dt"]
        self.substeps = int(substeps)
        self.max_episode_steps = max(1, round(values["episode_seconds"] / self.dt))
        self.mass = mass
        self.inertia = values["inertia"]
        self.inertia_about = inertia_about
        self.pivot_inertia = self.inertia + (mass * length**2 if inertia_about == "center_of_mass" else 0.0)
        self.length = length
        self.gravity = gravity
        self.damping = float(damping)
        # Viscous damping plus the motor's back-EMF, K^2 / R, for a voltage: tau = K/R (u - K theta') - b theta'.
        self.total_damping = self.damping + back_emf_damping
        self.gravity_torque = float(gravity_torque)
        self.max_velocity = values["max_velocity"]
        self.velocity_tile_width = values["velocity_tile_width"]
        self.render_mode = render_mode

        self.tile_widths = np.array([0.33, self.velocity_tile_width])
        self.wrap_periods = (2.0 * math.pi, None)
        self.observation_space = spaces.Box(
            low=np.array([-math.pi, -self.max_velocity]), high=np.array([math.pi, self.max_velocity]), dtype=np.float64
        )
        self.action_space = spaces.Discrete(len(self.action_levels))

        self.theta = -math.pi
        self.velocity = 0.0
        self._steps = 0
        self._last_action = 0.0

    def energy(self) -> float:
        """Mechanical energy J_pivot theta'^2 / 2 + m g l cos(theta) in J (zero potential at the horizontal)."""
        return 0.5 * self.pivot_inertia * self.velocity**2 + self.gravity_torque * math.cos(self.theta)

    def torque(self, action_value: float, velocity: float) -> float:
        """Joint torque in N m of the action ``action_value`` (N m, or V) at angular rate ``velocity``, damping aside.

        A torque is itself; a voltage u gives (K / R) * (u - K * theta'), the back-EMF included.

        :param action_value: the action in its unit (N m, or V).
        :param velocity: the angular rate [rad/s].
        """
        return self.torque_per_unit * action_value - (self.total_damping - self.damping) * velocity

    def reward(self, theta: float, velocity: float, action_value: float) -> float:
        """Thesis Eq. 4.1: r = -5 theta^2 - 0.1 theta'^2 - a^2, ``a`` the action in its unit (N m, or V), theta and
        theta' in rad and rad/s, or in degrees and degrees/s with ``reward_units="degrees"``.

        :param theta: the angle [rad], 0 upright.
        :param velocity: the angular rate [rad/s].
        :param action_value: the action in its unit (N m, or V).
        """
        theta, velocity = self._reward_scale * theta, self._reward_scale * velocity
        return -5.0 * theta * theta - 0.1 * velocity * velocity - action_value * action_value

    @property
    def reward_bounds(self) -> dict:
        """Where Eq. 4.1's rewards lie (the value watch of sb3-er reads it): -5 theta^2 - 0.1 theta'^2 - a^2 is at most
        0 and at least its value at |theta| = pi, |theta'| = max_velocity, |a| = the largest action; a terminating
        step (the goal) has |theta| < goal_angle and |theta'| < goal_velocity (at most max_velocity)."""
        largest = max(abs(a) for a in self.action_levels)
        step_low = self.reward(math.pi, self.max_velocity, largest)
        goal_velocity = min(self.goal_velocity, self.max_velocity)  # the rate is clipped; None sets no goal rate
        terminal = (self.reward(self.goal_angle, goal_velocity, largest), 0.0) if self.terminate_at_goal else None
        return {"step": (step_low, 0.0), "terminal": terminal}

    def set_state(self, theta: float, velocity: float) -> None:
        """Place the pendulum at angle ``theta`` (wrapped) with angular rate ``velocity`` (within the bound).

        :param theta: the angle [rad].
        :param velocity: the angular rate [rad/s].
        """
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
        self._last_action = 0.0
        return self._observation(), {"goal_reached": False, "fell": False}

    def step(self, action):
        action_value = self.action_levels[discrete_action_index(action, len(self.action_levels))]
        theta, velocity = self._integrate(
            self.theta,
            self.velocity,
            self.torque_per_unit * action_value,
            self.gravity_torque,
            self.total_damping,
            self.pivot_inertia,
            self.dt,
            self.substeps,
        )
        self.theta = wrap_angle(theta)
        self.velocity = min(max(velocity, -self.max_velocity), self.max_velocity)
        self._last_action = action_value
        self._steps += 1
        goal_reached = abs(self.theta) < self.goal_angle and abs(self.velocity) < self.goal_velocity
        terminated = self.terminate_at_goal and goal_reached
        truncated = not terminated and self._steps >= self.max_episode_steps
        reward = self.reward(self.theta, self.velocity, action_value)
        return self._observation(), reward, terminated, truncated, {"goal_reached": goal_reached, "fell": False}

    def render(self) -> np.ndarray | None:
        """An RGB image: the rod from the pivot (up is theta = 0), the bob coloured by the applied action."""
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
        push = self._last_action / self.max_action
        bob = (int(120 + 100 * max(push, 0.0)), 80, int(120 + 100 * max(-push, 0.0)))
        image[np.hypot(columns - tip_column, rows - tip_row) < 0.08 * size] = bob
        image[np.hypot(columns - centre, rows - centre) < 3.0] = (0, 0, 0)
        return image

    def _observation(self) -> np.ndarray:
        return np.array((self.theta, self.velocity), dtype=np.float64)

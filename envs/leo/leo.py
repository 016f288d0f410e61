"""LEO, the Delft biped of thesis section 4.2.3, as a dm_control domain (modelled on the suite's ``walker``).

The MJCF model ``leo.xml`` rebuilds Erik Schuitema's ODE model as the GRL framework keeps it
(``addons/leosim/cfg/leoconfig.xml``); this module adds the walking task of the thesis (Eq. 4.6-4.7, Table 4.3) with
Erik's task logic:

* 30 Hz control, voltages held over an exact number of physics substeps;
* the 10-D stance/swing observation of Eq. 4.6 with Butterworth-filtered joint rates;
* the learned voltages of the stance hip, swing hip and swing knee; proportional auto-controllers for the arm, the
stance
  knee and both ankles;
* stance-leg choice from the foot contacts, footsteps, and the reward of time, electrical energy, swing-foot progress
  and falls; a fall ends the episode, 25 s truncate it.

``walk()`` returns a ``dm_control.rl.control.Environment`` whose action is the three voltages in volts;
:class:`sb3_er_envs.leo.LeoEnv` is the Gymnasium face with Erik's 7 voltage levels per joint.
"""

from __future__ import annotations

import collections
import logging
import math
import os
from pathlib import Path

import numpy as np

from ._gl import prepare_backend

_USER_MUJOCO_GL = os.environ.get("MUJOCO_GL")
#: Why MuJoCo cannot render in this process (None: it can try). Simulation never needs OpenGL.
RENDERING_UNAVAILABLE = prepare_backend()

import mujoco as mujoco_engine  # noqa: E402  (MuJoCo's own bindings; `mujoco` below is dm_control's wrapper)
from dm_control import _render, mujoco  # noqa: E402
from dm_control.rl import control  # noqa: E402
from dm_control.suite import base  # noqa: E402
from dm_env import specs  # noqa: E402

#: The OpenGL backend dm_control took ("glfw", "egl", "osmesa", or "off" when rendering is unavailable).
RENDER_BACKEND = _render.BACKEND
if _USER_MUJOCO_GL is None:
    os.environ.pop("MUJOCO_GL", None)  # dm_control has read our choice; leave the user's environment as it was

MODEL_PATH = Path(__file__).with_name("leo.xml")

CONTROL_TIMESTEP = 1.0 / 30.0
#: Physics substeps per control step; the model's timestep is set to exactly CONTROL_TIMESTEP / PHYSICS_SUBSTEPS.
PHYSICS_SUBSTEPS = 30
TIME_LIMIT = 25.0

#: RX-28 voltage limit LEO_MAX_DXL_VOLTAGE [V]; every voltage is clipped to +-this.
MAX_VOLTAGE = 10.69189
#: Erik's 7 voltage levels of a learned joint: k * MAX_VOLTAGE / 3, k = -3..3.
VOLTAGE_LEVELS = np.linspace(-MAX_VOLTAGE, MAX_VOLTAGE, 7)
#: Motor constants used by the energy measure: torque constant x gear ratio [N m/A] and terminal resistance [ohm].
TORQUE_CONSTANT_TIMES_GEAR = 0.00992 * 193.0
TERMINAL_RESISTANCE = 8.6
#: The controllers' conversion of a torque into a voltage, 14.0 / 3.3 V/(N m).
TORQUE_TO_VOLTAGE = 14.0 / 3.3

ARM_GAIN = 5.0 * TORQUE_TO_VOLTAGE
ARM_TARGET = -15.0 * math.pi / 180.0
STANCE_KNEE_GAIN = 5.0 * TORQUE_TO_VOLTAGE
STANCE_KNEE_TARGET = 0.0
ANKLE_GAIN = 10.0 * TORQUE_TO_VOLTAGE
ANKLE_TARGET = 3.72 * math.pi / 180.0
FLOOR_PARALLEL_ANKLE_GAIN = 8.0 * TORQUE_TO_VOLTAGE

THIGH_LENGTH = 0.116
SHANK_LENGTH = 0.1045

REWARD_TIME = -1.0
REWARD_ENERGY = -3.0
REWARD_PROGRESS = 300.0
MAX_FOOTSTEP_LENGTH = 10.20
REWARD_FALL = -125.0
MAX_TORSO_ANGLE = 1.0
MAX_STANCE_LEG_ANGLE = 0.36 * math.pi

#: Butterworth cut-off of the joint-rate filters [Hz] (Erik's first-order filter at the 30 Hz sample rate).
RATE_FILTER_CUTOFF = 10.0

#: Erik's start pose (GRL's leoconfig.xml initial state, Eq. 4.7 with the torso in the task's sign): left leg stance
#: and vertical.
START_POSE = {
    "torso": -0.10,
    "hip_left": 0.10,
    "knee_left": 0.0,
    "ankle_left": 0.0,
    "hip_right": 0.82,
    "knee_right": -1.27,
    "ankle_right": 0.0,
    "shoulder": ARM_TARGET,
}

LEFT, RIGHT = 0, 1
_SIDES = ("left", "right")
_MOTOR_JOINTS = ("shoulder", "hip_left", "hip_right", "knee_left", "knee_right", "ankle_left", "ankle_right")
#: The task's state joints: the torso pitch (index 0), then the motor joints (index k is _MOTOR_JOINTS[k - 1]).
_STATE_JOINTS = ("torso", *_MOTOR_JOINTS)
#: Indices into _STATE_JOINTS of each side's hip, knee and ankle, indexed by LEFT / RIGHT.
_HIP, _KNEE, _ANKLE = (2, 3), (4, 5), (6, 7)
#: The hip and knee motors whose energy counts, in _MOTOR_JOINTS order.
_HIP_KNEE = (2, 3, 4, 5)
#: Observed joints of Eq. 4.6 (torso, stance hip, swing hip, stance knee, swing knee) by stance leg.
_OBSERVED = tuple((0, _HIP[stance], _HIP[1 - stance], _KNEE[stance], _KNEE[1 - stance]) for stance in (LEFT, RIGHT))


def butterworth_coefficients(cutoff: float, sample_rate: float) -> tuple[float, float]:
    """First-order low-pass by the Tustin transform without pre-warping: ``y[n] = b (x[n] + x[n-1]) - a y[n-1]``.

    Returns ``(b, a)``; for 10 Hz at 30 Hz this is (0.511527, 0.023055), the coefficients of Erik's rate filter.

    :param cutoff: the cut-off frequency [Hz].
    :param sample_rate: the sampling frequency [Hz].
    """
    if not 0.0 < cutoff:
        raise ValueError(f"filter cut-off must be positive, got {cutoff}")
    k = 2.0 * math.pi * cutoff / (2.0 * sample_rate)
    return k / (1.0 + k), (k - 1.0) / (k + 1.0)


def _clip(value: float, bound: float) -> float:
    return bound if value > bound else -bound if value < -bound else value


def ankle_x_from_hip(torso: float, hip: float, knee: float) -> float:
    """Horizontal position of the ankle relative to the hip from joint angles only (Erik's footstep measure) [m].

    :param torso: the torso's pitch [rad].
    :param hip: the hip angle [rad].
    :param knee: the knee angle [rad].
    """
    thigh = torso + hip
    return THIGH_LENGTH * math.sin(thigh) + SHANK_LENGTH * math.sin(thigh + knee)


_ZERO_CLOCK = []


def _zero_clock():
    """ctypes pointer of the numba-compiled C function returning 0.0 (``_clock.py``), compiled on first use."""
    if not _ZERO_CLOCK:
        from ._clock import zero_clock

        _ZERO_CLOCK.append(zero_clock.ctypes)  # kept alive here: MuJoCo holds only the address
    return _ZERO_CLOCK[0]


def get_model_and_assets() -> tuple[bytes, dict]:
    """The MJCF model as a string and its (empty) assets, as dm_control suite domains provide them."""
    return MODEL_PATH.read_bytes(), {}


class Physics(mujoco.Physics):
    """LEO's physics with accessors in LEO's own variables (angles about -y, the torso positive leaning backward).

    The task's hot path uses integer addresses into qpos/qvel/ctrl and NumPy views of MuJoCo's own arrays, all built
    once in ``_reload_from_data`` (which dm_control calls whenever the data changes), and :meth:`step_control` steps
    MuJoCo directly.
    """

    def _reload_from_data(self, data) -> None:
        super()._reload_from_data(data)
        model = self.model
        names = ("root_x", "root_z", "torso", *_MOTOR_JOINTS)
        self.qpos_index = {name: int(model.jnt_qposadr[model.name2id(name, "joint")]) for name in names}
        self.qvel_index = {name: int(model.jnt_dofadr[model.name2id(name, "joint")]) for name in names}
        self._motor_actuators = np.array([model.name2id(name, "actuator") for name in _MOTOR_JOINTS])
        first = int(self._motor_actuators[0])
        contiguous = np.array_equal(self._motor_actuators, np.arange(first, first + len(_MOTOR_JOINTS)))
        self._motor_ctrl = slice(first, first + len(_MOTOR_JOINTS)) if contiguous else self._motor_actuators
        self._foot_side = {
            model.name2id(f"{part}_{side}", "geom"): index
            for index, side in enumerate(_SIDES)
            for part in ("heel", "toe")
        }
        paired = set(model.pair_geom1.tolist()) | set(model.pair_geom2.tolist())
        filtered = set(np.flatnonzero(model.geom_contype | model.geom_conaffinity).tolist())
        self._contact_geoms = np.array(sorted(g for g in paired | filtered if model.geom_rbound[g] > 0.0))
        self._contact_radius = model.geom_size[self._contact_geoms, 0]
        self._left_heel = model.name2id("heel_left", "geom")
        self.hip_joint = model.name2id("hip_left", "joint")
        self._torso_body = model.name2id("torso", "body")
        # The task's state joints (torso pitch, then the motor joints) as plain integer addresses.
        self._state_qpos = [self.qpos_index[name] for name in _STATE_JOINTS]
        self._state_qvel = [self.qvel_index[name] for name in _STATE_JOINTS]
        raw_model, raw_data = self.model.ptr, self.data.ptr
        self._raw = (raw_model, raw_data)
        self._qpos, self._qvel, self._ctrl = raw_data.qpos, raw_data.qvel, raw_data.ctrl
        self._xanchor = raw_data.xanchor
        self._warning_counts = raw_data.warning.number

    def joint_angle(self, name: str) -> float:
        """Angle of a joint, or of the root ("torso" pitch, "root_x", "root_z"), in LEO's convention.

        :param name: a joint's name (e.g. "hip_left") or "torso", "root_x", "root_z".
        """
        return float(self.data.qpos[self.qpos_index[name]])

    def joint_rate(self, name: str) -> float:
        """Unfiltered rate of a joint or of the root.

        :param name: a joint's name or "torso", "root_x", "root_z".
        """
        return float(self.data.qvel[self.qvel_index[name]])

    def set_pose(self, angles: dict[str, float]) -> None:
        """Set joint angles with zero rates and place the robot so that its lowest contact point touches the floor and
        the left heel is at x = 0 (Erik's model fixes the left heel to the world origin).

        :param angles: joint angles [rad] by name (keys of ``qpos_index``; an unknown name is a ValueError).
        """
        unknown = set(angles) - set(self.qpos_index)
        if unknown:
            raise ValueError(f"unknown LEO joints {sorted(unknown)}; known: {sorted(self.qpos_index)}")
        model, data = self._raw
        qpos = self._qpos
        qpos[:] = 0.0
        self._qvel[:] = 0.0
        for name, value in angles.items():
            qpos[self.qpos_index[name]] = value
        mujoco_engine.mj_kinematics(model, data)  # geom positions only; the forward below recomputes everything
        geom_xpos = data.geom_xpos
        lowest = float(np.min(geom_xpos[self._contact_geoms, 2] - self._contact_radius))
        qpos[self.qpos_index["root_z"]] -= lowest
        qpos[self.qpos_index["root_x"]] -= float(geom_xpos[self._left_heel, 0])
        self.forward()

    def reset_for(self, task) -> None:
        """``with physics.reset_context(): task.initialize_episode(physics)``, leaving bit for bit the same data,
        with two of its four ``mj_forward`` calls dropped: dm_control's ``reset`` forwards the default pose, which
        ``set_pose`` then overwrites entirely (``mj_forward`` does not touch the warm start that ``mj_resetData``
        zeroed). The closing forward runs without actuation, as dm_control's ``after_reset``.

        :param task: the task whose ``initialize_episode`` sets the start pose.
        """
        model, data = self._raw
        mujoco_engine.mj_resetData(model, data)
        task.initialize_episode(self)
        flags = model.opt.disableflags
        model.opt.disableflags = flags | mujoco_engine.mjtDisableBit.mjDSBL_ACTUATION
        try:
            self.forward()
        finally:
            model.opt.disableflags = flags

    def set_voltages(self, voltages) -> None:
        """Set the 7 motor voltages (order: shoulder, hip left, hip right, knee left, knee right, ankle left, ankle
        right), each clipped to +-MAX_VOLTAGE.

        :param voltages: the 7 voltages [V], in the order above.
        """
        self.data.ctrl[self._motor_actuators] = np.clip(voltages, -MAX_VOLTAGE, MAX_VOLTAGE)

    #: Keep MuJoCo's profiling timers (``data.timer``) running during :meth:`step_control`. By default (False) and
    #: while no ``mjcb_time`` callback is installed, :meth:`step_control` installs one returning 0 for the duration
    #: of the step: MuJoCo 3.17 otherwise reads the system clock at every stage of every substep, about 10 % of a
    #: LEO substep. The simulation is the same either way; only ``data.timer`` stays 0.
    keep_mujoco_timers = False

    def step_control(self, nstep: int) -> None:
        """Advance ``nstep`` physics substeps exactly as dm_control's ``Physics.step`` does (its default "legacy"
        stepping for a non-RK4 integrator: ``mj_step2``, ``mj_step`` for the other ``nstep - 1`` substeps, then
        ``mj_step1`` so that positions, contacts and velocities in ``data`` belong to the final state), without the
        Python wrapper around it. Like dm_control, a new MuJoCo warning (a diverged and auto-reset state, a full
        contact buffer) raises ``dm_control.rl.control.PhysicsError`` unless errors are suppressed, then it is
        logged. See ``keep_mujoco_timers`` for the timer callback in place during the step.

        :param nstep: the number of MuJoCo substeps (30 per control step).
        """
        counts = self._warning_counts
        before = counts.tolist()
        model, data = self._raw
        quiet_clock = not self.keep_mujoco_timers and mujoco_engine.get_mjcb_time() is None
        if quiet_clock:
            mujoco_engine.set_mjcb_time(_zero_clock())
        try:
            mujoco_engine.mj_step2(model, data)
            if nstep > 1:
                mujoco_engine.mj_step(model, data, nstep - 1)
            mujoco_engine.mj_step1(model, data)
        finally:
            if quiet_clock:
                mujoco_engine.set_mjcb_time(None)
        if counts.tolist() != before:
            names = [
                name
                for name, old, new in zip(
                    mujoco_engine.mjtWarning.__members__, before, counts.tolist(), strict=False
                )  # the enum ends with its count, mjNWARNING
                if new > old
            ]
            message = f"Physics state is invalid. Warning(s) raised: {', '.join(names)}"
            if self._warnings_cause_exception:
                raise control.PhysicsError(message)
            logging.warning(message)

    def foot_contacts(self) -> tuple[bool, bool]:
        """Whether the heel or the toe of the left and of the right foot touches the floor."""
        data = self._raw[1]
        if not data.ncon:
            return False, False
        touching = [False, False]
        side_of = self._foot_side
        for geom1, geom2 in data.contact.geom.tolist():
            side = side_of.get(geom2, side_of.get(geom1))
            if side is not None:
                touching[side] = True
        return touching[LEFT], touching[RIGHT]

    def max_penetration(self) -> float:
        """Deepest current penetration of any contact [m] (0 without contacts)."""
        ncon = self.data.ncon
        return float(max(0.0, -np.min(self.data.contact.dist[:ncon]))) if ncon else 0.0

    def hip_position(self) -> np.ndarray:
        """World (x, z) of the hip axle [m]."""
        anchor = self.data.xanchor[self.hip_joint]
        return np.array([anchor[0], anchor[2]])

    def total_mass(self) -> float:
        """Simulated mass, the boom's lumped virtual mass included [kg]."""
        return float(self.model.body_subtreemass[self._torso_body])


class LeoWalk(base.Task):
    """Erik Schuitema's walking task on LEO (thesis 4.2.3; GRL's LeoBhWalkSym.cpp).

    Action: the voltages [V] of the stance hip, the swing hip and the swing knee, clipped to +-MAX_VOLTAGE.
    Observation ``state`` (Eq. 4.6): torso angle and rate, then angle and rate of the stance hip, swing hip, stance knee
    and swing knee. Angles are joint angles about -y; the torso angle is its pitch, positive when leaning backward.

    Parameters
    ----------
    random:
        ``numpy.random.RandomState``, a seed, or ``None``; drives the start-pose variation.
    start_noise:
        Half-width [rad] of the uniform variation of the torso, both hips and the swing knee around Erik's start pose
        (the thesis's "small random variations"); 0 gives Erik's deterministic pose. The stance foot stays flat.
    filter_rates:
        Low-pass the joint rates with Erik's first-order 10 Hz Butterworth filter (default) or observe them raw.
        The torso rate is never filtered: Erik's torso filter in GRL passes it through almost unchanged.
    floor_parallel_ankles:
        Hold each foot at 3.72 degrees to the floor (Erik's ``autoActuateAnkles``, gain 8 N m/rad: the feet stay about
        parallel to the floor as the thesis describes) instead of Erik's default, which holds each ankle joint at
        3.72 degrees relative to its shank.

    The per-step state is kept in plain lists in ``_STATE_JOINTS`` order (torso, then the motor joints), indexed with
    the integer tables ``_HIP``, ``_KNEE`` and ``_ANKLE`` by side, so that a control step builds no dicts.
    """

    def __init__(
        self, random=None, start_noise: float = 0.05, filter_rates: bool = True, floor_parallel_ankles: bool = False
    ):
        if not 0.0 <= start_noise <= 0.3:
            raise ValueError(f"start_noise must be in [0, 0.3] rad, got {start_noise}")
        super().__init__(random=random)
        self.start_noise = float(start_noise)
        self.filter_rates = bool(filter_rates)
        self.floor_parallel_ankles = bool(floor_parallel_ankles)
        self._filter_b, self._filter_a = butterworth_coefficients(RATE_FILTER_CUTOFF, 1.0 / CONTROL_TIMESTEP)
        self.stance = LEFT
        self._voltages = [0.0] * len(_MOTOR_JOINTS)
        self.footsteps = 0
        self.footstep = False
        self.footstep_length = 0.0
        self.stance_contact = True
        self.energy = 0.0
        self.reward = 0.0
        self.fell = False
        self.distance = 0.0

    @property
    def voltages(self) -> np.ndarray:
        """The 7 motor voltages [V] applied in the last step, in ``_MOTOR_JOINTS`` order, after clipping."""
        return np.array(self._voltages)

    def action_spec(self, physics):
        """Voltages of the stance hip, swing hip and swing knee.

        :param physics: the physics (dm_control's signature; unused).
        """
        return specs.BoundedArray((3,), np.float64, -MAX_VOLTAGE, MAX_VOLTAGE, name="stance_hip,swing_hip,swing_knee")

    def initialize_episode(self, physics) -> None:
        pose = dict(START_POSE)
        noise = self.start_noise
        if noise > 0.0:
            for name in ("torso", "hip_left", "hip_right", "knee_right"):
                pose[name] += self.random.uniform(-noise, noise)
        pose["ankle_left"] = -(pose["torso"] + pose["hip_left"] + pose["knee_left"])
        physics.set_pose(pose)
        self.stance = LEFT
        self._voltages = [0.0] * len(_MOTOR_JOINTS)
        physics.set_voltages(self._voltages)
        qpos = physics._qpos.tolist()
        self._angles = [qpos[index] for index in physics._state_qpos]
        self._raw_rates = [0.0] * len(_STATE_JOINTS)
        self._rates = [0.0] * len(_STATE_JOINTS)
        self._previous_rates = list(self._rates)
        self._progress = self._swing_progress()
        self._start_x = float(physics.hip_position()[0])
        self.footsteps = 0
        self.footstep = False
        self.footstep_length = 0.0
        # The contact sensors read the simulator's contacts. The left foot rests exactly on the floor, without
        # penetration, so none is reported yet; in Erik's ODE model, too, contacts exist only after a first step.
        self.stance_contact = physics.foot_contacts()[LEFT]
        self.energy = 0.0
        self.reward = 0.0
        self.fell = False
        self.distance = 0.0
        # No delegation to base.Task.initialize_episode: it only calls after_step (to recolour geoms by reward),
        # which here would count a control step at the reset.

    def auto_voltages(self) -> dict[str, float]:
        """Erik's controllers for the joints the agent does not drive (GRL's ``autoActuate*``), from the current state
        [V], before clipping."""
        voltages = self._auto_voltage_list()
        stance, swing = self.stance, 1 - self.stance
        auto = (0, _KNEE[stance] - 1, _ANKLE[stance] - 1, _ANKLE[swing] - 1)
        return {_MOTOR_JOINTS[index]: voltages[index] for index in auto}

    def _auto_voltage_list(self) -> list[float]:
        """The 7 motor voltages with the auto-controlled joints filled in and the learned ones 0."""
        angles = self._angles
        stance = self.stance
        voltages = [0.0] * len(_MOTOR_JOINTS)
        voltages[0] = ARM_GAIN * (ARM_TARGET - angles[1])
        knee = _KNEE[stance]
        voltages[knee - 1] = STANCE_KNEE_GAIN * (STANCE_KNEE_TARGET - angles[knee])
        for side in (stance, 1 - stance):
            ankle = _ANKLE[side]
            if self.floor_parallel_ankles:
                foot = angles[0] + angles[_HIP[side]] + angles[_KNEE[side]] + angles[ankle]
                voltages[ankle - 1] = FLOOR_PARALLEL_ANKLE_GAIN * (ANKLE_TARGET - foot)
            else:
                voltages[ankle - 1] = ANKLE_GAIN * (ANKLE_TARGET - angles[ankle])
        return voltages

    def before_step(self, action, physics) -> None:
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (3,) or not np.all(np.isfinite(action)):
            raise ValueError(f"LEO needs 3 finite voltages (stance hip, swing hip, swing knee), got {action!r}")
        self.apply_voltages(*action.tolist(), physics)

    def apply_voltages(self, stance_hip: float, swing_hip: float, swing_knee: float, physics) -> None:
        """``before_step`` for three finite voltages [V] given as Python floats (not checked): add the auto-controlled
        joints, clip all to +-MAX_VOLTAGE and set them as the motors' controls for the coming step.

        :param stance_hip: the stance hip's voltage [V].
        :param swing_hip: the swing hip's voltage [V].
        :param swing_knee: the swing knee's voltage [V].
        :param physics: the physics to set the controls of.
        """
        stance, swing = self.stance, 1 - self.stance
        voltages = self._auto_voltage_list()
        voltages[_HIP[stance] - 1] = stance_hip
        voltages[_HIP[swing] - 1] = swing_hip
        voltages[_KNEE[swing] - 1] = swing_knee
        voltages = [_clip(value, MAX_VOLTAGE) for value in voltages]
        self._voltages = voltages
        physics._ctrl[physics._motor_ctrl] = voltages

    def after_step(self, physics) -> None:
        qpos, qvel = physics._qpos.tolist(), physics._qvel.tolist()
        self._angles = [qpos[index] for index in physics._state_qpos]
        self._update_rates([qvel[index] for index in physics._state_qvel])
        self.energy = self._motor_energy()
        progress = self._swing_progress()
        self._update_stance(*physics.foot_contacts())
        torso = self._angles[0]
        self.fell = abs(torso) > MAX_TORSO_ANGLE or abs(torso + self._angles[_HIP[self.stance]]) > MAX_STANCE_LEG_ANGLE
        gained = _clip(progress, MAX_FOOTSTEP_LENGTH) - _clip(self._progress, MAX_FOOTSTEP_LENGTH)
        self.reward = (
            REWARD_TIME + REWARD_ENERGY * self.energy + REWARD_PROGRESS * gained + (REWARD_FALL if self.fell else 0.0)
        )
        self._progress = -progress if self.footstep else progress
        self.distance = physics._xanchor.item(physics.hip_joint, 0) - self._start_x

    def info(self, physics) -> dict:
        """Per-step facts: whether a footstep was made (and its length), the net footstep count, the hip's walked
        distance since the start, whether LEO fell, the hip and knee motors' electrical energy of this step [J],
        the stance leg and whether its foot touches the floor.

        :param physics: the physics after the step.
        """
        return {
            "footstep": self.footstep,
            "footstep_length": self.footstep_length,
            "footsteps": self.footsteps,
            "distance": self.distance,
            "fell": self.fell,
            "energy": self.energy,
            "stance_leg": _SIDES[self.stance],
            "stance_contact": self.stance_contact,
        }

    def _update_rates(self, raw: list[float]) -> None:
        """Erik's rate filter, ``y[n] = b (x[n] + x[n-1]) - a y[n-1]``, restarted at every episode (index 0, the
        torso, is never filtered)."""
        previous = self._rates
        self._previous_rates = previous
        if self.filter_rates:
            b, a = self._filter_b, self._filter_a
            raw_before = self._raw_rates
            rates = [raw[0]]
            rates.extend([b * (raw[k] + raw_before[k]) - a * previous[k] for k in range(1, len(raw))])
        else:
            rates = list(raw)
        self._raw_rates = raw
        self._rates = rates

    def _motor_energy(self) -> float:
        """Electrical energy of the hip and knee motors over the last step [J], negative work not counted."""
        energy = 0.0
        rates, previous, voltages = self._rates, self._previous_rates, self._voltages
        for index in _HIP_KNEE:
            voltage = voltages[index - 1]
            speed = 0.5 * (rates[index] + previous[index])
            current = (voltage - TORQUE_CONSTANT_TIMES_GEAR * speed) / TERMINAL_RESISTANCE
            energy += max(0.0, voltage * current) * CONTROL_TIMESTEP
        return energy

    def _update_stance(self, left_contact: bool, right_contact: bool) -> None:
        """Stance leg from the foot contacts; a change of stance leg is a footstep (GRL's
        ``updateDerivedStateVars``)."""
        previous = self.stance
        if left_contact and right_contact:
            self.stance = LEFT if self._ankle_x(LEFT) > self._ankle_x(RIGHT) else RIGHT
        elif left_contact:
            self.stance = LEFT
        elif right_contact:
            self.stance = RIGHT
        self.footstep = self.stance != previous
        self.stance_contact = (left_contact, right_contact)[self.stance]
        self.footstep_length = 0.0
        if self.footstep:
            self.footstep_length = self._ankle_x(self.stance) - self._ankle_x(previous)
            self.footsteps += 1 if self.footstep_length > 0.0 else -1

    def _ankle_x(self, side: int) -> float:
        angles = self._angles
        return ankle_x_from_hip(angles[0], angles[_HIP[side]], angles[_KNEE[side]])

    def _swing_progress(self) -> float:
        """Swing ankle ahead of the stance ankle [m], from joint angles."""
        return self._ankle_x(1 - self.stance) - self._ankle_x(self.stance)

    def stance_values(self) -> list[float]:
        """The 10 values of Eq. 4.6 in the current stance/swing assignment, as Python floats [rad, rad/s]."""
        angles, rates = self._angles, self._rates
        values = []
        for index in _OBSERVED[self.stance]:
            values.append(angles[index])
            values.append(rates[index])
        return values

    def stance_observation(self) -> np.ndarray:
        """The 10-D state of Eq. 4.6 in the current stance/swing assignment."""
        return np.array(self.stance_values())

    def get_observation(self, physics) -> collections.OrderedDict:
        return collections.OrderedDict(state=self.stance_observation())

    def get_reward(self, physics) -> float:
        return self.reward

    def get_termination(self, physics):
        """Discount 0 at a fall (absorbing); the 25 s limit is left to the environment.

        :param physics: the physics after the step.
        """
        return 0.0 if self.fell else None


def load_physics() -> Physics:
    """LEO's physics with the timestep set to exactly CONTROL_TIMESTEP / PHYSICS_SUBSTEPS."""
    physics = Physics.from_xml_string(*get_model_and_assets())
    physics.model.opt.timestep = CONTROL_TIMESTEP / PHYSICS_SUBSTEPS
    return physics


def walk(time_limit: float = TIME_LIMIT, random=None, environment_kwargs: dict | None = None, **task_kwargs):
    """The LEO walking task as a dm_control environment (voltages in volts), like the suite's ``walker.walk``.

    :param time_limit: the episode's length [s] (default 25).
    :param random: the task's random state or seed, as in dm_control (default None).
    :param environment_kwargs: keyword arguments of ``dm_control.rl.control.Environment`` (default None).
    """
    task = LeoWalk(random=random, **task_kwargs)
    return control.Environment(
        load_physics(), task, time_limit=time_limit, control_timestep=CONTROL_TIMESTEP, **(environment_kwargs or {})
    )

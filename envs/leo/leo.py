"""LEO, the Delft biped of thesis section 4.2.3, as a dm_control domain (modelled on the suite's ``walker``).

The MJCF model ``leo.xml`` rebuilds Erik Schuitema's ODE model (facts and figures: ``leo_reference.md``); this module adds
the walking task of the thesis (Eq. 4.6-4.7, Table 4.3) with Erik's task logic:

* 30 Hz control, voltages held over an exact number of physics substeps;
* the 10-D stance/swing observation of Eq. 4.6 with Butterworth-filtered joint rates;
* the learned voltages of the stance hip, swing hip and swing knee; proportional auto-controllers for the arm, the stance
  knee and both ankles;
* stance-leg choice from the foot contacts, footsteps, and the reward of time, electrical energy, swing-foot progress
  and falls; a fall ends the episode, 25 s truncate it.

``walk()`` returns a ``dm_control.rl.control.Environment`` whose action is the three voltages in volts;
:class:`sb3_er_envs.leo.LeoEnv` is the Gymnasium face with Erik's 7 voltage levels per joint.
"""

from __future__ import annotations

import collections
import math
import os
from pathlib import Path

import numpy as np

from ._gl import prepare_backend

_USER_MUJOCO_GL = os.environ.get("MUJOCO_GL")
#: Why MuJoCo cannot render in this process (None: it can try). Simulation never needs OpenGL.
RENDERING_UNAVAILABLE = prepare_backend()

from dm_control import _render, mujoco  # noqa: E402
from dm_control.rl import control  # noqa: E402
from dm_control.suite import base  # noqa: E402
from dm_env import specs  # noqa: E402

#: The OpenGL backend dm_control took ("glfw", "egl", "osmesa", or "disable" when rendering is unavailable).
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

#: Erik's start pose (reference section 2, Eq. 4.7 with the torso in the task's sign): left leg stance and vertical.
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


def butterworth_coefficients(cutoff: float, sample_rate: float) -> tuple[float, float]:
    """First-order low-pass by the Tustin transform without pre-warping: ``y[n] = b (x[n] + x[n-1]) - a y[n-1]``.

    Returns ``(b, a)``; for 10 Hz at 30 Hz this is (0.511527, 0.023055), the coefficients of Erik's rate filter.
    """
    if not 0.0 < cutoff:
        raise ValueError(f"filter cut-off must be positive, got {cutoff}")
    k = 2.0 * math.pi * cutoff / (2.0 * sample_rate)
    return k / (1.0 + k), (k - 1.0) / (k + 1.0)


def _clip(value: float, bound: float) -> float:
    return bound if value > bound else -bound if value < -bound else value


def ankle_x_from_hip(torso: float, hip: float, knee: float) -> float:
    """Horizontal position of the ankle relative to the hip from joint angles only (Erik's footstep measure) [m]."""
    thigh = torso + hip
    return THIGH_LENGTH * math.sin(thigh) + SHANK_LENGTH * math.sin(thigh + knee)


def get_model_and_assets() -> tuple[bytes, dict]:
    """The MJCF model as a string and its (empty) assets, as dm_control suite domains provide them."""
    return MODEL_PATH.read_bytes(), {}


class Physics(mujoco.Physics):
    """LEO's physics with accessors in LEO's own variables (angles about -y, the torso positive leaning backward)."""

    def _reload_from_data(self, data) -> None:
        super()._reload_from_data(data)
        model = self.model
        names = ("root_x", "root_z", "torso", *_MOTOR_JOINTS)
        self.qpos_index = {name: int(model.jnt_qposadr[model.name2id(name, "joint")]) for name in names}
        self.qvel_index = {name: int(model.jnt_dofadr[model.name2id(name, "joint")]) for name in names}
        self._motor_actuators = np.array([model.name2id(name, "actuator") for name in _MOTOR_JOINTS])
        self._foot_geoms = [frozenset(model.name2id(f"{part}_{side}", "geom") for part in ("heel", "toe"))
                            for side in _SIDES]
        self._contact_geoms = np.flatnonzero(model.geom_contype)
        self._left_heel = model.name2id("heel_left", "geom")
        self.hip_joint = model.name2id("hip_left", "joint")
        self._torso_body = model.name2id("torso", "body")

    def joint_angle(self, name: str) -> float:
        """Angle of a joint, or of the root ("torso" pitch, "root_x", "root_z"), in LEO's convention."""
        return float(self.data.qpos[self.qpos_index[name]])

    def joint_rate(self, name: str) -> float:
        """Unfiltered rate of a joint or of the root."""
        return float(self.data.qvel[self.qvel_index[name]])

    def set_pose(self, angles: dict[str, float]) -> None:
        """Set joint angles with zero rates and place the robot so that its lowest contact point touches the floor and
        the left heel is at x = 0 (Erik's model fixes the left heel to the world origin)."""
        unknown = set(angles) - set(self.qpos_index)
        if unknown:
            raise ValueError(f"unknown LEO joints {sorted(unknown)}; known: {sorted(self.qpos_index)}")
        self.data.qpos[:] = 0.0
        self.data.qvel[:] = 0.0
        for name, value in angles.items():
            self.data.qpos[self.qpos_index[name]] = value
        self.forward()
        radius = self.model.geom_size[self._contact_geoms, 0]
        lowest = float(np.min(self.data.geom_xpos[self._contact_geoms, 2] - radius))
        self.data.qpos[self.qpos_index["root_z"]] -= lowest
        self.data.qpos[self.qpos_index["root_x"]] -= float(self.data.geom_xpos[self._left_heel, 0])
        self.forward()

    def set_voltages(self, voltages) -> None:
        """Set the 7 motor voltages (order: shoulder, hip left, hip right, knee left, knee right, ankle left, ankle
        right), each clipped to +-MAX_VOLTAGE."""
        self.data.ctrl[self._motor_actuators] = np.clip(voltages, -MAX_VOLTAGE, MAX_VOLTAGE)

    def foot_contacts(self) -> tuple[bool, bool]:
        """Whether the heel or the toe of the left and of the right foot touches the floor."""
        ncon = self.data.ncon
        touching = set(self.data.contact.geom1[:ncon].tolist()) | set(self.data.contact.geom2[:ncon].tolist())
        return bool(touching & self._foot_geoms[LEFT]), bool(touching & self._foot_geoms[RIGHT])

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
    """Erik Schuitema's walking task on LEO (thesis 4.2.3; reference sections 4.2-4.8).

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
    """

    def __init__(self, random=None, start_noise: float = 0.05, filter_rates: bool = True,
                 floor_parallel_ankles: bool = False):
        if not 0.0 <= start_noise <= 0.3:
            raise ValueError(f"start_noise must be in [0, 0.3] rad, got {start_noise}")
        super().__init__(random=random)
        self.start_noise = float(start_noise)
        self.filter_rates = bool(filter_rates)
        self.floor_parallel_ankles = bool(floor_parallel_ankles)
        self._filter_b, self._filter_a = butterworth_coefficients(RATE_FILTER_CUTOFF, 1.0 / CONTROL_TIMESTEP)
        self._names = ("torso", *_MOTOR_JOINTS)
        self.stance = LEFT
        self.voltages = np.zeros(len(_MOTOR_JOINTS))
        self.footsteps = 0
        self.footstep = False
        self.footstep_length = 0.0
        self.stance_contact = True
        self.energy = 0.0
        self.reward = 0.0
        self.fell = False
        self.distance = 0.0

    def action_spec(self, physics):
        """Voltages of the stance hip, swing hip and swing knee."""
        return specs.BoundedArray((3,), np.float64, -MAX_VOLTAGE, MAX_VOLTAGE,
                                  name="stance_hip,swing_hip,swing_knee")

    def initialize_episode(self, physics) -> None:
        pose = dict(START_POSE)
        noise = self.start_noise
        if noise > 0.0:
            for name in ("torso", "hip_left", "hip_right", "knee_right"):
                pose[name] += self.random.uniform(-noise, noise)
        pose["ankle_left"] = -(pose["torso"] + pose["hip_left"] + pose["knee_left"])
        physics.set_pose(pose)
        self.stance = LEFT
        self.voltages = np.zeros(len(_MOTOR_JOINTS))
        physics.set_voltages(self.voltages)
        self._angles = {name: physics.joint_angle(name) for name in self._names}
        self._raw_rates = dict.fromkeys(self._names, 0.0)
        self._rates = dict.fromkeys(self._names, 0.0)
        self._previous_rates = dict(self._rates)
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
        """Erik's controllers for the joints the agent does not drive (reference 4.5), from the current state."""
        angles = self._angles
        stance, swing = _SIDES[self.stance], _SIDES[1 - self.stance]
        voltages = {
            "shoulder": ARM_GAIN * (ARM_TARGET - angles["shoulder"]),
            f"knee_{stance}": STANCE_KNEE_GAIN * (STANCE_KNEE_TARGET - angles[f"knee_{stance}"]),
        }
        for side in (stance, swing):
            if self.floor_parallel_ankles:
                foot = angles["torso"] + angles[f"hip_{side}"] + angles[f"knee_{side}"] + angles[f"ankle_{side}"]
                voltages[f"ankle_{side}"] = FLOOR_PARALLEL_ANKLE_GAIN * (ANKLE_TARGET - foot)
            else:
                voltages[f"ankle_{side}"] = ANKLE_GAIN * (ANKLE_TARGET - angles[f"ankle_{side}"])
        return voltages

    def before_step(self, action, physics) -> None:
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (3,) or not np.all(np.isfinite(action)):
            raise ValueError(f"LEO needs 3 finite voltages (stance hip, swing hip, swing knee), got {action!r}")
        stance, swing = _SIDES[self.stance], _SIDES[1 - self.stance]
        voltages = self.auto_voltages()
        voltages[f"hip_{stance}"], voltages[f"hip_{swing}"], voltages[f"knee_{swing}"] = action.tolist()
        self.voltages = np.array([_clip(voltages[name], MAX_VOLTAGE) for name in _MOTOR_JOINTS])
        physics.set_voltages(self.voltages)

    def after_step(self, physics) -> None:
        qpos, qvel = physics.data.qpos.tolist(), physics.data.qvel.tolist()
        self._angles = {name: qpos[physics.qpos_index[name]] for name in self._names}
        self._update_rates({name: qvel[physics.qvel_index[name]] for name in self._names})
        self.energy = self._motor_energy()
        progress = self._swing_progress()
        self._update_stance(*physics.foot_contacts())
        self.fell = (abs(self._angles["torso"]) > MAX_TORSO_ANGLE
                     or abs(self._angles["torso"] + self._angles[f"hip_{_SIDES[self.stance]}"]) > MAX_STANCE_LEG_ANGLE)
        gained = _clip(progress, MAX_FOOTSTEP_LENGTH) - _clip(self._progress, MAX_FOOTSTEP_LENGTH)
        self.reward = (REWARD_TIME + REWARD_ENERGY * self.energy + REWARD_PROGRESS * gained
                       + (REWARD_FALL if self.fell else 0.0))
        self._progress = -progress if self.footstep else progress
        self.distance = float(physics.data.xanchor[physics.hip_joint, 0]) - self._start_x

    def info(self, physics) -> dict:
        """Per-step facts: whether a footstep was made (and its length), the net footstep count, the hip's walked
        distance since the start, whether LEO fell, the hip and knee motors' electrical energy of this step [J],
        the stance leg and whether its foot touches the floor."""
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

    def _update_rates(self, raw: dict[str, float]) -> None:
        """Erik's rate filter, ``y[n] = b (x[n] + x[n-1]) - a y[n-1]``, restarted at every episode."""
        self._previous_rates = self._rates
        if self.filter_rates:
            b, a = self._filter_b, self._filter_a
            rates = {name: b * (raw[name] + self._raw_rates[name]) - a * self._rates[name] for name in _MOTOR_JOINTS}
            rates["torso"] = raw["torso"]
        else:
            rates = dict(raw)
        self._raw_rates = raw
        self._rates = rates

    def _motor_energy(self) -> float:
        """Electrical energy of the hip and knee motors over the last step [J], negative work not counted."""
        energy = 0.0
        for index, name in enumerate(_MOTOR_JOINTS):
            if name.startswith(("hip", "knee")):
                voltage = float(self.voltages[index])
                speed = 0.5 * (self._rates[name] + self._previous_rates[name])
                current = (voltage - TORQUE_CONSTANT_TIMES_GEAR * speed) / TERMINAL_RESISTANCE
                energy += max(0.0, voltage * current) * CONTROL_TIMESTEP
        return energy

    def _update_stance(self, left_contact: bool, right_contact: bool) -> None:
        """Stance leg from the foot contacts; a change of stance leg is a footstep (reference 4.3)."""
        previous = self.stance
        if left_contact and right_contact:
            ahead_left = self._ankle_x("left") > self._ankle_x("right")
            self.stance = LEFT if ahead_left else RIGHT
        elif left_contact:
            self.stance = LEFT
        elif right_contact:
            self.stance = RIGHT
        self.footstep = self.stance != previous
        self.stance_contact = (left_contact, right_contact)[self.stance]
        self.footstep_length = 0.0
        if self.footstep:
            self.footstep_length = self._ankle_x(_SIDES[self.stance]) - self._ankle_x(_SIDES[previous])
            self.footsteps += 1 if self.footstep_length > 0.0 else -1

    def _ankle_x(self, side: str) -> float:
        angles = self._angles
        return ankle_x_from_hip(angles["torso"], angles[f"hip_{side}"], angles[f"knee_{side}"])

    def _swing_progress(self) -> float:
        """Swing ankle ahead of the stance ankle [m], from joint angles."""
        return self._ankle_x(_SIDES[1 - self.stance]) - self._ankle_x(_SIDES[self.stance])

    def stance_observation(self) -> np.ndarray:
        """The 10-D state of Eq. 4.6 in the current stance/swing assignment."""
        angles, rates = self._angles, self._rates
        stance, swing = _SIDES[self.stance], _SIDES[1 - self.stance]
        names = ("torso", f"hip_{stance}", f"hip_{swing}", f"knee_{stance}", f"knee_{swing}")
        return np.array([value for name in names for value in (angles[name], rates[name])])

    def get_observation(self, physics) -> collections.OrderedDict:
        return collections.OrderedDict(state=self.stance_observation())

    def get_reward(self, physics) -> float:
        return self.reward

    def get_termination(self, physics):
        """Discount 0 at a fall (absorbing); the 25 s limit is left to the environment."""
        return 0.0 if self.fell else None


def load_physics() -> Physics:
    """LEO's physics with the timestep set to exactly CONTROL_TIMESTEP / PHYSICS_SUBSTEPS."""
    physics = Physics.from_xml_string(*get_model_and_assets())
    physics.model.opt.timestep = CONTROL_TIMESTEP / PHYSICS_SUBSTEPS
    return physics


def walk(time_limit: float = TIME_LIMIT, random=None, environment_kwargs: dict | None = None, **task_kwargs):
    """The LEO walking task as a dm_control environment (voltages in volts), like the suite's ``walker.walk``."""
    task = LeoWalk(random=random, **task_kwargs)
    return control.Environment(load_physics(), task, time_limit=time_limit, control_timestep=CONTROL_TIMESTEP,
                               **(environment_kwargs or {}))

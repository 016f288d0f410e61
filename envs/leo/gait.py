"""Erik Schuitema's hand-made LEO gait: the "observing" controller his agent watched before learning
(GRL's LeoBhWalkSym.cpp, ``autoActuateHips2`` and the knee controller).

The hips follow ``autoActuateHips2``: a spring on the angle between the legs (target 0.680 rad) drives the swing hip,
and the stance hip gets a fifth of it in reverse plus, while the stance foot is on the floor, a torso-pitch controller
(target -0.09 rad, leaning slightly forward). The swing knee bends with full negative voltage for 0.184 s after each
footstep and is then stretched by a proportional controller. A fraction ``explore_rate`` of the steps takes uniformly
random voltage levels instead, as Erik's observing mode did.
"""

from __future__ import annotations

import bisect

import numpy as np

from .leo import CONTROL_TIMESTEP, MAX_VOLTAGE, TORQUE_TO_VOLTAGE, VOLTAGE_LEVELS

HIP_SPREAD_TARGET = 0.680
HIP_SPREAD_GAIN = 4.0
STANCE_HIP_SHARE = -0.20
TORSO_TARGET = -0.09
TORSO_GAIN = -14.0
EARLY_SWING_VOLTAGE = -14.0
EARLY_SWING_TIME = 0.184
SWING_KNEE_GAIN = 65.0


class ObservingGait:
    """Erik's hand-made gait as a policy over LEO's observation (Eq. 4.6 order) and step ``info``.

    Call :meth:`reset` at the start of an episode and :meth:`voltages` (or :meth:`action` for ``LeoEnv``'s voltage
    levels) every control step with the observation and the ``info`` of the step that produced it.

    :param explore_rate: the fraction of control steps that take uniformly random voltages instead (a probability;
        default 0, the pure gait).
    :param seed: seed of those random choices; None (default) for fresh entropy.
    """

    def __init__(self, explore_rate: float = 0.0, seed: int | None = None):
        if not 0.0 <= explore_rate <= 1.0:
            raise ValueError(f"explore_rate must be a probability, got {explore_rate}")
        self.explore_rate = explore_rate
        self.rng = np.random.default_rng(seed)
        self.swing_time = 0.0

    def reset(self) -> None:
        """Start a new episode: the swing phase of the initial swing leg begins now."""
        self.swing_time = 0.0

    def voltages(self, observation: np.ndarray, info: dict) -> np.ndarray:
        """Voltages of the stance hip, swing hip and swing knee for this control step.

        ``info`` needs ``stance_contact`` (the stance foot touches the floor) and ``footstep_length`` (the length of
        the footstep made in the last step, 0 without one); a forward footstep restarts the swing timer.

        :param observation: LeoEnv's observation.
        :param info: LeoEnv's info dict of the last step.
        """
        return np.array(self._command(observation, info))

    def action(self, observation: np.ndarray, info: dict) -> np.ndarray:
        """The same command on Erik's 7 voltage levels: the nearest level index per joint (the lower one at a tie),
        for ``LeoEnv``.

        :param observation: LeoEnv's observation.
        :param info: LeoEnv's info dict of the last step.
        """
        return np.array([_nearest_level(voltage) for voltage in self._command(observation, info)])

    def _command(self, observation, info: dict) -> list[float]:
        """:meth:`voltages` as Python floats (plain float arithmetic: the same numbers NumPy scalars would give)."""
        self.swing_time += CONTROL_TIMESTEP
        if info["footstep_length"] > 0.0:
            self.swing_time = 0.0
        values = observation.tolist() if isinstance(observation, np.ndarray) else [float(v) for v in observation]
        torso, _, stance_hip, _, swing_hip, _, _, _, swing_knee, _ = values
        if self.explore_rate and self.rng.random() < self.explore_rate:
            return self.rng.choice(VOLTAGE_LEVELS, size=3).tolist()
        spread = HIP_SPREAD_GAIN * (HIP_SPREAD_TARGET - (swing_hip - stance_hip))
        stance_torque = STANCE_HIP_SHARE * spread
        if info["stance_contact"]:
            stance_torque += TORSO_GAIN * (TORSO_TARGET - torso)
        knee = EARLY_SWING_VOLTAGE if self.swing_time < EARLY_SWING_TIME else SWING_KNEE_GAIN * (0.0 - swing_knee)
        command = (TORQUE_TO_VOLTAGE * stance_torque, TORQUE_TO_VOLTAGE * spread, knee)
        return [MAX_VOLTAGE if v > MAX_VOLTAGE else -MAX_VOLTAGE if v < -MAX_VOLTAGE else v for v in command]


_LEVELS = VOLTAGE_LEVELS.tolist()


def _nearest_level(voltage: float) -> int:
    """Index of the voltage level nearest to ``voltage`` (the lower at a tie, as ``argmin`` over all 7 gives)."""
    upper = bisect.bisect_left(_LEVELS, voltage)
    if upper == 0:
        return 0
    if upper == len(_LEVELS):
        return upper - 1
    return upper - 1 if abs(voltage - _LEVELS[upper - 1]) <= abs(voltage - _LEVELS[upper]) else upper

"""The possible returns of an env and the value watch that says when a learner's values leave them.

With rewards in [r_lo, r_hi] on transitions that do not terminate and in [c_lo, c_hi] on terminating ones (a
truncation by a time limit is not a termination: it bootstraps), a discounted return
G = r_1 + gamma r_2 + ... + gamma^(n-1) c is a convex combination of sums that lie between the extremes, so every
return lies in

    [min(r_lo / (1 - gamma), c_lo), max(r_hi / (1 - gamma), c_hi)]        (gamma < 1)

(Sutton and Barto 2018, 3.3: the return of an infinite reward sequence bounded by r_max is at most r_max / (1 - gamma)).
With gamma = 1 the returns are bounded only when every episode terminates within H steps (``horizon``): then at most
H - 1 step rewards precede the terminal one, [c_lo + (H - 1) min(r_lo, 0), c_hi + (H - 1) max(r_hi, 0)].

Q-values are expected returns, so a value outside these bounds, and outside the range the values started in (the
policy's ``initial_value``), is impossible: the watch flags it. Bounds come from the env's ``reward_bounds`` attribute
(every sb3-er env declares one; Gymnasium 1.x has no ``reward_range``), or, for other envs and under a wrapper that may
change rewards, from the rewards observed so far.
"""

from __future__ import annotations

import math
import re
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_er.common import kernels
from sb3_er.common.checks import is_real

#: A value counts as outside the possible returns only beyond this share of the largest reward's size (one reward's
#: worth of rounding and generalisation, whatever the width of the returns).
TOLERANCE = 0.05
VALUE_BOUND_ACTIONS = ("warn", "raise", "ignore")

#: Wrappers that never change the reward (besides observation and action wrappers): declared bounds still hold.
REWARD_PRESERVING_WRAPPERS = (
    "TimeLimit",
    "OrderEnforcing",
    "PassiveEnvChecker",
    "Monitor",
    "RecordEpisodeStatistics",
    "RecordVideo",
    "HumanRendering",
    "RenderCollection",
    "EnvCompatibility",
    "StickyAction",
    "Autoreset",
    "AutoResetWrapper",
    "FlattenObservation",
    "TimeAwareObservation",
    "FrameStackObservation",
    "StepAPICompatibility",
)


class ValueBoundError(ArithmeticError):
    """A learner's value (a target or Q(s, a)) left the possible returns (``value_bound_action="raise"``)."""


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"reward_bounds[{name!r}] must be a (low, high) pair of numbers, got {value!r}") from None
    if math.isnan(low) or math.isnan(high) or low > high:
        raise ValueError(f"reward_bounds[{name!r}] must be a (low, high) pair with low <= high, got {value!r}")
    return low, high


@dataclass(frozen=True)
class RewardBounds:
    """Where an env's rewards lie.

    :param step: (r_lo, r_hi), the rewards of transitions that do not terminate (truncated ones included).
    :param terminal: (c_lo, c_hi), the rewards of terminating transitions; None if the env never terminates.
    :param horizon: every episode terminates within this many steps (only needed for gamma = 1), or None.
    """

    step: tuple[float, float]
    terminal: tuple[float, float] | None = None
    horizon: int | None = None

    @classmethod
    def from_attribute(cls, value: Any) -> RewardBounds:
        """An env's ``reward_bounds``: a RewardBounds or a mapping with ``step``, optional ``terminal`` and
        ``horizon``, e.g. ``{"step": (-1, 30), "terminal": (-50, -50)}``; ValueError naming the problem.

        :param value: the env's ``reward_bounds`` attribute.
        """
        if isinstance(value, RewardBounds):
            return value
        if not isinstance(value, Mapping) or "step" not in value or set(value) - {"step", "terminal", "horizon"}:
            raise ValueError(
                "reward_bounds must be a mapping with a 'step' (low, high) pair and optionally 'terminal' (low, high) "
                f"and 'horizon' (steps), got {value!r}"
            )
        terminal = value.get("terminal")
        horizon = value.get("horizon")
        if horizon is not None and (isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1):
            raise ValueError(f"reward_bounds['horizon'] must be a positive integer or None, got {horizon!r}")
        return cls(
            _pair("step", value["step"]),
            None if terminal is None else _pair("terminal", terminal),
            None if horizon is None else int(horizon),
        )

    def returns(self, gamma: float) -> tuple[float, float]:
        """The interval of every possible return under discount ``gamma`` (module docstring); +-inf where unbounded.

        :param gamma: the discount factor, in [0, 1].
        """
        r_lo, r_hi = self.step
        c_lo, c_hi = self.terminal if self.terminal is not None else (math.inf, -math.inf)
        if gamma < 1.0:
            low = min(r_lo / (1.0 - gamma), c_lo)
            high = max(r_hi / (1.0 - gamma), c_hi)
            return low, high
        if self.horizon is not None and self.terminal is not None:
            steps = self.horizon - 1
            return c_lo + steps * min(r_lo, 0.0), c_hi + steps * max(r_hi, 0.0)
        # gamma = 1 without a horizon: a sum of any number of step rewards
        low = -math.inf if r_lo < 0.0 else min(0.0, c_lo)
        high = math.inf if r_hi > 0.0 else max(0.0, c_hi)
        return low, high


def value_bounds(returns: tuple[float, float], initial: tuple[float, float]) -> tuple[float, float]:
    """The hull of the possible returns and the range the values started in.

    :param returns: the (low, high) interval of the possible returns.
    :param initial: the (low, high) range of the initial values.
    """
    return min(returns[0], initial[0]), max(returns[1], initial[1])


def reward_size(rewards: RewardBounds | None) -> float:
    """The largest |r| the rewards can take (0 before any is known; infinite when a bound is).

    :param rewards: the reward bounds, or None.
    """
    if rewards is None:
        return 0.0
    ends = [*rewards.step, *(rewards.terminal or ())]
    return max(abs(end) for end in ends)


def margin(rewards: RewardBounds | None, bounds: tuple[float, float], tolerance: float = TOLERANCE) -> float:
    """How far beyond the possible returns a value may lie before it counts as outside: ``tolerance`` times the
    largest reward's size (:func:`reward_size`), plus a rounding margin of 1e-9 of the bounds' magnitude.

    Why one reward's size rather than the returns' width: the width grows as 1 / (1 - gamma) (10,485 on the pendulum
    swing-up), so a share of it lets values many rewards beyond the bounds pass (a Q of +87.6 from rewards <= 0
    there), while a share of one reward is what rounding and the generalisation of a linear approximator may add.

    :param rewards: the reward bounds (None before any reward is known).
    :param bounds: the (low, high) bounds of the values.
    :param tolerance: the share of the largest reward's size (default 0.05).
    """
    size = reward_size(rewards)
    finite = [abs(b) for b in bounds if math.isfinite(b)]
    rounding = 1e-9 * max(1.0, *finite)
    return tolerance * size + rounding if math.isfinite(size) else math.inf


def widened(bounds: tuple[float, float], width: float) -> tuple[float, float]:
    """The bounds widened by ``width`` on each side (:func:`margin`).

    :param bounds: the (low, high) interval; either end may be infinite.
    :param width: how far to widen each side.
    """
    return bounds[0] - width, bounds[1] + width


def reward_changing_wrapper(env: gym.Env) -> str | None:
    """The name of the outermost wrapper of ``env`` that may change rewards, or None.

    Observation and action wrappers and the wrappers of :data:`REWARD_PRESERVING_WRAPPERS` keep them; every other
    wrapper (a RewardWrapper such as TransformReward or ClipReward, NormalizeReward, or an unknown one) may not.

    :param env: the (possibly wrapped) Gymnasium env.
    """
    while isinstance(env, gym.Wrapper):
        if _changes_rewards(env):
            return type(env).__name__
        env = env.env
    return None


#: VecEnv wrappers that never change the reward.
REWARD_PRESERVING_VEC_WRAPPERS = (
    "VecMonitor",
    "VecCheckNan",
    "VecFrameStack",
    "VecTransposeImage",
    "VecExtractDictObs",
    "VecVideoRecorder",
)


def _wrapper_names(description: str) -> list[str]:
    """The class names in Gymnasium's ``str(env)`` of a wrapped env, outermost first, the env's own class last.

    Gymnasium prints a wrapper as ``<Name`` + its env + ``>``, and the env as ``<EnvClass<env id>>`` (with a spec) or
    ``<EnvClass instance>``, so ``<TimeLimit<Monitor<CartPoleEnv<CartPole-v1>>>>`` gives TimeLimit, Monitor,
    CartPoleEnv: the id, whatever characters it holds (``dm_control/cartpole-swingup-v0``), is not a class.
    """
    segments = re.findall(r"<([^<>]*)", description)
    if not segments:
        return []
    if segments[-1].endswith(" instance"):
        return [*segments[:-1], segments[-1].removesuffix(" instance")]
    return segments[:-1]  # the last segment is the env id


def _changes_rewards(level) -> bool:
    """Whether one level of a wrapped env may change the rewards: a Gymnasium wrapper that is neither an observation
    or action wrapper nor one of :data:`REWARD_PRESERVING_WRAPPERS` (the env itself does not count)."""
    return isinstance(level, gym.Wrapper) and not (
        isinstance(level, (gym.ObservationWrapper, gym.ActionWrapper))
        or type(level).__name__ in REWARD_PRESERVING_WRAPPERS
    )


class _RewardChangingMeta(type):
    def __instancecheck__(cls, instance) -> bool:
        return _changes_rewards(instance)


class RewardChangingWrapper(metaclass=_RewardChangingMeta):
    """Matches (``isinstance``) any wrapper that may change the rewards (:func:`_changes_rewards`), so that
    ``VecEnv.env_is_wrapped(RewardChangingWrapper)`` asks each env, in its own process, the question
    :func:`reward_changing_wrapper` answers in this one. It is sent to subprocess workers by reference (by name)."""


def vec_reward_changer(vec_env) -> str | None:
    """The wrapper that may change the rewards a VecEnv's envs declare, at any level, or None: a VecNormalize that
    normalises rewards, a VecEnv wrapper off the allow-list :data:`REWARD_PRESERVING_VEC_WRAPPERS`, or a Gymnasium
    wrapper of the (first) env off :data:`REWARD_PRESERVING_WRAPPERS` (:func:`reward_changing_wrapper`). Envs in
    subprocesses answer the same question in their own process (``env_is_wrapped`` with
    :class:`RewardChangingWrapper`); the name reported comes from their ``str`` (Gymnasium prints the wrapper chain).

    :param vec_env: the VecEnv, possibly wrapped.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper, VecNormalize

    level = vec_env
    while isinstance(level, VecEnvWrapper):
        if isinstance(level, VecNormalize):
            if level.norm_reward:
                return "VecNormalize(norm_reward=True)"
        elif type(level).__name__ not in REWARD_PRESERVING_VEC_WRAPPERS:
            return type(level).__name__
        level = level.venv
    if isinstance(level, DummyVecEnv):
        return reward_changing_wrapper(level.envs[0])
    try:  # asked in the env's own process: the same test as reward_changing_wrapper, level by level
        changed = level.env_is_wrapped(RewardChangingWrapper, indices=0)[0]
    except Exception:  # a VecEnv that cannot inspect its envs: assume the worst
        return f"an env of {type(level).__name__} that cannot be inspected"
    if not changed:
        return None
    try:  # the wrapper's name, for the message, from Gymnasium's description of the chain
        names = _wrapper_names(level.env_method("__str__", indices=0)[0])
    except Exception:
        names = []
    unknown = [name for name in names[:-1] if name not in REWARD_PRESERVING_WRAPPERS]
    return unknown[0] if unknown else "a wrapper of the env"


class ValueWatch:
    """The bounds a learner's values must keep, the kernels' watch array, and what a learner makes of them: the
    stored rewards a replay phase is about to learn from, the phase's figures, and the message when a value first
    leaves the bounds.

    :param source: where the reward bounds come from: ``"env"`` (declared) or ``"observed"`` (the rewards seen so far,
        updated by :meth:`observe`).
    :param bounds: the declared RewardBounds (``source="env"``).
    :param gamma: the learner's discount.
    :param initial: (low, high) of the initial values.
    :param reason: why the bounds are observed (shown in messages), e.g. "the env declares no reward_bounds".
    :param enabled: whether the kernels watch (False: the array is empty and the kernels skip it; the bounds are
        still kept, for the stabilizers that read them).
    """

    def __init__(
        self,
        source: str,
        bounds: RewardBounds | None,
        gamma: float,
        initial: tuple[float, float],
        reason: str = "",
        enabled: bool = True,
    ):
        self.source = source
        self.gamma = float(gamma)
        self.initial = (float(initial[0]), float(initial[1]))
        self.reason = reason
        self.enabled = enabled
        #: Names this watch to the buffers whose stored rewards it has read (``observed_by_watch``).
        self.token = uuid.uuid4().hex
        self.array = kernels.new_watch() if enabled else kernels.NO_WATCH
        self._declared = bounds
        self._step = [math.inf, -math.inf]
        self._terminal = [math.inf, -math.inf]
        self.bounds = (math.inf, -math.inf)
        self.margin = 0.0
        self._phase_start: tuple[float, np.ndarray] | None = None
        self._update_bounds()

    @classmethod
    def for_env(
        cls,
        vec_env,
        gamma: float,
        initial: tuple[float, float],
        enabled: bool = True,
        earlier: ValueWatch | None = None,
    ) -> ValueWatch:
        """The watch of a VecEnv: the (first) env's declared ``reward_bounds``, unless a wrapper at any level may
        change the rewards (:func:`vec_reward_changer`) or the env declares none, then the rewards observed. The
        counts and the first excursion carry over from ``earlier`` (a watch of the same run).

        :param vec_env: the VecEnv.
        :param gamma: the learner's discount.
        :param initial: (low, high) of the initial values.
        :param enabled: whether the kernels watch (default True).
        :param earlier: the run's previous watch, or None.
        """
        declared = vec_env.get_attr("reward_bounds", indices=0)[0] if vec_env.has_attr("reward_bounds") else None
        changer = vec_reward_changer(vec_env)
        if declared is not None and changer is None:
            watch = cls("env", RewardBounds.from_attribute(declared), gamma, initial, enabled=enabled)
        else:
            reason = (
                "the env declares no reward_bounds"
                if declared is None
                else f"{changer} may change the rewards the env declares"
            )
            watch = cls("observed", None, gamma, initial, reason, enabled=enabled)
        if earlier is not None and enabled and earlier.enabled:
            for entry in CUMULATIVE:
                watch.array[entry] = earlier.array[entry]
        return watch

    def observed_rewards(self) -> dict[str, list[float] | None] | None:
        """The extremes of the rewards observed so far, as plain lists ({"step": [low, high] or None, "terminal":
        likewise}), so that a saved model keeps them; None for declared bounds."""
        if not self.observing:
            return None
        return {
            "step": list(self._step) if self._step[0] <= self._step[1] else None,
            "terminal": list(self._terminal) if self._terminal[0] <= self._terminal[1] else None,
        }

    def observe_rewards(self, observed: dict[str, list[float] | None] | None) -> None:
        """Widen observed bounds with the extremes of :meth:`observed_rewards` (a saved model's, or an earlier
        watch's); nothing for declared bounds or None.

        :param observed: {"step": [low, high] or None, "terminal": likewise}, or None.
        """
        if observed is None:
            return
        if not isinstance(observed, dict) or set(observed) != {"step", "terminal"}:
            raise ValueError(f"observed_rewards: expected a dict of 'step' and 'terminal', got {observed!r}")
        for key, extremes in observed.items():
            if extremes is not None and not (
                isinstance(extremes, (list, tuple))
                and len(extremes) == 2
                and all(is_real(end) and math.isfinite(end) for end in extremes)
                and extremes[0] <= extremes[1]
            ):
                raise ValueError(f"observed_rewards[{key!r}]: expected None or [low, high] finite, got {extremes!r}")
        if not self.observing:
            return
        for key, terminated in (("step", False), ("terminal", True)):
            for reward in observed[key] or ():
                self.observe(float(reward), terminated)

    @property
    def observing(self) -> bool:
        """Whether the bounds come from the rewards observed (they widen with each new reward)."""
        return self.source == "observed"

    @property
    def reward_bounds(self) -> RewardBounds | None:
        """The reward bounds in use: declared, or observed so far (None before the first reward)."""
        if self.source == "env":
            return self._declared
        if self._step[0] > self._step[1]:
            return None
        terminal = tuple(self._terminal) if self._terminal[0] <= self._terminal[1] else None
        return RewardBounds(step=tuple(self._step), terminal=terminal)

    def _update_bounds(self) -> None:
        rewards = self.reward_bounds
        if rewards is not None:
            returns = rewards.returns(self.gamma)
        elif self._terminal[0] <= self._terminal[1]:  # only terminating transitions so far: a return is one reward
            returns = tuple(self._terminal)
        else:
            returns = self.initial
        self.bounds = value_bounds(returns, self.initial)
        self.margin = margin(rewards, self.bounds)
        if self.enabled:
            kernels.set_watch_bounds(self.array, *self.bounds, self.margin)

    def observe(self, reward: float, terminated: bool) -> bool:
        """Widen observed bounds with one reward (``source="observed"``; call per transition); True when the bounds
        moved.

        :param reward: the transition's reward.
        :param terminated: whether the transition ended the episode in a terminal state.
        """
        seen = self._terminal if terminated else self._step
        if seen[0] <= reward <= seen[1]:
            return False
        seen[0], seen[1] = min(seen[0], reward), max(seen[1], reward)
        self._update_bounds()
        return True

    def observe_many(self, rewards: np.ndarray, terminal: np.ndarray) -> None:
        """:meth:`observe` for arrays of rewards and termination flags (a replay buffer's stored transitions).

        :param rewards: the rewards, (n,).
        :param terminal: whether each transition was terminal, (n,) bool.
        """
        for flag in (False, True):
            chosen = rewards[terminal == flag]
            if chosen.size:
                self.observe(float(chosen.min()), flag)
                self.observe(float(chosen.max()), flag)

    def read_buffer(self, buffer) -> None:
        """With observed bounds, widen them with every reward of a buffer this watch has not read yet, before a
        learner learns from it: a buffer assigned directly (``model.replay_buffer = other.replay_buffer``) or loaded
        is then covered as well as the transitions the learner collected (which it observes step by step). A buffer
        is read once per watch (it carries the watch's token, ``observed_by_watch``), so later calls cost nothing.

        :param buffer: the TrajectoryReplayBuffer, or None.
        """
        if not self.observing or buffer is None or buffer.observed_by_watch == self.token:
            return
        rewards, terminal = buffer.stored_rewards()
        if rewards.size:
            self.observe_many(rewards, terminal)
        buffer.observed_by_watch = self.token

    def begin_phase(self, buffer) -> None:
        """Before a replay phase: read the buffer's rewards (:meth:`read_buffer`) and start the phase's own figures
        of ER-sigma's target shift (the period's are kept aside and added back by :meth:`end_phase`).

        :param buffer: the TrajectoryReplayBuffer the phase replays.
        """
        self.read_buffer(buffer)
        if not self.enabled:
            return
        self._phase_start = (self.array[kernels.WATCH_UPDATES], self.array[SHIFT_ENTRIES].copy())
        self.array[SHIFT_ENTRIES] = 0.0

    def end_phase(self, flagged: bool) -> tuple[dict[str, float], int | None]:
        """After a replay phase: (ER-sigma's shift figures of the phase: ``sigma_shift``, the mean T_sigma - T,
        ``sigma_raised`` and ``sigma_lowered``, the shares of targets it raised and lowered; the 1-based number within
        the phase of the update whose value first left the bounds, when the kernel reported it (``flagged``)).

        :param flagged: whether the phase's kernel returned STATUS_OUT_OF_BOUNDS.
        """
        if not self.enabled or self._phase_start is None:
            return {}, None
        updates_before, period_shift = self._phase_start
        self._phase_start = None
        figures = {}
        shift_sum, shifted, raised, lowered = self.array[SHIFT_ENTRIES]
        if shifted > 0:
            figures = dict(
                sigma_shift=float(shift_sum / shifted),
                sigma_raised=float(raised / shifted),
                sigma_lowered=float(lowered / shifted),
            )
        self.array[SHIFT_ENTRIES] += period_shift
        first = int(self.array[kernels.WATCH_FIRST_UPDATE] - updates_before) + 1 if flagged else None
        return figures, first

    @property
    def first_value(self) -> float:
        """The first value the watch saw outside the bounds (NaN: none yet)."""
        return float(self.array[kernels.WATCH_FIRST_VALUE]) if self.enabled else math.nan

    @property
    def out_of_range(self) -> int:
        """How many targets and Q-values the watch saw outside the bounds (cumulative)."""
        return int(self.array[kernels.WATCH_OUT_OF_RANGE]) if self.enabled else 0

    @property
    def largest_excursion(self) -> float:
        """The largest distance of a target or Q-value beyond the possible returns so far, margin or not (0: none),
        recorded so that another margin needs no rerun."""
        return float(self.array[kernels.WATCH_EXCURSION]) if self.enabled else 0.0

    def describe(self) -> str:
        """The bounds and where they come from, for messages."""
        rewards = self.reward_bounds
        where = (
            "the env's reward_bounds"
            if self.source == "env"
            else f"the rewards observed so far ({self.reason})"
            if self.reason
            else "the rewards observed so far"
        )
        detail = (
            ""
            if rewards is None
            else (
                f"step rewards in [{rewards.step[0]:.6g}, {rewards.step[1]:.6g}]"
                + (
                    ""
                    if rewards.terminal is None
                    else f", terminal rewards in [{rewards.terminal[0]:.6g}, {rewards.terminal[1]:.6g}]"
                )
            )
        )
        source = (
            f"{detail} from {where}"
            if detail
            else "no reward observed yet" + (f" ({self.reason})" if self.reason else "")
        )
        return (
            f"[{self.bounds[0]:.6g}, {self.bounds[1]:.6g}] (gamma {self.gamma:g}; {source}; initial "
            f"values in [{self.initial[0]:.6g}, {self.initial[1]:.6g}])"
        )

    def excursion_message(self, learner: str, step: int, where: str, remedy: str) -> str:
        """What the first value outside the bounds means, for the ValueBoundWarning (or ValueBoundError): the value,
        how far beyond the bounds and the margin, whether the policy can still be good and how to check it, and where
        the documentation explains it.

        :param learner: the algorithm's name.
        :param step: the environment step.
        :param where: which update it was (e.g. "replayed update 3 of replay phase 20").
        :param remedy: what the learner's options can do about it (the learner's ``_value_watch_remedy``).
        """
        value = self.first_value
        low, high = self.bounds
        side = f"{value - high:.6g} above" if value > high else f"{low - value:.6g} below"
        share = f"{TOLERANCE * 100:g} % of the largest reward, {reward_size(self.reward_bounds):.6g}"
        return (
            f"{learner}: at step {step} ({where}) a value of {value:.6g} left the possible returns "
            f"{self.describe()}: it lies {side} them, beyond the margin of {self.margin:.6g} ({share}). No expected "
            "return lies there, so the learner's values have stopped being estimates of returns (the sign of "
            "divergence). The greedy policy may still be good, since only the order of the actions' values "
            "chooses it: check it with stable_baselines3.common.evaluation.evaluate_policy(model, env, "
            "deterministic=True), and compare runs by that rather than by the values. The documentation's page "
            f"'The value watch' (docs/value_watch.md) explains the bounds and {remedy}. "
            "value_bound_action='ignore' only counts such values "
            "(model.values_out_of_range); 'raise' stops at the first."
        )

    def period_figures(self) -> dict[str, float]:
        """The logging period's figures (NaN where nothing was seen), then a new period."""
        watch = self.array
        figures = {
            "q_min": watch[kernels.WATCH_Q_MIN],
            "q_max": watch[kernels.WATCH_Q_MAX],
            "target_min": watch[kernels.WATCH_TARGET_MIN],
            "target_max": watch[kernels.WATCH_TARGET_MAX],
        }
        figures = {k: float(v) if np.isfinite(v) else math.nan for k, v in figures.items()}
        count = watch[kernels.WATCH_SHIFT_COUNT]
        if count > 0:
            figures["sigma_shift"] = float(watch[kernels.WATCH_SHIFT_SUM] / count)
            figures["sigma_raised"] = float(watch[kernels.WATCH_RAISED] / count)
            figures["sigma_lowered"] = float(watch[kernels.WATCH_LOWERED] / count)
        figures["q_out_of_range"] = int(watch[kernels.WATCH_OUT_OF_RANGE])
        figures["value_excursion"] = float(watch[kernels.WATCH_EXCURSION])
        figures["value_bound_low"], figures["value_bound_high"] = self.bounds
        kernels.reset_watch_period(watch)
        return figures


#: The value watch's entries of ER-sigma's target shift (kernels.watch_shift).
SHIFT_ENTRIES = [kernels.WATCH_SHIFT_SUM, kernels.WATCH_SHIFT_COUNT, kernels.WATCH_RAISED, kernels.WATCH_LOWERED]
#: The entries that accumulate over a whole run (kept when a run's watch is rebuilt for a new env).
CUMULATIVE = (
    kernels.WATCH_UPDATES,
    kernels.WATCH_OUT_OF_RANGE,
    kernels.WATCH_FIRST_UPDATE,
    kernels.WATCH_FIRST_VALUE,
    kernels.WATCH_EXCURSION,
)

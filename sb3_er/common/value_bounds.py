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
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_er.common import kernels

#: A value beyond the bounds by more than this share of their width is flagged.
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


def widened(bounds: tuple[float, float], tolerance: float = TOLERANCE) -> tuple[float, float]:
    """The bounds widened on each side by ``tolerance`` times their width (and a rounding margin); a half-infinite
    interval's finite end by ``tolerance`` times its magnitude (at least 1).

    :param bounds: the (low, high) interval; either end may be infinite.
    :param tolerance: the widening per side as a share of the width (default 0.05).
    """
    low, high = bounds
    finite = [b for b in bounds if math.isfinite(b)]
    if not finite:
        return low, high
    width = high - low if len(finite) == 2 else max(1.0, abs(finite[0]))
    margin = tolerance * width + 1e-9 * max(1.0, *(abs(b) for b in finite))
    return low - margin, high + margin


def reward_changing_wrapper(env: gym.Env) -> str | None:
    """The name of the outermost wrapper of ``env`` that may change rewards, or None.

    Observation and action wrappers and the wrappers of :data:`REWARD_PRESERVING_WRAPPERS` keep them; every other
    wrapper (a RewardWrapper such as TransformReward or ClipReward, NormalizeReward, or an unknown one) may not.

    :param env: the (possibly wrapped) Gymnasium env.
    """
    while isinstance(env, gym.Wrapper):
        if not (
            isinstance(env, (gym.ObservationWrapper, gym.ActionWrapper))
            or type(env).__name__ in REWARD_PRESERVING_WRAPPERS
        ):
            return type(env).__name__
        env = env.env
    return None


class ValueWatch:
    """The bounds a learner's values must keep and the kernels' watch array (``kernels.new_watch``).

    :param source: where the reward bounds come from: ``"env"`` (declared) or ``"observed"`` (the rewards seen so far,
        updated by :meth:`observe`).
    :param bounds: the declared RewardBounds (``source="env"``).
    :param gamma: the learner's discount.
    :param initial: (low, high) of the initial values.
    :param reason: why the bounds are observed (shown in messages), e.g. "the env declares no reward_bounds".
    """

    def __init__(
        self, source: str, bounds: RewardBounds | None, gamma: float, initial: tuple[float, float], reason: str = ""
    ):
        self.source = source
        self.gamma = float(gamma)
        self.initial = (float(initial[0]), float(initial[1]))
        self.reason = reason
        #: Names this watch to the buffers whose stored rewards it has read (``observed_by_watch``).
        self.token = uuid.uuid4().hex
        self.array = kernels.new_watch()
        self._declared = bounds
        self._step = [math.inf, -math.inf]
        self._terminal = [math.inf, -math.inf]
        self.bounds = (math.inf, -math.inf)
        self._update_bounds()

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
        self.array[kernels.WATCH_LOW], self.array[kernels.WATCH_HIGH] = widened(self.bounds)

    def observe(self, reward: float, terminated: bool) -> None:
        """Widen observed bounds with one reward (``source="observed"``; call per transition).

        :param reward: the transition's reward.
        :param terminated: whether the transition ended the episode in a terminal state.
        """
        seen = self._terminal if terminated else self._step
        if seen[0] <= reward <= seen[1]:
            return
        seen[0], seen[1] = min(seen[0], reward), max(seen[1], reward)
        self._update_bounds()

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
        figures["value_bound_low"], figures["value_bound_high"] = self.bounds
        kernels.reset_watch_period(watch)
        return figures

"""Shared SB3 machinery of the tile-coded algorithms: spaces, the learn loop, online Sarsa(lambda), logging."""

import inspect
import io
import math
import pathlib
import re
import sys
import time
import warnings
from collections import deque
from collections.abc import Iterable
from typing import Any, ClassVar, TypeVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, ConvertCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import check_for_correct_spaces, safe_mean
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    VecEnv,
    VecEnvWrapper,
    VecNormalize,
    unwrap_vec_normalize,
    unwrap_vec_wrapper,
)

from sb3_er.common import kernels
from sb3_er.common.checks import check_bool, check_choice, check_integer, check_number
from sb3_er.common.dict_observations import (
    dict_vec_env_message,
    flatten_dict_observation,
    flattened_dict_space,
    vec_observation_keys,
)
from sb3_er.common.env_ids import register_env_id
from sb3_er.common.env_stepping import make_stepper
from sb3_er.common.policies import TileQPolicy, _initial_range, action_nvec, initial_value_seed_of
from sb3_er.common.serialization import (
    PLAIN_STATE_KEY,
    atomic_path,
    check_file_object,
    check_rng_state,
    deflated_zip,
    plain_state,
    read_zip_data,
    resolve_zip_path,
    restore_entries,
    sb3_write_path,
    zip_without_entries,
)
from sb3_er.common.tile_coding import resolve_tiling
from sb3_er.common.value_bounds import (
    REWARD_PRESERVING_WRAPPERS,
    VALUE_BOUND_ACTIONS,
    ValueBoundError,
    ValueWatch,
    _wrapper_names,
)

try:
    from stable_baselines3.common.utils import ConstantSchedule, FloatSchedule
except ImportError:  # SB3 before 2.4 builds schedules as closures: read at every step
    ConstantSchedule = FloatSchedule = None

DEFAULT_TOTAL_TIMESTEPS = 100_000

#: Wrappers whose recorded constructor arguments are plain data (no callables), so that the spec of an env wrapped
#: only in them pickles: an env in a subprocess is asked for its spec only then (TileQAlgorithm._env_spec).
SPEC_SAFE_WRAPPERS = frozenset(REWARD_PRESERVING_WRAPPERS) - {"RecordVideo"} | {
    "FlattenSuiteObservation",
    "RescaleAction",
    "ClipAction",
    "RescaleObservation",
    "DtypeObservation",
    "ReshapeObservation",
    "FilterObservation",
}
SelfTileQAlgorithm = TypeVar("SelfTileQAlgorithm", bound="TileQAlgorithm")


def _is_constant(schedule: Schedule) -> bool:
    """Whether SB3's learning-rate schedule is a constant (a float ``learning_rate``), so that it is read once."""
    return (
        FloatSchedule is not None
        and isinstance(schedule, FloatSchedule)
        and isinstance(schedule.value_schedule, ConstantSchedule)
    )


def is_fall(info: dict[str, Any], terminated: bool) -> bool:
    """Whether an episode's end counts as a fall: ``info["fell"]`` where the env reports it (the walkers, LEO, the
    pendulum), else any ``terminated`` end (a goal then counts too, so envs with goals should report ``fell``).

    :param info: the info dict of the episode's last step.
    :param terminated: whether the episode terminated (rather than being truncated).
    """
    return bool(info["fell"]) if "fell" in info else terminated


class DivergenceError(ArithmeticError):
    """The Q-function's weights became non-finite."""


class ValueBoundWarning(RuntimeWarning):
    """A learner's value (a target or Q(s, a)) left the possible returns (``value_bound_action="warn"``)."""


def _observation_space_advice(observation_space: spaces.Space) -> str:
    """What to do with an observation space tile coding cannot read (a sentence for the error)."""
    if isinstance(observation_space, (spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)):
        if isinstance(observation_space, spaces.Discrete):
            start = int(observation_space.start)
            k, low, high = 1, f"{start}", f"{start + int(observation_space.n) - 1}"
        elif isinstance(observation_space, spaces.MultiDiscrete):
            k, low, high = (
                int(observation_space.nvec.size),
                "0",
                f"np.array({(observation_space.nvec - 1).ravel().tolist()})",
            )
        else:
            k, low, high = int(np.prod(observation_space.shape)), "0", "1"
        return (
            "Its values are table indices: give them as a Box and tile each with width 1, so that every value has a "
            "tile of its own (a table), e.g. env = gymnasium.wrappers.TransformObservation(env, lambda s: "
            f"np.asarray(s, np.float32).reshape(-1), gymnasium.spaces.Box({low}, {high}, ({k},), np.float32)) and "
            f"policy_kwargs=dict(tile_widths=[1.0] * {k})."
        )
    return (
        "Flatten it into a vector (gymnasium.wrappers.FlattenObservation) and give tile widths in the flat vector's "
        "units (policy_kwargs=dict(tile_widths=...)), or pick the low-dimensional features to tile."
    )


#: The attribute through which ``_setup_model`` of a loaded model sees which parameters ``load``'s keyword arguments
#: gave (ER: a stabilizer given there replaces the saved one); removed once the model is loaded.
GIVEN_AT_LOAD = "_given_at_load"


class TileQAlgorithm(BaseAlgorithm):
    """Base of the tile-coded algorithms: epsilon-greedy acting on TileQ and, optionally, online Sarsa(lambda).

    Subclasses react to each transition through ``_after_transition``. Tile coding defaults come from the env: its
    ``tile_widths``, ``wrap_periods``, ``action_values``, ``action_tile_widths`` and ``memory_size`` attributes, else
    sb3-er's tiling for the env id (``sb3_er/data/tilings.yml``: CartPole-v1, MountainCar-v0, Acrobot-v1,
    Pendulum-v1, MountainCarContinuous-v0), else finite observation bounds split into tiles by the generic rule
    (``default_tile_widths``).

    :param policy: "TileQ" or a TileQPolicy subclass.
    :param env: a Gymnasium env (or id) with a flat Box observation and a Discrete, MultiDiscrete or Box action space
        (a Box is discretised: see TileQPolicy's ``action_bins`` and ``action_values``). A single env with a Dict
        observation of Box arrays (dm_control's suite) is flattened with Gymnasium's ``FlattenObservation``. The
        ``sb3_er/...`` ids and the ``dm_control/<domain>-<task>-v0`` ids (shimmy, the ``dmc`` extra) register
        themselves (see :mod:`sb3_er.common.env_ids`).
    :param learning_rate: alpha, the step on Q (each of the N active weights moves by alpha * delta / N); a float or a
        schedule of the remaining progress (default 0.2, the thesis's alpha for every experiment but LEO's).
    :param gamma: discount factor per control step (default 0.99, thesis sections 4.2 and 5.1).
    :param exploration_rate: epsilon of epsilon-greedy acting (default 0.05, the thesis's).
    :param trace_lambda: lambda of online Sarsa(lambda) learning; None (default) acts without learning online.
    :param trace_cutoff: traces below this value are dropped (default 0.01).
    :param value_watch: watch every target and every Q(s_t, a_t) of the updates (the kernels fold them into an array,
        without allocating or drawing a random number, so results are the same with and without it) against the
        possible returns (:mod:`sb3_er.common.value_bounds`), logging ``train/q_min``, ``train/q_max``,
        ``train/target_min``, ``train/target_max``, ``train/q_out_of_range`` (values outside, cumulative) and for
        ER-sigma ``train/sigma_shift``, ``train/sigma_raised``, ``train/sigma_lowered``. The bounds come from the env's
        ``reward_bounds`` attribute, else (and under a wrapper that may change rewards) from the rewards observed so
        far, widened by the initial values.
    :param value_bound_action: what a value beyond the bounds by more than 5 % of their width does: "warn" (once per
        run, a ValueBoundWarning naming the algorithm, the step, the value and the bound), "raise" (ValueBoundError)
        or "ignore" (only counted and logged). The first such value is kept in ``value_excursion``.
    :param policy_kwargs: tile coding (see TileQPolicy: ``n_tilings``, 16 unless given; ``tile_widths``;
        ``wrap_periods``; ``memory_size``, 2**22 unless given; ``action_values``; ``action_tile_widths``;
        ``initial_value``, 0 unless given), plus ``tiles_per_dimension`` for bounded observations; None (default): the
        env's attributes and sb3-er's rules.
    :param stats_window_size: episodes averaged in ``rollout/ep_rew_mean`` and ``rollout/ep_len_mean`` (SB3's, 100).
    :param tensorboard_log: folder of TensorBoard logs, or None for none (SB3's).
    :param verbose: 0 silent, 1 the tiling in use and SB3's training messages, 2 debug (SB3's).
    :param seed: seed of every random stream (exploration, trajectory picks, ``predict``, the env), or None.
    :param device: "cpu": the weights live in NumPy arrays; no GPU is used (SB3's argument, kept for its API).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"TileQ": TileQPolicy, "TileQPolicy": TileQPolicy}
    #: Parameters added after files were first saved, with the value that reproduces a file saved without them
    #: (``load`` sets it; a parameter's default may change, what an old file learned with does not).
    older_file_values: ClassVar[dict[str, Any]] = {}
    policy: TileQPolicy
    #: The name users give lambda of online Sarsa(lambda) (ER calls it online_lambda), for error messages.
    _trace_lambda_parameter: ClassVar[str] = "trace_lambda"

    def __init__(
        self,
        policy: str | type[TileQPolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
        trace_lambda: float | None = None,
        trace_cutoff: float = 0.01,
        value_watch: bool = True,
        value_bound_action: str = "warn",
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: str = "cpu",
        _init_setup_model: bool = True,
    ):
        register_env_id(env)  # sb3_er/ and (shimmy's, only when one is used) dm_control/ ids, before SB3 makes it
        try:
            super().__init__(
                policy,
                env,
                learning_rate,
                policy_kwargs=policy_kwargs,
                stats_window_size=stats_window_size,
                tensorboard_log=tensorboard_log,
                verbose=verbose,
                device=device,
                support_multi_env=True,
                seed=seed,
            )
        except AssertionError as error:  # SB3's check of Box action bounds, the only assert of its __init__ on spaces
            if "finite lower and upper bound" not in str(error):
                raise
            raise ValueError(
                f"The action space {self.action_space} has infinite bounds, which Stable-Baselines3 refuses for every "
                "algorithm, and levels cannot be spaced between them. Give the env finite bounds (its actuators' "
                "limits), or keep them unbounded with bounds of float32's maximum magnitude and give the levels: "
                "policy_kwargs=dict(action_values=[[...], ...]), one list per action dimension"
            ) from error
        self.gamma = gamma
        self.exploration_rate = exploration_rate
        self.trace_lambda = trace_lambda
        self.trace_cutoff = trace_cutoff
        self.value_watch = value_watch
        self.value_bound_action = value_bound_action
        self.value_excursion: dict[str, Any] | None = None
        self._observed_rewards: dict[str, list[float] | None] | None = None  # see observed_rewards
        self._watch: ValueWatch | None = None
        self._seed_generators(seed)
        self.falls = 0
        self._td_error_sum = 0.0
        self._td_error_count = 0
        if self.env is not None:
            self._check_spaces(self.observation_space, self.action_space)
            self._check_env_wrappers(self.env)
        if _init_setup_model:
            self._setup_model()

    def _check_hyperparameters(self) -> None:
        """Validate every hyperparameter; runs wherever a model is built, loaded (``load(..., **kwargs)``) or
        rebuilt."""
        learning_rate = self.learning_rate(1.0) if callable(self.learning_rate) else self.learning_rate
        check_number("learning_rate (alpha)", learning_rate, 0.0)
        check_number("gamma", self.gamma, 0.0, 1.0)
        check_number("exploration_rate", self.exploration_rate, 0.0, 1.0)
        check_number(self._trace_lambda_parameter, self.trace_lambda, 0.0, 1.0, optional=True)
        check_number("trace_cutoff", self.trace_cutoff, 0.0, 1.0, low_open=True, high_open=True)
        check_integer("stats_window_size", self._stats_window_size, minimum=1)
        check_bool("value_watch", self.value_watch)
        check_choice("value_bound_action", self.value_bound_action, VALUE_BOUND_ACTIONS)

    @staticmethod
    def _wrap_env(env: GymEnv | str, verbose: int = 0, monitor_wrapper: bool = True) -> VecEnv:
        """SB3's wrapping into a VecEnv, after flattening a single env's Dict observation (Gymnasium's
        ``FlattenObservation``; pixels refused). An env id is made first (``load(path, env="dm_control/...")``)."""
        if isinstance(env, str):
            register_env_id(env)
            env = gym.make(env)
        if not isinstance(env, VecEnv):
            env = flatten_dict_observation(env)
        return BaseAlgorithm._wrap_env(env, verbose, monitor_wrapper)

    @staticmethod
    def _check_env_wrappers(env: VecEnv) -> None:
        """Refuse wrappers that rescale observations: tile widths are in the env's raw observation units."""
        normalize = unwrap_vec_wrapper(env, VecNormalize)
        normalized = normalize is not None and normalize.norm_obs
        try:
            normalized = normalized or any(env.env_is_wrapped(gym.wrappers.NormalizeObservation))
        except (AttributeError, NotImplementedError):
            pass
        if normalized:
            raise ValueError(
                "The env normalises observations (VecNormalize with norm_obs=True, rl-zoo's `normalize: true`, or "
                "gymnasium's NormalizeObservation), but tile widths are in the env's raw observation units: tiles "
                "would shrink to a tiny fraction of their width and drift as the running statistics change, and "
                "learning silently fails. Remove the observation normalisation (VecNormalize(norm_obs=False) keeps "
                "reward normalisation), or tile the raw observations with suitable tile_widths."
            )

    @staticmethod
    def _check_spaces(observation_space: spaces.Space, action_space: spaces.Space) -> None:
        if not isinstance(action_space, spaces.Box):  # a Box's levels are checked with the policy's settings
            action_nvec(action_space)
        if isinstance(observation_space, spaces.Dict):
            raise ValueError(dict_vec_env_message(observation_space))
        if not isinstance(observation_space, spaces.Box):
            raise ValueError(
                f"Tile coding needs a flat Box observation space, got {observation_space}. "
                + _observation_space_advice(observation_space)
            )
        if len(observation_space.shape) != 1:
            kind = "image" if len(observation_space.shape) == 3 else "multi-dimensional"
            raise ValueError(
                f"Tile coding needs a flat vector observation; got {kind} observations of shape "
                f"{observation_space.shape}. Extract low-dimensional features first."
            )

    def _get_policy_from_name(self, policy_name: str) -> type[BasePolicy]:
        """SB3's lookup of a policy by name; a name sb3-er lacks (SB3's "MlpPolicy", "CnnPolicy") is a ValueError
        naming the policy to use."""
        if policy_name not in self.policy_aliases:
            raise ValueError(
                f"Policy {policy_name} unknown: sb3-er's algorithms learn a tile-coded linear Q-function, whose policy "
                f'is "TileQ" (SB3\'s network policies do not apply), e.g. {type(self).__name__}("TileQ", env); '
                f"policy_kwargs set its tile coding (see TileQPolicy)"
            )
        return super()._get_policy_from_name(policy_name)

    def _env_attribute(self, name: str) -> Any:
        """An optional attribute of the (first) env, None when absent. Probed with ``has_attr``: a SubprocVecEnv's
        ``get_attr`` of a missing attribute kills its worker. ``spec`` is :meth:`_env_spec`."""
        if self.env is None:
            return None
        if name == "spec":
            return self._env_spec()
        if not self.env.has_attr(name):
            return None
        return self.env.get_attr(name, indices=0)[0]  # env 0 alone: only its answer is read

    def _env_spec(self) -> Any:
        """The (first) env's ``EnvSpec``, or None. A wrapped env's spec holds its wrappers' constructor arguments, and
        an env in another process (SubprocVecEnv) must pickle it to answer: a wrapper built with a lambda (e.g.
        ``TransformReward``) would kill the worker. So such an env's spec is asked for only when every wrapper in
        Gymnasium's description of the chain is one whose arguments are plain data (SPEC_SAFE_WRAPPERS); otherwise
        it is the registry's spec of the id in that description (the id decides the tiling; the arguments given to
        ``make`` are then not known)."""
        level = self.env
        while isinstance(level, VecEnvWrapper):
            level = level.venv
        if isinstance(level, DummyVecEnv):
            return self.env.get_attr("spec", indices=0)[0] if self.env.has_attr("spec") else None
        try:
            description = self.env.env_method("__str__", indices=0)[0]
        except Exception:  # a VecEnv that cannot call its envs' methods
            return None
        names = _wrapper_names(description)
        if all(name in SPEC_SAFE_WRAPPERS for name in names[:-1]):
            return self.env.get_attr("spec", indices=0)[0] if self.env.has_attr("spec") else None
        segments = re.findall(r"<([^<>]*)", description)
        if not segments or segments[-1].endswith(" instance"):
            return None
        try:
            return gym.spec(segments[-1])
        except gym.error.Error:
            return None

    def _resolve_policy_kwargs(self) -> dict[str, Any]:
        """Explicit tile-coding settings (:func:`~sb3_er.common.tile_coding.resolve_tiling`), so that save/load
        rebuilds the same coder; printed with where each came from at ``verbose >= 1``."""
        envs = getattr(self.env, "envs", None)
        return resolve_tiling(
            self.policy_kwargs,
            self._env_attribute,
            self.observation_space,
            self.action_space,
            self.policy_class,
            dict_space=lambda: flattened_dict_space(envs[0]) if envs else None,
            verbose=self.verbose,
        )

    def _setup_model(self) -> None:
        self._check_hyperparameters()
        self._setup_lr_schedule()
        BaseAlgorithm.set_random_seed(self, self.seed)  # not ours: load() has just restored their states
        self.policy_kwargs = self._resolve_policy_kwargs()
        policy_kwargs = dict(self.policy_kwargs)
        if self.seed is not None and policy_kwargs.get("initial_value_seed") is None:
            policy_kwargs["initial_value_seed"] = initial_value_seed_of(self.seed)  # not NumPy's shared global stream
        self.policy = self.policy_class(self.observation_space, self.action_space, self.lr_schedule, **policy_kwargs)
        if self.policy.initial_value_seed is not None:  # keep the drawn seed: a reloaded model rebuilds the same start
            self.policy_kwargs["initial_value_seed"] = self.policy.initial_value_seed
        coder = self.policy.tile_coder
        self._q_scratch = np.zeros(coder.n_actions, dtype=np.float64)
        self._w_scratch = np.zeros(coder.n_actions, dtype=np.float64)
        self._plain_layout = tuple(coder.layout)  # the per-step kernels take plain tuples (kernels.bundles)
        self._target_copy: kernels.TargetCopy | None = None
        if not isinstance(getattr(self, "_step_cap", None), np.ndarray):
            self._step_cap = np.full(1, np.inf)  # the step-size bound so far (saved: it only ever tightens)
        self._setup_env_state()
        self._setup_value_watch()
        if self.env is not None:
            if getattr(self, "observation_keys", None) is None:
                self.observation_keys = vec_observation_keys(self.env)
            else:  # a loaded model meets its env
                self._check_observation_keys(self.env)

    def _setup_env_state(self) -> None:
        """What each env of the VecEnv carries from one step to the next: the tiles of its s_k and s_{k+1}, its pending
        a_{k+1} (-1: none) and, learning online, its eligibility trace (Sarsa(lambda) keeps one trace per env)."""
        coder = self.policy.tile_coder
        n_envs = self.n_envs or 1
        self._env_slots = [np.zeros(coder.n_tilings, dtype=np.int64) for _ in range(n_envs)]
        self._env_next_slots = [np.zeros(coder.n_tilings, dtype=np.int64) for _ in range(n_envs)]
        self._next_actions = [-1] * n_envs  # a list of ints: read and written per step, where numpy scalars cost
        self._traces = [self._new_trace() for _ in range(n_envs)] if self.trace_lambda is not None else []

    # --- the value watch (sb3_er.common.value_bounds) ------------------------------------------------------------

    def _setup_value_watch(self) -> None:
        """The bounds of the possible returns for the current env, and the kernels' watch array (empty when the
        watch is off: the bounds are kept all the same). The counts and the first excursion carry over from the
        run's earlier watch (a new env in the same run)."""
        self._remember_observed_rewards()
        initial = _initial_range(self.policy.initial_value)
        if self.env is None:  # bounds from the rewards a loaded buffer holds, until an env is set
            self._watch = ValueWatch("observed", None, self.gamma, initial, "no env yet", self.value_watch)
        else:
            self._watch = ValueWatch.for_env(self.env, self.gamma, initial, self.value_watch, earlier=self._watch)
        self._watch_array = self._watch.array
        self._watch.observe_rewards(self._observed_rewards)
        self._watch.read_buffer(getattr(self, "replay_buffer", None))

    @property
    def observed_rewards(self) -> dict[str, list[float] | None] | None:
        """The extremes of the rewards the model has observed where the env declares no reward bounds, which bound
        its values (the value watch's and the stabilizers' bounds): {"step": [low, high] or None, "terminal":
        likewise}, or None before any. Kept across ``learn`` calls and ``set_env`` (bounds only widen) and saved
        with the model."""
        observed = None if self._watch is None else self._watch.observed_rewards()
        return observed or self._observed_rewards  # a watch that observes holds the saved ones too (set up with them)

    def _remember_observed_rewards(self) -> None:
        """Keep the current watch's observed reward extremes (before a new watch replaces it, and before saving)."""
        self._observed_rewards = self.observed_rewards

    def _observe_stored_rewards(self) -> None:
        """With observed bounds, widen them with every reward of the buffer not read yet
        (:meth:`ValueWatch.read_buffer`): a buffer assigned directly or loaded is covered before anything learns from
        it."""
        if self._watch is not None:
            self._watch.read_buffer(getattr(self, "replay_buffer", None))

    @property
    def value_bounds(self) -> tuple[float, float] | None:
        """(low, high) of the values the learner may take (the possible returns and the initial values), or None
        without a watch."""
        return None if self._watch is None or not self.value_watch else self._watch.bounds

    @property
    def values_out_of_range(self) -> int:
        """How many targets and Q-values the watch saw outside the bounds (cumulative)."""
        return 0 if self._watch is None else self._watch.out_of_range

    @property
    def largest_excursion(self) -> float:
        """The largest distance of a target or Q-value beyond the possible returns in this run, however small (0:
        none), recorded so that a comparison under another margin needs no rerun."""
        return 0.0 if self._watch is None else self._watch.largest_excursion

    def _value_out_of_bounds(self, where: str) -> None:
        """A kernel reported the first value outside the bounds: remember it, then warn or raise as asked."""
        watch = self._watch
        low, high = watch.bounds
        self.value_excursion = {
            "step": int(self.num_timesteps),
            "value": watch.first_value,
            "low": low,
            "high": high,
            "margin": watch.margin,
            "where": where,
        }
        if self.value_bound_action == "ignore":
            return
        message = watch.excursion_message(type(self).__name__, self.num_timesteps, where, self._value_watch_remedy())
        if self.value_bound_action == "raise":
            raise ValueBoundError(message)
        warnings.warn(message, ValueBoundWarning, stacklevel=3)

    # --- the kernels' arguments and what they report -------------------------------------------------------------

    def _new_trace(self) -> tuple:
        """A sparse replacing trace sized for the longest a trace can live above the cut-off, as
        :func:`kernels.sarsa_lambda_step` takes it (a plain tuple of a ``kernels.Trace``)."""
        coder = self.policy.tile_coder
        decay = self.gamma * self.trace_lambda
        if decay <= 0.0:
            lifetime = 1
        elif decay >= 1.0:
            lifetime = coder.n_weights
        else:
            lifetime = int(math.ceil(math.log(self.trace_cutoff / coder.n_tilings) / math.log(decay))) + 2
        capacity = min(coder.n_weights, coder.n_tilings * lifetime)
        return tuple(
            kernels.make(
                kernels.Trace,
                index=np.zeros(capacity, dtype=np.int64),
                value=np.zeros(capacity, dtype=np.float64),
                position=np.full(coder.n_weights, -1, dtype=np.int32),
                length=np.zeros(1, dtype=np.int64),
                decay=decay,
                cutoff=self.trace_cutoff,
            )
        )

    def _stabilizer_options(self) -> dict[str, Any]:
        """Hook: UpdateRule fields of the stabilizers a learner uses (ER's; none here)."""
        return {}

    def _weights(self) -> kernels.Weights:
        """theta as the kernels read it, with the target copy of a learner that keeps one."""
        low, span, seed = self.policy.initial_arguments
        return kernels.weights_bundle(self.policy.theta_array, low, span, seed, self._target_copy)

    @property
    def _scratch(self) -> kernels.Scratch:
        """The kernels' scratch space (allocated once per model)."""
        return kernels.Scratch(self._q_scratch, self._w_scratch)

    @property
    def step_size(self) -> float:
        """alpha / N, the step of each of the N active weights at the current learning rate (thesis convention: the
        learning rate is the step on Q). A learning-rate schedule is checked at every reading."""
        rate = self.current_learning_rate
        if not (math.isfinite(rate) and rate >= 0.0):
            raise ValueError(
                f"The learning-rate schedule gave {rate} at progress remaining {self._current_progress_remaining:.4g} "
                f"(step {self.num_timesteps}); a learning rate must be a finite number >= 0 throughout"
            )
        return rate / self.policy.tile_coder.n_tilings

    def _update_rule(self, **options) -> kernels.UpdateRule:
        """The update rule of this learner at the current learning rate: alpha / N per active weight, gamma and epsilon;
        ``options`` set the other fields (ER's target, sigma and residual direction; default plain Sarsa).

        :param options: UpdateRule fields to set besides step_size, gamma and epsilon.
        """
        fields = dict(step_cap=self._step_cap, **self._stabilizer_options())
        fields.update(options)
        return kernels.update_rule(self.step_size, self.gamma, self.exploration_rate, **fields)

    def _check_status(self, status: int, where: str, delta: float = math.nan, obs: np.ndarray | None = None) -> None:
        """React to what a kernel reported: the first value outside the possible returns (warn or raise, as asked),
        an observation that cannot be tiled, a full trace, or divergence (a non-finite TD error).

        :param status: the kernel's STATUS_*.
        :param where: the update it was in, for messages (e.g. "the Sarsa(lambda) update").
        :param delta: the TD error it returned.
        :param obs: the observation it tiled.
        """
        if status == kernels.STATUS_OUT_OF_BOUNDS:
            self._value_out_of_bounds(where)
        elif status == kernels.STATUS_BAD_OBSERVATION:
            raise ValueError(self.policy.tile_coder.bad_observation_message(obs, f" at step {self.num_timesteps}"))
        elif status == kernels.STATUS_TRACE_FULL:
            raise RuntimeError("The eligibility trace outgrew its capacity; raise trace_cutoff")
        elif status == kernels.STATUS_DIVERGED:
            raise DivergenceError(
                f"The Q-function diverged at step {self.num_timesteps} in {where}: TD error {delta}. "
                f"Lower the learning rate (now {self.current_learning_rate}) or check the rewards' scale."
            )

    def _excluded_save_params(self) -> list[str]:
        return super()._excluded_save_params() + [
            "_env_slots",
            "_env_next_slots",
            "_q_scratch",
            "_w_scratch",
            "_plain_layout",
            "_traces",
            "_next_actions",
            "_watch",
            "_weights_scanned_at",  # the logging's own schedule: a loaded model scans at its first dump
            "_watch_array",
            "_target_copy",
        ]

    def set_random_seed(self, seed: int | None = None) -> None:
        """Seed SB3's generators, the env, and the generators of exploration and prediction.

        :param seed: the seed; None leaves every generator as it is.
        """
        super().set_random_seed(seed)
        if seed is not None:
            self._seed_generators(seed)

    def _seed_generators(self, seed: int | None) -> None:
        check_integer("seed", seed, minimum=0, optional=True)
        self.action_rng = kernels.new_rng_state(seed, kernels.RNG_STREAM_ACTIONS)
        self.predict_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(kernels.RNG_STREAM_PREDICT,)))

    @property
    def current_learning_rate(self) -> float:
        return float(self.lr_schedule(self._current_progress_remaining))

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Greedy actions if deterministic, else epsilon-greedy with the model's exploration rate.

        :param observation: one observation (shape of the observation space) or a batch of them (n, ...).
        :param state: unused (no recurrent state); returned as given, as SB3 does.
        :param episode_start: unused; accepted for SB3's signature.
        :param deterministic: greedy actions if True, else epsilon-greedy with ``exploration_rate`` (default False).
        """
        actions, state = self.policy.predict(observation, state, episode_start, deterministic=True)
        if deterministic or self.exploration_rate == 0.0:
            return actions, state
        flat = np.atleast_1d(np.asarray(actions)).reshape(-1, *self.action_space.shape)
        explore = self.predict_rng.random(len(flat)) < self.exploration_rate
        if explore.any():
            random_flat = self.predict_rng.integers(0, self.policy.tile_coder.n_actions, explore.sum())
            flat[explore] = self.policy.to_env_actions(random_flat)
        return flat.reshape(np.shape(actions)), state

    def learn(
        self: SelfTileQAlgorithm,
        total_timesteps: int = DEFAULT_TOTAL_TIMESTEPS,
        callback: MaybeCallback = None,
        log_interval: int = 8,
        tb_log_name: str = "",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfTileQAlgorithm:
        """Interact for total_timesteps env steps (default 100,000), learning as the algorithm prescribes.

        With N envs, each step of the VecEnv is N env steps (``num_timesteps`` moves by N), and each env's transition
        is learned from (and stored) as it would be alone. A ``learn`` interrupted by an exception (Ctrl-C included)
        loses nothing that happened; the next ``learn(reset_num_timesteps=False)`` closes what the interruption left
        open and starts from freshly reset envs, so that no stored trajectory joins two episodes.

        :param total_timesteps: env steps to take (default 100,000).
        :param callback: SB3 callback(s) called at every step (default None).
        :param log_interval: log (and print at ``verbose=1``) every this many finished episodes (default 8: SB3's
            off-policy algorithms use 4, which prints about 30 tables in 20,000 steps of CartPole-v1; 8 still logs the
            walker, whose episodes last at most 500 steps, at least every 4,000 steps); None never.
        :param tb_log_name: name of the TensorBoard run (default: the class's name).
        :param reset_num_timesteps: start the step count and the episode afresh (default True); False continues a
            previous ``learn``.
        :param progress_bar: show SB3's progress bar (default False; needs tqdm and rich).
        """
        if self.env is None:
            raise ValueError("This model has no environment: pass env= to load() or call set_env() before learn()")
        if not reset_num_timesteps and getattr(self, "_interrupted", False):
            self._last_obs = None  # where the envs stand after the interruption is unknown: _setup_learn resets them
        if reset_num_timesteps or self._last_obs is None:
            # _setup_learn resets the env: the episode in progress ends here, unfinished (see _end_episode_at_reset).
            self._end_episode_at_reset()
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name or type(self).__name__, progress_bar
        )
        if reset_num_timesteps:
            self.falls = 0
            self.value_excursion = None
            self._remember_observed_rewards()  # the rewards seen stay known
            self._watch = None  # a new run: a new watch, its counts from zero
        self._setup_value_watch()
        callback.on_training_start(locals(), globals())
        callback.on_rollout_start()
        given = not (isinstance(callback, ConvertCallback) and callback.callback is None)
        self._interrupted = True  # until the loop returns: an exception leaves the envs and the episodes mid-step
        self._interact(total_timesteps, callback if given else None, log_interval)
        self._interrupted = False
        callback.on_rollout_end()
        callback.on_training_end()
        return self

    def _end_episode_at_reset(self) -> None:
        """The envs are about to be reset with episodes in progress (a new ``learn()``, ``set_env``, ``load``, the
        resumption of an interrupted ``learn``): forget the pending a_{k+1} and the eligibility traces, so nothing of
        the old episodes reaches the new ones. Subclasses close what they store of them (ER: the open trajectories,
        as truncated)."""
        self._next_actions[:] = [-1] * len(self._next_actions)
        for trace in self._traces:
            kernels.clear_trace(trace)
        self._interrupted = False

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """SB3's ``set_env``, refusing observation-normalising wrappers; any number of envs. With ``force_reset`` (the
        default) the next ``learn()`` resets the new env and the episode in progress ends, unfinished.

        :param env: the new environment (a Gymnasium env or a VecEnv) with the same spaces.
        :param force_reset: reset the new env at the next ``learn()`` (default True).
        """
        env = self._wrap_env(env, self.verbose)
        self._check_env_wrappers(env)
        self._check_observation_keys(env)
        check_for_correct_spaces(env, self.observation_space, self.action_space)
        if env.num_envs != self.n_envs:  # SB3 refuses another number of envs; here each env's state is rebuilt
            if getattr(self, "policy", None) is not None:
                self._end_episode_at_reset()  # the episodes in progress end with the old envs
            force_reset = True  # the last observations are the old envs'
        self._vec_normalize_env = unwrap_vec_normalize(env)
        if force_reset:
            self._last_obs = None
        self.n_envs = env.num_envs
        self.env = env
        if getattr(self, "observation_keys", None) is None:
            self.observation_keys = vec_observation_keys(self.env)
        if getattr(self, "policy", None) is not None:
            if len(self._next_actions) != self.n_envs:
                self._setup_env_state()
                self._on_n_envs_changed()
            self._setup_value_watch()  # the new env's rewards

    def _on_n_envs_changed(self) -> None:
        """Hook: the VecEnv's number of envs changed (ER's buffer keeps one open trajectory per env)."""

    def _check_observation_keys(self, env: VecEnv) -> None:
        """The Dict observation an env flattens must keep the keys and sizes, in order, that the model was built
        with (its tile widths are per flattened entry): a ValueError naming both layouts otherwise.

        :param env: the VecEnv (new or loaded).
        """
        expected = getattr(self, "observation_keys", None)
        actual = vec_observation_keys(env)
        if expected is not None and actual is not None and actual != expected:
            raise ValueError(
                f"This model was built on a Dict observation flattened as {expected} ([key, size] in order), but the "
                f"env flattens {actual}: its tile widths would fall on the wrong entries. Give the env the same keys "
                "in the same order (FlattenObservation sorts them by name unless the space is ordered otherwise)"
            )

    def __getstate__(self) -> dict[str, Any]:
        """What a copy keeps (``copy.deepcopy``, pickling by Ray or ``multiprocessing``): everything but the logger,
        whose writers hold open files (stdout, TensorBoard); the copy configures its own at its next ``learn()``, as a
        new model does (``set_logger`` gives it another)."""
        state = self.__dict__.copy()
        state.pop("_logger", None)
        state["_custom_logger"] = False
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        buffer = getattr(self, "replay_buffer", None)
        if buffer is not None and buffer.tile_coder.config() == self.policy.tile_coder.config():
            buffer.tile_coder = self.policy.tile_coder  # the buffer restores its own copy: share the policy's again

    # --- files: SB3's save and load, written atomically, checked when read, and loadable without pickle ------------

    def save(
        self,
        path: str | pathlib.Path | io.BufferedIOBase,
        exclude: Iterable[str] | None = None,
        include: Iterable[str] | None = None,
    ) -> None:
        """SB3's ``save``, written atomically (a partial file, then renamed), with a plain copy of every attribute SB3
        pickles that has one, so that ``load(..., allow_pickle=False)`` can read the file without unpickling, and its
        entries deflated (SB3 stores them; a tile-coded model's file shrinks tens to hundreds of times). Paths
        are taken as SB3 takes them: ``.zip`` added when there is no suffix, a missing folder created and a folder's
        name turned into ``<name>_2``, each with SB3's warning. A file object is written where it stands and left open.

        :param path: the zip file (a path, ``.zip`` added when missing, or an open binary file).
        :param exclude: attribute names not to save, besides SB3's defaults (default None).
        :param include: attribute names to save that SB3 leaves out by default (default None).
        """
        if isinstance(path, (str, pathlib.Path)):
            path = sb3_write_path(path, "zip")
        else:
            check_file_object(path, "w")
        data = deflated_zip(
            self._sb3_zip(exclude, include)
        )  # SB3 stores the entries; mostly initial weights deflate well
        if isinstance(path, pathlib.Path):
            with atomic_path(path, ".zip") as partial:
                partial.write_bytes(data)
        else:
            path.write(data)

    def _sb3_zip(self, exclude: Iterable[str] | None = None, include: Iterable[str] | None = None) -> bytes:
        """The zip SB3's ``save`` writes for this model (its members stored), with sb3-er's plain copies in its data
        entry: what :meth:`save` deflates (``benchmarks/model_size.py`` compares the two).

        :param exclude: attribute names not to save, besides SB3's defaults (default None).
        :param include: attribute names to save that SB3 leaves out by default (default None).
        """
        self._remember_observed_rewards()
        self.__dict__[PLAIN_STATE_KEY] = plain_state(self, exclude, include)
        try:
            stored = io.BytesIO()
            super().save(stored, exclude, include)
        finally:
            del self.__dict__[PLAIN_STATE_KEY]
        return stored.getvalue()

    @classmethod
    def load(
        cls: type[SelfTileQAlgorithm],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: str | Any = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        allow_pickle: bool = True,
        **kwargs,
    ) -> SelfTileQAlgorithm:
        """SB3's ``load``, with every field checked (hyperparameters, generator states, counters, the last
        observation, the weights' shape and finiteness): a corrupt or crafted file is a ValueError naming the file and
        the field.

        An entry that cannot be unpickled here (a learning-rate schedule saved under another Python version, a class
        this environment cannot import) is restored from the plain copy sb3-er saves beside it where there is one;
        a function's bytecode saved under another Python minor version counts as such (it would unpickle, and then
        compute something else);
        otherwise it gets SB3's warning and keeps the class's default, as in SB3, and ``custom_objects`` replaces it.
        The spaces, the tiling settings and the policy class cannot be left out: the weights and the replay buffer are
        laid out by them, so a file whose copies of them cannot be restored is refused, naming the entry.

        :param allow_pickle: True (SB3's behaviour) unpickles the zip's ``":serialized:"`` entries, which runs any code
            a crafted file names. False unpickles nothing: those entries are rebuilt from the plain copies sb3-er saves
            beside them (spaces, generators, arrays, the policy class) and ``custom_objects`` supplies any other; one
            without either is handled as an entry that cannot be unpickled.
        :param path: the zip file written by ``save`` (a path, tried with ``.zip`` added if it does not exist, or an
            open binary file, read wherever it stands and left open, as SB3 does).
        :param env: the environment to attach (default None: set one later with ``set_env``).
        :param device: torch device of the policy's buffers (default "auto"; sb3-er computes on the CPU).
        :param custom_objects: values replacing saved entries by name, as in SB3 (default None).
        :param print_system_info: print the system info saved in the file and this one's (default False).
        :param force_reset: reset the env at the next ``learn()`` (default True).
        :param kwargs: parameters of the class replacing the saved values, as in SB3 (ER classes: a stabilizer given
            here replaces the saved one, a ``preset`` resolves them anew); a name the class does not take is a
            TypeError, as the constructor's.
        """
        cls._check_load_kwargs(kwargs)
        if isinstance(path, (str, pathlib.Path)):
            path = resolve_zip_path(path)  # so that errors name the file read
        else:
            check_file_object(path, "r")  # SB3's TypeError or ValueError for what is not an open binary file
        try:
            data, source, saved_python = read_zip_data(path)
            classes = {f"{c.__module__}:{c.__qualname__}": c for c in cls.policy_aliases.values()}
            custom_objects, left_out = restore_entries(data, classes, custom_objects, allow_pickle, saved_python)
            source = zip_without_entries(source, left_out)
            # a file saved before a parameter existed gets the value that reproduces what it was saved with, which
            # need not be the parameter's default now (SB3's load sets kwargs before _setup_model reads them)
            older = {name: value for name, value in cls.older_file_values.items() if name not in data}
            model = super().load(
                source,
                env,
                device,
                custom_objects,
                print_system_info,
                force_reset,
                **{**older, **kwargs, GIVEN_AT_LOAD: tuple(kwargs)},
            )
            model.__dict__.pop(PLAIN_STATE_KEY, None)
            model.__dict__.pop(GIVEN_AT_LOAD, None)
            model._check_loaded_state()
        except FileNotFoundError:
            raise
        except Exception as error:  # a corrupt file fails inside zipfile, json, torch or SB3 with many error types
            cause = f" ({error.__cause__})" if error.__cause__ is not None else ""
            problem = str(error) if isinstance(error, ValueError) else f"{type(error).__name__}: {error}"
            raise ValueError(f"{path}: {problem}{cause}") from error
        return model

    @classmethod
    def _check_load_kwargs(cls, kwargs: dict[str, Any]) -> None:
        """TypeError for a keyword argument of ``load`` that is not a parameter of the class, as the constructor
        refuses it: SB3 would set it as an attribute that nothing reads (``SarsaLambda.load(path, preset="stable")``
        would load the thesis's Sarsa(lambda) without a word)."""
        parameters = inspect.signature(cls.__init__).parameters
        if any(parameter.kind is inspect.Parameter.VAR_KEYWORD for parameter in parameters.values()):
            return
        unknown = [name for name in kwargs if name not in parameters and not name.startswith("_")]
        if unknown:
            raise TypeError(
                f"{cls.__name__}.load() got {', '.join(map(repr, unknown))}: not a parameter of {cls.__name__}, so "
                "nothing would read it (load's keyword arguments replace the saved parameters; see its page)"
            )

    def _value_watch_remedy(self) -> str:
        """What the value watch's message offers against values leaving the possible returns (ER classes: their
        stabilizers)."""
        return "the stabilizers of the ER classes that keep values inside them (preset='stable')"

    def _check_loaded_state(self) -> None:
        """Check what a loaded file restored that a kernel or the learn loop reads: generator states, counters, the
        last observation. ValueError naming the attribute."""
        for name, value in vars(self).items():
            if name.endswith("_rng"):
                check_rng_state(name, value)
        for name in ("num_timesteps", "_num_timesteps_at_start", "_total_timesteps", "_episode_num", "falls"):
            check_integer(name, getattr(self, name), minimum=0)
        last_obs = self._last_obs
        if last_obs is not None:
            shape = (self.n_envs, *self.observation_space.shape)
            if not (
                isinstance(last_obs, np.ndarray)
                and last_obs.shape == shape
                and last_obs.dtype.kind in "biuf"
                and np.all(np.isfinite(last_obs))
            ):
                raise ValueError(f"_last_obs: expected finite numbers of shape {shape}, got {last_obs!r}")
        for name in ("ep_info_buffer", "ep_success_buffer"):
            if not isinstance(getattr(self, name), (deque, type(None))):
                raise ValueError(f"{name}: expected a deque, got {type(getattr(self, name)).__name__}")

    def set_parameters(
        self,
        load_path_or_dict: str | pathlib.Path | dict[str, Any],
        exact_match: bool = True,
        device: str | Any = "auto",
    ) -> None:
        """SB3's ``set_parameters``; the weights are checked (shape, finite) before they replace the current ones,
        which stay as they were on failure. A bad file is a ValueError naming it.

        :param load_path_or_dict: a zip file written by ``save``, or a dict of parameters by object name (``{"policy":
            state_dict}``).
        :param exact_match: require every object's parameters to be given (default True).
        :param device: torch device to load onto (default "auto").
        """
        source = load_path_or_dict
        try:
            if not isinstance(load_path_or_dict, dict):
                if isinstance(load_path_or_dict, (str, pathlib.Path)):
                    load_path_or_dict = resolve_zip_path(load_path_or_dict)  # so that errors name the file read
                else:
                    check_file_object(load_path_or_dict, "r")  # SB3's TypeError or ValueError, as load
                _, source, _ = read_zip_data(load_path_or_dict)  # every member read whole, a deflated one inflated once
            super().set_parameters(source, exact_match, device)
        except (ValueError, RuntimeError) as error:
            if isinstance(load_path_or_dict, dict):
                raise
            raise ValueError(f"{load_path_or_dict}: {error}") from error

    def _select_action(self, obs: np.ndarray, env: int = 0) -> int:
        """Epsilon-greedy a_k at s_k of env ``env`` (its tiles are written to that env's slots).

        :param obs: s_k, float64 (D,).
        :param env: the env's index (default 0).
        """
        action = kernels.select_action(
            self.policy.theta_array,
            obs,
            self._plain_layout,
            self.exploration_rate,
            self.action_rng,
            self._env_slots[env],
            self._q_scratch,
        )
        if action < 0:
            raise ValueError(self.policy.tile_coder.bad_observation_message(obs, f" at step {self.num_timesteps}"))
        return action

    def _env_action_table(self) -> tuple[list[Any], bool]:
        """Each flat action in the env's format (what ``to_env_actions`` makes of it), built once per ``learn()``,
        and whether an entry must be copied before each step (an array, which an env could change in place)."""
        flat = np.arange(self.policy.tile_coder.n_actions)
        table = list(self.policy.to_env_actions(flat))
        return table, bool(table) and isinstance(table[0], np.ndarray)

    def _observation(self, obs: Any, env: int, what: str) -> np.ndarray:
        """An observation as it enters, checked once: an array of the observation space's shape, of numbers (a NaN
        or an infinity is caught where it is tiled), as float64. ValueError naming the env, the space and what came.

        :param obs: what the env returned.
        :param env: the env's index.
        :param what: where it came from (e.g. "step", "reset").
        """
        if type(obs) is np.ndarray and obs.shape == self.observation_space.shape:  # the per-step case, checked cheaply
            kind = obs.dtype.kind
            if kind == "f":
                return obs if obs.dtype.itemsize == 8 else obs.astype(np.float64)
            if kind in "biu":
                return obs.astype(np.float64)
        array = np.asarray(obs) if obs is not None else None
        if array is None or array.shape != self.observation_space.shape or array.dtype.kind not in "biuf":
            came = (
                "None"
                if obs is None
                else f"{type(obs).__name__} {obs!r:.200}"
                + (f" of shape {array.shape} and dtype {array.dtype}" if isinstance(obs, np.ndarray) else "")
            )
            raise ValueError(
                f"env {env} of {type(self.env).__name__} returned from {what} at step {self.num_timesteps} an "
                f"observation that does not fit the observation space {self.observation_space}: {came}"
            )
        return array.astype(np.float64, copy=False)

    def _interact(self, total_timesteps: int, callback: BaseCallback | None, log_interval: int | None) -> None:
        """The interaction loop of ``learn()``: steps until ``total_timesteps`` or a callback's on_step returns False.

        One step of the N envs is: each env's a_k (its pending a_{k+1} from the online update, else epsilon-greedy at
        s_k), the envs' step, ``num_timesteps`` (by N), the callback (only when one is given), SB3's episode-info
        buffers, then per env in turn: the online Sarsa(lambda) update (one kernel call that also picks a_{k+1}), the
        subclass's ``_after_transition`` (storage, replay; only when the subclass has one), the episode's end
        (counters, trace reset, log dump). Each transition is learned and stored even when the callback stops
        training, so that the envs, ``_last_obs`` and the stored trajectories stay in step and a later
        ``learn(reset_num_timesteps=False)`` continues the episodes exactly where they were. The envs are stepped by
        :func:`~sb3_er.common.env_stepping.make_stepper`'s stepper (a plain DummyVecEnv's envs directly).

        :param total_timesteps: the step count at which to stop.
        :param callback: SB3's callback, or None when none was given.
        :param log_interval: episodes between log dumps (None or 0: none).
        """
        n_envs = self.n_envs
        env_actions, copy_action = self._env_action_table()
        step_envs = make_stepper(self.env, self.policy.to_env_actions, env_actions, copy_action).step
        after_transition = (
            None if type(self)._after_transition is TileQAlgorithm._after_transition else self._after_transition
        )
        online = self.trace_lambda is not None
        # the per-step kernels take plain tuples (kernels.bundles): built once here, the rule again when alpha moves
        weights = tuple(self._weights())
        layout = self._plain_layout
        rule = tuple(self._update_rule()) if online else ()
        scratch = tuple(self._scratch)
        traces, env_slots, env_next_slots, next_actions = (
            self._traces,
            self._env_slots,
            self._env_next_slots,
            self._next_actions,
        )
        action_rng = self.action_rng
        constant_rate = _is_constant(self.lr_schedule)
        sarsa_lambda_step, clear_trace, isfinite = kernels.sarsa_lambda_step, kernels.clear_trace, math.isfinite
        watch = self._watch
        observe = watch.observe if watch is not None and watch.observing else None
        total = float(total_timesteps)
        observations = [self._observation(self._last_obs[i], i, "reset") for i in range(n_envs)]
        # the per-step check of an observation: an array of the space's shape, float64 as it is, float32 converted
        shape, float64, float32 = self.observation_space.shape, np.dtype(np.float64), np.dtype(np.float32)
        actions = [-1] * n_envs
        while self.num_timesteps < total_timesteps:
            for i in range(n_envs):
                action = next_actions[i]
                actions[i] = action if action >= 0 else self._select_action(observations[i], i)
            new_obs, env_obs, rewards, dones, infos = step_envs(actions)
            self.num_timesteps += n_envs
            continue_training = True
            if callback is not None:
                callback.update_locals(
                    {
                        "self": self,
                        "callback": callback,
                        "log_interval": log_interval,
                        "obs": observations[0] if n_envs == 1 else np.stack(observations),
                        "action": actions[0] if n_envs == 1 else np.array(actions),
                        "actions": self.policy.to_env_actions(np.array(actions)),  # the env's format, as SB3 reads it
                        "new_obs": new_obs,
                        "rewards": np.array(rewards, dtype=np.float64),
                        "dones": np.array(dones, dtype=bool),
                        "infos": infos,
                    }
                )
                continue_training = callback.on_step()
                if self.policy.theta_array is not weights[0] or self.action_rng is not action_rng:
                    weights, action_rng = tuple(self._weights()), self.action_rng  # replaced by the callback
            for info in infos:
                if "episode" in info or "is_success" in info:
                    self._update_info_buffer(infos, np.array(dones, dtype=bool))
                    break
            if online and not constant_rate:
                rule = tuple(self._update_rule())
            for i in range(n_envs):
                info, done, reward, action = infos[i], dones[i], rewards[i], actions[i]
                truncated = done and bool(info.get("TimeLimit.truncated", False))
                terminated = done and not truncated
                next_obs = info["terminal_observation"] if done else env_obs[i]
                dtype = next_obs.dtype if type(next_obs) is np.ndarray and next_obs.shape == shape else None
                if dtype is not float64:  # float32 converted here; anything else checked in full
                    next_obs = next_obs.astype(float64) if dtype is float32 else self._observation(next_obs, i, "step")
                if not isfinite(reward):
                    raise ValueError(f"env {i} returned a non-finite reward {reward} at step {self.num_timesteps}")
                if observe is not None and observe(reward, terminated) and online:
                    rule = tuple(self._update_rule())  # the bounds moved: truncation reads them
                next_action = -1
                if online:
                    transition = (env_slots[i], action, reward, terminated, next_obs, env_next_slots[i])
                    next_action, delta, status = sarsa_lambda_step(
                        weights, traces[i], layout, rule, transition, action_rng, scratch, self._watch_array
                    )
                    if status:
                        self._check_status(status, "the Sarsa(lambda) update", delta, next_obs)
                    if not isfinite(delta):
                        self._check_status(kernels.STATUS_DIVERGED, "the Sarsa(lambda) update", delta)
                    self._td_error_sum += abs(delta)
                    self._td_error_count += 1
                next_actions[i] = next_action
                if after_transition is not None:
                    after_transition(i, env_slots[i], observations[i], action, reward, next_obs, terminated, done, info)
                if done:
                    self._episode_num += 1
                    self.falls += is_fall(info, terminated)
                    next_actions[i] = -1
                    if online:
                        clear_trace(traces[i])
                    if log_interval and self._episode_num % log_interval == 0:
                        self.dump_logs()
                    observations[i] = self._observation(env_obs[i], i, "reset")
                else:
                    env_slots[i], env_next_slots[i] = env_next_slots[i], env_slots[i]
                    observations[i] = next_obs
            self._last_obs = new_obs
            self._current_progress_remaining = 1.0 - float(self.num_timesteps) / total
            if not continue_training:
                break

    def _after_transition(
        self,
        env: int,
        slots: np.ndarray,
        obs: np.ndarray,
        action: int,
        reward: float,
        next_obs: np.ndarray,
        terminated: bool,
        done: bool,
        info: dict[str, Any],
    ) -> None:
        """Hook for experience storage and replay; the base class learns online only.

        :param env: the env the transition came from.
        :param slots: the tiles of s_k.
        :param obs: s_k.
        :param action: a_k, the flat action index.
        :param reward: r_{k+1}.
        :param next_obs: s_{k+1} (the true last observation at an episode's end).
        :param terminated: whether s_{k+1} is terminal.
        :param done: whether the episode ended (terminated or truncated).
        :param info: the env's info of this step.
        """

    def _record_train_metrics(self) -> None:
        if self._td_error_count:
            self.logger.record("train/td_error", self._td_error_sum / self._td_error_count)
            self._td_error_sum, self._td_error_count = 0.0, 0
        # the two table statistics scan every weight (about 10 ms at the default 2^22): at most once per
        # n_weights / 4096 env steps (1,024 there), so that dumps at every one-step episode do not set the fps
        scanned_at = getattr(self, "_weights_scanned_at", None)
        every = max(1, self.policy.tile_coder.n_weights >> 12)
        if scanned_at is None or not 0 <= self.num_timesteps - scanned_at < every:
            self._weights_scanned_at = self.num_timesteps
            weights_abs_mean, memory_fill = kernels.weight_statistics(self.policy.weights)
            self.logger.record("train/weights_abs_mean", weights_abs_mean)
            self.logger.record("train/memory_fill", memory_fill)
        self.logger.record("train/learning_rate", self.current_learning_rate)
        if self._watch is not None:
            for name, value in self._watch.period_figures().items():
                if not (isinstance(value, float) and math.isnan(value)):
                    self.logger.record(f"train/{name}", value)

    def dump_logs(self) -> None:
        """Record and write the rollout, train and time scalars. Skipped only for SB3's own logger when it writes
        nowhere (verbose=0 without TensorBoard), where no one could read them; a logger given with ``set_logger``
        receives every key, with or without output formats (SB3's in-memory logger pattern)."""
        if not self.logger.output_formats and not self._custom_logger:
            return
        time_elapsed = max((time.time_ns() - self.start_time) / 1e9, sys.float_info.epsilon)
        fps = int((self.num_timesteps - self._num_timesteps_at_start) / time_elapsed)
        self.logger.record("time/episodes", self._episode_num, exclude="tensorboard")
        if len(self.ep_info_buffer) > 0:
            self.logger.record("rollout/ep_rew_mean", safe_mean([ep["r"] for ep in self.ep_info_buffer]))
            self.logger.record("rollout/ep_len_mean", safe_mean([ep["l"] for ep in self.ep_info_buffer]))
        if len(self.ep_success_buffer) > 0:
            self.logger.record("rollout/success_rate", safe_mean(self.ep_success_buffer))
        self.logger.record("rollout/falls", self.falls)
        self._record_train_metrics()
        self.logger.record("time/fps", fps)
        self.logger.record("time/time_elapsed", int(time_elapsed), exclude="tensorboard")
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(step=self.num_timesteps)

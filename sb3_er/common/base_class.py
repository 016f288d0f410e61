"""Shared SB3 machinery of the tile-coded algorithms: spaces, the learn loop, online Sarsa(lambda), logging."""

import inspect
import io
import math
import pathlib
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
from stable_baselines3.common.utils import safe_mean
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize, unwrap_vec_wrapper

from sb3_er.common import kernels
from sb3_er.common.checks import check_bool, check_choice, check_integer, check_number
from sb3_er.common.dict_observations import (
    dict_vec_env_message,
    flatten_dict_observation,
    flattened_dict_space,
    observation_keys,
)
from sb3_er.common.env_ids import register_env_id
from sb3_er.common.policies import TileQPolicy, _initial_range, action_nvec, initial_value_seed_of
from sb3_er.common.serialization import (
    PLAIN_STATE_KEY,
    atomic_path,
    check_file_object,
    check_rng_state,
    plain_state,
    read_zip_data,
    resolve_zip_path,
    restore_entries,
    sb3_write_path,
    zip_without_entries,
)
from sb3_er.common.tile_coding import (
    DEFAULT_CELL_BUDGET,
    default_tile_widths,
    default_tiles_per_dimension,
    package_tilings,
    varying_dimensions,
)
from sb3_er.common.value_bounds import (
    TOLERANCE,
    VALUE_BOUND_ACTIONS,
    RewardBounds,
    ValueBoundError,
    ValueWatch,
    reward_changing_wrapper,
    widened,
)

try:
    from stable_baselines3.common.utils import ConstantSchedule, FloatSchedule
except ImportError:  # SB3 before 2.4 builds schedules as closures: read at every step
    ConstantSchedule = FloatSchedule = None

DEFAULT_TOTAL_TIMESTEPS = 100_000
ENV_TILING_ATTRIBUTES = ("tile_widths", "wrap_periods", "action_values", "action_tile_widths", "memory_size")

SelfTileQAlgorithm = TypeVar("SelfTileQAlgorithm", bound="TileQAlgorithm")


def _to_builtin(value: Any) -> Any:
    """Arrays and tuples (possibly nested) as lists of Python numbers, so settings pickle and print plainly."""
    if isinstance(value, (np.ndarray, list, tuple)):
        return [_to_builtin(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


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


class TileQAlgorithm(BaseAlgorithm):
    """Base of the tile-coded algorithms: epsilon-greedy acting on TileQ and, optionally, online Sarsa(lambda).

    Subclasses react to each transition through ``_after_transition``. Tile coding defaults come from the env: its
    ``tile_widths``, ``wrap_periods``, ``action_values``, ``action_tile_widths`` and ``memory_size`` attributes, else
    sb3-er's tiling for the env id (``sb3_er/data/tilings.yml``: CartPole-v1, MountainCar-v0, Acrobot-v1,
    Pendulum-v1, MountainCarContinuous-v0), else finite observation bounds split into tiles by the generic rule
    (``default_tile_widths``).

    :param policy: "TileQ" (default) or a TileQPolicy subclass.
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
    :param policy_kwargs: tile coding (see TileQPolicy: ``n_tilings``, default 16; ``tile_widths``; ``wrap_periods``;
        ``memory_size``, default 2**22; ``action_values``; ``action_tile_widths``; ``initial_value``, default 0), plus
        ``tiles_per_dimension`` for bounded observations; default None: the env's attributes and sb3-er's rules.
    :param stats_window_size: episodes averaged in ``rollout/ep_rew_mean`` and ``rollout/ep_len_mean`` (SB3's, 100).
    :param tensorboard_log: folder of TensorBoard logs, or None for none (SB3's).
    :param verbose: 0 silent, 1 the tiling in use and SB3's training messages, 2 debug (SB3's).
    :param seed: seed of every random stream (exploration, trajectory picks, ``predict``, the env), or None.
    :param device: "cpu": the weights live in NumPy arrays; no GPU is used (SB3's argument, kept for its API).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"TileQ": TileQPolicy, "TileQPolicy": TileQPolicy}
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
                support_multi_env=False,
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
            raise ValueError(f"Tile coding needs a flat Box observation space, got {observation_space}")
        if len(observation_space.shape) != 1:
            kind = "image" if len(observation_space.shape) == 3 else "multi-dimensional"
            raise ValueError(
                f"Tile coding needs a flat vector observation; got {kind} observations of shape "
                f"{observation_space.shape}. Extract low-dimensional features first."
            )

    def _env_attribute(self, name: str) -> Any:
        """An optional attribute of the (first) env, None when absent. Probed with ``has_attr``: a SubprocVecEnv's
        ``get_attr`` of a missing attribute kills its worker."""
        if self.env is None or not self.env.has_attr(name):
            return None
        return self.env.get_attr(name)[0]

    def _resolve_policy_kwargs(self) -> dict[str, Any]:
        """Explicit tile-coding settings, so that save/load rebuilds the same coder.

        Each setting comes from the first of: ``policy_kwargs``; the env's attribute of that name; sb3-er's tiling for
        the env's id (``package_tilings()``: only when neither ``policy_kwargs`` (``tile_widths`` or
        ``tiles_per_dimension``) nor the env give tile widths, and the observation has the entry's shape); for tile
        widths, the generic rule (``default_tile_widths``: ``tiles_per_dimension`` if given, else a cell budget per
        tiling). At ``verbose >= 1`` the tiling in use is printed with where it came from.
        """
        kwargs = dict(self.policy_kwargs)
        tiles_per_dimension = kwargs.pop("tiles_per_dimension", None)
        origins = {name: "policy_kwargs" for name, value in kwargs.items() if value is not None}
        for name in ENV_TILING_ATTRIBUTES:
            if (
                kwargs.get(name) is None
                and not (name == "tile_widths" and tiles_per_dimension is not None)
                and not (name == "action_values" and kwargs.get("action_bins") is not None)
            ):
                kwargs[name] = self._env_attribute(name)
                if kwargs[name] is not None:
                    origins[name] = f"the env's {name} attribute"
        notes = []
        if kwargs.get("tile_widths") is None and tiles_per_dimension is None:
            spec = self._env_attribute("spec")
            env_id = getattr(spec, "id", None)
            entry = package_tilings().get(env_id) if isinstance(env_id, str) else None
            shape = tuple(self.observation_space.shape)
            if entry is not None and tuple(entry["observation_shape"]) != shape:
                notes.append(
                    f"sb3-er's tiling for {env_id} is for observations of shape "
                    f"{tuple(entry['observation_shape'])}, not {shape}: not used"
                )
            elif entry is not None:
                notes.extend(self._check_observation_keys(env_id, entry))
                for name, value in entry.items():
                    if name not in ("observation_shape", "observation_keys", "source") and kwargs.get(name) is None:
                        kwargs[name] = value
                        origins[name] = f"sb3-er's tiling for {env_id} ({entry['source']})"
        if kwargs.get("tile_widths") is None:
            if tiles_per_dimension is None:
                tiles_per_dimension = default_tiles_per_dimension(varying_dimensions(self.observation_space))
                origins["tile_widths"] = (
                    f"the generic rule: {tiles_per_dimension} tiles per bounded dimension, "
                    f"min(10, floor({DEFAULT_CELL_BUDGET} cells ^ (1/D))), at least 2"
                )
            else:
                origins["tile_widths"] = f"policy_kwargs: {tiles_per_dimension} tiles per bounded dimension"
            kwargs["tile_widths"] = default_tile_widths(self.observation_space, tiles_per_dimension)
        resolved = {k: _to_builtin(v) for k, v in kwargs.items() if v is not None}
        if self.verbose >= 1:
            self._print_tiling(resolved, origins, notes)
        return resolved

    def _check_observation_keys(self, env_id: str, entry: dict[str, Any]) -> list[str]:
        """Compare the key order and sizes sb3-er's tiling for ``env_id`` assumes (``observation_keys``) with the Dict
        the env's ``FlattenObservation`` flattens: a ValueError when they differ (its tile widths would fall on the
        wrong arrays). Returns a note when the env's Dict cannot be seen (a VecEnv other than DummyVecEnv)."""
        expected = entry.get("observation_keys")
        if expected is None:
            return []
        envs = getattr(self.env, "envs", None)
        space = flattened_dict_space(envs[0]) if envs else None
        if space is None:
            return [
                f"the key order of {env_id}'s Dict observation is not checked against sb3-er's tiling "
                f"{expected}: the env's FlattenObservation is out of reach"
            ]
        actual = observation_keys(space)
        if actual != [list(pair) for pair in expected]:
            raise ValueError(
                f"sb3-er's tiling for {env_id} assumes the Dict observation {expected} ([key, size] in flattening "
                f"order), but the env flattens {actual}: its tile widths would fall on the wrong arrays. Give "
                "policy_kwargs=dict(tile_widths=[...]) for this env"
            )
        return []

    def _print_tiling(self, resolved: dict[str, Any], origins: dict[str, str], notes: list[str]) -> None:
        """Print the tiling in use and where each setting came from (verbose >= 1), e.g.
        ``Tile coding: 8 tilings, tile widths [0.225, 0.0175] from sb3-er's tiling for MountainCar-v0 (...)``."""
        n_tilings = resolved.get("n_tilings")
        if n_tilings is None:
            n_tilings = inspect.signature(self.policy_class).parameters["n_tilings"].default
            origins["n_tilings"] = f"{self.policy_class.__name__}'s default"
        widths = [float(f"{w:.4g}") for w in resolved["tile_widths"]]
        if origins["n_tilings"] == origins["tile_widths"]:
            line = f"Tile coding: {n_tilings} tilings, tile widths {widths} from {origins['tile_widths']}"
        else:
            line = (
                f"Tile coding: {n_tilings} tilings from {origins['n_tilings']}; tile widths {widths} from "
                f"{origins['tile_widths']}"
            )
        others = [
            f"{name}={resolved[name]} from {origins[name]}"
            for name in resolved
            if name not in ("n_tilings", "tile_widths") and name in origins
        ]
        print("\n  ".join([line, *others, *[f"({note})" for note in notes]]))

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
        self._slots = np.zeros(coder.n_tilings, dtype=np.int64)
        self._next_slots = np.zeros(coder.n_tilings, dtype=np.int64)
        self._q_scratch = np.zeros(coder.n_actions, dtype=np.float64)
        self._next_action = -1
        if self.trace_lambda is not None:
            self._setup_trace()
        self._setup_value_watch()

    # --- the value watch (sb3_er.common.value_bounds) ------------------------------------------------------------

    def _setup_value_watch(self) -> None:
        """The bounds of the possible returns for the current env, and the kernels' watch array (empty when the
        watch is off). The first excursion and the count of values outside carry over from an earlier watch."""
        earlier = self._watch
        self._watch = None
        self._observing_rewards = False
        self._watch_array = np.zeros(0)
        if not self.value_watch or self.env is None:
            return
        initial = _initial_range(self.policy.initial_value)
        declared = self._env_attribute("reward_bounds")
        changer = self._reward_changing_wrapper()
        if declared is not None and changer is None:
            watch = ValueWatch("env", RewardBounds.from_attribute(declared), self.gamma, initial)
        else:
            reason = (
                "the env declares no reward_bounds"
                if declared is None
                else f"{changer} may change the rewards the env declares"
            )
            watch = ValueWatch("observed", None, self.gamma, initial, reason)
            self._observing_rewards = True
        if earlier is not None:
            for entry in (
                kernels.WATCH_UPDATES,
                kernels.WATCH_OUT_OF_RANGE,
                kernels.WATCH_FIRST_UPDATE,
                kernels.WATCH_FIRST_VALUE,
            ):
                watch.array[entry] = earlier.array[entry]
        self._watch = watch
        self._watch_array = watch.array
        self._observe_stored_rewards()

    def _observe_stored_rewards(self) -> None:
        """With observed bounds (an env that declares none), widen them with every reward of a buffer this watch has
        not read yet before learning from it: a buffer assigned directly (``model.replay_buffer =
        other.replay_buffer``) is then covered as well as the transitions this learner collected (which it observes
        step by step). Called when the watch is set up, when a buffer is loaded and before each replay phase or fit; a
        buffer is read once per watch (it carries the watch's token, ``observed_by_watch``), so later calls cost
        nothing. Declared bounds need nothing."""
        buffer = getattr(self, "replay_buffer", None)  # None in learners without storage (Sarsa(lambda))
        if not self._observing_rewards or self._watch is None or buffer is None:
            return
        if buffer.observed_by_watch == self._watch.token:
            return
        rewards, terminal = buffer.stored_rewards()
        if rewards.size:
            self._watch.observe_many(rewards, terminal)
        buffer.observed_by_watch = self._watch.token

    def _reward_changing_wrapper(self) -> str | None:
        """The wrapper that may change the env's rewards (VecNormalize with norm_reward, a reward wrapper), or None."""
        normalize = unwrap_vec_wrapper(self.env, VecNormalize)
        if normalize is not None and normalize.norm_reward:
            return "VecNormalize(norm_reward=True)"
        if isinstance(self.env, DummyVecEnv):
            return reward_changing_wrapper(self.env.envs[0])
        return None

    @property
    def value_bounds(self) -> tuple[float, float] | None:
        """(low, high) of the values the learner may take (the possible returns and the initial values), or None
        without a watch."""
        return None if self._watch is None else self._watch.bounds

    @property
    def values_out_of_range(self) -> int:
        """How many targets and Q-values the watch saw outside the bounds (cumulative)."""
        return 0 if self._watch is None else int(self._watch.array[kernels.WATCH_OUT_OF_RANGE])

    def _value_out_of_bounds(self, where: str) -> None:
        """A kernel reported the first value outside the bounds: remember it, then warn or raise as asked."""
        watch = self._watch
        value = float(watch.array[kernels.WATCH_FIRST_VALUE])
        low, high = watch.bounds
        self.value_excursion = {
            "step": int(self.num_timesteps),
            "value": value,
            "low": low,
            "high": high,
            "where": where,
        }
        if self.value_bound_action == "ignore":
            return
        side = f"above {high:.6g}" if value > high else f"below {low:.6g}"
        flagged_low, flagged_high = widened(watch.bounds)
        margin = flagged_high - high if value > high else low - flagged_low
        percent = f"{TOLERANCE * 100:g} %"
        share = (
            f"{percent} of their width"
            if math.isfinite(high - low)
            else f"{percent} of the size of their finite end, at least {TOLERANCE:g}"
        )
        message = (
            f"{type(self).__name__}: at step {self.num_timesteps} ({where}) a value of {value:.6g} left the possible "
            f"returns {watch.describe()}: it lies {side} by more than {margin:.6g} ({share}). Values outside "
            "them are impossible; the run's results reflect a learner that has left the regime it is meant for. "
            "Set value_bound_action='ignore' to only count such values, 'raise' to stop."
        )
        if self.value_bound_action == "raise":
            raise ValueBoundError(message)
        warnings.warn(message, ValueBoundWarning, stacklevel=2)

    def _setup_trace(self) -> None:
        """Sparse replacing trace sized for the longest a trace can live above the cut-off."""
        coder = self.policy.tile_coder
        decay = self.gamma * self.trace_lambda
        if decay <= 0.0:
            lifetime = 1
        elif decay >= 1.0:
            lifetime = coder.n_weights
        else:
            lifetime = int(math.ceil(math.log(self.trace_cutoff / coder.n_tilings) / math.log(decay))) + 2
        capacity = min(coder.n_weights, coder.n_tilings * lifetime)
        self._trace_index = np.zeros(capacity, dtype=np.int64)
        self._trace_value = np.zeros(capacity, dtype=np.float64)
        self._trace_position = np.full(coder.n_weights, -1, dtype=np.int32)
        self._trace_length = np.zeros(1, dtype=np.int64)

    def _excluded_save_params(self) -> list[str]:
        return super()._excluded_save_params() + [
            "_slots",
            "_next_slots",
            "_q_scratch",
            "_trace_index",
            "_trace_value",
            "_trace_position",
            "_trace_length",
            "_next_action",
            "_single_env",
            "_watch",
            "_watch_array",
            "_observing_rewards",
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
        log_interval: int = 1,
        tb_log_name: str = "",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfTileQAlgorithm:
        """Interact for total_timesteps env steps (default 100,000), learning as the algorithm prescribes.

        :param log_interval: log every this many episodes.
        :param total_timesteps: env steps to take (default 100,000).
        :param callback: SB3 callback(s) called at every step (default None).
        :param tb_log_name: name of the TensorBoard run (default: the class's name).
        :param reset_num_timesteps: start the step count and the episode afresh (default True); False continues a
            previous ``learn``.
        :param progress_bar: show SB3's progress bar (default False; needs tqdm and rich).
        """
        if self.env is None:
            raise ValueError("This model has no environment: pass env= to load() or call set_env() before learn()")
        if reset_num_timesteps or self._last_obs is None:
            # _setup_learn resets the env: the episode in progress ends here, unfinished (see _end_episode_at_reset).
            self._end_episode_at_reset()
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name or type(self).__name__, progress_bar
        )
        if reset_num_timesteps:
            self.falls = 0
            self.value_excursion = None
            self._watch = None  # a new run: a new watch
        self._setup_value_watch()
        self._single_env = self.env.envs[0] if type(self.env) is DummyVecEnv else None
        callback.on_training_start(locals(), globals())
        callback.on_rollout_start()
        given = not (isinstance(callback, ConvertCallback) and callback.callback is None)
        self._interact(total_timesteps, callback if given else None, log_interval)
        callback.on_rollout_end()
        callback.on_training_end()
        return self

    def _end_episode_at_reset(self) -> None:
        """The env is about to be reset with an episode in progress (a new ``learn()``, ``set_env``, ``load``): forget
        the pending a_{k+1} and the eligibility trace, so nothing of the old episode reaches the new one. Subclasses
        close what they store of it (ER: the open trajectory, as truncated)."""
        self._next_action = -1
        if self.trace_lambda is not None:
            kernels.clear_trace(self._trace_index, self._trace_position, self._trace_length)

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """SB3's ``set_env``, refusing observation-normalising wrappers. With ``force_reset`` (the default) the next
        ``learn()`` resets the new env and the episode in progress ends, unfinished.

        :param env: the new environment (a Gymnasium env or a VecEnv of one env) with the same spaces.
        :param force_reset: reset the new env at the next ``learn()`` (default True).
        """
        super().set_env(env, force_reset)
        self._check_env_wrappers(self.env)
        if getattr(self, "policy", None) is not None:
            self._setup_value_watch()  # the new env's rewards

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
        pickles that has one, so that ``load(..., allow_pickle=False)`` can read the file without unpickling. Paths
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
        self.__dict__[PLAIN_STATE_KEY] = plain_state(self, exclude, include)
        try:
            if isinstance(path, pathlib.Path):
                with atomic_path(path, ".zip") as partial:
                    super().save(partial, exclude, include)
            else:
                super().save(path, exclude, include)
        finally:
            del self.__dict__[PLAIN_STATE_KEY]

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
        """
        if isinstance(path, (str, pathlib.Path)):
            path = resolve_zip_path(path)  # so that errors name the file read
        else:
            check_file_object(path, "r")  # SB3's TypeError or ValueError for what is not an open binary file
        try:
            data, source, saved_python = read_zip_data(path)
            classes = {f"{c.__module__}:{c.__qualname__}": c for c in cls.policy_aliases.values()}
            custom_objects, left_out = restore_entries(data, classes, custom_objects, allow_pickle, saved_python)
            if left_out:
                source = zip_without_entries(source, left_out)
            model = super().load(source, env, device, custom_objects, print_system_info, force_reset, **kwargs)
            model.__dict__.pop(PLAIN_STATE_KEY, None)
            model._check_loaded_state()
        except FileNotFoundError:
            raise
        except Exception as error:  # a corrupt file fails inside zipfile, json, torch or SB3 with many error types
            cause = f" ({error.__cause__})" if error.__cause__ is not None else ""
            problem = str(error) if isinstance(error, ValueError) else f"{type(error).__name__}: {error}"
            raise ValueError(f"{path}: {problem}{cause}") from error
        return model

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
        try:
            super().set_parameters(load_path_or_dict, exact_match, device)
        except (ValueError, RuntimeError) as error:
            if isinstance(load_path_or_dict, dict):
                raise
            raise ValueError(f"{load_path_or_dict}: {error}") from error

    def _select_action(self, obs: np.ndarray) -> int:
        action = kernels.select_action(
            self.policy.theta_array,
            obs,
            *self.policy.tile_coder.kernel_arguments,
            self.exploration_rate,
            self.action_rng,
            self._slots,
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

    def _interact(self, total_timesteps: int, callback: BaseCallback | None, log_interval: int) -> None:
        """The interaction loop of ``learn()``: steps until ``total_timesteps`` or a callback's on_step returns False.

        One step is: a_k (the pending a_{k+1} of the online update, else epsilon-greedy at s_k), the env step,
        ``num_timesteps``, the callback (only when one is given), SB3's episode-info buffers, the online Sarsa(lambda)
        update (one kernel call that also picks a_{k+1}), the subclass's ``_after_transition`` (storage, replay; only
        when the subclass has one), the episode's end (counters, trace reset, log dump) and SB3's progress. A plain
        one-env DummyVecEnv is stepped directly: the same results as its ``step`` without its per-step deep copy of
        ``info`` and with the env's float64 reward (DummyVecEnv's buffer would round it to float32). The transition
        is learned and stored even when the callback stops training, so that the env, ``_last_obs`` and the stored
        trajectory stay in step and a later ``learn(reset_num_timesteps=False)`` continues the episode exactly where
        it was.
        """
        single, vec_env = self._single_env, self.env
        env_actions, copy_action = self._env_action_table()
        after_transition = (
            None if type(self)._after_transition is TileQAlgorithm._after_transition else self._after_transition
        )
        online = self.trace_lambda is not None
        coder = self.policy.tile_coder
        theta = self.policy.theta_array
        trace = (self._trace_index, self._trace_value, self._trace_position, self._trace_length) if online else ()
        kernel_arguments = coder.kernel_arguments
        n_tilings, gamma, epsilon = coder.n_tilings, self.gamma, self.exploration_rate
        trace_decay = gamma * self.trace_lambda if online else 0.0
        trace_cutoff, action_rng, q_scratch = self.trace_cutoff, self.action_rng, self._q_scratch
        constant_rate = _is_constant(self.lr_schedule)
        step_size = self.current_learning_rate / n_tilings
        sarsa_lambda_step, clear_trace, isfinite = kernels.sarsa_lambda_step, kernels.clear_trace, math.isfinite
        observe = self._watch.observe if self._observing_rewards else None
        total = float(total_timesteps)
        obs = np.asarray(self._last_obs[0], dtype=np.float64)
        while self.num_timesteps < total_timesteps:
            action = self._next_action
            if action < 0:
                action = self._select_action(obs)
            if single is not None:
                env_action = env_actions[action].copy() if copy_action else env_actions[action]
                new_obs, reward, terminated, truncated, info = single.step(env_action)
                done = bool(terminated or truncated)
                truncated = truncated and not terminated
                info["TimeLimit.truncated"] = truncated
                next_obs = np.asarray(new_obs, dtype=np.float64)
                if done:
                    info["terminal_observation"] = new_obs
                    new_obs, vec_env.reset_infos[0] = single.reset()
                terminated, truncated = bool(terminated), bool(truncated)
                reward = float(reward)
                new_obs = np.asarray(new_obs)[np.newaxis]
            else:
                new_obs, rewards, dones, infos = vec_env.step(self.policy.to_env_actions(np.array([action])))
                info, done, reward = infos[0], bool(dones[0]), float(rewards[0])
                truncated = done and bool(info.get("TimeLimit.truncated", False))
                terminated = done and not truncated
                next_obs = np.asarray(info["terminal_observation"] if done else new_obs[0], dtype=np.float64)
            self.num_timesteps += 1
            continue_training = True
            if callback is not None:
                actions = self.policy.to_env_actions(np.array([action]))  # the env's format, as SB3's callbacks read it
                if single is not None:
                    rewards, dones, infos = np.array([reward], dtype=np.float64), np.array([done]), [info]
                callback.update_locals(
                    {
                        "self": self,
                        "callback": callback,
                        "log_interval": log_interval,
                        "obs": obs,
                        "action": action,
                        "actions": actions,
                        "new_obs": new_obs,
                        "rewards": rewards,
                        "dones": dones,
                        "infos": infos,
                    }
                )
                continue_training = callback.on_step()
                theta, action_rng = self.policy.theta_array, self.action_rng  # a callback may have replaced them
            if "episode" in info or "is_success" in info:
                self._update_info_buffer([info], np.array([done]))
            if not isfinite(reward):
                raise ValueError(f"The environment returned a non-finite reward {reward} at step {self.num_timesteps}")
            if observe is not None:
                observe(reward, terminated)
            next_action = -1
            if online:
                if not constant_rate:
                    step_size = self.current_learning_rate / n_tilings
                next_action, delta, status = sarsa_lambda_step(
                    theta,
                    *trace,
                    self._slots,
                    action,
                    reward,
                    terminated,
                    next_obs,
                    self._next_slots,
                    q_scratch,
                    *kernel_arguments,
                    step_size,
                    gamma,
                    trace_decay,
                    trace_cutoff,
                    epsilon,
                    action_rng,
                    self._watch_array,
                )
                if status:
                    self._online_update_status(status, next_obs)
                if not isfinite(delta):
                    self._raise_divergence(delta, "the Sarsa(lambda) update")
                self._td_error_sum += abs(delta)
                self._td_error_count += 1
            self._next_action = next_action
            if after_transition is not None:
                after_transition(obs, action, reward, next_obs, terminated, done, info)
            if done:
                self._episode_num += 1
                self.falls += is_fall(info, terminated)
                self._next_action = -1
                if online:
                    clear_trace(self._trace_index, self._trace_position, self._trace_length)
                if log_interval and self._episode_num % log_interval == 0:
                    self.dump_logs()
                obs = np.asarray(new_obs[0], dtype=np.float64)
            else:
                self._slots, self._next_slots = self._next_slots, self._slots
                obs = next_obs
            self._last_obs = new_obs
            self._current_progress_remaining = 1.0 - float(self.num_timesteps) / total
            if not continue_training:
                break

    def _online_update_status(self, status: int, next_obs: np.ndarray) -> None:
        """React to a status of the Sarsa(lambda) kernel other than STATUS_OK."""
        if status == kernels.STATUS_OUT_OF_BOUNDS:
            self._value_out_of_bounds("the Sarsa(lambda) update")
        elif status == kernels.STATUS_BAD_OBSERVATION:
            raise ValueError(self.policy.tile_coder.bad_observation_message(next_obs, f" at step {self.num_timesteps}"))
        if status == kernels.STATUS_TRACE_FULL:
            raise RuntimeError("The eligibility trace outgrew its capacity; raise trace_cutoff")

    def _raise_divergence(self, delta: float, where: str) -> None:
        raise DivergenceError(
            f"The Q-function diverged at step {self.num_timesteps} in {where}: TD error {delta}. "
            f"Lower the learning rate (now {self.current_learning_rate}) or check the rewards' scale."
        )

    def _after_transition(
        self,
        obs: np.ndarray,
        action: int,
        reward: float,
        next_obs: np.ndarray,
        terminated: bool,
        done: bool,
        info: dict[str, Any],
    ) -> None:
        """Hook for experience storage and replay; the base class learns online only."""

    def _record_train_metrics(self) -> None:
        if self._td_error_count:
            self.logger.record("train/td_error", self._td_error_sum / self._td_error_count)
            self._td_error_sum, self._td_error_count = 0.0, 0
        weights_abs_mean, memory_fill = kernels.weight_statistics(
            self.policy.theta_array, *self.policy.initial_arguments
        )
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

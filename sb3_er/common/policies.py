"""TileQ: a tile-coded linear action-value function Q(s, a) = theta . phi(s, a) as an SB3 policy."""

import io
import pathlib
import pickle
import warnings
from collections.abc import Sequence

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.common.utils import is_vectorized_observation

from sb3_er.common import kernels
from sb3_er.common.action_levels import box_action_levels
from sb3_er.common.serialization import atomic_path, decode_plain, encode_plain
from sb3_er.common.tile_coding import HashCollisionWarning, TileCoder, collision_warning


def action_start(action_space: spaces.Space) -> np.ndarray:
    """The first action of each action dimension (gymnasium's ``start``; 0 unless the space says otherwise).

    :param action_space: a Discrete, MultiDiscrete or Box action space.
    """
    return np.atleast_1d(np.asarray(getattr(action_space, "start", 0), dtype=np.int64)).reshape(-1)


def action_nvec(action_space: spaces.Space) -> list[int]:
    """Choices per action dimension of a Discrete or MultiDiscrete space.

    :param action_space: a Discrete or MultiDiscrete action space.
    """
    if isinstance(action_space, spaces.Discrete):
        return [int(action_space.n)]
    if isinstance(action_space, spaces.MultiDiscrete):
        if action_space.nvec.ndim != 1:
            raise ValueError(
                f"Only flat MultiDiscrete action spaces are supported, got nvec of shape {action_space.nvec.shape}"
            )
        return [int(n) for n in action_space.nvec]
    raise ValueError(f"Tile-coded Q-learning needs a Discrete, MultiDiscrete or Box action space, got {action_space}")


def initial_value_seed_of(seed: int) -> int:
    """The seed of the initial weights' draw of a model seeded with ``seed``: the first ``randint(0, 2^62)`` of NumPy's
    legacy generator seeded with ``seed``, as NumPy's global generator gave it right after SB3's
    ``set_random_seed(seed)``, drawn from a private generator so that models built at the same time in threads (rl-zoo's
    ``optimize --n-jobs``) do not draw from one another's stream.

    :param seed: the algorithm's seed (0 to 2^32 - 1, as NumPy's legacy seeding takes).
    """
    return int(np.random.RandomState(seed).randint(0, 2**62))


def _initial_range(initial_value) -> tuple[float, float]:
    """(low, high) of Q's initial values from a number or a (low, high) pair; ValueError naming the problem."""
    values = np.atleast_1d(np.asarray(initial_value, dtype=np.float64)) if _is_numeric(initial_value) else None
    if values is None or values.ndim != 1 or values.size not in (1, 2) or not np.all(np.isfinite(values)):
        raise ValueError(f"initial_value must be a finite number or a (low, high) pair, got {initial_value!r}")
    low, high = float(values[0]), float(values[-1])
    if low > high:
        raise ValueError(f"initial_value (low, high) needs low <= high, got {initial_value!r}")
    return low, high


def _is_numeric(value) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
        return True
    except (TypeError, ValueError):
        return False


def _tileable(coder: TileCoder, obs: np.ndarray) -> bool:
    return bool(np.all(np.abs(obs * coder.inv_widths) < kernels.MAX_TILE_COORDINATE))


class TileQPolicy(BasePolicy):
    """Greedy policy of a binary tile-coded linear Q-function (thesis Eq. 2.8).

    The weights theta are a float64 CPU tensor registered as a buffer, so SB3's save/load and get/set_parameters work
    unchanged; the numba kernels update its NumPy view in place. MultiDiscrete actions are flattened in C order.
    Exploration belongs to the algorithm: ``predict`` here is always greedy. Internally actions are flat indices
    0..A-1; the env sees them shifted by the space's ``start`` (``Discrete(3, start=-1)`` receives -1, 0, 1). A Box
    action space is discretised (:mod:`sb3_er.common.action_levels`): each dimension gets levels spaced evenly from its
    lower to its upper bound, both included (7 by default, at most 7^3 joint actions so), the joint actions are
    flattened in C order like a MultiDiscrete space's, and the env receives the levels in the Box's shape and dtype.

    :param observation_space: a flat Box.
    :param action_space: Discrete, MultiDiscrete or a Box of a floating-point dtype.
    :param lr_schedule: unused (SB3 interface); the algorithm applies the learning rate.
    :param tile_widths: tile width per observation dimension.
    :param n_tilings: number of tilings N.
    :param memory_size: upper bound on the number of weights (default 2^22, 32 MiB). The table holds memory_size //
        stride state-tile slots (rounded down to a power of two), the stride being the actions' row rounded up to
        whole cache lines: many actions leave few slots. Building the policy warns (HashCollisionWarning) when the
        actions leave so few slots that more than half of the state tiles a run would visit are expected to share
        one, with the memory_size that avoids it; the table never grows past memory_size on its own.
    :param wrap_periods: per observation dimension a period or None.
    :param action_values: per action dimension the value of each choice (for action tiling); for a Box action space
        the levels the env receives, each inside the bounds (needed where a bound is infinite).
    :param action_bins: Box action spaces only: levels per dimension (an int or one per dimension), spaced evenly
        from the lower to the upper bound, both included; default 7 per dimension while that makes at most 343 joint
        actions. Give this or ``action_values``, not both.
    :param action_tile_widths: per action dimension a tile width over action_values; None keeps actions apart.
    :param initial_value: where Q starts. A number c sets every weight to c / N, so that Q(s, a) = c everywhere; a pair
        (low, high) draws each weight from U(low / N, high / N), so that Q starts in [low, high] (GRL's walker draws
        its averaged weights from U[0, 1]: ``initial_value=(0, 1)`` here). Default 0, the thesis's Alg. 2-14 line 1.
        Optimistic values explore; pessimistic ones (thesis Figure 5.5) trust only visited features. ER-sigma
        replaces the initial values of unvisited features by sigma(s') (Eq. 5.4).
    :param initial_value_seed: seed of the draw of (low, high) initial weights; None draws one from fresh entropy. An
        algorithm with a ``seed`` passes :func:`initial_value_seed_of` its seed. The resolved seed is kept, so a
        reloaded model knows every weight's initial value.
    """

    def __init__(
        self,
        observation_space: spaces.Box,
        action_space: spaces.Discrete | spaces.MultiDiscrete | spaces.Box,
        lr_schedule: Schedule | None = None,
        tile_widths: Sequence[float] | None = None,
        n_tilings: int = 16,
        memory_size: int = 2**22,
        wrap_periods: Sequence[float | None] | None = None,
        action_values: Sequence[Sequence[float]] | None = None,
        action_tile_widths: Sequence[float] | None = None,
        initial_value: float | Sequence[float] = 0.0,
        initial_value_seed: int | None = None,
        action_bins: int | Sequence[int] | None = None,
    ):
        super().__init__(observation_space, action_space)
        if tile_widths is None:
            raise ValueError("TileQPolicy needs tile_widths (one per observation dimension)")
        continuous = isinstance(action_space, spaces.Box)
        if continuous:
            levels = box_action_levels(action_space, action_bins, action_values)
            action_values = levels
        elif action_bins is not None:
            raise ValueError(f"action_bins discretises a Box action space; this one is {action_space}")
        self.tile_coder = TileCoder(
            tile_widths,
            [len(v) for v in levels] if continuous else action_nvec(action_space),
            n_tilings=n_tilings,
            memory_size=memory_size,
            wrap_periods=wrap_periods,
            action_values=action_values,
            action_tile_widths=action_tile_widths,
        )
        if self.tile_coder.n_dims != int(np.prod(observation_space.shape)):
            raise ValueError(
                f"tile_widths has {self.tile_coder.n_dims} entries for an observation of shape "
                f"{observation_space.shape}"
            )
        if isinstance(observation_space, spaces.Box):
            crowded = collision_warning(self.tile_coder, observation_space)
            if crowded is not None:
                warnings.warn(crowded, HashCollisionWarning, stacklevel=2)
        low, high = _initial_range(initial_value)
        if low != high and initial_value_seed is None:
            initial_value_seed = int(np.random.default_rng().integers(0, 2**62))  # fresh entropy
        self.initial_value = initial_value if low != high else low
        self.initial_value_seed = None if low == high else int(initial_value_seed)
        n = self.tile_coder.n_tilings
        #: How the weights start, per weight: (initial_low, initial_span, initial_seed) of the kernels' Weights.
        self.initial_arguments = (low / n, (high - low) / n, np.uint64(self.initial_value_seed or 0))
        # NumPy allocates large arrays with transparent huge pages, which spares the random row reads TLB misses.
        self.register_buffer("theta", th.from_numpy(np.zeros(self.tile_coder.n_weights, dtype=np.float64)))
        self._share_theta()
        if low != 0.0 or high != 0.0:
            kernels.fill_initial_weights(self.weights)
        choices = np.stack(np.unravel_index(np.arange(self.tile_coder.n_actions), self.tile_coder.action_nvec), axis=1)
        if continuous:  # the level of each dimension of each joint action, in the Box's dtype
            self.action_table = np.stack([levels[j][choices[:, j]] for j in range(len(levels))], axis=1).astype(
                action_space.dtype
            )
        else:
            self.action_table = choices + action_start(action_space)
        self._actions_are_indices = isinstance(action_space, spaces.Discrete) and int(action_space.start) == 0
        self._slots_scratch = np.zeros(self.tile_coder.n_tilings, dtype=np.int64)
        self._q_scratch = np.zeros(self.tile_coder.n_actions, dtype=np.float64)

    # theta_array is the NumPy view of the tensor theta that the kernels update in place; acting, learning, saving and
    # get/set_parameters must see one array. The view is rebuilt wherever the tensor can be replaced (assigning theta,
    # ``.to()``, a deep copy, unpickling) rather than derived at each access, which would cost every step.

    def __setattr__(self, name, value) -> None:
        if name == "theta":
            self._check_theta(value)  # before it replaces the weights in place
        super().__setattr__(name, value)
        if name == "theta":
            self._share_theta()

    def _check_theta(self, theta) -> None:
        if not (
            isinstance(theta, th.Tensor)
            and theta.device.type == "cpu"
            and theta.dtype == th.float64
            and tuple(theta.shape) == (self.tile_coder.n_weights,)
            and theta.is_contiguous()
        ):
            raise ValueError(
                f"TileQPolicy keeps its weights as one contiguous float64 CPU tensor of "
                f"{self.tile_coder.n_weights} entries, got {getattr(theta, 'dtype', type(theta).__name__)} "
                f"{tuple(getattr(theta, 'shape', ()))} on {getattr(theta, 'device', '?')}"
            )

    def _share_theta(self) -> None:
        self._check_theta(self.theta)
        self.__dict__["theta_array"] = self.theta.numpy()

    @property
    def weights(self):
        """theta and how it started, as the kernels read them (a :class:`~sb3_er.common.kernels.bundles.Weights`),
        without a target copy (an algorithm that keeps one builds its own bundle)."""
        low, span, seed = self.initial_arguments
        return kernels.weights_bundle(self.theta_array, low, span, seed)

    def _apply(self, fn, recurse=True):
        """Keep theta a CPU float64 tensor whose NumPy view the kernels share (``.to(device)`` must not rebind it)."""
        result = super()._apply(fn, recurse)
        self._share_theta()
        return result

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("theta_array", None)  # a copy of the view would be a second array: rebuilt from theta instead
        return state

    def __setstate__(self, state: dict) -> None:
        super().__setstate__(state)
        self._share_theta()

    def _load_from_state_dict(
        self, state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs
    ) -> None:
        """Check incoming weights before they are copied into theta (set_parameters, load, ``TileQPolicy.load``): the
        tile coding's number of weights, all finite. A problem is reported as PyTorch reports a size mismatch (a
        RuntimeError of ``load_state_dict``), and the weights in place stay as they were."""
        theta = state_dict.get(prefix + "theta")
        problem = None
        if theta is not None:
            if not isinstance(theta, th.Tensor) or not theta.dtype.is_floating_point:
                problem = (
                    f"the weights theta must be a floating-point tensor, got {type(theta).__name__} "
                    f"{getattr(theta, 'dtype', '')}"
                )
            elif tuple(theta.shape) != (self.tile_coder.n_weights,):
                problem = (
                    f"the weights theta have shape {tuple(theta.shape)}, but this tile coding has "
                    f"{self.tile_coder.n_weights} weights: they were saved with another tile coding"
                )
            elif not bool(th.isfinite(theta).all()):
                bad = th.nonzero(~th.isfinite(theta)).reshape(-1)[:5].tolist()
                problem = f"the weights theta hold non-finite values (at indices {bad})"
        if problem is not None:
            error_msgs.append(problem)
            return
        super()._load_from_state_dict(
            state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs
        )

    def parameters_to_vector(self) -> np.ndarray:
        """The weights theta as a 1D array (a copy; SB3's BasePolicy reads ``parameters()``, which theta, a buffer the
        kernels update without gradients, is not among)."""
        return self.theta_array.copy()

    def load_from_vector(self, vector: np.ndarray) -> None:
        """Write a 1D array of weights into theta in place (the inverse of ``parameters_to_vector``).

        :param vector: the weights, 1D of theta's size.
        """
        self.load_state_dict({"theta": th.as_tensor(np.asarray(vector, dtype=np.float64))})

    def save(self, path: str | pathlib.Path | io.BufferedIOBase) -> None:
        """Save the weights and the constructor settings (SB3's policy file, ``TileQPolicy.load`` reads it back), the
        spaces in plain form, so that loading needs no pickle; written atomically.

        :param path: the file to write (a path or an open binary file).
        """
        saved = {"state_dict": self.state_dict(), "data": encode_plain(self._get_constructor_parameters())}
        if not isinstance(path, (str, pathlib.Path)):  # a file object, as torch.save takes
            th.save(saved, path)
            return
        with atomic_path(path, ".pth") as partial:
            th.save(saved, partial)

    @classmethod
    def load(
        cls,
        path: str | pathlib.Path | io.BufferedIOBase,
        device: th.device | str = "auto",
        allow_pickle: bool = True,
    ) -> "TileQPolicy":
        """Load a policy saved by ``save``. Its file is read with ``torch.load(weights_only=True)``: no pickle runs.
        A policy file in SB3's own format (spaces pickled) needs ``allow_pickle`` (the default, as in SB3), as
        unpickling it can run code from the file. ValueError naming the file for anything unreadable or inconsistent.

        :param device: accepted for SB3's signature; the weights live on the CPU.
        :param path: the file written by ``save`` (a path or an open binary file).
        :param allow_pickle: read a policy file of SB3's own format, whose spaces are pickled (default True, as in SB3).
        """
        start = path.tell() if hasattr(path, "seek") and hasattr(path, "tell") else None
        try:
            try:
                saved = th.load(path, map_location="cpu", weights_only=True)
                plain = True
            except pickle.UnpicklingError:
                if not allow_pickle:
                    raise ValueError("a policy file with pickled settings, refused with allow_pickle=False") from None
                if start is not None:
                    path.seek(start)  # where the stream stood: torch read it from there, as SB3's load does
                saved = th.load(path, map_location="cpu", weights_only=False)
                plain = False
            if not (isinstance(saved, dict) and set(saved) == {"state_dict", "data"}):
                raise ValueError("not a policy file: expected the entries state_dict and data")
            data = decode_plain(saved["data"], {}) if plain else dict(saved["data"])
            if not isinstance(data, dict):
                raise ValueError("the data entry is not a dict of constructor settings")
            data.pop("normalize_images", None)  # written by SB3's BaseModel, not a setting of tile coding
            model = cls(**data)
            model.load_state_dict(saved["state_dict"])
        except (ValueError, TypeError, RuntimeError, EOFError, OSError) as error:
            if isinstance(error, FileNotFoundError):
                raise
            raise ValueError(f"{path}: {error}") from error
        return model

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        data.pop("normalize_images", None)  # SB3's image option: tile coding takes flat vectors and has no such setting
        config = self.tile_coder.config()
        del config["action_nvec"]
        data.update(config, initial_value=self.initial_value, initial_value_seed=self.initial_value_seed)
        return data

    def initial_weights(self, indices: np.ndarray) -> np.ndarray:
        """The initial values of the weights at ``indices`` (any integer array shape).

        :param indices: weight indices, any integer array shape.
        """
        indices = np.ascontiguousarray(indices, dtype=np.int64)
        out = np.empty(indices.size, dtype=np.float64)
        kernels.initial_weights_at(indices.reshape(-1), self.weights, out)
        return out.reshape(indices.shape)

    def _as_batch(self, observation) -> tuple[np.ndarray, bool]:
        obs = np.asarray(observation, dtype=np.float64)
        vectorized = is_vectorized_observation(obs, self.observation_space)
        return np.ascontiguousarray(obs.reshape(-1, self.tile_coder.n_dims)), vectorized

    def flat_greedy_actions(self, observations: np.ndarray) -> np.ndarray:
        """Greedy flat action index for each row of a (B, D) float64 array; lowest index on ties.

        :param observations: the states, (B, D) float64.
        """
        coder = self.tile_coder
        out = np.empty(observations.shape[0], dtype=np.int64)
        ok = kernels.greedy_actions(
            self.theta_array, observations, coder.layout, self._slots_scratch, self._q_scratch, out
        )
        if not ok:
            bad = next(row for row in observations if not _tileable(coder, row))
            raise ValueError(coder.bad_observation_message(bad))
        return out

    def to_env_actions(self, flat_actions: np.ndarray) -> np.ndarray:
        """Flat action indices (B,) to the action space's format: (B,) for Discrete, (B, dims) for MultiDiscrete,
        shifted by the space's ``start``; (B, *shape) levels in the Box's dtype for a Box.

        :param flat_actions: flat action indices, (B,).
        """
        if self._actions_are_indices:
            return flat_actions
        table = self.action_table[flat_actions]
        if isinstance(self.action_space, spaces.Box):
            return table.reshape((-1, *self.action_space.shape))
        return table[:, 0] if isinstance(self.action_space, spaces.Discrete) else table

    def q_values(self, observations: np.ndarray) -> np.ndarray:
        """Q(s, .) for each observation: (B, D) -> (B, n_actions), MultiDiscrete actions flattened in C order.

        :param observations: the states, (B, D) (or one state, (D,)).
        """
        batch, _ = self._as_batch(observations)
        coder = self.tile_coder
        out = np.empty((batch.shape[0], coder.n_actions), dtype=np.float64)
        if not kernels.batch_q_values(self.theta_array, batch, coder.layout, self._slots_scratch, out):
            bad = next(row for row in batch if not _tileable(coder, row))
            raise ValueError(coder.bad_observation_message(bad))
        return out

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Greedy actions for one observation or a batch, computed in float64 (no float32 round trip).

        :param observation: one observation or a batch (n, ...).
        :param state: unused (no recurrent state); returned as given.
        :param episode_start: unused; accepted for SB3's signature.
        :param deterministic: accepted for SB3's signature: the policy is greedy either way (the algorithm's ``predict``
            adds exploration).
        """
        if isinstance(observation, dict):
            raise ValueError(
                "TileQPolicy needs a flat Box observation, got a dict: flatten it as the model's env "
                "does (gymnasium.wrappers.FlattenObservation around the env, or "
                "gymnasium.spaces.flatten(env.observation_space, observation))"
            )
        if isinstance(observation, tuple):
            # SB3's own predict, whose checks catch a Gymnasium (obs, info) pair passed for a VecEnv observation;
            # any other tuple is an observation and comes back through _predict.
            return super().predict(observation, state, episode_start, deterministic)
        batch, vectorized = self._as_batch(observation)
        actions = self.to_env_actions(self.flat_greedy_actions(batch))
        actions = actions.reshape((-1, *self.action_space.shape))
        if not vectorized:
            actions = actions.squeeze(axis=0)
        return actions, state

    def _predict(self, observation: th.Tensor, deterministic: bool = False) -> th.Tensor:
        batch = np.ascontiguousarray(
            observation.detach().cpu().numpy().astype(np.float64).reshape(-1, self.tile_coder.n_dims)
        )
        return th.as_tensor(self.to_env_actions(self.flat_greedy_actions(batch)))

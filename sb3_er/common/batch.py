"""Shared machinery of the methods of thesis chapter 3 that keep a sample database D (Dyna, FQI, LSPI).

- ``stored_transitions``: D as arrays, one row per transition (s_d, a_d, r_d, s'_d, terminal_d), read from the
  ``TrajectoryReplayBuffer`` that ER also uses.
- ``TileFeatures``: the binary design matrix Phi (n, f) of phi(s_d, a_d) over the f weights the data touches, as the
  projection methods (thesis 3.5.1, Alg. 6) need it.
- ``BufferedTileQAlgorithm``: a TileQAlgorithm that stores every transition (thesis Alg. 3 line 6 with
  D <- D u {(s_k, a_k, s_{k+1}, r_{k+1})}) and saves/loads its buffer like ER.
- ``FittedTileQAlgorithm``: adds the batch trigger of Alg. 3 line 7 (every ``fit_every`` episodes) for FQI and LSPI.
"""

import contextlib
import time
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from sb3_er.common import kernels
from sb3_er.common.base_class import DivergenceError, TileQAlgorithm
from sb3_er.common.buffers import TrajectoryBufferIO, TrajectoryReplayBuffer
from sb3_er.common.checks import check_integer, check_number
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.tile_coding import TileCoder

try:
    from threadpoolctl import ThreadpoolController
except ImportError:  # optional: without it, BLAS keeps its own thread count
    ThreadpoolController = None
_blas_controller = None  # made at the first fit: finding the loaded BLAS libraries costs milliseconds each time


class Transitions(NamedTuple):
    """The sample database D, oldest transition first (n rows; D observation dimensions, N tilings).

    :param observations: the states s_d, float64 (n, D).
    :param slots: the state tiles of s_d, int64 (n, N).
    :param actions: the flat actions a_d, int64 (n,).
    :param rewards: the rewards r_d, float64 (n,).
    :param next_observations: the next states s'_d, float64 (n, D).
    :param next_slots: the state tiles of s'_d, int64 (n, N).
    :param terminal: whether s'_d ended the episode by termination (the target is then r_d), bool (n,).
    """

    observations: np.ndarray
    slots: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_observations: np.ndarray
    next_slots: np.ndarray
    terminal: np.ndarray

    def __len__(self) -> int:
        return self.actions.shape[0]


def stored_transitions(buffer: TrajectoryReplayBuffer, include_open: bool = False) -> Transitions:
    """Every closed transition of the buffer as arrays (copies), oldest first.

    s'_d is s_{d+1} of the next row inside a trajectory and the trajectory's stored last observation at its end.
    ``include_open`` adds the open trajectory (the episode in progress), its last s' being the buffer's
    ``open_next_obs``; its transitions are not terminal.

    :param buffer: the replay buffer to read.
    :param include_open: add the open trajectory's transitions (default False).
    """
    capacity = buffer.capacity
    n_trajectories = buffer.n_trajectories
    first = int(buffer.trajectory_start[buffer.oldest_trajectory]) if n_trajectories else buffer.write_row
    n_open = buffer.open_length if include_open else 0
    n = buffer.n_closed_transitions + n_open
    rows = (first + np.arange(n)) % capacity
    next_rows = (rows + 1) % capacity
    next_observations = buffer.observations[next_rows]
    next_slots = buffer.slots[next_rows]
    terminal = np.zeros(n, dtype=np.bool_)
    if n_trajectories:
        trajectories = (buffer.oldest_trajectory + np.arange(n_trajectories)) % capacity
        ends = np.cumsum(buffer.trajectory_length[trajectories]) - 1
        next_observations[ends] = buffer.trajectory_next_obs[trajectories]
        next_slots[ends] = buffer.trajectory_next_slots[trajectories]
        terminal[ends] = buffer.trajectory_terminated[trajectories]
    if n_open:
        next_observations[n - 1] = buffer.open_next_obs
        next_slots[n - 1] = buffer.tile_coder.slots(buffer.open_next_obs)
    return Transitions(
        buffer.observations[rows],
        buffer.slots[rows],
        buffer.actions[rows],
        buffer.rewards[rows],
        next_observations,
        next_slots,
        terminal,
    )


def single_threaded_blas() -> contextlib.AbstractContextManager:
    """Run BLAS (the vector operations inside scipy's solvers) on one thread, if threadpoolctl is installed.

    The fits' vector operations are memory-bound, and OpenBLAS's thread synchronisation made them 10-30 times slower on
    a loaded 2-core machine (a dot product of 383,000 numbers: 7.7 ms of CPU against 0.28 ms single-threaded). One
    thread also keeps the summation order, and so the results, independent of the machine's core count.

    The BLAS libraries are found once, at the first call: threadpoolctl's ``threadpool_limits`` searched the process's
    loaded libraries at every fit (1-3 ms, as long as a small FQI fit itself).
    """
    global _blas_controller
    if ThreadpoolController is None:
        return contextlib.nullcontext()
    if _blas_controller is None:
        _blas_controller = ThreadpoolController()
    return _blas_controller.limit(limits=1, user_api="blas")


def weight_indices(coder: TileCoder, slots: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Indices (n, N) of the active weights of phi(s_d, a_d), given the state tiles (n, N) and flat actions (n,).

    :param coder: the tile coder of the weights.
    :param slots: state tile slots, (n, N) for N tilings.
    :param actions: flat action indices, (n,).
    """
    tilings = np.arange(coder.n_tilings)[None, :]
    return slots * coder.stride + coder.action_columns[tilings, np.asarray(actions)[:, None]]


class TileFeatures:
    """The binary design matrix Phi (n, f) of phi(s_d, a_d), restricted to the f weights the data touches.

    Column j stands for weight ``touched[j]``; ``columns[d]`` are the N active columns of row d (a column repeated in a
    row, a hash collision, has the value 2 there); ``counts[j]`` is how often column j is active.

    :param coder: the policy's tile coder.
    :param slots: (n, N) state tiles of s_d.
    :param actions: (n,) flat actions a_d.
    """

    def __init__(self, coder: TileCoder, slots: np.ndarray, actions: np.ndarray):
        self.coder = coder
        indices = weight_indices(coder, slots, actions)
        self.touched, inverse = np.unique(indices, return_inverse=True)
        self.columns = np.ascontiguousarray(inverse.reshape(indices.shape), dtype=np.int64)
        self.counts = np.bincount(self.columns.ravel(), minlength=self.n_features).astype(np.float64)

    @property
    def n_features(self) -> int:
        return int(self.touched.shape[0])

    def columns_of(self, slots: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Columns (n, N) of phi(s, a) for other states and actions; -1 for weights outside the touched set and for rows
        with a negative action (a terminal s').

        :param slots: state tile slots, (n, N).
        :param actions: flat action indices, (n,); negative for a terminal s'.
        """
        indices = weight_indices(self.coder, slots, np.maximum(actions, 0))
        position = np.minimum(np.searchsorted(self.touched, indices), self.n_features - 1)
        found = (self.touched[position] == indices) & (np.asarray(actions) >= 0)[:, None]
        return np.where(found, position, -1)

    def matrix(self, columns: np.ndarray | None = None) -> sp.csr_matrix:
        """Phi as a scipy CSR matrix (n, f), or the matrix of other ``columns`` (entries -1 dropped).

        :param columns: feature columns (n, N) from :meth:`columns_of`; default None: this object's own rows.
        """
        columns = self.columns if columns is None else columns
        n = columns.shape[0]
        rows = np.repeat(np.arange(n), columns.shape[1])
        flat = columns.ravel()
        keep = flat >= 0
        matrix = sp.csr_matrix((np.ones(int(keep.sum())), (rows[keep], flat[keep])), shape=(n, self.n_features))
        matrix.sum_duplicates()
        return matrix


@inherit_parameters
class BufferedTileQAlgorithm(TrajectoryBufferIO, TileQAlgorithm):
    """A TileQAlgorithm that keeps every transition in a TrajectoryReplayBuffer (the database D of thesis 3.5.3).

    A trajectory closes at each episode end and wherever the env sets ``info["segment_end"]``, as in ER.

    :param buffer_size: transitions kept; the oldest whole trajectories are evicted beyond it.
    :param replay_buffer_kwargs: keyword arguments of the TrajectoryReplayBuffer, e.g. ``dict(prune="coverage")`` for
        the pruned database of thesis 3.5.3.
    """

    def __init__(
        self, policy, env, buffer_size: int = 1_000_000, replay_buffer_kwargs: dict[str, Any] | None = None, **kwargs
    ):
        self.buffer_size = buffer_size
        self.replay_buffer_kwargs = replay_buffer_kwargs
        self.replay_buffer: TrajectoryReplayBuffer | None = None
        super().__init__(policy, env, **kwargs)

    def _check_hyperparameters(self) -> None:
        super()._check_hyperparameters()
        check_integer("buffer_size", self.buffer_size, minimum=1)
        TrajectoryReplayBuffer.check_kwargs(self.replay_buffer_kwargs)

    def _setup_model(self) -> None:
        super()._setup_model()
        self.replay_buffer = TrajectoryReplayBuffer(
            self.buffer_size, self.policy.tile_coder, **(self.replay_buffer_kwargs or {}), n_envs=self.n_envs or 1
        )

    def _end_episode_at_reset(self) -> None:
        """The episodes in progress were cut off by an env reset: their trajectories are closed as truncated at their
        last real s_{t+1} (as ER does), never joined to the next episodes; no fit is triggered."""
        super()._end_episode_at_reset()
        if self.replay_buffer is not None:
            self.replay_buffer.truncate_open_trajectory()

    def _on_n_envs_changed(self) -> None:
        if self.replay_buffer is not None:
            self.replay_buffer.set_n_envs(self.n_envs)

    def _store_transition(self, env, slots, obs, action, reward, next_obs, terminated, done, info) -> bool:
        """Add (s_k, a_k, r_{k+1}, s_{k+1}) to env ``env``'s open trajectory; close it at s_{k+1} if it ends here.
        Returns whether it closed (and was kept)."""
        closes = done or info.get("segment_end", False)
        return self.replay_buffer.add(obs, slots, action, reward, next_obs, env, end=terminated if closes else None)

    def _record_train_metrics(self) -> None:
        super()._record_train_metrics()
        self.logger.record("train/transitions", self.replay_buffer.n_transitions)
        self.logger.record("train/trajectories", self.replay_buffer.n_trajectories)
        self.replay_buffer.record_fill(self.logger)


@inherit_parameters
class FittedTileQAlgorithm(BufferedTileQAlgorithm):
    """A projection method (thesis Alg. 6) run on the whole database every ``fit_every`` episodes (Alg. 3 line 7 with
    an event-based L). Between fits the agent acts epsilon-greedily on the current Q without learning.

    Subclasses implement ``_fit(data)``, which writes theta and returns scalars to log under ``train/``.

    :param fit_every: episodes between fits.
    :param n_iterations: sweeps per fit (E of thesis 3.5.4; LSPI stops earlier once its policy is stable).
    :param ridge: lambda of the ridge term lambda ||theta||^2 that keeps the least-squares systems regular.
    """

    def __init__(self, policy, env, fit_every: int = 5, n_iterations: int = 20, ridge: float = 1.0, **kwargs):
        self.fit_every = fit_every
        self.n_iterations = n_iterations
        self.ridge = ridge
        self.fits = 0
        self.fit_seconds = 0.0
        self.sample_backups = 0
        self._fit_stats: dict[str, float] = {}
        super().__init__(policy, env, **kwargs)

    def _check_hyperparameters(self) -> None:
        super()._check_hyperparameters()
        check_integer("fit_every", self.fit_every, minimum=1, unit=" episode")
        check_integer("n_iterations", self.n_iterations, minimum=1)
        check_number("ridge", self.ridge, 0.0, low_open=True, unit=" (it keeps the systems regular)")

    def _after_transition(self, env, slots, obs, action, reward, next_obs, terminated, done, info) -> None:
        self._store_transition(env, slots, obs, action, reward, next_obs, terminated, done, info)
        if done and (self._episode_num + 1) % self.fit_every == 0:
            self.fit()

    def fit(self) -> dict[str, float]:
        """Fit Q on every closed transition now (one call of Alg. 6); returns the fit's statistics."""
        data = stored_transitions(self.replay_buffer)
        if len(data) == 0:
            return {}
        self._observe_stored_rewards()
        start = time.perf_counter()
        with single_threaded_blas():
            stats = self._fit(data)
        if not np.all(np.isfinite(self.policy.theta_array)):
            raise DivergenceError(
                f"The Q-function diverged in fit {self.fits + 1} at step {self.num_timesteps}: non-finite weights. "
                f"Raise ridge (now {self.ridge}) or check the rewards' scale."
            )
        self.fits += 1
        self.fit_seconds += time.perf_counter() - start
        # the Bellman operator applied to every sample once per sweep (FQI) or policy evaluation (LSPI)
        self.sample_backups += len(data) * int(stats.get("policy_iterations", self.n_iterations))
        self._fit_stats = stats
        return stats

    def _fit(self, data: Transitions) -> dict[str, float]:
        raise NotImplementedError

    def _record_train_metrics(self) -> None:
        super()._record_train_metrics()
        self.logger.record("train/fits", self.fits)
        self.logger.record("train/fit_seconds", self.fit_seconds)
        for name, value in self._fit_stats.items():
            self.logger.record(f"train/{name}", value)

    def _watch_batch(self, targets: np.ndarray, values: np.ndarray, where: str) -> None:
        """The value watch over a sweep: every target and every fitted Q(s_d, a_d) of the database."""
        if self._watch_array.shape[0] and kernels.watch_batch(self._watch_array, targets, values):
            self._value_out_of_bounds(where)

    def _initial_values(self, indices: np.ndarray) -> np.ndarray:
        """theta_0 (the policy's initial weights, 0 by default) at the weight ``indices`` (f,)."""
        out = np.empty(indices.shape[0])
        kernels.initial_weights_at(indices, self.policy.weights, out)
        return out

    def _reset_weights(self, touched: np.ndarray, values: np.ndarray) -> None:
        """theta <- values on the touched weights and theta_0 elsewhere: Q is a function of the data alone."""
        theta = self.policy.theta_array
        low, span, _ = self.policy.initial_arguments
        if low == 0.0 and span == 0.0:
            theta.fill(0.0)
        else:
            kernels.fill_initial_weights(self.policy.weights)
        theta[touched] = values


def features_summary(features: TileFeatures) -> dict[str, Any]:
    """Sizes worth logging: touched features and the share of them seen only once.

    :param features: the touched features of a fit.
    """
    return {"features": features.n_features, "features_seen_once": float(np.mean(features.counts == 1))}

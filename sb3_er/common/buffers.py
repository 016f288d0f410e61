"""The trajectory replay buffer of experience replay (thesis Alg. 7 lines 10-12, Alg. 9 lines 10-13), and its files.

A buffer is saved as a pickle (``.pkl``, SB3's and rl-zoo's format: loading a pickle can run code from the file) or as
an ``.npz`` archive of plain arrays (read without unpickling anything). Either way every field is checked when it is
read back, before any kernel indexes with it: a corrupt or crafted file is a ValueError naming the file and the field.
"""

import io
import json
import pathlib
import pickle
import zlib
from typing import Any

import numpy as np
from stable_baselines3.common.save_util import save_to_pkl

from sb3_er.common import kernels
from sb3_er.common.atomic import write_atomically
from sb3_er.common.checks import check_choice, check_number
from sb3_er.common.tile_coding import TileCoder

#: The format of a buffer's .npz file, stored in it: arrays as .npy members, everything else in its "meta" JSON.
NPZ_FORMAT = "sb3-er trajectory replay buffer"
NPZ_VERSION = 1
ZIP_MAGIC = b"PK\x03\x04"


class _Stretch:
    """One env's open stretch while several envs step (kept apart until it closes): rows that grow by doubling."""

    def __init__(self, n_dims: int, n_tilings: int, capacity: int = 64):
        self.observations = np.zeros((capacity, n_dims), dtype=np.float64)
        self.slots = np.zeros((capacity, n_tilings), dtype=np.int64)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float64)
        self.next_observations = np.zeros((capacity, n_dims), dtype=np.float64)

    def write(self, t: int, obs, slots, action, reward, next_obs) -> None:
        """Write row t with its s_{t+1} (the caller counts it afterwards: until then nothing reads it)."""
        if t == self.actions.shape[0]:
            for name in ("observations", "slots", "actions", "rewards", "next_observations"):
                old = getattr(self, name)
                grown = np.zeros((2 * old.shape[0], *old.shape[1:]), dtype=old.dtype)
                grown[: old.shape[0]] = old
                setattr(self, name, grown)
        self.observations[t] = obs
        self.slots[t] = slots
        self.actions[t] = action
        self.rewards[t] = reward
        self.next_observations[t] = next_obs


def _counter(index: int, doc: str) -> property:
    """A property over one entry of the buffer's counters array (see TrajectoryReplayBuffer)."""

    def get(self) -> int:
        return int(self._counters[index])

    def set(self, value: int) -> None:
        self._counters[index] = value

    return property(get, set, doc=doc)


# the buffer's counters, one int64 array (see TrajectoryReplayBuffer); several envs' open stretches follow them
(N_TRAJECTORIES, N_TRANSITIONS, OPEN_LENGTH, WRITE_ROW, OLDEST_TRAJECTORY, OPEN_NEXT, N_OPEN_NEW, OPEN_COVERED) = range(
    8
)
N_COUNTERS = 8


class TrajectoryReplayBuffer:
    """Transitions (s_t, a_t, r_{t+1}) grouped in trajectories, with the tiles of s_t precomputed, and the visit vector
    w.

    Transitions live in a ring of ``capacity`` rows; consecutive rows of one trajectory are consecutive time steps, so
    s_{t+1} of a row is s_t of the next row, except for a trajectory's last row, whose s_{t+1} is kept with the
    trajectory together with whether it was terminal (``terminated``: a fall or the goal, target r) or not (a time
    limit or a segment end such as a footstep: replay bootstraps from it). When the ring is full, whole trajectories are
    evicted oldest first. ``visits`` is w of Eq. 5.1-5.2: one byte per weight, set for the features of every stored
    (s_t, a_t); eviction does not clear it (a feature once visited stays visited).

    The open trajectory (the episode in progress) also keeps the s_{t+1} of its latest transition, so that when its
    episode is cut off without an end of its own (the env reset by a new ``learn()``, ``set_env`` or ``load``; SB3's
    ``truncate_last_traj``), :meth:`truncate_open_trajectory` closes it as truncated: replay bootstraps from that real
    s_{t+1} and never joins the cut episode to the next one.

    Several envs (``n_envs`` > 1) step in turn, so their transitions arrive interleaved: each env's open stretch is
    kept apart (staged) and enters the ring whole when it closes (its episode's end, or a segment end), so that a
    stored trajectory is one stretch of one env's episode. Replay then draws from the closed trajectories; an open
    stretch is replayed once it closes. With one env the open trajectory is stored in the ring as it grows and is
    replayed with the rest (Alg. 8 line 2 draws e' from {1, ..., e}, the current episode included).

    Every change is made so that an interruption at any point (Ctrl-C, a ``KeyboardInterrupt`` between any two Python
    statements) leaves a consistent buffer that holds only transitions that happened: rows and trajectory records are
    written first and counted by a single assignment to the counters array at the end.

    A pruned database (thesis 3.5.3: "it might be beneficial to remove excess samples from the database [...] a
    pruned database with evenly distributed samples"), ``prune="coverage"``: when a trajectory closes, it is dropped
    if at least ``prune_threshold`` of its samples (s_t, a_t) were already covered by the data stored before it, all
    N features of phi(s_t, a_t) visited (W(s_t, a_t) = N, Eq. 5.1). Its own earlier samples do not count towards
    coverage, so a trajectory that lingers in new territory is kept. A dropped trajectory's transitions are never
    replayed and the features only it visited are unmarked in w. ``n_pruned_trajectories`` and
    :meth:`pruned_share` report what was dropped, :meth:`record_fill` logs it with the buffer's fill.

    :param capacity: maximum number of stored transitions.
    :param tile_coder: the policy's tile coder; w shares its weight layout.
    :param prune: None (keep every trajectory, the thesis's ER) or "coverage".
    :param prune_threshold: with ``prune="coverage"``, the share of covered samples (in (0, 1]) at which a trajectory
        is dropped; default 0.9.
    :param n_envs: the envs whose transitions arrive interleaved (default 1).
    """

    PRUNE_OPTIONS = (None, "coverage")
    DEFAULT_PRUNE_THRESHOLD = 0.9

    n_trajectories = _counter(N_TRAJECTORIES, "Closed trajectories stored.")
    n_transitions = _counter(N_TRANSITIONS, "Stored transitions in the ring, the open trajectory's included.")
    open_length = _counter(OPEN_LENGTH, "Rows of the open trajectory in the ring (one env).")
    write_row = _counter(WRITE_ROW, "The first row after the closed trajectories.")
    oldest_trajectory = _counter(OLDEST_TRAJECTORY, "The index of the oldest closed trajectory.")
    n_open_new = _counter(N_OPEN_NEW, "Pruning: features first visited by the open trajectory.")
    open_covered = _counter(OPEN_COVERED, "Pruning: the open trajectory's samples covered before it began.")

    def __init__(
        self,
        capacity: int,
        tile_coder: TileCoder,
        prune: str | None = None,
        prune_threshold: float = DEFAULT_PRUNE_THRESHOLD,
        n_envs: int = 1,
    ):
        if isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1:
            raise ValueError(f"buffer_size must be an integer of at least 1, got {capacity!r}")
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs must be an integer of at least 1, got {n_envs!r}")
        self.check_kwargs({"prune": prune, "prune_threshold": prune_threshold})
        self.capacity = int(capacity)
        self.tile_coder = tile_coder
        self.prune = prune
        self.prune_threshold = float(prune_threshold)
        n_tilings, n_dims = tile_coder.n_tilings, tile_coder.n_dims
        self.observations = np.zeros((self.capacity, n_dims), dtype=np.float64)
        self.slots = np.zeros((self.capacity, n_tilings), dtype=np.int64)
        self.actions = np.zeros(self.capacity, dtype=np.int64)
        self.rewards = np.zeros(self.capacity, dtype=np.float64)
        self.transition_trajectory = np.zeros(self.capacity, dtype=np.int64)
        self.trajectory_start = np.zeros(self.capacity, dtype=np.int64)
        self.trajectory_length = np.zeros(self.capacity, dtype=np.int64)
        self.trajectory_terminated = np.zeros(self.capacity, dtype=np.bool_)
        self.trajectory_next_obs = np.zeros((self.capacity, n_dims), dtype=np.float64)
        self.trajectory_next_slots = np.zeros((self.capacity, n_tilings), dtype=np.int64)
        # the open trajectory's latest s_{t+1} in one of two rows, the counters naming which (written, then counted)
        self._open_next = np.zeros((2, n_dims), dtype=np.float64)
        self.open_next_slots = np.zeros(n_tilings, dtype=np.int64)
        self.visits = np.zeros(tile_coder.n_weights, dtype=np.uint8)
        self.n_envs = int(n_envs)
        self._counters = np.zeros(N_COUNTERS + (self.n_envs if self.n_envs > 1 else 0), dtype=np.int64)
        self._stretches = [_Stretch(n_dims, n_tilings) for _ in range(self.n_envs)] if self.n_envs > 1 else []
        # the pruned database: features first visited by the open trajectory, and how many of its samples were covered
        self.fresh = np.zeros(tile_coder.n_weights, dtype=np.uint8) if prune else np.zeros(0, dtype=np.uint8)
        self.open_new_features = np.zeros(16 * tile_coder.n_tilings if prune else 0, dtype=np.int64)
        # The token of the value watch that has read this buffer's stored rewards (ValueWatch.token); None: none has.
        # Not saved: a loaded buffer is read again by the watch it meets.
        self.observed_by_watch: str | None = None
        self.n_closed_total = 0
        self.n_pruned_trajectories = 0
        self.n_pruned_transitions = 0

    @staticmethod
    def check_kwargs(kwargs: dict[str, Any] | None) -> None:
        """ValueError for keyword arguments that this buffer does not take or whose values are out of range.

        :param kwargs: the keyword arguments meant for the buffer (``replay_buffer_kwargs``); None is none.
        """
        kwargs = dict(kwargs or {})
        unknown = sorted(set(kwargs) - {"prune", "prune_threshold"})
        if unknown:
            raise ValueError(
                f"replay_buffer_kwargs: unknown {unknown}; the trajectory buffer takes prune and prune_threshold"
            )
        check_choice("prune", kwargs.get("prune"), TrajectoryReplayBuffer.PRUNE_OPTIONS)
        check_number(
            "prune_threshold (a share)",
            kwargs.get("prune_threshold", TrajectoryReplayBuffer.DEFAULT_PRUNE_THRESHOLD),
            0.0,
            1.0,
            low_open=True,
        )

    def pruned_share(self) -> float:
        """The share of closed trajectories that pruning dropped (0 before any closed)."""
        return self.n_pruned_trajectories / self.n_closed_total if self.n_closed_total else 0.0

    def record_fill(self, logger) -> None:
        """Log the buffer's fill (stored transitions / capacity) and, when pruning, the pruned share of trajectories
        and of transitions as ``train/buffer_fill``, ``train/pruned_share`` and ``train/pruned_transitions_share``.

        :param logger: the SB3 logger to record to.
        """
        logger.record("train/buffer_fill", self.n_transitions / self.capacity)
        if self.prune:
            logger.record("train/pruned_share", self.pruned_share())
            seen = self.n_pruned_transitions + self.n_closed_transitions
            logger.record("train/pruned_transitions_share", self.n_pruned_transitions / seen if seen else 0.0)

    @property
    def open_next_obs(self) -> np.ndarray:
        """The open trajectory's latest s_{t+1} (one env), (D,)."""
        return self._open_next[self._counters[OPEN_NEXT]]

    @property
    def n_closed_transitions(self) -> int:
        return self.n_transitions - self.open_length

    @property
    def n_stored_trajectories(self) -> int:
        """Closed trajectories, plus the open one when it holds transitions (replay draws from all of them)."""
        return self.n_trajectories + (1 if self.open_length else 0)

    @property
    def open_trajectory(self) -> int:
        return (self.oldest_trajectory + self.n_trajectories) % self.capacity

    def staged_length(self, env: int) -> int:
        """The transitions of env ``env``'s open stretch not yet in the ring (several envs; 0 with one env).

        :param env: the env's index.
        """
        return int(self._counters[N_COUNTERS + env]) if self.n_envs > 1 else 0

    def add(
        self,
        obs: np.ndarray,
        slots: np.ndarray,
        action: int,
        reward: float,
        next_obs: np.ndarray,
        env: int = 0,
        end: bool | None = None,
    ) -> bool:
        """Append (s_t, a_t, r_{t+1}) to env ``env``'s open trajectory, remember s_{t+1} and mark phi(s_t, a_t) as
        visited (Eq. 5.2); with ``end`` given, the trajectory then closes at s_{t+1} (:meth:`close_trajectory`), both
        counted at once. Returns whether a trajectory was closed and kept (not pruned).

        :param obs: the state s_t, in the observation space's shape.
        :param slots: its tile slots, (N,) for N tilings.
        :param action: the flat action index a_t.
        :param reward: the reward r_{t+1}.
        :param next_obs: the next state s_{t+1}.
        :param env: the env it came from (default 0).
        :param end: None (default) to keep the trajectory open; else whether s_{t+1} is terminal, closing it there.
        """
        if self.n_envs > 1:
            stretch, index = self._stretches[env], N_COUNTERS + env
            length = int(self._counters[index])
            stretch.write(length, obs, slots, action, reward, next_obs)
            if end is None:
                self._counters[index] = length + 1  # counted
                return False
            return self._commit_stretch(env, next_obs, end, length + 1)  # counted and stored at once
        counts = self._counters.tolist()  # Python ints: read and written a dozen times per step, where numpy's cost
        if counts[N_TRANSITIONS] == self.capacity:
            counts = self._evict_oldest_trajectory().tolist()
        p = (counts[WRITE_ROW] + counts[OPEN_LENGTH]) % self.capacity
        self.observations[p] = obs
        self.slots[p] = slots
        self.actions[p] = action
        self.rewards[p] = reward
        self.transition_trajectory[p] = (counts[OLDEST_TRAJECTORY] + counts[N_TRAJECTORIES]) % self.capacity
        spare = 1 - counts[OPEN_NEXT]
        self._open_next[spare] = next_obs
        if self.prune:
            self._mark(slots, action, counts)
        else:  # _mark's common case, without its call
            coder = self.tile_coder
            kernels.mark_visited(self.visits, slots, coder.stride, coder.action_columns, action)
        counts[OPEN_LENGTH] += 1
        counts[N_TRANSITIONS] += 1
        counts[OPEN_NEXT] = spare
        kept = False
        if end is not None:
            kept = self._close(counts, next_obs, end)
        self._counters[:] = counts  # counted: the transition (and the close) all at once
        return kept

    def _mark(self, slots: np.ndarray, action: int, counts: np.ndarray | list[int]) -> None:
        """w <- w OR phi(s_t, a_t); with pruning, also track the open trajectory's new features and coverage in
        ``counts`` (committed with the transition)."""
        coder = self.tile_coder
        if not self.prune:
            kernels.mark_visited(self.visits, slots, coder.stride, coder.action_columns, action)
            return
        if counts[N_OPEN_NEW] + coder.n_tilings > self.open_new_features.shape[0]:
            self.open_new_features = np.concatenate([self.open_new_features, np.zeros_like(self.open_new_features)])
        n_new, covered = kernels.mark_visited_tracked(
            self.visits,
            self.fresh,
            slots,
            coder.stride,
            coder.action_columns,
            action,
            self.open_new_features,
            int(counts[N_OPEN_NEW]),
        )
        counts[N_OPEN_NEW] = n_new
        counts[OPEN_COVERED] += covered

    def close_trajectory(self, next_obs: np.ndarray, terminated: bool, env: int = 0) -> bool:
        """End env ``env``'s open trajectory at s_{t+1} = next_obs; returns False if it was empty or pruning dropped
        it.

        :param next_obs: the trajectory's last next state s_{t+1}.
        :param terminated: whether it ended in a terminal state (no bootstrap from it) rather than truncated.
        :param env: the env whose trajectory closes (default 0).
        """
        if self.n_envs > 1:
            return self._commit_stretch(env, next_obs, terminated)
        counts = self._counters.copy()
        kept = self._close(counts, next_obs, terminated)
        self._counters[:] = counts
        return kept

    def _close(self, counts: np.ndarray | list[int], next_obs: np.ndarray, terminated: bool) -> bool:
        """Close the open trajectory in ``counts`` (the caller commits them): its record is written first, in the
        trajectory slot after the closed ones, which no count covers yet."""
        open_length = int(counts[OPEN_LENGTH])
        if open_length == 0:
            return False
        if self.prune:
            self.n_closed_total += 1
            new = self.open_new_features[: counts[N_OPEN_NEW]]
            self.fresh[new] = 0
            dropped = counts[OPEN_COVERED] >= self.prune_threshold * open_length
            counts[N_OPEN_NEW] = counts[OPEN_COVERED] = 0
            if dropped:  # its rows are overwritten by the next trajectory; only it visited its new features
                self.visits[new] = 0
                self.n_pruned_trajectories += 1
                self.n_pruned_transitions += open_length
                counts[N_TRANSITIONS] -= open_length
                counts[OPEN_LENGTH] = 0
                return False
        j = (counts[OLDEST_TRAJECTORY] + counts[N_TRAJECTORIES]) % self.capacity
        self.trajectory_start[j] = counts[WRITE_ROW]
        self.trajectory_length[j] = open_length
        self.trajectory_terminated[j] = terminated
        self.trajectory_next_obs[j] = next_obs
        self.trajectory_next_slots[j] = self.tile_coder.slots(next_obs)
        counts[N_TRAJECTORIES] += 1
        counts[WRITE_ROW] = (counts[WRITE_ROW] + open_length) % self.capacity
        counts[OPEN_LENGTH] = 0
        return True

    def _commit_stretch(self, env: int, next_obs: np.ndarray, terminated: bool, length: int | None = None) -> bool:
        """Several envs: env ``env``'s staged stretch enters the ring whole (its features marked visited in w then)
        and closes there. Room is made first (each eviction committed on its own); then its rows are written and the
        ring's counters and the stretch's length committed in one assignment, so an interruption leaves the stretch
        either staged or stored, never both."""
        index = N_COUNTERS + env
        length = int(self._counters[index]) if length is None else length
        if length == 0:
            return False
        if length > self.capacity:
            raise ValueError(
                f"A single trajectory ({length} transitions) is longer than buffer_size={self.capacity}; increase "
                "buffer_size or close trajectories more often (episode ends, info['segment_end'])"
            )
        while self.n_transitions + length > self.capacity:
            self._evict_oldest_trajectory()
        stretch = self._stretches[env]
        counts = self._counters.copy()
        for t in range(length):
            p = (counts[WRITE_ROW] + counts[OPEN_LENGTH]) % self.capacity
            self.observations[p] = stretch.observations[t]
            self.slots[p] = stretch.slots[t]
            self.actions[p] = stretch.actions[t]
            self.rewards[p] = stretch.rewards[t]
            self.transition_trajectory[p] = (counts[OLDEST_TRAJECTORY] + counts[N_TRAJECTORIES]) % self.capacity
            self._mark(stretch.slots[t], int(stretch.actions[t]), counts)
            counts[OPEN_LENGTH] += 1
            counts[N_TRANSITIONS] += 1
        kept = self._close(counts, next_obs, terminated)
        counts[index] = 0
        self._counters[:] = counts
        return kept

    def truncate_open_trajectory(self) -> bool:
        """Close every open trajectory as truncated at its latest s_{t+1} (its episode was cut off); False if all
        were empty."""
        if self.n_envs > 1:
            closed = []
            for env, stretch in enumerate(self._stretches):
                length = self.staged_length(env)
                if length:
                    closed.append(self._commit_stretch(env, stretch.next_observations[length - 1].copy(), False))
            return any(closed)
        return self.close_trajectory(self.open_next_obs.copy(), terminated=False)

    def set_n_envs(self, n_envs: int) -> None:
        """Take transitions from ``n_envs`` envs from now on; every open trajectory is first closed as truncated.

        :param n_envs: the number of envs.
        """
        if n_envs == self.n_envs:
            return
        self.truncate_open_trajectory()
        n_dims, n_tilings = self.tile_coder.n_dims, self.tile_coder.n_tilings
        counters = np.zeros(N_COUNTERS + (n_envs if n_envs > 1 else 0), dtype=np.int64)
        counters[:N_COUNTERS] = self._counters[:N_COUNTERS]
        self._stretches = [_Stretch(n_dims, n_tilings) for _ in range(n_envs)] if n_envs > 1 else []
        self.n_envs = int(n_envs)
        self._counters = counters

    def _evict_oldest_trajectory(self) -> np.ndarray:
        """Drop the oldest closed trajectory, committed at once; returns the new counters."""
        if self.n_trajectories == 0:
            raise ValueError(
                f"A single trajectory is longer than buffer_size={self.capacity}; increase buffer_size or close "
                "trajectories more often (episode ends, info['segment_end'])"
            )
        counts = self._counters.copy()
        j = counts[OLDEST_TRAJECTORY]
        counts[N_TRANSITIONS] -= self.trajectory_length[j]
        counts[OLDEST_TRAJECTORY] = (j + 1) % self.capacity
        counts[N_TRAJECTORIES] -= 1
        self._counters[:] = counts
        return counts

    def replay_data(self) -> kernels.Trajectories:
        """The stored data as the replay kernels read it (a :class:`~sb3_er.common.kernels.bundles.Trajectories`),
        the open trajectory included: its latest s_{t+1} is tiled here."""
        if self.open_length:
            self.open_next_slots[:] = self.tile_coder.slots(self.open_next_obs)
        first_row = self._oldest_row()
        return kernels.make(
            kernels.Trajectories,
            visits=self.visits,
            slots=self.slots,
            actions=self.actions,
            rewards=self.rewards,
            transition_trajectory=self.transition_trajectory,
            trajectory_start=self.trajectory_start,
            trajectory_length=self.trajectory_length,
            trajectory_terminated=self.trajectory_terminated,
            trajectory_next_slots=self.trajectory_next_slots,
            oldest_trajectory=self.oldest_trajectory,
            n_closed_trajectories=self.n_trajectories,
            first_row=first_row,
            n_transitions=self.n_transitions,
            open_trajectory=self.open_trajectory,
            open_start=(first_row + self.n_transitions - self.open_length) % self.capacity,
            open_length=self.open_length,
            open_next_slots=self.open_next_slots,
        )

    def stored_rewards(self) -> tuple[np.ndarray, np.ndarray]:
        """The rewards of every stored transition, the open trajectory's included, and whether each ended its
        episode with a termination (the last transition of a terminated trajectory): what the learner replays."""
        rows = (self._oldest_row() + np.arange(self.n_transitions)) % self.capacity
        terminal = np.zeros(rows.shape[0], dtype=bool)
        trajectories = (self.oldest_trajectory + np.arange(self.n_trajectories)) % self.capacity
        ends = (self.trajectory_start[trajectories] + self.trajectory_length[trajectories] - 1) % self.capacity
        ends = ends[self.trajectory_terminated[trajectories]]
        terminal[(ends - self._oldest_row()) % self.capacity] = True
        return self.rewards[rows], terminal

    def trajectories(self) -> list[dict[str, Any]]:
        """The closed trajectories, oldest first, as dicts of arrays (observations, actions, rewards, next_obs, ...)."""
        result = []
        for i in range(self.n_trajectories):
            j = (self.oldest_trajectory + i) % self.capacity
            rows = (self.trajectory_start[j] + np.arange(self.trajectory_length[j])) % self.capacity
            result.append(
                {
                    "observations": self.observations[rows].copy(),
                    "actions": self.actions[rows].copy(),
                    "rewards": self.rewards[rows].copy(),
                    "next_obs": self.trajectory_next_obs[j].copy(),
                    "terminated": bool(self.trajectory_terminated[j]),
                }
            )
        return result

    def __getstate__(self) -> dict[str, Any]:
        """Only the stored rows, oldest first, so a large empty buffer saves small; each field with its checksum."""
        rows = (self._oldest_row() + np.arange(self.n_transitions)) % self.capacity
        trajectories = (self.oldest_trajectory + np.arange(self.n_trajectories)) % self.capacity
        starts = (self.trajectory_start[trajectories] - self._oldest_row()) % self.capacity
        state = {
            "capacity": self.capacity,
            "tile_coder_config": self.tile_coder.config(),
            "observations": self.observations[rows],
            "slots": self.slots[rows],
            "actions": self.actions[rows],
            "rewards": self.rewards[rows],
            "trajectory_start": starts,
            "trajectory_length": self.trajectory_length[trajectories],
            "trajectory_terminated": self.trajectory_terminated[trajectories],
            "trajectory_next_obs": self.trajectory_next_obs[trajectories],
            "trajectory_next_slots": self.trajectory_next_slots[trajectories],
            "open_length": self.open_length,
            "open_next_obs": self.open_next_obs,
            "visits": self.visits,
            "prune": self.prune,
            "prune_threshold": self.prune_threshold,
            "open_new_features": self.open_new_features[: self.n_open_new].copy(),
            "open_covered": self.open_covered,
            "pruned": (self.n_closed_total, self.n_pruned_trajectories, self.n_pruned_transitions),
        }
        if self.n_envs > 1:  # each env's open stretch, staged outside the ring
            lengths = np.array([self.staged_length(env) for env in range(self.n_envs)], dtype=np.int64)
            state["n_envs"] = self.n_envs
            state["stretch_lengths"] = lengths
            for name in ("observations", "slots", "actions", "rewards"):
                state[f"stretch_{name}"] = np.concatenate(
                    [getattr(stretch, name)[:length] for stretch, length in zip(self._stretches, lengths, strict=True)]
                )
            state["stretch_next_observations"] = np.concatenate(
                [stretch.next_observations[:length] for stretch, length in zip(self._stretches, lengths, strict=True)]
            )
        state["checksums"] = {name: field_checksum(value) for name, value in state.items()}
        return state

    def _oldest_row(self) -> int:
        if self.n_trajectories > 0:
            return int(self.trajectory_start[self.oldest_trajectory])
        return self.write_row

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore a saved state after checking every field (see ``check_state``): a corrupt or crafted state is a
        ValueError naming the field, never an index out of range inside a kernel."""
        check_state(state)
        self.__init__(
            int(state["capacity"]),
            TileCoder(**state["tile_coder_config"]),
            state.get("prune"),
            state.get("prune_threshold", self.DEFAULT_PRUNE_THRESHOLD),
            int(state.get("n_envs", 1)),
        )
        if self.prune:
            new = state["open_new_features"]
            self.open_new_features = np.zeros(max(new.shape[0] * 2, 16 * self.tile_coder.n_tilings), dtype=np.int64)
            self.open_new_features[: new.shape[0]] = new
            self.n_open_new = new.shape[0]
            self.fresh[new] = 1
            self.open_covered = int(state["open_covered"])
            self.n_closed_total, self.n_pruned_trajectories, self.n_pruned_transitions = map(int, state["pruned"])
        n, m, open_length = len(state["actions"]), len(state["trajectory_length"]), int(state["open_length"])
        for name in ("observations", "slots", "actions", "rewards"):
            getattr(self, name)[:n] = state[name]
        for name in (
            "trajectory_start",
            "trajectory_length",
            "trajectory_terminated",
            "trajectory_next_obs",
            "trajectory_next_slots",
        ):
            getattr(self, name)[:m] = state[name]
        for j in range(m):
            rows = self.trajectory_start[j] + np.arange(self.trajectory_length[j])
            self.transition_trajectory[rows] = j
        self.transition_trajectory[n - open_length : n] = m
        self.visits[:] = state["visits"]
        self.n_trajectories, self.n_transitions, self.open_length = m, n, open_length
        if "open_next_obs" in state:
            self.open_next_obs[:] = state["open_next_obs"]
        else:  # saved before the open trajectory kept its s_{t+1}: it cannot be closed, so drop it
            self.n_transitions, self.open_length = n - open_length, 0
        self.write_row = (n - open_length) % self.capacity
        if self.n_envs > 1:
            first = 0
            for env, length in enumerate(state["stretch_lengths"]):
                stretch = self._stretches[env]
                for t in range(first, first + int(length)):
                    stretch.write(
                        t - first,
                        state["stretch_observations"][t],
                        state["stretch_slots"][t],
                        state["stretch_actions"][t],
                        state["stretch_rewards"][t],
                        state["stretch_next_observations"][t],
                    )
                self._counters[N_COUNTERS + env] = length
                first += int(length)


# --- checking a saved state ------------------------------------------------------------------------------------------


def field_checksum(value: Any) -> int:
    """CRC-32 of one saved field: an array's dtype, shape and bytes, or any other value's JSON form.

    :param value: the field: a NumPy array or a JSON-able value.
    """
    if isinstance(value, np.ndarray):
        header = f"{value.dtype.str}{value.shape}".encode()
        return zlib.crc32(np.ascontiguousarray(value).tobytes(), zlib.crc32(header))
    return zlib.crc32(json.dumps(value, sort_keys=True).encode())


def _field_error(name: str, problem: str) -> ValueError:
    return ValueError(f"replay buffer field {name!r}: {problem}")


def _array(state: dict[str, Any], name: str, dtype, shape: tuple) -> np.ndarray:
    """The array ``state[name]`` of exactly this dtype and shape (None: any length)."""
    if name not in state:
        raise _field_error(name, "missing")
    value = state[name]
    if not isinstance(value, np.ndarray):
        raise _field_error(name, f"expected an array, got {type(value).__name__}")
    if value.dtype != np.dtype(dtype):
        raise _field_error(name, f"expected dtype {np.dtype(dtype)}, got {value.dtype}")
    if value.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(value.shape, shape, strict=True)
    ):
        expected = tuple("n" if want is None else want for want in shape)
        raise _field_error(name, f"expected shape {expected}, got {value.shape}")
    return value


def _in_range(name: str, values: np.ndarray, stop: int, what: str) -> None:
    if values.size and (values.min() < 0 or values.max() >= stop):
        bad = np.flatnonzero((values < 0) | (values >= stop))[0]
        raise _field_error(
            name,
            f"entry {np.unravel_index(bad, values.shape)} = {values.reshape(-1)[bad]} is outside [0, {stop}), {what}",
        )


def _integer(state: dict[str, Any], name: str, minimum: int, maximum: int | None = None) -> int:
    if name not in state:
        raise _field_error(name, "missing")
    value = state[name]
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, np.integer))
        or value < minimum
        or (maximum is not None and value > maximum)
    ):
        bound = f"in [{minimum}, {maximum}]" if maximum is not None else f"at least {minimum}"
        raise _field_error(name, f"expected an integer {bound}, got {value!r}")
    return int(value)


def _finite(name: str, values: np.ndarray) -> None:
    if not np.all(np.isfinite(values)):
        raise _field_error(name, f"non-finite values at {np.argwhere(~np.isfinite(values))[:3].tolist()}")


def _tiles_match(name: str, slots_name: str, observations: np.ndarray, slots: np.ndarray, coder: TileCoder) -> None:
    """The stored tiles are the tiles of the stored observations (either one altered shows here)."""
    expected = np.empty_like(slots)
    if not kernels.batch_state_slots(observations, coder.layout, expected):
        raise _field_error(name, "observations too large to tile")
    mismatch = np.flatnonzero(np.any(expected != slots, axis=1))
    if mismatch.size:
        raise _field_error(
            slots_name,
            f"row {mismatch[0]} does not hold the tiles of its observation in {name!r} ({mismatch.size} such rows)",
        )


def check_state(state: Any) -> None:
    """Check a saved buffer state field by field: the checksums where saved, dtypes, shapes, index ranges (tile slots,
    actions, visited features), trajectory starts and lengths against the stored rows, and the stored tiles against
    the stored observations. ValueError naming the first bad field. Runs once, where a buffer is restored.

    :param state: the buffer's state as read from the file (a dict of fields).
    """
    if not isinstance(state, dict):
        raise ValueError(f"a replay buffer state must be a dict of fields, got {type(state).__name__}")
    checksums = state.get("checksums")
    if checksums is not None:
        if not isinstance(checksums, dict):
            raise _field_error("checksums", f"expected a dict, got {type(checksums).__name__}")
        for name in sorted(set(checksums) - set(state)):
            raise _field_error(name, "missing (its checksum is stored)")
        for name, value in state.items():
            try:
                intact = name == "checksums" or checksums.get(name) == field_checksum(value)
            except (TypeError, ValueError):  # a value without a JSON form was never saved by this package
                intact = False
            if not intact:
                raise _field_error(name, "does not match its checksum: the file is corrupt")
    capacity = _integer(state, "capacity", 1)
    config = state.get("tile_coder_config")
    expected_keys = set(TileCoder([1.0], [1]).config())
    if not isinstance(config, dict) or set(config) != expected_keys:
        raise _field_error("tile_coder_config", f"expected a dict with keys {sorted(expected_keys)}, got {config!r}")
    try:
        coder = TileCoder(**config)
    except (ValueError, TypeError) as error:
        raise _field_error("tile_coder_config", str(error)) from None
    n_dims, n_tilings = coder.n_dims, coder.n_tilings
    observations = _array(state, "observations", np.float64, (None, n_dims))
    n = observations.shape[0]
    if n > capacity:
        raise _field_error("observations", f"{n} rows in a buffer of capacity {capacity}")
    _finite("observations", observations)
    slots = _array(state, "slots", np.int64, (n, n_tilings))
    _in_range("slots", slots, coder.n_slots, "the tile coding's slots")
    _tiles_match("observations", "slots", observations, slots, coder)
    actions = _array(state, "actions", np.int64, (n,))
    _in_range("actions", actions, coder.n_actions, "the flat action indices")
    _finite("rewards", _array(state, "rewards", np.float64, (n,)))

    lengths = _array(state, "trajectory_length", np.int64, (None,))
    m = lengths.shape[0]
    if m and lengths.min() < 1:
        raise _field_error("trajectory_length", f"trajectory {int(np.argmin(lengths))} has length {lengths.min()}")
    open_length = _integer(state, "open_length", 0, n)
    if int(lengths.sum()) + open_length != n:
        raise _field_error(
            "trajectory_length",
            f"lengths sum to {int(lengths.sum())} plus {open_length} open rows, but {n} rows are stored",
        )
    starts = _array(state, "trajectory_start", np.int64, (m,))
    expected_starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]) if m else starts
    if not np.array_equal(starts, expected_starts):
        bad = int(np.flatnonzero(starts != expected_starts)[0])
        raise _field_error(
            "trajectory_start",
            f"trajectory {bad} starts at row {starts[bad]}, but the rows before it end at {expected_starts[bad]}",
        )
    _array(state, "trajectory_terminated", np.bool_, (m,))
    next_obs = _array(state, "trajectory_next_obs", np.float64, (m, n_dims))
    _finite("trajectory_next_obs", next_obs)
    next_slots = _array(state, "trajectory_next_slots", np.int64, (m, n_tilings))
    _in_range("trajectory_next_slots", next_slots, coder.n_slots, "the tile coding's slots")
    _tiles_match("trajectory_next_obs", "trajectory_next_slots", next_obs, next_slots, coder)
    if "open_next_obs" in state:
        open_next_obs = _array(state, "open_next_obs", np.float64, (n_dims,))
        if open_length:
            _finite("open_next_obs", open_next_obs)

    if "n_envs" in state:
        n_envs = _integer(state, "n_envs", 2)
        lengths = _array(state, "stretch_lengths", np.int64, (n_envs,))
        if lengths.min() < 0:
            raise _field_error("stretch_lengths", f"a negative length {lengths.min()}")
        staged = int(lengths.sum())
        stretch_observations = _array(state, "stretch_observations", np.float64, (staged, n_dims))
        _finite("stretch_observations", stretch_observations)
        stretch_slots = _array(state, "stretch_slots", np.int64, (staged, n_tilings))
        _in_range("stretch_slots", stretch_slots, coder.n_slots, "the tile coding's slots")
        _tiles_match("stretch_observations", "stretch_slots", stretch_observations, stretch_slots, coder)
        _in_range(
            "stretch_actions",
            _array(state, "stretch_actions", np.int64, (staged,)),
            coder.n_actions,
            "the flat action indices",
        )
        _finite("stretch_rewards", _array(state, "stretch_rewards", np.float64, (staged,)))
        _finite("stretch_next_observations", _array(state, "stretch_next_observations", np.float64, (staged, n_dims)))
        if open_length:
            raise _field_error("open_length", "several envs keep no open trajectory in the ring")

    visits = _array(state, "visits", np.uint8, (coder.n_weights,))
    if visits.size and visits.max() > 1:
        raise _field_error("visits", f"w is 0 or 1 per weight, got {visits.max()} at {int(np.argmax(visits))}")
    stored = slots * coder.stride + coder.action_columns[np.arange(n_tilings)[None, :], actions[:, None]]
    if n and not visits[stored].all():
        raise _field_error("visits", "features of stored samples are marked unvisited")

    prune, threshold = state.get("prune"), state.get("prune_threshold", TrajectoryReplayBuffer.DEFAULT_PRUNE_THRESHOLD)
    try:
        TrajectoryReplayBuffer.check_kwargs({"prune": prune, "prune_threshold": threshold})
    except ValueError as error:
        raise _field_error(
            "prune" if prune not in TrajectoryReplayBuffer.PRUNE_OPTIONS else "prune_threshold", str(error)
        ) from None
    if prune:
        new = _array(state, "open_new_features", np.int64, (None,))
        _in_range("open_new_features", new, coder.n_weights, "the weight indices")
        _integer(state, "open_covered", 0, open_length)
        pruned = state.get("pruned")
        if not (isinstance(pruned, (tuple, list)) and len(pruned) == 3):
            raise _field_error("pruned", f"expected (closed, pruned trajectories, pruned transitions), got {pruned!r}")
        closed, pruned_trajectories, _ = (_integer({"pruned": v}, "pruned", 0) for v in pruned)
        if pruned_trajectories > closed:
            raise _field_error("pruned", f"{pruned_trajectories} pruned of {closed} closed trajectories")


# --- files -----------------------------------------------------------------------------------------------------------


def _npz_bytes(state: dict[str, Any]) -> bytes:
    arrays = {name: value for name, value in state.items() if isinstance(value, np.ndarray)}
    meta = {name: value for name, value in state.items() if not isinstance(value, np.ndarray)}
    meta = {"format": NPZ_FORMAT, "version": NPZ_VERSION, **meta}
    out = io.BytesIO()
    np.savez(out, meta=np.array(json.dumps(meta)), **arrays)
    return out.getvalue()


def _state_from_npz(data: bytes) -> dict[str, Any]:
    """The state stored in an .npz buffer file, read with ``allow_pickle=False``; ValueError naming a bad member."""
    try:
        archive = np.load(io.BytesIO(data), allow_pickle=False)
    except Exception as error:  # a truncated or altered archive fails in zipfile or numpy with many error types
        raise ValueError(f"not a readable .npz archive ({type(error).__name__}: {error})") from None
    state: dict[str, Any] = {}
    with archive:
        for name in archive.files:
            try:
                state[name] = archive[name]
            except Exception as error:
                raise _field_error(name, f"unreadable ({type(error).__name__}: {error})") from None
    meta_array = state.pop("meta", None)
    if meta_array is None or meta_array.dtype.kind != "U" or meta_array.ndim != 0:
        raise _field_error("meta", "missing or not a JSON string")
    try:
        meta = json.loads(str(meta_array))
    except ValueError as error:
        raise _field_error("meta", f"not JSON ({error})") from None
    if not isinstance(meta, dict) or meta.pop("format", None) != NPZ_FORMAT or meta.pop("version", None) != NPZ_VERSION:
        raise _field_error("meta", f"not a version-{NPZ_VERSION} {NPZ_FORMAT} file")
    overlap = sorted(set(meta) & set(state))
    if overlap:
        raise _field_error(overlap[0], "stored twice")
    state.update(meta)
    return state


def _resolve_read_path(path: pathlib.Path) -> pathlib.Path:
    """SB3's convention: a path without suffix that does not exist is tried with .pkl (and here .npz)."""
    if path.exists() or path.suffix:
        return path
    for suffix in (".pkl", ".npz"):
        candidate = path.with_name(path.name + suffix)
        if candidate.exists():
            return candidate
    return path


def save_buffer(buffer: TrajectoryReplayBuffer, path: str | pathlib.Path | io.BufferedIOBase, verbose: int = 0) -> None:
    """Write ``buffer`` to ``path``: an .npz archive of plain arrays if the path ends in .npz, else a pickle (SB3's
    format; ``.pkl`` is added to a path without suffix). A path is written atomically (a partial file, then renamed).

    :param buffer: the buffer to save.
    :param path: the file (.npz for plain arrays, else a pickle), or an open binary file.
    :param verbose: verbosity passed to SB3's ``save_to_pkl`` (default 0: silent).
    """
    if not isinstance(path, (str, pathlib.Path)):
        save_to_pkl(path, buffer, verbose)
        return
    path = pathlib.Path(path)
    if not path.suffix:
        path = path.with_suffix(".pkl")
    path.parent.mkdir(parents=True, exist_ok=True)
    data = _npz_bytes(buffer.__getstate__()) if path.suffix == ".npz" else pickle.dumps(buffer, pickle.HIGHEST_PROTOCOL)
    write_atomically(path, data)


def load_buffer(
    path: str | pathlib.Path | io.BufferedIOBase, tile_coder: TileCoder, allow_pickle: bool = True
) -> TrajectoryReplayBuffer:
    """Read a buffer written by ``save_buffer`` and check it against ``tile_coder``; ValueError naming the file and
    the field for anything corrupt, truncated, crafted or of another tile coding.

    An .npz file is read without unpickling; a file whose name ends in .npz is never unpickled. A pickle is unpickled
    only with ``allow_pickle`` (the default, as in SB3): unpickling a crafted file runs code from it, before any check.

    :param path: the file written by ``save_buffer``, or an open binary file.
    :param tile_coder: the tile coder the buffer's stored tiles must match.
    :param allow_pickle: unpickle a pickle file (default True, as SB3).
    """
    if isinstance(path, (str, pathlib.Path)):
        path = _resolve_read_path(pathlib.Path(path))
        with open(path, "rb") as stream:
            data = stream.read()
        is_npz_name = path.suffix == ".npz"
    else:
        data, is_npz_name = path.read(), False
    try:
        if data.startswith(ZIP_MAGIC):
            buffer = TrajectoryReplayBuffer.__new__(TrajectoryReplayBuffer)
            buffer.__setstate__(_state_from_npz(data))
        elif is_npz_name:
            raise ValueError("not an .npz archive (a file named .npz is never unpickled)")
        elif not allow_pickle:
            raise ValueError(
                "a pickle, refused with allow_pickle=False (unpickling can run code from the file); "
                "save buffers as .npz to load them without pickle"
            )
        else:
            try:
                buffer = pickle.loads(data)
            except ValueError:
                raise
            except Exception as error:  # truncated or altered pickles fail with many error types
                raise ValueError(f"not a readable pickle ({type(error).__name__}: {error})") from None
            if not isinstance(buffer, TrajectoryReplayBuffer):
                raise ValueError(f"holds a {type(buffer).__name__}, not a TrajectoryReplayBuffer")
        if buffer.tile_coder.config() != tile_coder.config():
            raise ValueError(
                "the replay buffer was stored with a different tile coding than this model's "
                f"({buffer.tile_coder!r}, the model's {tile_coder!r})"
            )
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from error.__cause__
    buffer.tile_coder = tile_coder
    return buffer


class TrajectoryBufferIO:
    """``save_replay_buffer`` and ``load_replay_buffer`` of the algorithms that keep a ``TrajectoryReplayBuffer``
    (ER and its presets, Dyna, FQI, LSPI); a mixin before TileQAlgorithm."""

    replay_buffer: TrajectoryReplayBuffer | None

    def save_replay_buffer(self, path: str | pathlib.Path | io.BufferedIOBase) -> None:
        """Save the trajectories and the visit vector w: an .npz archive of plain arrays if ``path`` ends in .npz
        (loadable without unpickling), else a pickle (SB3's format). Paths are taken as SB3 takes them, with its
        warnings: .pkl added to a path without suffix, a missing folder created, a folder's name turned into
        ``<name>_2``, and at ``verbose >= 2`` an existing file reported.

        :param path: the file (.npz for plain arrays, else a pickle), or an open binary file.
        """
        from sb3_er.common.serialization import sb3_write_path

        if isinstance(path, (str, pathlib.Path)):
            path = sb3_write_path(path, "pkl", self.verbose)
        save_buffer(self.replay_buffer, path, self.verbose)

    def load_replay_buffer(
        self,
        path: str | pathlib.Path | io.BufferedIOBase,
        truncate_last_traj: bool = True,
        allow_pickle: bool = True,
    ) -> None:
        """Load a buffer saved by save_replay_buffer (of any algorithm of this package); its tile coding must match.
        Every field is checked first; a bad file is a ValueError naming it and the field, and the model keeps its
        previous buffer.

        :param truncate_last_traj: as in SB3: if True (the default, which rl-zoo always passes), the episode that was
            in progress when the buffer was saved is over: its open trajectory is closed as truncated at its last
            s_{t+1}, with the warning SB3's HerReplayBuffer gives then. If False, it stays open, to be continued by
            ``learn(reset_num_timesteps=False)`` on an env that was not reset since; any env reset (a ``learn()`` that
            resets, ``set_env``, a freshly loaded model) closes it as truncated all the same, so it is never joined
            to another episode.
        :param allow_pickle: unpickle .pkl files (True, SB3's behaviour). Unpickling a crafted file runs code from
            it; with False only .npz buffers load.
        :param path: the file written by ``save_replay_buffer`` (a path that does not exist is tried with .pkl, then
            .npz appended, reported at ``verbose >= 2`` as SB3 does), or an open binary file, read from where it
            stands.
        """
        import warnings

        from sb3_er.common.serialization import check_file_object, sb3_read_path

        if isinstance(path, (str, pathlib.Path)):
            path = sb3_read_path(path, ("pkl", "npz"), self.verbose)
        else:
            check_file_object(path, "r")  # SB3's TypeError or ValueError for what is not an open binary file
        buffer = load_buffer(path, self.policy.tile_coder, allow_pickle)
        in_progress = buffer.open_length + sum(buffer.staged_length(env) for env in range(buffer.n_envs))
        if truncate_last_traj:
            buffer.truncate_open_trajectory()
            if in_progress:
                warnings.warn(  # SB3's HerReplayBuffer.truncate_last_trajectory, the buffer of SB3 that keeps episodes
                    "The last trajectory in the replay buffer will be truncated.\n"
                    "If you are in the same episode as when the replay buffer was saved,\n"
                    "you should use `truncate_last_traj=False` to avoid that issue.",
                    stacklevel=2,
                )
        buffer.set_n_envs(self.n_envs or 1)  # saved by a model of another number of envs: its open stretches close
        self.replay_buffer = buffer
        self._on_buffer_replaced()
        self._observe_stored_rewards()  # the value watch takes the reward range of the loaded data too

    def _on_buffer_replaced(self) -> None:
        """Hook: drop anything derived from the previous buffer."""

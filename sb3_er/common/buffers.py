"""The trajectory replay buffer of experience replay (thesis Alg. 7 lines 10-12, Alg. 9 lines 10-13)."""

import math
from typing import Any, Optional

import numpy as np

from sb3_er.common import kernels
from sb3_er.common.tile_coding import TileCoder


class TrajectoryReplayBuffer:
    """Transitions (s_t, a_t, r_{t+1}) grouped in trajectories, with the tiles of s_t precomputed, and the visit vector w.

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
    """

    PRUNE_OPTIONS = (None, "coverage")
    DEFAULT_PRUNE_THRESHOLD = 0.9

    def __init__(self, capacity: int, tile_coder: TileCoder, prune: Optional[str] = None,
                 prune_threshold: float = DEFAULT_PRUNE_THRESHOLD):
        if capacity < 1:
            raise ValueError(f"buffer_size must be at least 1, got {capacity}")
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
        self.open_next_obs = np.zeros(n_dims, dtype=np.float64)
        self.open_next_slots = np.zeros(n_tilings, dtype=np.int64)
        self.visits = np.zeros(tile_coder.n_weights, dtype=np.uint8)
        self.oldest_trajectory = 0
        self.write_row = 0
        self.n_trajectories = 0
        self.n_transitions = 0
        self.open_length = 0
        # the pruned database: features first visited by the open trajectory, and how many of its samples were covered
        self.fresh = np.zeros(tile_coder.n_weights, dtype=np.uint8) if prune else np.zeros(0, dtype=np.uint8)
        self.open_new_features = np.zeros(16 * tile_coder.n_tilings if prune else 0, dtype=np.int64)
        self.n_open_new = 0
        self.open_covered = 0
        self.n_closed_total = 0
        self.n_pruned_trajectories = 0
        self.n_pruned_transitions = 0

    @staticmethod
    def check_kwargs(kwargs: Optional[dict[str, Any]]) -> None:
        """ValueError for keyword arguments that this buffer does not take or whose values are out of range."""
        kwargs = dict(kwargs or {})
        unknown = sorted(set(kwargs) - {"prune", "prune_threshold"})
        if unknown:
            raise ValueError(f"replay_buffer_kwargs: unknown {unknown}; the trajectory buffer takes prune and "
                             "prune_threshold")
        prune = kwargs.get("prune")
        if prune not in TrajectoryReplayBuffer.PRUNE_OPTIONS:
            raise ValueError(f"prune must be one of {list(TrajectoryReplayBuffer.PRUNE_OPTIONS)}, got {prune!r}")
        threshold = kwargs.get("prune_threshold", TrajectoryReplayBuffer.DEFAULT_PRUNE_THRESHOLD)
        if isinstance(threshold, bool) or not (isinstance(threshold, (int, float)) and math.isfinite(threshold)
                                               and 0.0 < threshold <= 1.0):
            raise ValueError(f"prune_threshold must be a share in (0, 1], got {threshold!r}")

    def pruned_share(self) -> float:
        """The share of closed trajectories that pruning dropped (0 before any closed)."""
        return self.n_pruned_trajectories / self.n_closed_total if self.n_closed_total else 0.0

    def record_fill(self, logger) -> None:
        """Log the buffer's fill (stored transitions / capacity) and, when pruning, the pruned share of trajectories
        and of transitions as ``train/buffer_fill``, ``train/pruned_share`` and ``train/pruned_transitions_share``."""
        logger.record("train/buffer_fill", self.n_transitions / self.capacity)
        if self.prune:
            logger.record("train/pruned_share", self.pruned_share())
            seen = self.n_pruned_transitions + self.n_closed_transitions
            logger.record("train/pruned_transitions_share", self.n_pruned_transitions / seen if seen else 0.0)

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

    def add(self, obs: np.ndarray, slots: np.ndarray, action: int, reward: float, next_obs: np.ndarray) -> None:
        """Append (s_t, a_t, r_{t+1}) to the open trajectory, remember s_{t+1} and mark phi(s_t, a_t) as visited
        (Eq. 5.2)."""
        if self.n_transitions == self.capacity:
            self._evict_oldest_trajectory()
        p = (self.write_row + self.open_length) % self.capacity
        self.observations[p] = obs
        self.slots[p] = slots
        self.actions[p] = action
        self.rewards[p] = reward
        self.transition_trajectory[p] = self.open_trajectory
        self.open_next_obs[:] = next_obs
        self.open_length += 1
        self.n_transitions += 1
        coder = self.tile_coder
        if not self.prune:
            kernels.mark_visited(self.visits, slots, coder.stride, coder.action_columns, action)
            return
        if self.n_open_new + coder.n_tilings > self.open_new_features.shape[0]:
            self.open_new_features = np.concatenate([self.open_new_features, np.zeros_like(self.open_new_features)])
        self.n_open_new, covered = kernels.mark_visited_tracked(
            self.visits, self.fresh, slots, coder.stride, coder.action_columns, action, self.open_new_features,
            self.n_open_new)
        self.open_covered += covered

    def close_trajectory(self, next_obs: np.ndarray, terminated: bool) -> bool:
        """End the open trajectory at s_{t+1} = next_obs; returns False if it was empty or pruning dropped it."""
        if self.open_length == 0:
            return False
        if self.prune:
            self.n_closed_total += 1
            new = self.open_new_features[: self.n_open_new]
            self.fresh[new] = 0
            dropped = self.open_covered >= self.prune_threshold * self.open_length
            if dropped:  # its rows are overwritten by the next trajectory; only it visited its new features
                self.visits[new] = 0
                self.n_pruned_trajectories += 1
                self.n_pruned_transitions += self.open_length
                self.n_transitions -= self.open_length
            self.n_open_new, self.open_covered = 0, 0
            if dropped:
                self.open_length = 0
                return False
        j = self.open_trajectory
        self.trajectory_start[j] = self.write_row
        self.trajectory_length[j] = self.open_length
        self.trajectory_terminated[j] = terminated
        self.trajectory_next_obs[j] = next_obs
        self.trajectory_next_slots[j] = self.tile_coder.slots(next_obs)
        self.n_trajectories += 1
        self.write_row = (self.write_row + self.open_length) % self.capacity
        self.open_length = 0
        return True

    def truncate_open_trajectory(self) -> bool:
        """Close the open trajectory as truncated at its latest s_{t+1} (its episode was cut off); False if empty."""
        return self.close_trajectory(self.open_next_obs.copy(), terminated=False)

    def _evict_oldest_trajectory(self) -> None:
        if self.n_trajectories == 0:
            raise ValueError(
                f"A single trajectory is longer than buffer_size={self.capacity}; increase buffer_size or close "
                "trajectories more often (episode ends, info['segment_end'])"
            )
        j = self.oldest_trajectory
        self.n_transitions -= self.trajectory_length[j]
        self.oldest_trajectory = (j + 1) % self.capacity
        self.n_trajectories -= 1

    def replay_arguments(self) -> tuple:
        """The buffer's arrays and counters in the order of ``kernels.replay_phase``, the open trajectory included."""
        if self.open_length:
            self.open_next_slots[:] = self.tile_coder.slots(self.open_next_obs)
        return (
            self.slots,
            self.actions,
            self.rewards,
            self.transition_trajectory,
            self.trajectory_start,
            self.trajectory_length,
            self.trajectory_terminated,
            self.trajectory_next_slots,
            self.oldest_trajectory,
            self.n_trajectories,
            self._oldest_row(),
            self.n_transitions,
            self.open_trajectory,
            self.open_length,
            self.open_next_slots,
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
        """Pickle only the stored rows, oldest first, so a large empty buffer saves small."""
        rows = (self._oldest_row() + np.arange(self.n_transitions)) % self.capacity
        trajectories = (self.oldest_trajectory + np.arange(self.n_trajectories)) % self.capacity
        starts = (self.trajectory_start[trajectories] - self._oldest_row()) % self.capacity
        return {
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

    def _oldest_row(self) -> int:
        if self.n_trajectories > 0:
            return int(self.trajectory_start[self.oldest_trajectory])
        return self.write_row

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["capacity"], TileCoder(**state["tile_coder_config"]), state.get("prune"),
                      state.get("prune_threshold", self.DEFAULT_PRUNE_THRESHOLD))
        if self.prune:
            new = state["open_new_features"]
            self.open_new_features = np.zeros(max(new.shape[0] * 2, 16 * self.tile_coder.n_tilings), dtype=np.int64)
            self.open_new_features[: new.shape[0]] = new
            self.n_open_new = new.shape[0]
            self.fresh[new] = 1
            self.open_covered = state["open_covered"]
            self.n_closed_total, self.n_pruned_trajectories, self.n_pruned_transitions = state["pruned"]
        n, m = len(state["actions"]), len(state["trajectory_length"])
        for name in ("observations", "slots", "actions", "rewards"):
            getattr(self, name)[:n] = state[name]
        for name in ("trajectory_start", "trajectory_length", "trajectory_terminated", "trajectory_next_obs",
                     "trajectory_next_slots"):
            getattr(self, name)[:m] = state[name]
        for j in range(m):
            rows = self.trajectory_start[j] + np.arange(self.trajectory_length[j])
            self.transition_trajectory[rows] = j
        self.transition_trajectory[n - state["open_length"] : n] = m
        self.visits[:] = state["visits"]
        self.n_trajectories, self.n_transitions, self.open_length = m, n, state["open_length"]
        if "open_next_obs" in state:
            self.open_next_obs[:] = state["open_next_obs"]
        else:  # saved before the open trajectory kept its s_{t+1}: it cannot be closed, so drop it
            self.n_transitions, self.open_length = n - state["open_length"], 0
        self.write_row = (n - state["open_length"]) % self.capacity

"""Experience replay of whole trajectories on tile-coded Q (thesis Alg. 7-14): one implementation, four presets."""

from typing import Any, Literal

import numpy as np
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_er.common import kernels
from sb3_er.common.base_class import TileQAlgorithm
from sb3_er.common.buffers import TrajectoryBufferIO, TrajectoryReplayBuffer
from sb3_er.common.checks import check_choice, check_integer, check_number
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.policies import TileQPolicy

REPLAY_ORDERS = {
    "reversed": kernels.ORDER_REVERSED,
    "forward": kernels.ORDER_FORWARD,
    "uniform": kernels.ORDER_UNIFORM,
    "prioritized": kernels.ORDER_PRIORITIZED,
}
PREDECESSORS = {"tiles": kernels.PREDECESSORS_TILES, "trajectory": kernels.PREDECESSORS_TRAJECTORY}
TARGETS = {
    "sarsa": kernels.TARGET_SARSA,
    "q_learning": kernels.TARGET_Q_LEARNING,
    "expected_sarsa": kernels.TARGET_EXPECTED_SARSA,
}
SIGMAS = {
    None: kernels.SIGMA_NONE,
    "worst": kernels.SIGMA_WORST,
    "average": kernels.SIGMA_AVERAGE,
    "best": kernels.SIGMA_BEST,
    "average_worst": kernels.SIGMA_AVERAGE_WORST,
    "average_best": kernels.SIGMA_AVERAGE_BEST,
}
#: The value watch's entries of ER-sigma's target shift (kernels.watch_shift)
SHIFT_ENTRIES = [kernels.WATCH_SHIFT_SUM, kernels.WATCH_SHIFT_COUNT, kernels.WATCH_RAISED, kernels.WATCH_LOWERED]
REPLAY_TRIGGERS = ("episode", "segment")
REPLAY_UNITS = ("episode", "segment")
RESIDUAL_ACTIONS = ("taken", "next")


@inherit_parameters(hidden=("trace_lambda",))  # ER sets trace_lambda from online_lambda
class ER(TrajectoryBufferIO, TileQAlgorithm):
    """Experience replay with the Sarsa update (thesis Alg. 7-8) and its variants (Alg. 9-14).

    Every transition is stored in trajectories. A trajectory is a whole episode (``replay_unit="episode"``, Alg. 7:
    D_e closes at the episode's end) or, with ``replay_unit="segment"``, also closes wherever the env sets
    ``info["segment_end"]`` (the simplest walker's footsteps). At each replay trigger, ``n_replays`` trajectories (or
    ``replays_per_stored_trajectory`` times the number stored) are drawn uniformly and replayed from their last sample
    to their first, each sample updating Q towards r + gamma Q(s', a') with a' epsilon-greedy at s'. The episode in
    progress is one of the stored trajectories (Alg. 8 line 2 draws e' from {1, ..., e}, the current episode e
    included); its last sample bootstraps from the latest s'. At an episode's end it is empty, so this matters only for
    replays triggered mid-episode (the walker's footsteps).

    Between replays the agent acts epsilon-greedily on the current Q, or learns online with Sarsa(lambda) if
    ``online_lambda`` is given (the thesis's LEO setup).

    :param buffer_size: transitions kept (default 1,000,000); the oldest whole trajectories are evicted beyond it.
    :param replay_trigger: "episode" (default) replays every ``replay_every`` episodes; "segment" at every episode end
        and every ``info["segment_end"]`` (each footstep and each fall for the walker: thesis 4.2.2, "after every step
        or fall").
    :param replay_unit: what a stored trajectory is: "episode" (default, the thesis's Alg. 7-8) or "segment" (closed
        also at each ``info["segment_end"]``: the walker's footstep-to-footstep stretches, our earlier reading).
    :param replay_every: episodes between replay phases for the "episode" trigger (default 1).
    :param n_replays: trajectories replayed per phase (default 100, the walker's and LEO's K).
    :param replays_per_stored_trajectory: if given, replay round(x * trajectories stored) per phase instead (the
        thesis's 10 for the pendulum and the grid world); default None.
    :param replay_order: "reversed" (default, the thesis's), "forward" or "uniform" samples (Appendix A), or
        "prioritized": prioritized sweeping (Moore and Atkeson 1993; thesis 3.2 and 7.2), which replays single
        transitions by their |delta| from a priority queue and re-queues the predecessors of each replayed one (see
        ``kernels.prioritized_phase``). A phase makes as many updates as the other orders would on average
        (``prioritized_updates``), fewer when no |delta| exceeds ``priority_threshold``.
    :param priority_threshold: theta of prioritized sweeping: a transition is queued only while its |delta| exceeds
        it (default 0: every transition with a non-zero error; in the reward's units).
    :param predecessors: which transitions prioritized sweeping re-queues after replaying one, (s, a, r, s'):
        "tiles" (default), the stored transitions whose s' shares a tile with s (their targets moved: predecessors
        under function approximation, found through an index from tile slots to transitions built each phase), the
        previous transition of its trajectory first; or "trajectory", only that one (cheaper).
    :param max_predecessors: at most this many distinct predecessors re-queued per replayed transition (default
        4), after the trajectory's own the newest stored first; bounds the cost of an update, as each predecessor
        costs a |delta| evaluation (about 1 + max_predecessors evaluations per update).
    :param prioritized_updates: updates per prioritized phase; None (default) matches the other orders' budget,
        the trajectories to replay times the mean length of a stored trajectory.
    :param target: "sarsa" (default, the thesis's), "q_learning" or "expected_sarsa" (thesis 7.2, future work).
    :param sigma: ER-sigma's sigma(s') (Appendix B): "worst", "average", "best", "average_worst" (definition 4, the
        thesis's choice), "average_best"; None (default) is vanilla ER.
    :param residual_zeta: residual-gradient ER with direction phi(s, a) - zeta gamma phi(s', a) (Eq. 5.7-5.9);
        1 is the residual gradient of Alg. 12, None (default) plain ER.
    :param residual_action: the action of the residual term: "taken" (default; a_t, the thesis's Eq. 5.7 and Alg. 12) or
        "next" (a_{t+1}, Baird's residual gradient of the squared TD error; not with the expected-Sarsa target).
    :param online_lambda: lambda of Sarsa(lambda) between replays (LEO: 0.859), or None (default) to act without
        online learning.
    :param replay_buffer_kwargs: keyword arguments of the TrajectoryReplayBuffer, e.g. ``dict(prune="coverage",
        prune_threshold=0.9)`` for the pruned database of thesis 3.5.3; default None.
    """

    _trace_lambda_parameter = "online_lambda"

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        buffer_size: int = 1_000_000,
        replay_trigger: Literal["episode", "segment"] = "episode",
        replay_unit: Literal["episode", "segment"] = "episode",
        replay_every: int = 1,
        n_replays: int = 100,
        replays_per_stored_trajectory: float | None = None,
        replay_order: Literal["reversed", "forward", "uniform", "prioritized"] = "reversed",
        target: Literal["sarsa", "q_learning", "expected_sarsa"] = "sarsa",
        sigma: str | None = None,
        residual_zeta: float | None = None,
        residual_action: Literal["taken", "next"] = "taken",
        online_lambda: float | None = None,
        priority_threshold: float = 0.0,
        predecessors: Literal["tiles", "trajectory"] = "tiles",
        max_predecessors: int = 4,
        prioritized_updates: int | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
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
        self.buffer_size = buffer_size
        self.replay_trigger = replay_trigger
        self.replay_unit = replay_unit
        self.replay_order = replay_order
        self.target = target
        self.sigma = sigma
        self.residual_action = residual_action
        self.replay_every = replay_every
        self.n_replays = n_replays
        self.replays_per_stored_trajectory = replays_per_stored_trajectory
        self.residual_zeta = residual_zeta
        self.priority_threshold = priority_threshold
        self.predecessors = predecessors
        self.max_predecessors = max_predecessors
        self.prioritized_updates = prioritized_updates
        self.replay_buffer_kwargs = replay_buffer_kwargs
        self.priority_evaluations = 0
        self.replay_updates = 0
        self.replay_phases = 0
        self.replay_buffer: TrajectoryReplayBuffer | None = None
        super().__init__(
            policy,
            env,
            trace_lambda=online_lambda,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

    @property
    def online_lambda(self) -> float | None:
        return self.trace_lambda

    def _check_hyperparameters(self) -> None:
        super()._check_hyperparameters()
        check_choice("replay_trigger", self.replay_trigger, REPLAY_TRIGGERS)
        check_choice("replay_unit", self.replay_unit, REPLAY_UNITS)
        check_choice("replay_order", self.replay_order, REPLAY_ORDERS)
        check_choice("target", self.target, TARGETS)
        check_choice("sigma", self.sigma, SIGMAS)
        check_choice("residual_action", self.residual_action, RESIDUAL_ACTIONS)
        check_integer("buffer_size", self.buffer_size, minimum=1)
        check_integer("replay_every", self.replay_every, minimum=1, unit=" episode")
        check_integer("n_replays", self.n_replays, minimum=0)
        check_number("replays_per_stored_trajectory", self.replays_per_stored_trajectory, 0.0, optional=True)
        check_number("residual_zeta (Eq. 5.9)", self.residual_zeta, 0.0, 1.0, optional=True)
        if self.residual_action == "next" and self.target == "expected_sarsa":
            raise ValueError("residual_action=\"next\" needs a single a' at s': use the sarsa or q_learning target")
        check_choice("predecessors", self.predecessors, PREDECESSORS)
        check_number("priority_threshold", self.priority_threshold, 0.0, unit=" (a |delta|)")
        check_integer("max_predecessors", self.max_predecessors, minimum=0)
        check_integer("prioritized_updates", self.prioritized_updates, minimum=0, optional=True)
        TrajectoryReplayBuffer.check_kwargs(self.replay_buffer_kwargs)

    def _setup_model(self) -> None:
        super()._setup_model()
        self.replay_buffer = TrajectoryReplayBuffer(
            self.buffer_size, self.policy.tile_coder, **(self.replay_buffer_kwargs or {})
        )
        self._w_scratch = np.zeros(self.policy.tile_coder.n_actions, dtype=np.float64)
        self._priority_workspace: dict[str, np.ndarray] | None = None

    def _excluded_save_params(self) -> list[str]:
        return super()._excluded_save_params() + ["_w_scratch", "_priority_workspace"]

    def _seed_generators(self, seed: int | None) -> None:
        super()._seed_generators(seed)
        self.seed_replay(seed)

    def _end_episode_at_reset(self) -> None:
        """The episode in progress was cut off by an env reset: its trajectory is closed as truncated at its last
        real s_{t+1} (replay bootstraps there), never joined to the next episode; no replay is triggered."""
        super()._end_episode_at_reset()
        if self.replay_buffer is not None:
            self.replay_buffer.truncate_open_trajectory()

    def seed_replay(self, seed: int | None) -> None:
        """Reseed the generator that picks trajectories, so models given the same buffer replay the same ones.

        :param seed: the seed of the replay generator; None seeds it from fresh entropy.
        """
        self.replay_rng = kernels.new_rng_state(seed, kernels.RNG_STREAM_REPLAY)

    def _after_transition(self, obs, action, reward, next_obs, terminated, done, info) -> None:
        self.replay_buffer.add(obs, self._slots, action, reward, next_obs)
        segment_end = bool(info.get("segment_end", False))
        if not (done or segment_end):
            return
        if done or self.replay_unit == "segment":
            self.replay_buffer.close_trajectory(next_obs, terminated)
        episode_trigger = done and (self._episode_num + 1) % self.replay_every == 0
        if self.replay_trigger == "segment" or episode_trigger:
            self.replay(self._replays_per_phase())

    def _replays_per_phase(self) -> int:
        if self.replays_per_stored_trajectory is not None:
            return int(round(self.replays_per_stored_trajectory * self.replay_buffer.n_stored_trajectories))
        return self.n_replays

    def replay(self, n_trajectories: int) -> dict[str, float]:
        """One replay phase of n_trajectories on the stored data (one kernel call); returns its update count and mean
        |delta|, and for ER-sigma the phase's mean target shift T_sigma - T and the shares of targets it raised and
        lowered (``sigma_shift``, ``sigma_raised``, ``sigma_lowered``; with the value watch on). Prioritized sweeping
        makes ``prioritized_updates`` updates, by default n_trajectories times the mean length of a stored
        trajectory.

        :param n_trajectories: trajectories to replay in this phase (drawn uniformly from those stored, the open one
            included).
        """
        buffer = self.replay_buffer
        if buffer.n_stored_trajectories == 0 or n_trajectories <= 0:
            return {"updates": 0, "td_error": 0.0}
        self._observe_stored_rewards()
        coder = self.policy.tile_coder
        watch = self._watch_array
        updates_before = watch[kernels.WATCH_UPDATES] if watch.shape[0] else 0.0
        period_shift = watch[SHIFT_ENTRIES].copy() if watch.shape[0] else None
        if period_shift is not None:
            watch[SHIFT_ENTRIES] = 0.0  # the phase's own shift figures, added to the period's after it
        update_arguments = (
            TARGETS[self.target],
            SIGMAS[self.sigma],
            0.0 if self.residual_zeta is None else float(self.residual_zeta),
            self.residual_action == "next",
            self.current_learning_rate / coder.n_tilings,
            self.gamma,
            self.exploration_rate,
        )
        if self.replay_order == "prioritized":
            n_updates = self.prioritized_updates
            if n_updates is None:
                n_updates = round(n_trajectories * buffer.n_transitions / buffer.n_stored_trajectories)
            updates, sum_abs_delta, last_delta, status, evaluations = kernels.prioritized_phase(
                self.policy.theta_array,
                buffer.visits,
                *buffer.replay_arguments(),
                coder.stride,
                coder.action_columns,
                coder.columns_are_actions,
                int(n_updates),
                float(self.priority_threshold),
                PREDECESSORS[self.predecessors],
                int(self.max_predecessors),
                *update_arguments,
                self.action_rng,
                self._q_scratch,
                self._w_scratch,
                *self.policy.initial_arguments,
                *self._priority_arrays(),
                self._watch_array,
            )
            self.priority_evaluations += evaluations
        else:
            updates, sum_abs_delta, last_delta, status = kernels.replay_phase(
                self.policy.theta_array,
                buffer.visits,
                *buffer.replay_arguments(),
                coder.stride,
                coder.action_columns,
                coder.columns_are_actions,
                int(n_trajectories),
                REPLAY_ORDERS[self.replay_order],
                *update_arguments,
                self.replay_rng,
                self.action_rng,
                self._q_scratch,
                self._w_scratch,
                *self.policy.initial_arguments,
                self._watch_array,
            )
        self.replay_updates += updates
        self.replay_phases += 1
        if status == kernels.STATUS_DIVERGED:
            self._raise_divergence(last_delta, f"replayed update {updates} of a replay phase")
        self._td_error_sum += sum_abs_delta
        self._td_error_count += updates
        result = {"updates": updates, "td_error": sum_abs_delta / max(updates, 1)}
        watch = self._watch_array
        if period_shift is not None:
            shift_sum, shifted, raised, lowered = watch[SHIFT_ENTRIES]
            if shifted > 0:
                result.update(
                    sigma_shift=float(shift_sum / shifted),
                    sigma_raised=float(raised / shifted),
                    sigma_lowered=float(lowered / shifted),
                )
            watch[SHIFT_ENTRIES] += period_shift
        if status == kernels.STATUS_OUT_OF_BOUNDS:
            first = int(watch[kernels.WATCH_FIRST_UPDATE] - updates_before) + 1
            self._value_out_of_bounds(f"replayed update {first} of replay phase {self.replay_phases}")
        return result

    def _priority_arrays(self) -> tuple[np.ndarray, ...]:
        """The workspace of ``kernels.prioritized_phase``, allocated here (the kernel allocates nothing) and grown with
        the buffer: heap_rows, heap_keys, heap_position, heap_size, index_start, index_rows, stamp, stamp_counter.

        Arrays indexed by a buffer row have one entry per row of the ring; the heap and the tile index grow in steps
        of doubling with the stored transitions. Nothing of it is saved: the queue is rebuilt at every phase.
        """
        buffer = self.replay_buffer
        coder = self.policy.tile_coder
        space = self._priority_workspace
        if space is None or space["heap_position"].shape[0] != buffer.capacity:
            space = {
                "heap_rows": np.zeros(0, dtype=np.int64),
                "heap_keys": np.zeros(0, dtype=np.float64),
                "heap_position": np.full(buffer.capacity, -1, dtype=np.int64),
                "heap_size": np.zeros(1, dtype=np.int64),
                "index_start": np.zeros(0, dtype=np.int64),
                "index_rows": np.zeros(0, dtype=np.int64),
                "stamp": np.zeros(buffer.capacity, dtype=np.int64),
                "stamp_counter": np.zeros(1, dtype=np.int64),
            }
            self._priority_workspace = space
        n = buffer.n_transitions
        if space["heap_rows"].shape[0] < n:
            size = min(buffer.capacity, max(n, 2 * space["heap_rows"].shape[0]))
            space["heap_rows"] = np.zeros(size, dtype=np.int64)
            space["heap_keys"] = np.zeros(size, dtype=np.float64)
        if self.predecessors == "tiles":
            if space["index_start"].shape[0] != coder.slot_mask + 2:
                space["index_start"] = np.zeros(coder.slot_mask + 2, dtype=np.int64)
            if space["index_rows"].shape[0] < n * coder.n_tilings:
                rows = min(buffer.capacity, max(n, 2 * space["index_rows"].shape[0] // coder.n_tilings))
                space["index_rows"] = np.zeros(rows * coder.n_tilings, dtype=np.int64)
        elif space["index_start"].shape[0] == 0:
            space["index_start"] = np.zeros(1, dtype=np.int64)
        return tuple(
            space[name]
            for name in (
                "heap_rows",
                "heap_keys",
                "heap_position",
                "heap_size",
                "index_start",
                "index_rows",
                "stamp",
                "stamp_counter",
            )
        )

    def _record_train_metrics(self) -> None:
        super()._record_train_metrics()
        self.logger.record("train/replay_updates", self.replay_updates)
        self.logger.record("train/trajectories", self.replay_buffer.n_trajectories)
        if self.replay_order == "prioritized":
            self.logger.record("train/priority_evaluations", self.priority_evaluations)
        self.replay_buffer.record_fill(self.logger)

    def _on_buffer_replaced(self) -> None:
        self._priority_workspace = None


@inherit_parameters
class ERSigma(ER):
    """ER-sigma (thesis Alg. 9-10): never-visited features take the state-dependent value sigma(s').

    ER whose replayed targets replace the values of the features of (s', a) never visited by sigma(s') (Eq. 5.4),
    estimated from the visited ones (Eq. 5.3, Appendix B).

    :param sigma: the definition of sigma(s') (Appendix B): "average_worst" (default, definition 4, the thesis's
        choice: halfway between the average and the worst case), "worst", "average", "best" or "average_best".
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        sigma: str = "average_worst",
        buffer_size: int = 1_000_000,
        replay_trigger: Literal["episode", "segment"] = "episode",
        replay_unit: Literal["episode", "segment"] = "episode",
        replay_every: int = 1,
        n_replays: int = 100,
        replays_per_stored_trajectory: float | None = None,
        replay_order: Literal["reversed", "forward", "uniform", "prioritized"] = "reversed",
        target: Literal["sarsa", "q_learning", "expected_sarsa"] = "sarsa",
        residual_zeta: float | None = None,
        residual_action: Literal["taken", "next"] = "taken",
        online_lambda: float | None = None,
        priority_threshold: float = 0.0,
        predecessors: Literal["tiles", "trajectory"] = "tiles",
        max_predecessors: int = 4,
        prioritized_updates: int | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
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
        super().__init__(
            policy,
            env,
            sigma=sigma,
            buffer_size=buffer_size,
            replay_trigger=replay_trigger,
            replay_unit=replay_unit,
            replay_every=replay_every,
            n_replays=n_replays,
            replays_per_stored_trajectory=replays_per_stored_trajectory,
            replay_order=replay_order,
            target=target,
            residual_zeta=residual_zeta,
            residual_action=residual_action,
            online_lambda=online_lambda,
            priority_threshold=priority_threshold,
            predecessors=predecessors,
            max_predecessors=max_predecessors,
            prioritized_updates=prioritized_updates,
            replay_buffer_kwargs=replay_buffer_kwargs,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )


@inherit_parameters
class ResidualER(ER):
    """Residual-gradient ER (thesis Alg. 11-12, Eq. 5.7-5.9).

    ER whose replayed updates follow the residual-gradient direction phi(s, a) - zeta gamma phi(s', a) instead of the
    semi-gradient phi(s, a).

    :param residual_zeta: zeta of Eq. 5.9 in [0, 1]: 1 (default) is the thesis's residual gradient (Alg. 12), 0 plain
        ER, values between Baird's residual algorithm.
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        residual_zeta: float = 1.0,
        buffer_size: int = 1_000_000,
        replay_trigger: Literal["episode", "segment"] = "episode",
        replay_unit: Literal["episode", "segment"] = "episode",
        replay_every: int = 1,
        n_replays: int = 100,
        replays_per_stored_trajectory: float | None = None,
        replay_order: Literal["reversed", "forward", "uniform", "prioritized"] = "reversed",
        target: Literal["sarsa", "q_learning", "expected_sarsa"] = "sarsa",
        sigma: str | None = None,
        residual_action: Literal["taken", "next"] = "taken",
        online_lambda: float | None = None,
        priority_threshold: float = 0.0,
        predecessors: Literal["tiles", "trajectory"] = "tiles",
        max_predecessors: int = 4,
        prioritized_updates: int | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
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
        super().__init__(
            policy,
            env,
            residual_zeta=residual_zeta,
            buffer_size=buffer_size,
            replay_trigger=replay_trigger,
            replay_unit=replay_unit,
            replay_every=replay_every,
            n_replays=n_replays,
            replays_per_stored_trajectory=replays_per_stored_trajectory,
            replay_order=replay_order,
            target=target,
            sigma=sigma,
            residual_action=residual_action,
            online_lambda=online_lambda,
            priority_threshold=priority_threshold,
            predecessors=predecessors,
            max_predecessors=max_predecessors,
            prioritized_updates=prioritized_updates,
            replay_buffer_kwargs=replay_buffer_kwargs,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )


@inherit_parameters
class ResidualERSigma(ER):
    """Residual ER-sigma (thesis Alg. 13-14): ER-sigma's sigma(s') for never-visited features and the residual-gradient
    direction of residual ER, both.

    :param sigma: the definition of sigma(s') (Appendix B): "average_worst" (default, definition 4), "worst",
        "average", "best" or "average_best".
    :param residual_zeta: zeta of Eq. 5.9 in [0, 1]: 1 (default) is the thesis's residual gradient (Alg. 14).
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        sigma: str = "average_worst",
        residual_zeta: float = 1.0,
        buffer_size: int = 1_000_000,
        replay_trigger: Literal["episode", "segment"] = "episode",
        replay_unit: Literal["episode", "segment"] = "episode",
        replay_every: int = 1,
        n_replays: int = 100,
        replays_per_stored_trajectory: float | None = None,
        replay_order: Literal["reversed", "forward", "uniform", "prioritized"] = "reversed",
        target: Literal["sarsa", "q_learning", "expected_sarsa"] = "sarsa",
        residual_action: Literal["taken", "next"] = "taken",
        online_lambda: float | None = None,
        priority_threshold: float = 0.0,
        predecessors: Literal["tiles", "trajectory"] = "tiles",
        max_predecessors: int = 4,
        prioritized_updates: int | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
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
        super().__init__(
            policy,
            env,
            sigma=sigma,
            residual_zeta=residual_zeta,
            buffer_size=buffer_size,
            replay_trigger=replay_trigger,
            replay_unit=replay_unit,
            replay_every=replay_every,
            n_replays=n_replays,
            replays_per_stored_trajectory=replays_per_stored_trajectory,
            replay_order=replay_order,
            target=target,
            residual_action=residual_action,
            online_lambda=online_lambda,
            priority_threshold=priority_threshold,
            predecessors=predecessors,
            max_predecessors=max_predecessors,
            prioritized_updates=prioritized_updates,
            replay_buffer_kwargs=replay_buffer_kwargs,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

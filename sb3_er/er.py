"""Experience replay of whole trajectories on tile-coded Q (thesis Alg. 7-14): one implementation, four presets."""

from typing import Any, ClassVar, Literal

import numpy as np
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_er.common import kernels
from sb3_er.common.base_class import GIVEN_AT_LOAD, TileQAlgorithm
from sb3_er.common.buffers import TrajectoryBufferIO, TrajectoryReplayBuffer
from sb3_er.common.checks import check_bool, check_choice, check_integer, check_number
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
#: The replay stabilizers a preset fills, with the replay volume, unless given explicitly. "thesis": the thesis's
#: algorithms exactly (Alg. 7-14: 100 trajectories per phase, no stabilizer). "stable": the projection of the weights
#: onto the possible returns, the combination the stabilizer screen chose over the whole sample-efficiency suite
#: (results/measured/stable_replay_screen; its rule in docs/stable_replay.md), the same on every task.
_THESIS_PRESET: dict[str, Any] = dict(
    n_replays=100,
    replays_per_stored_trajectory=None,
    replay_ratio=None,
    truncate_targets=False,
    target_copy=False,
    step_size_bound=False,
    averager=False,
    project_weights=False,
)
PRESETS: dict[str, dict[str, Any]] = {
    "thesis": _THESIS_PRESET,
    "stable": {**_THESIS_PRESET, "project_weights": True},
}
#: What a preset resolves: the replay volume (one of its three forms) and the stabilizers.
STABILIZERS = (
    "n_replays",
    "replays_per_stored_trajectory",
    "replay_ratio",
    "truncate_targets",
    "target_copy",
    "step_size_bound",
    "averager",
    "project_weights",
)
REPLAY_VOLUME = ("n_replays", "replays_per_stored_trajectory", "replay_ratio")
#: The stabilizers proper: each on or off.
SWITCHES = tuple(name for name in STABILIZERS if name not in REPLAY_VOLUME)


def resolve_preset(preset: str, given: dict[str, Any]) -> dict[str, Any]:
    """The stabilizers and replay volume of ``preset`` (:data:`PRESETS`), with every argument given explicitly (not
    None) winning. The replay volume has three forms (:data:`REPLAY_VOLUME`): one given explicitly replaces the
    preset's as a whole, the other two None, so that the resolved values name the volume the replay uses; two given
    at once are a ValueError.

    :param preset: "thesis" or "stable".
    :param given: the arguments as given, None where not given (the names of :data:`STABILIZERS`).
    """
    check_choice("preset", preset, PRESETS)
    volume = [name for name in REPLAY_VOLUME if given.get(name) is not None]
    if len(volume) > 1:
        raise ValueError(
            f"give one replay volume, not {' and '.join(f'{name}={given[name]}' for name in volume)}: "
            "n_replays (trajectories per phase), replays_per_stored_trajectory (per trajectory stored) and "
            "replay_ratio (updates per new sample) each set the whole of it"
        )
    resolved = dict(PRESETS[preset])
    if volume:
        resolved.update(dict.fromkeys(REPLAY_VOLUME))
    resolved.update({name: given[name] for name in STABILIZERS if given.get(name) is not None})
    return resolved


def check_stabilizers(resolved: dict[str, Any], where: str = "stabilizers") -> None:
    """ValueError naming the entry unless ``resolved`` holds exactly :data:`STABILIZERS` with valid values and at most
    one replay volume: what a saved model's file is checked against before it replays.

    :param resolved: the stabilizers and replay volume.
    :param where: the name to give in messages.
    """
    if not isinstance(resolved, dict) or set(resolved) != set(STABILIZERS):
        raise ValueError(f"{where}: expected the entries {list(STABILIZERS)}, got {resolved!r}")
    check_integer(f"{where}['n_replays']", resolved["n_replays"], minimum=0, optional=True)
    check_number(
        f"{where}['replays_per_stored_trajectory']", resolved["replays_per_stored_trajectory"], 0.0, optional=True
    )
    check_number(f"{where}['replay_ratio']", resolved["replay_ratio"], 0.0, optional=True, low_open=True)
    for name in SWITCHES:
        check_bool(f"{where}[{name!r}]", resolved[name])
    volumes = [name for name in REPLAY_VOLUME if resolved[name] is not None]
    if len(volumes) != 1:
        raise ValueError(f"{where}: expected one replay volume of {list(REPLAY_VOLUME)}, got {volumes or 'none'}")


def saved_stabilizers(saved: dict[str, Any], replays_per_stored_trajectory: float | None = None) -> dict[str, Any]:
    """The stabilizers a saved model replayed with, from its file's ``stabilizers``, checked
    (:func:`check_stabilizers`): a stabilizer added after the file was written was off (the thesis's value), and a
    file written before the resolved values named their replay volume, which then replayed by its
    ``replays_per_stored_trajectory`` attribute where that was given, names it now.

    :param saved: the ``stabilizers`` dict read from the file.
    :param replays_per_stored_trajectory: the file's attribute of that name, read where ``saved`` lacks the entry.
    """
    if not isinstance(saved, dict):
        raise ValueError(f"stabilizers: expected a dict, got {saved!r}")
    resolved = {**PRESETS["thesis"], **saved}
    if "replays_per_stored_trajectory" not in saved:
        resolved["replays_per_stored_trajectory"] = replays_per_stored_trajectory
    if resolved["replays_per_stored_trajectory"] is not None or resolved["replay_ratio"] is not None:
        resolved["n_replays"] = None
    check_stabilizers(resolved)
    return resolved


#: "As many trajectories as it takes": a phase with a budget of updates (the replay ratio) ends by that budget.
UNLIMITED = 2**62
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
    :param n_replays: trajectories replayed per phase; None (default): the preset's (100, the walker's and LEO's K).
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
        the trajectories to replay times the mean length of a stored trajectory, or with ``replay_ratio`` the
        ratio's budget of the phase (the two cannot both be given).
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
    :param preset: fills every stabilizer and the replay volume not given explicitly (:data:`PRESETS`): "thesis"
        (default), the thesis's algorithms exactly; "stable", the projection of the weights onto the possible
        returns (``project_weights``), chosen by measurement over the sample-efficiency suite: no value leaves the
        possible returns, though it does not pay on every task (docs/stable_replay.md). Explicit arguments win; the
        resolved values are in ``stabilizers``.
    :param truncate_targets: truncate every bootstrapped value to the possible returns (the value watch's bounds;
        Chen, Clarke and Maguluri 2023, "Target network and truncation overcome the deadly triad in Q-learning");
        None (default): the preset's. The watch still sees each target before truncation.
    :param target_copy: bootstrap from a copy of the weights taken at the start of each replay phase (their target
        network); None (default): the preset's. With truncation, linear Q-learning's iterates stay bounded (their
        theorem); the copy also stops a phase's updates from chasing their own moving targets.
    :param step_size_bound: bound the step by Dabney and Barto's (2012) alpha-bound, min(alpha / N, 1 /
        |(gamma phi' - phi)^T e|) over the run, so that no update carries its own TD error past zero; None (default):
        the preset's. With binary tiles and alpha / N per weight it binds in replay only for alpha > 1 / (1 - gamma
        o / N) (o tiles shared by s and s'), so at the thesis's alpha only with traces (online_lambda) and hash
        collisions.
    :param averager: each replayed update moves every active weight towards its share of the target, theta_i <-
        theta_i + alpha / N (T - N theta_i), instead of adding alpha delta / N to each (Gordon 1995, "Stable function
        approximation in dynamic programming": an averager is a max-norm non-expansion, so the fitted Bellman
        operator stays a contraction); None (default): the preset's. Q(s, a) moves by the same alpha (T - Q(s, a)),
        but each weight stays a convex combination of its start and the targets / N, so with rewards in [r_min,
        r_max] and initial values inside the possible returns no replayed value can leave them. Needs a learning
        rate of at most 1; not with the residual direction (``residual_zeta``), whose update has no averager form (a
        preset's averager is dropped there). Online Sarsa(lambda) steps between phases (``online_lambda``) keep their
        trace update.
    :param project_weights: after each replayed update, project every weight it moved onto [V_min / N, V_max / N],
        with [V_min, V_max] the value watch's bounds of the possible returns (projected TD: Bhandari, Russo and Singal
        2018, "A finite time analysis of temporal difference learning with linear function approximation"; Zou, Xu
        and Liang 2019 for Sarsa with linear function approximation); None (default): the preset's. No Q(s, a) built
        from moved weights can then leave the possible returns, on every ER variant, the residual ones included;
        weights no update touched keep their initial values. Online Sarsa(lambda) steps between phases
        (``online_lambda``) are not projected.
    :param replay_ratio: replayed updates per new stored transition (D'Oro et al., ICLR 2023): each phase replays
        whole trajectories until it has made this many updates per transition stored since the last phase, instead of
        ``n_replays`` trajectories; None (default): the preset's. The thesis's protocols make about 10^4 updates per
        new transition. Above 0 (``n_replays=0`` replays nothing); ``n_replays``, ``replays_per_stored_trajectory``
        and ``replay_ratio`` each set the whole replay volume, so at most one of them is given.
    """

    _trace_lambda_parameter = "online_lambda"

    #: Files saved before presets (or a later stabilizer) existed replayed with the thesis's algorithm.
    older_file_values: ClassVar[dict[str, Any]] = {"preset": "thesis", "averager": False, "project_weights": False}

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        buffer_size: int = 1_000_000,
        replay_trigger: Literal["episode", "segment"] = "episode",
        replay_unit: Literal["episode", "segment"] = "episode",
        replay_every: int = 1,
        n_replays: int | None = None,
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
        preset: Literal["thesis", "stable"] = "thesis",
        truncate_targets: bool | None = None,
        target_copy: bool | None = None,
        step_size_bound: bool | None = None,
        averager: bool | None = None,
        project_weights: bool | None = None,
        replay_ratio: float | None = None,
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
        self.preset = preset
        self.truncate_targets = truncate_targets
        self.target_copy = target_copy
        self.step_size_bound = step_size_bound
        self.averager = averager
        self.project_weights = project_weights
        self.replay_ratio = replay_ratio
        self.stabilizers: dict[str, Any] = {}
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
        check_integer("n_replays", self.n_replays, minimum=0, optional=True)
        check_number("replays_per_stored_trajectory", self.replays_per_stored_trajectory, 0.0, optional=True)
        check_number(
            "replay_ratio (replayed updates per new sample)", self.replay_ratio, 0.0, optional=True, low_open=True
        )
        for name in SWITCHES:
            check_bool(name, getattr(self, name), optional=True)
        check_choice("preset", self.preset, PRESETS)
        check_number("residual_zeta (Eq. 5.9)", self.residual_zeta, 0.0, 1.0, optional=True)
        if self.residual_action == "next" and self.target == "expected_sarsa":
            raise ValueError("residual_action=\"next\" needs a single a' at s': use the sarsa or q_learning target")
        check_choice("predecessors", self.predecessors, PREDECESSORS)
        check_number("priority_threshold", self.priority_threshold, 0.0, unit=" (a |delta|)")
        check_integer("max_predecessors", self.max_predecessors, minimum=0)
        check_integer("prioritized_updates", self.prioritized_updates, minimum=0, optional=True)
        TrajectoryReplayBuffer.check_kwargs(self.replay_buffer_kwargs)

    def _setup_model(self) -> None:
        self._check_hyperparameters()
        given = {name: getattr(self, name) for name in STABILIZERS}
        self.stabilizers = self._resolve_stabilizers(given)
        if self.residual_zeta and self.stabilizers["averager"]:
            if self.averager:
                raise ValueError(
                    f"averager=True with residual_zeta={self.residual_zeta}: the averager moves each weight towards "
                    "its share of the target, and the residual direction phi(s, a) - zeta gamma phi(s', a) has no "
                    "such form; project_weights keeps the residual variants inside the possible returns"
                )
            self.stabilizers["averager"] = False  # a preset's averager: the semi-gradient variants only
        if self.prioritized_updates is not None and self.stabilizers["replay_ratio"] is not None:
            raise ValueError(
                f"prioritized_updates={self.prioritized_updates} and replay_ratio={self.stabilizers['replay_ratio']} "
                "both set a prioritized phase's updates: give one"
            )
        super()._setup_model()
        self._check_averager_step(whole_schedule=True)
        self.replay_buffer = TrajectoryReplayBuffer(
            self.buffer_size, self.policy.tile_coder, **(self.replay_buffer_kwargs or {}), n_envs=self.n_envs or 1
        )
        self._priority_workspace: kernels.PriorityQueue | None = None
        self._setup_target_copy()
        self._new_samples = 0  # transitions stored since the last replay phase (the replay ratio's denominator)
        self._ratio_carry = 0.0

    def _resolve_stabilizers(self, given: dict[str, Any]) -> dict[str, Any]:
        """The preset's stabilizers with the arguments given explicitly winning (:func:`resolve_preset`); for a loaded
        model, the ones it was saved with (:func:`saved_stabilizers`: a later change to a preset does not change what
        a saved model does), with what ``load``'s keyword arguments give winning (a new ``preset`` resolves anew). A
        replay volume given to ``load`` replaces the saved one as a whole, and the model's other volume arguments are
        cleared, so that the file it saves next names one volume."""
        saved = self.stabilizers  # {} when built; the file's when loaded
        at_load = self.__dict__.get(GIVEN_AT_LOAD, ())
        if any(name in REPLAY_VOLUME and given[name] is not None for name in at_load):
            for name in REPLAY_VOLUME:
                if name not in at_load:
                    given[name] = None
                    setattr(self, name, None)
        if not saved or "preset" in at_load:
            return resolve_preset(self.preset, given)
        resolved = saved_stabilizers(saved, self.replays_per_stored_trajectory)
        overrides = {name: given[name] for name in STABILIZERS if name in at_load and given[name] is not None}
        if any(name in REPLAY_VOLUME for name in overrides):
            resolved.update(dict.fromkeys(REPLAY_VOLUME))
        resolved.update(overrides)
        check_stabilizers(resolved)
        return resolved

    def _value_watch_remedy(self) -> str:
        on = [name for name in ("truncate_targets", "project_weights", "averager") if self.stabilizers.get(name)]
        if not on:
            return super()._value_watch_remedy()
        return (
            f"the stabilizers; this model already replays with {', '.join(on)}, which bound what replay does but not "
            "the online Sarsa(lambda) steps between phases (online_lambda), the weights no replayed update has "
            "moved, or values learned before the rewards that set observed bounds were seen"
        )

    def _setup_target_copy(self) -> None:
        """The target copy of theta that bootstrapping reads (``target_copy``), taken now; None without."""
        self._target_copy = kernels.TargetCopy(self.policy.theta_array) if self.stabilizers["target_copy"] else None

    def set_parameters(self, load_path_or_dict, exact_match: bool = True, device="auto") -> None:
        """SB3's ``set_parameters`` (see TileQAlgorithm's); the target copy is taken again from the new weights.

        :param load_path_or_dict: a zip file written by ``save``, or a dict of parameters by object name.
        :param exact_match: require every object's parameters to be given (default True).
        :param device: torch device to load onto (default "auto").
        """
        super().set_parameters(load_path_or_dict, exact_match, device)
        self._setup_target_copy()

    def _check_averager_step(self, whole_schedule: bool = False) -> None:
        """ValueError if the averager would step with a learning rate above 1 (each weight carried past its share of
        the target, and the bound on the values lost): the rate in use at every phase, and with ``whole_schedule``
        (once, when the model is built) the schedule at 101 points of its course.

        :param whole_schedule: check the schedule's course too (default False: the current rate only).
        """
        if not self.stabilizers["averager"]:
            return
        rates = [(self.current_learning_rate, None)]
        if whole_schedule:
            rates += [(float(self.lr_schedule(remaining)), remaining) for remaining in np.linspace(1.0, 0.0, 101)]
        rate, remaining = max(rates, key=lambda pair: pair[0])
        if rate > 1.0:
            where = "now" if remaining is None else f"at progress_remaining {remaining:.2f} of its schedule"
            raise ValueError(
                f"averager=True needs a learning rate of at most 1 ({rate:.6g} {where}): a larger step carries each "
                "weight past its share of the target, and the averager's bound on the values is lost"
            )

    def _stabilizer_options(self) -> dict[str, Any]:
        """The UpdateRule fields of the resolved stabilizers: truncation to the value watch's bounds of the possible
        returns (Chen, Clarke and Maguluri 2023) and the step-size bound (Dabney and Barto 2012)."""
        options = dict(
            truncate=self.stabilizers["truncate_targets"],
            step_bound=self.stabilizers["step_size_bound"],
            averager=self.stabilizers["averager"],
            project=self.stabilizers["project_weights"],
        )
        self._check_averager_step()
        if options["truncate"] or options["project"]:
            options["value_low"], options["value_high"] = self._watch.bounds
        return options

    def _excluded_save_params(self) -> list[str]:
        return super()._excluded_save_params() + ["_priority_workspace", "_new_samples", "_ratio_carry"]

    def _seed_generators(self, seed: int | None) -> None:
        super()._seed_generators(seed)
        self.seed_replay(seed)

    def _end_episode_at_reset(self) -> None:
        """The episodes in progress were cut off by an env reset: their trajectories are closed as truncated at their
        last real s_{t+1} (replay bootstraps there), never joined to the next episodes; no replay is triggered."""
        super()._end_episode_at_reset()
        if self.replay_buffer is not None:
            self.replay_buffer.truncate_open_trajectory()

    def _on_n_envs_changed(self) -> None:
        if self.replay_buffer is not None:
            self.replay_buffer.set_n_envs(self.n_envs)

    def seed_replay(self, seed: int | None) -> None:
        """Reseed the generator that picks trajectories, so models given the same buffer replay the same ones.

        :param seed: the seed of the replay generator; None seeds it from fresh entropy.
        """
        self.replay_rng = kernels.new_rng_state(seed, kernels.RNG_STREAM_REPLAY)

    def _after_transition(self, env, slots, obs, action, reward, next_obs, terminated, done, info) -> None:
        """Store the transition in env ``env``'s open trajectory, closing it at an episode's end (and at a segment's
        end with ``replay_unit="segment"``), then replay at a trigger (Alg. 7 lines 10-13)."""
        segment_end = bool(info.get("segment_end", False))
        closes = done or (segment_end and self.replay_unit == "segment")
        self.replay_buffer.add(obs, slots, action, reward, next_obs, env, end=terminated if closes else None)
        self._new_samples += 1
        if not (done or segment_end):
            return
        episode_trigger = done and (self._episode_num + 1) % self.replay_every == 0
        if self.replay_trigger == "segment" or episode_trigger:
            self._replay_at_trigger()

    def _replays_per_phase(self) -> int:
        per_stored = self.stabilizers["replays_per_stored_trajectory"]
        if per_stored is not None:
            return int(round(per_stored * self.replay_buffer.n_stored_trajectories))
        return self.stabilizers["n_replays"]

    def _replay_at_trigger(self) -> None:
        """One replay phase at a trigger: ``n_replays`` (or ``replays_per_stored_trajectory`` times the stored)
        trajectories, or with ``replay_ratio`` whole trajectories until the phase has made ratio x (the transitions
        stored since the last phase) updates, the excess carried to the next phase."""
        ratio = self.stabilizers["replay_ratio"]
        if ratio is None:
            self.replay(self._replays_per_phase())
            return
        budget = ratio * self._new_samples + self._ratio_carry
        self._new_samples = 0
        if budget < 1.0:
            self._ratio_carry = max(budget, 0.0)
            return
        updates = self.replay(UNLIMITED, max_updates=int(budget))["updates"]
        # a phase of trajectories ends by its budget, at most one trajectory beyond it: that excess is carried; a phase
        # that ends short (nothing stored, or prioritized sweeping with no |delta| above its threshold) carries nothing
        self._ratio_carry = budget - updates if updates >= int(budget) else 0.0

    def replay(self, n_trajectories: int, max_updates: int | None = None) -> dict[str, float]:
        """One replay phase of n_trajectories on the stored data (one kernel call); returns its update count and mean
        |delta|, and for ER-sigma the phase's mean target shift T_sigma - T and the shares of targets it raised and
        lowered (``sigma_shift``, ``sigma_raised``, ``sigma_lowered``; with the value watch on). Prioritized sweeping
        makes ``prioritized_updates`` updates, by default n_trajectories times the mean length of a stored
        trajectory.

        :param n_trajectories: trajectories to replay in this phase (drawn uniformly from those stored, the open one
            included).
        :param max_updates: begin no trajectory once the phase has made this many updates (default None: no limit).
        """
        buffer = self.replay_buffer
        if buffer.n_stored_trajectories == 0 or n_trajectories <= 0:
            return {"updates": 0, "td_error": 0.0}
        watch = self._watch
        watch.begin_phase(buffer)
        if self._target_copy is not None:  # the copy bootstrapping reads: taken anew at each phase (Chen et al.)
            kernels.refresh_target(self._weights())
        rule = self._update_rule(
            target_kind=TARGETS[self.target],
            sigma_kind=SIGMAS[self.sigma],
            residual_zeta=0.0 if self.residual_zeta is None else self.residual_zeta,
            residual_next_action=self.residual_action == "next",
        )
        weights, data, layout = self._weights(), buffer.replay_data(), self.policy.tile_coder.layout
        if self.replay_order == "prioritized":  # single transitions: a budget of updates is the phase's length
            if max_updates is not None:
                n_updates = max_updates
            elif self.prioritized_updates is not None:
                n_updates = self.prioritized_updates
            else:
                n_updates = round(n_trajectories * buffer.n_transitions / buffer.n_stored_trajectories)
            sweep = kernels.make(
                kernels.Sweep,
                n_updates=n_updates,
                threshold=self.priority_threshold,
                predecessors=PREDECESSORS[self.predecessors],
                max_predecessors=self.max_predecessors,
            )
            updates, sum_abs_delta, last_delta, status, evaluations = kernels.prioritized_phase(
                weights, data, layout, rule, sweep, self.action_rng, self._scratch, self._priority_queue(), watch.array
            )
            self.priority_evaluations += evaluations
        else:
            replay = kernels.make(
                kernels.Replay,
                n_trajectories=n_trajectories,
                max_updates=-1 if max_updates is None else max_updates,
                order=REPLAY_ORDERS[self.replay_order],
                picks_rng=self.replay_rng,
            )
            updates, sum_abs_delta, last_delta, status = kernels.replay_phase(
                weights, data, layout, rule, replay, self.action_rng, self._scratch, watch.array
            )
        self.replay_updates += updates
        self.replay_phases += 1
        shift, first = watch.end_phase(status == kernels.STATUS_OUT_OF_BOUNDS)
        self._check_status(
            status, f"replayed update {first if first else updates} of replay phase {self.replay_phases}", last_delta
        )
        self._td_error_sum += sum_abs_delta
        self._td_error_count += updates
        return {"updates": updates, "td_error": sum_abs_delta / max(updates, 1), **shift}

    def _priority_queue(self) -> kernels.PriorityQueue:
        """The workspace of ``kernels.prioritized_phase`` (a :class:`~sb3_er.common.kernels.bundles.PriorityQueue`),
        allocated here (the kernel allocates nothing) and grown with the buffer.

        Arrays indexed by a buffer row have one entry per row of the ring; the heap and the tile index grow in steps
        of doubling with the stored transitions. Nothing of it is saved: the queue is rebuilt at every phase.
        """
        buffer = self.replay_buffer
        coder = self.policy.tile_coder
        queue = self._priority_workspace
        if queue is None or queue.position.shape[0] != buffer.capacity:
            queue = kernels.PriorityQueue(
                rows=np.zeros(0, dtype=np.int64),
                keys=np.zeros(0, dtype=np.float64),
                position=np.full(buffer.capacity, -1, dtype=np.int64),
                size=np.zeros(1, dtype=np.int64),
                index_start=np.zeros(0, dtype=np.int64),
                index_rows=np.zeros(0, dtype=np.int64),
                stamp=np.zeros(buffer.capacity, dtype=np.int64),
                stamp_counter=np.zeros(1, dtype=np.int64),
            )
        n = buffer.n_transitions
        if queue.rows.shape[0] < n:
            size = min(buffer.capacity, max(n, 2 * queue.rows.shape[0]))
            queue = queue._replace(rows=np.zeros(size, dtype=np.int64), keys=np.zeros(size, dtype=np.float64))
        if self.predecessors == "tiles":
            if queue.index_start.shape[0] != coder.slot_mask + 2:
                queue = queue._replace(index_start=np.zeros(coder.slot_mask + 2, dtype=np.int64))
            if queue.index_rows.shape[0] < n * coder.n_tilings:
                rows = min(buffer.capacity, max(n, 2 * queue.index_rows.shape[0] // coder.n_tilings))
                queue = queue._replace(index_rows=np.zeros(rows * coder.n_tilings, dtype=np.int64))
        elif queue.index_start.shape[0] == 0:
            queue = queue._replace(index_start=np.zeros(1, dtype=np.int64))
        self._priority_workspace = queue
        return queue

    def _record_train_metrics(self) -> None:
        watch = self._watch.array if self._watch is not None else kernels.NO_WATCH
        if self.stabilizers["truncate_targets"] and watch.shape[0] and watch[kernels.WATCH_PERIOD_UPDATES] > 0:
            truncated = watch[kernels.WATCH_TRUNCATED] / watch[kernels.WATCH_PERIOD_UPDATES]
            self.logger.record("train/truncated_share", float(truncated))
        if self.stabilizers["project_weights"] and watch.shape[0] and watch[kernels.WATCH_PERIOD_UPDATES] > 0:
            projected = watch[kernels.WATCH_PROJECTED] / watch[kernels.WATCH_PERIOD_UPDATES]
            self.logger.record("train/projected_share", float(projected))
        if self.stabilizers["step_size_bound"]:
            bound = float(self._step_cap[0]) * self.policy.tile_coder.n_tilings
            self.logger.record("train/effective_learning_rate", min(self.current_learning_rate, bound))
        super()._record_train_metrics()
        self.logger.record("train/replay_ratio", self.replay_updates / max(self.num_timesteps, 1))
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
        n_replays: int | None = None,
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
        preset: Literal["thesis", "stable"] = "thesis",
        truncate_targets: bool | None = None,
        target_copy: bool | None = None,
        step_size_bound: bool | None = None,
        averager: bool | None = None,
        project_weights: bool | None = None,
        replay_ratio: float | None = None,
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
            preset=preset,
            truncate_targets=truncate_targets,
            target_copy=target_copy,
            step_size_bound=step_size_bound,
            averager=averager,
            project_weights=project_weights,
            replay_ratio=replay_ratio,
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
        n_replays: int | None = None,
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
        preset: Literal["thesis", "stable"] = "thesis",
        truncate_targets: bool | None = None,
        target_copy: bool | None = None,
        step_size_bound: bool | None = None,
        averager: bool | None = None,
        project_weights: bool | None = None,
        replay_ratio: float | None = None,
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
            preset=preset,
            truncate_targets=truncate_targets,
            target_copy=target_copy,
            step_size_bound=step_size_bound,
            averager=averager,
            project_weights=project_weights,
            replay_ratio=replay_ratio,
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
        n_replays: int | None = None,
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
        preset: Literal["thesis", "stable"] = "thesis",
        truncate_targets: bool | None = None,
        target_copy: bool | None = None,
        step_size_bound: bool | None = None,
        averager: bool | None = None,
        project_weights: bool | None = None,
        replay_ratio: float | None = None,
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
            preset=preset,
            truncate_targets=truncate_targets,
            target_copy=target_copy,
            step_size_bound=step_size_bound,
            averager=averager,
            project_weights=project_weights,
            replay_ratio=replay_ratio,
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

"""The argument bundles of the kernels, each documented once here.

A kernel takes a few bundles instead of a long list of positional arguments. Each bundle is a ``typing.NamedTuple``,
which numba compiles as a tuple: reading ``layout.stride`` inside a kernel costs what reading a positional argument
costs. Build bundles with :func:`make`, which converts each scalar to its annotated type, so that a kernel always
meets the same types and compiles once (an ``int`` where a ``float`` was seen before would compile a second version).

Passing a named tuple into a kernel costs about 2 us more per call than plain tuples of the same fields, as numba
types each element in Python (4.5 us against 2.0 us for 26 arrays in 4 bundles, numba 0.68, measured by
``benchmarks/replay_throughput.py``'s dispatch figures). That does not matter for a kernel called once per replay
phase; the kernels called once per environment step (:func:`~sb3_er.common.kernels.sarsa.sarsa_lambda_step`,
:func:`~sb3_er.common.kernels.policy.select_action`, :func:`~sb3_er.common.kernels.dyna.dyna_step`) take plain tuples
in the bundle's field order (``tuple(bundle)``) and name them again on entry (``TileLayout(*layout)``).
"""

from __future__ import annotations

import functools
import inspect
import typing
from typing import NamedTuple

import numpy as np

from sb3_er.common.docstrings import parameter_fields

# --- enumerations the bundles carry ----------------------------------------------------------------------------------
ORDER_REVERSED, ORDER_FORWARD, ORDER_UNIFORM, ORDER_PRIORITIZED = 0, 1, 2, 3
PREDECESSORS_TILES, PREDECESSORS_TRAJECTORY = 0, 1
TARGET_SARSA, TARGET_Q_LEARNING, TARGET_EXPECTED_SARSA = 0, 1, 2
SIGMA_NONE, SIGMA_WORST, SIGMA_AVERAGE, SIGMA_BEST, SIGMA_AVERAGE_WORST, SIGMA_AVERAGE_BEST = -1, 0, 1, 2, 3, 4

# --- what kernels return ----------------------------------------------------------------------------------------------
STATUS_OK, STATUS_DIVERGED, STATUS_TRACE_FULL, STATUS_BAD_OBSERVATION = 0, 1, 2, 3
#: A kernel call that otherwise succeeded, during which the value watch saw its first value outside the bounds.
STATUS_OUT_OF_BOUNDS = 4


class TileLayout(NamedTuple):
    """A tile coder as the kernels read it (``TileCoder.layout``). The weight of action a in tiling k at state-tile slot
    s is ``theta[s * stride + action_columns[k, a]]``: all actions of one (tiling, state tile) are adjacent in memory.

    :param inv_widths: 1 / tile width per state dimension, float64 (D,).
    :param offsets: the tilings' displacements in tile widths, float64 (N, D) (Eq. 2.9).
    :param wrap_tiles: tiles per period of each periodic dimension, int64 (D,) (0: not periodic).
    :param slot_mask: the number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: the column of each (tiling, action) within a slot's row, int64 (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    """

    inv_widths: np.ndarray
    offsets: np.ndarray
    wrap_tiles: np.ndarray
    slot_mask: int
    stride: int
    action_columns: np.ndarray
    columns_are_actions: bool


class Weights(NamedTuple):
    """The weights theta of Q(s, a) = theta . phi(s, a) (Eq. 2.8), the copy that bootstrapped values read, and how the
    weights started: weight i started at ``initial_low + initial_span * u_i``, u_i in [0, 1) a counter-based hash of
    (``initial_seed``, i) (:func:`~sb3_er.common.kernels.tiles.initial_weight`), so any weight's initial value can be
    recomputed where it is needed without a second table.

    Without a target copy (the thesis's algorithms) ``target`` is ``theta`` itself and the change log is empty. With
    one (the stabilizer of Chen, Clarke and Maguluri 2023), every update bootstraps from ``target``, a copy of theta
    taken at the start of the replay phase; each weight the kernels change is logged once (``changed``, its flag in
    ``changed_flag``) so that :func:`~sb3_er.common.kernels.tiles.refresh_target` copies only those.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param target: the weights Q(s', .) is read from when bootstrapping: ``theta``, or the target copy.
    :param changed_flag: per weight, 1 when it changed since the target copy was refreshed, uint8 (empty: no copy).
    :param changed: the changed weights' indices, int64 (room for every weight; empty: no copy).
    :param n_changed: how many entries of ``changed`` are in use, an int64 (1,) array.
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash.
    """

    theta: np.ndarray
    target: np.ndarray
    changed_flag: np.ndarray
    changed: np.ndarray
    n_changed: np.ndarray
    initial_low: float
    initial_span: float
    initial_seed: np.uint64


class UpdateRule(NamedTuple):
    """What an update does: its target, ER-sigma's sigma, the residual direction, and the step.

    :param target_kind: TARGET_SARSA (a' epsilon-greedy at s', the thesis's), TARGET_Q_LEARNING (max_a Q(s', a)) or
        TARGET_EXPECTED_SARSA (the expectation under the epsilon-greedy policy).
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of sigma(s') (Appendix B).
    :param residual_zeta: zeta of the residual direction phi(s, a) - zeta gamma phi(s', .) (Eq. 5.9); 0: plain ER.
    :param residual_next_action: the residual term takes a_{t+1} instead of a_t (Baird's residual gradient).
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param truncate: truncate each bootstrapped value to [value_low, value_high] (Chen, Clarke and Maguluri 2023;
        the value watch still sees the target before truncation).
    :param value_low: the lower end of the possible returns (used with ``truncate``).
    :param value_high: their upper end.
    :param step_bound: bound the step by Dabney and Barto's (2012) alpha-bound, so that no update overshoots its own
        target: the step per weight becomes min(step_size, step_cap[0]), and step_cap[0] <- min(step_cap[0],
        1 / |(gamma phi' - phi)^T e|) with e the update's direction (the trace, or phi(s, a) in replay).
    :param step_cap: the bound so far, a float64 (1,) array changed in place (+inf: none yet); kept by the model.
    :param averager: a replayed semi-gradient update moves each active weight towards its share of the target,
        theta_i <- theta_i + step_size (T - N theta_i), instead of adding step_size delta to each (Gordon 1995's
        averager): Q(s, a) moves by the same alpha (T - Q(s, a)), but every weight stays a convex combination of its
        start and the targets / N, so no Q leaves their range (needs alpha <= 1).
    :param project: after a replayed update, each weight it moved is projected onto [value_low / N, value_high / N]
        (projected TD: Bhandari, Russo and Singal 2018; Zou, Xu and Liang 2019 for Sarsa), so that no Q(s, a) leaves
        [value_low, value_high].
    """

    target_kind: int
    sigma_kind: int
    residual_zeta: float
    residual_next_action: bool
    step_size: float
    gamma: float
    epsilon: float
    truncate: bool
    value_low: float
    value_high: float
    step_bound: bool
    step_cap: np.ndarray
    averager: bool
    project: bool


class Trace(NamedTuple):
    """Sarsa(lambda)'s sparse replacing eligibility trace (Eq. 2.6): ``index[:length[0]]`` are the weights with a trace,
    ``value`` their traces, ``position[i]`` where weight i sits in that list (-1: no trace).

    :param index: the weights with a non-zero trace, int64 (capacity,).
    :param value: their traces, float64 (capacity,).
    :param position: each weight's place in ``index``, -1 if absent, int32 (weights,).
    :param length: the trace's length, an int64 (1,) array changed in place.
    :param decay: gamma lambda, the decay per step.
    :param cutoff: traces that decay below it are dropped.
    """

    index: np.ndarray
    value: np.ndarray
    position: np.ndarray
    length: np.ndarray
    decay: float
    cutoff: float


class Transition(NamedTuple):
    """One real transition (s_k, a_k, r_{k+1}, s_{k+1}) of the environment, as the per-step kernels take it.

    :param slots: the state-tile slots of s_k, int64 (N,).
    :param action: a_k, the flat action index.
    :param reward: the reward r_{k+1}.
    :param terminated: whether s_{k+1} is terminal (no bootstrap from it).
    :param next_obs: s_{k+1}, float64 (D,).
    :param next_slots: written: the state-tile slots of s_{k+1}, int64 (N,).
    """

    slots: np.ndarray
    action: int
    reward: float
    terminated: bool
    next_obs: np.ndarray
    next_slots: np.ndarray


class Trajectories(NamedTuple):
    """The stored data of experience replay (``TrajectoryReplayBuffer.trajectories_bundle()``): transitions in a ring of
    rows, grouped in trajectories whose rows are consecutive time steps, and the visit vector w (Eq. 5.1-5.2).

    Within a trajectory, s_{t+1} of a row is s_t of the next row; a trajectory's last s_{t+1} is stored with the
    trajectory, with whether it was terminal. The open trajectory (the episode in progress) follows the closed rows in
    the ring and is one of the stored trajectories (Alg. 8 line 2 draws e' from {1, ..., e}, the current episode e
    included); its last transition bootstraps from ``open_next_slots``, the tiles of its latest s_{t+1}.

    :param visits: w (Eq. 5.2): one uint8 per weight, like theta, set for the features of every stored (s_t, a_t).
    :param slots: the state-tile slots of each stored s_t, int64 (rows, N).
    :param actions: the flat action of each stored row, int64 (rows,).
    :param rewards: the reward of each stored row, float64 (rows,).
    :param transition_trajectory: the trajectory of each stored row, int64 (rows,).
    :param trajectory_start: the first row of each trajectory, int64 (trajectories,).
    :param trajectory_length: the rows of each trajectory, int64 (trajectories,).
    :param trajectory_terminated: whether each trajectory ended in a terminal state, bool (trajectories,).
    :param trajectory_next_slots: the slots of each trajectory's last s_{t+1}, int64 (trajectories, N).
    :param oldest_trajectory: the index of the oldest closed trajectory in the ring of trajectories.
    :param n_closed_trajectories: the number of closed trajectories stored.
    :param first_row: the oldest stored row.
    :param n_transitions: the stored transitions, the open trajectory's included.
    :param open_trajectory: the index of the open trajectory.
    :param open_start: the first row of the open trajectory.
    :param open_length: the rows of the open trajectory (0: none).
    :param open_next_slots: the slots of the open trajectory's latest s_{t+1}, int64 (N,).
    """

    visits: np.ndarray
    slots: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    transition_trajectory: np.ndarray
    trajectory_start: np.ndarray
    trajectory_length: np.ndarray
    trajectory_terminated: np.ndarray
    trajectory_next_slots: np.ndarray
    oldest_trajectory: int
    n_closed_trajectories: int
    first_row: int
    n_transitions: int
    open_trajectory: int
    open_start: int
    open_length: int
    open_next_slots: np.ndarray


class Replay(NamedTuple):
    """Which stored trajectories a replay phase replays, and in which order (Alg. 8 lines 1-4, Appendix A).

    :param n_trajectories: K, the trajectories to replay, each drawn uniformly from the stored ones.
    :param max_updates: no trajectory is begun once the phase has made this many updates (-1: no limit), so that a
        replay ratio of updates per new sample is kept to within one trajectory.
    :param order: ORDER_REVERSED (each from its last sample to its first, the thesis's), ORDER_FORWARD (in temporal
        order) or ORDER_UNIFORM (as many single transitions drawn uniformly from all stored ones).
    :param picks_rng: the xoshiro256** state (4 uint64) of the trajectory picks, advanced in place.
    """

    n_trajectories: int
    max_updates: int
    order: int
    picks_rng: np.ndarray


class Sweep(NamedTuple):
    """A phase of prioritized sweeping (Moore and Atkeson 1993): its budget and which predecessors it re-queues.

    :param n_updates: the most updates of the phase.
    :param threshold: only a |delta| above it is queued.
    :param predecessors: PREDECESSORS_TILES (the stored transitions whose s' shares a tile with s) or
        PREDECESSORS_TRAJECTORY (only the previous transition of the trajectory).
    :param max_predecessors: the most distinct predecessors re-queued per update.
    """

    n_updates: int
    threshold: float
    predecessors: int
    max_predecessors: int


class PriorityQueue(NamedTuple):
    """Prioritized sweeping's workspace, allocated by Python and grown with the buffer: a binary max-heap of stored
    rows by |delta| in preallocated arrays, and the index from tile slots to the transitions whose s' has that tile.
    A node pops before its children: the higher priority first, on equal priorities the lower row (the order of
    Python's heapq on (-priority, row) pairs).

    :param rows: the stored row at each heap node, int64 (capacity,).
    :param keys: the priority |delta| of each node, float64 (capacity,).
    :param position: the node of each row, -1 for a row not queued, int64 (rows,).
    :param size: the number of queued rows, an int64 (1,) array changed in place.
    :param index_start: the predecessor index's start per slot, int64 (slots + 1,).
    :param index_rows: the predecessor index's rows, int64 (n_transitions * N,).
    :param stamp: per row, the last update that queued it as a predecessor, int64 (rows,).
    :param stamp_counter: the update counter of ``stamp``, an int64 (1,) array.
    """

    rows: np.ndarray
    keys: np.ndarray
    position: np.ndarray
    size: np.ndarray
    index_start: np.ndarray
    index_rows: np.ndarray
    stamp: np.ndarray
    stamp_counter: np.ndarray


class Plan(NamedTuple):
    """Dyna's planned transitions, predicted by its model when it was fit (rows with a negative ``continuation`` were
    not covered by the model and are skipped).

    :param slots: the slots of each planned s, int64 (M, N).
    :param actions: their actions, int64 (M,).
    :param rewards: their predicted rewards, float64 (M,).
    :param continuation: their predicted probability that s' is not terminal (negative: not covered), float64 (M,).
    :param next_slots: the slots of each predicted s', int64 (M, N).
    :param start: the first planned row to use.
    :param count: the planning updates to make.
    """

    slots: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    continuation: np.ndarray
    next_slots: np.ndarray
    start: int
    count: int


class Scratch(NamedTuple):
    """Scratch space of one state's action values, allocated once per model (kernels allocate nothing).

    :param q: Q(s, .), float64 (A,).
    :param w: W(s, .) = w . phi(s, .) for ER-sigma (Eq. 5.1), float64 (A,).
    """

    q: np.ndarray
    w: np.ndarray


BUNDLES = (
    TileLayout,
    Weights,
    UpdateRule,
    Trace,
    Transition,
    Trajectories,
    Replay,
    Sweep,
    PriorityQueue,
    Plan,
    Scratch,
)

_SCALARS = {int: int, float: float, bool: bool, np.uint64: np.uint64}


@functools.cache
def _converters(bundle: type) -> tuple:
    """Per field of ``bundle``, the converter of its annotated scalar type, or None for an array."""
    hints = typing.get_type_hints(bundle)
    return tuple(_SCALARS.get(hints[name]) for name in bundle._fields)


def make(bundle: type, **fields):
    """An instance of ``bundle`` with each scalar field converted to its annotated type (``int``, ``float``, ``bool``,
    ``np.uint64``), so that every call meets the types the kernel compiled for; arrays are taken as they are.

    :param bundle: one of the bundle classes of this module.
    :param fields: every field of the bundle, by name.
    """
    if fields.keys() != set(bundle._fields):
        missing = sorted(set(bundle._fields) - set(fields))
        unknown = sorted(set(fields) - set(bundle._fields))
        raise TypeError(f"{bundle.__name__}: missing fields {missing}, unknown fields {unknown}")
    return bundle(
        *(
            fields[name] if convert is None else convert(fields[name])
            for name, convert in zip(bundle._fields, _converters(bundle), strict=True)
        )
    )


NO_CHANGE_LOG = np.zeros(0, dtype=np.uint8)
NO_CHANGES = np.zeros(0, dtype=np.int64)


class TargetCopy:
    """A copy of theta that bootstrapped values read, refreshed at the start of each replay phase (Chen, Clarke and
    Maguluri's target network), with the log of the weights changed since: a refresh copies those alone, so its cost
    follows the updates made, not the table's size.

    :param theta: the weights to copy.
    """

    def __init__(self, theta: np.ndarray):
        self.values = theta.copy()
        self.changed_flag = np.zeros(theta.shape[0], dtype=np.uint8)
        self.changed = np.zeros(theta.shape[0], dtype=np.int64)
        self.n_changed = np.zeros(1, dtype=np.int64)


def update_rule(
    step_size: float,
    gamma: float,
    epsilon: float = 0.0,
    *,
    target_kind: int = TARGET_SARSA,
    sigma_kind: int = SIGMA_NONE,
    residual_zeta: float = 0.0,
    residual_next_action: bool = False,
    truncate: bool = False,
    value_low: float = -np.inf,
    value_high: float = np.inf,
    step_bound: bool = False,
    step_cap: np.ndarray | None = None,
    averager: bool = False,
    project: bool = False,
) -> UpdateRule:
    """An :class:`UpdateRule` with the stabilizers off unless given: the thesis's Sarsa update by default (the
    fields are documented on the class). ``step_cap`` None gives a fresh bound of +inf."""
    return make(
        UpdateRule,
        target_kind=target_kind,
        sigma_kind=sigma_kind,
        residual_zeta=residual_zeta,
        residual_next_action=residual_next_action,
        step_size=step_size,
        gamma=gamma,
        epsilon=epsilon,
        truncate=truncate,
        value_low=value_low,
        value_high=value_high,
        step_bound=step_bound,
        step_cap=np.full(1, np.inf) if step_cap is None else step_cap,
        averager=averager,
        project=project,
    )


# each argument is the UpdateRule field of its name: its documentation is the class's, shown by help() and the API pages
update_rule.__doc__ = (
    inspect.cleandoc(update_rule.__doc__)
    + "\n\n"
    + "\n".join(parameter_fields(UpdateRule.__doc__)[name] for name in inspect.signature(update_rule).parameters)
)


def weights_bundle(
    theta: np.ndarray, initial_low: float, initial_span: float, initial_seed, target: TargetCopy | None = None
) -> Weights:
    """The Weights of ``theta``: without ``target``, bootstrapping reads theta itself; with a TargetCopy, it reads
    the copy and the kernels log their changes into it.

    :param theta: the weights.
    :param initial_low: the initial weights' lower end.
    :param initial_span: their range.
    :param initial_seed: the seed of their hash.
    :param target: the TargetCopy, or None (default).
    """
    if target is None:
        values, flag, changed, n_changed = theta, NO_CHANGE_LOG, NO_CHANGES, np.zeros(1, dtype=np.int64)
    else:
        values, flag, changed, n_changed = target.values, target.changed_flag, target.changed, target.n_changed
    return make(
        Weights,
        theta=theta,
        target=values,
        changed_flag=flag,
        changed=changed,
        n_changed=n_changed,
        initial_low=initial_low,
        initial_span=initial_span,
        initial_seed=initial_seed,
    )

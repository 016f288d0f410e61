"""Numba kernels: tile indices, action selection, the Sarsa(lambda) step and a whole replay phase.

Everything that runs per update lives here and reads like the thesis pseudocode (equation and algorithm numbers refer to
the thesis). Conventions shared by all kernels:

- A tile coder is given by ``inv_widths`` (D,), ``offsets`` (N, D) in tile units, ``wrap_tiles`` (D,) (0 = no wrap),
  ``slot_mask`` (number of state-tile slots minus one), ``stride``, ``action_columns`` (N, A) and
  ``columns_are_actions`` (True when actions are not tiled, so column a is action a). The weight of action a in tiling
  k at state-tile slot s is ``theta[s * stride + action_columns[k, a]]``: all actions of one (tiling, state tile) are
  adjacent in memory.
- Q(s, a) = sum of the N active weights (Eq. 2.8); a learning rate alpha on Q moves each active weight by alpha / N,
  passed in as ``step_size``.
- Random numbers come from a xoshiro256** generator whose 4-word state array is passed in (``new_rng_state`` seeds
  one); a NumPy Generator would cost ~20 us per kernel call to unbox. Kernels allocate nothing.
- Initial weights are ``initial_low + initial_span * u_i`` with u_i in [0, 1) a counter-based hash of
  (``initial_seed``, i) (:func:`initial_weight`), so any weight's initial value can be recomputed where it is needed
  (ER-sigma at unvisited features, the statistics of touched weights) without storing a second table.
"""

import numba as nb
import numpy as np

ORDER_REVERSED, ORDER_FORWARD, ORDER_UNIFORM, ORDER_PRIORITIZED = 0, 1, 2, 3
PREDECESSORS_TILES, PREDECESSORS_TRAJECTORY = 0, 1
TARGET_SARSA, TARGET_Q_LEARNING, TARGET_EXPECTED_SARSA = 0, 1, 2
SIGMA_NONE, SIGMA_WORST, SIGMA_AVERAGE, SIGMA_BEST, SIGMA_AVERAGE_WORST, SIGMA_AVERAGE_BEST = -1, 0, 1, 2, 3, 4

STATUS_OK, STATUS_DIVERGED, STATUS_TRACE_FULL, STATUS_BAD_OBSERVATION = 0, 1, 2, 3
#: A kernel call that otherwise succeeded, during which the value watch saw its first value outside the bounds.
STATUS_OUT_OF_BOUNDS = 4

# The value watch: a float64 array of WATCH_SIZE entries that the learning kernels update in place with every target
# T and every Q(s_t, a_t) before its update (see :func:`watch_update`); an empty array switches it off. Python sets
# the bounds [WATCH_LOW, WATCH_HIGH] (the possible returns widened by a tolerance, sb3_er.common.value_bounds) and
# resets the per-period entries after logging them; counts and the first excursion accumulate for the model's life.
(
    WATCH_TARGET_MIN,
    WATCH_TARGET_MAX,
    WATCH_Q_MIN,
    WATCH_Q_MAX,  # per logging period
    WATCH_SHIFT_SUM,
    WATCH_SHIFT_COUNT,
    WATCH_RAISED,
    WATCH_LOWERED,  # per logging period: ER-sigma's T_sigma - T
    WATCH_LOW,
    WATCH_HIGH,  # the bounds, set by Python
    WATCH_UPDATES,
    WATCH_OUT_OF_RANGE,  # cumulative: updates watched, values (T or Q) outside the bounds
    WATCH_FIRST_UPDATE,
    WATCH_FIRST_VALUE,
) = range(14)  # the first value outside: its update number (-1: none), value
WATCH_SIZE = 14
WATCH_PERIOD = (
    WATCH_TARGET_MIN,
    WATCH_TARGET_MAX,
    WATCH_Q_MIN,
    WATCH_Q_MAX,
    WATCH_SHIFT_SUM,
    WATCH_SHIFT_COUNT,
    WATCH_RAISED,
    WATCH_LOWERED,
)

#: (initial_low, initial_span, initial_seed) of all-zero initial weights, the thesis's theta <- 0.
ZERO_INITIAL = (0.0, 0.0, np.uint64(0))

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@nb.njit(inline="always", cache=True)
def _mix64(h):
    """The splitmix64 finaliser: a bijective 64-bit mix."""
    h ^= h >> np.uint64(30)
    h *= _MIX1
    h ^= h >> np.uint64(27)
    h *= _MIX2
    h ^= h >> np.uint64(31)
    return h


RNG_STREAM_ACTIONS, RNG_STREAM_REPLAY, RNG_STREAM_PREDICT = 0, 1, 2
RNG_STREAM_PLANNING = 100  # Dyna's planning picks


def new_rng_state(seed=None, stream: int = RNG_STREAM_ACTIONS) -> np.ndarray:
    """A seeded xoshiro256** state for the kernels; each stream of one seed is independent (None: fresh entropy).

    :param seed: the seed (default None: fresh entropy).
    :param stream: the stream of that seed (RNG_STREAM_*; default the actions' stream).
    """
    return np.random.SeedSequence(seed, spawn_key=(stream,)).generate_state(4, dtype=np.uint64)


@nb.njit(inline="always", cache=True)
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@nb.njit(inline="always", cache=True)
def random_uint64(state):
    """Next output of xoshiro256** (Blackman and Vigna, 2018); advances state in place.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    """
    result = _rotl(state[1] * np.uint64(5), 7) * np.uint64(9)
    t = state[1] << np.uint64(17)
    state[2] ^= state[0]
    state[3] ^= state[1]
    state[1] ^= state[2]
    state[0] ^= state[3]
    state[2] ^= t
    state[3] = _rotl(state[3], 45)
    return result


@nb.njit(inline="always", cache=True)
def random_float(state):
    """Uniform in [0, 1) with 53 random bits.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    """
    return np.float64(random_uint64(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(inline="always", cache=True)
def random_integer(state, n):
    """Uniform in {0, ..., n-1}.

    :param state: a xoshiro256** state (4 uint64), advanced in place.
    :param n: the number of values, at least 1.
    """
    return np.int64(random_float(state) * n)


@nb.njit(inline="always", cache=True)
def tile_coordinate(x, inv_width, offset, wrap_tiles):
    """Integer tile coordinate of x in a tiling displaced by ``offset`` tile widths (Eq. 2.9), wrapped if periodic.

    :param x: the state's value in this dimension.
    :param inv_width: 1 / the tile width.
    :param offset: the tiling's displacement in tile widths.
    :param wrap_tiles: tiles per period (0: not periodic).
    """
    c = np.int64(np.floor(x * inv_width + offset))
    if wrap_tiles > 0:
        c = c % wrap_tiles
    return c


@nb.njit(inline="always", cache=True)
def hash_tile(tiling, coords_hash):
    """Final slot hash of one tiling given the running hash of its coordinates.

    :param tiling: the tiling's index k.
    :param coords_hash: the running hash of its coordinates.
    """
    return _mix64(coords_hash ^ (np.uint64(tiling) * _GOLDEN))


#: Largest |x / width| a tile coordinate may have: beyond it the int64 coordinate would overflow.
MAX_TILE_COORDINATE = 2.0**62


@nb.njit(cache=True)
def state_slots(obs, inv_widths, offsets, wrap_tiles, slot_mask, out_slots):
    """Hashed state-tile slot of obs in each tiling; False if an entry of obs is NaN, infinite or so large that its
    tile coordinate would overflow (|x / width| >= MAX_TILE_COORDINATE).

    :param obs: the state s, float64 (D,).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param out_slots: written: the state-tile slots, (N,) (or (B, N) for a batch).
    """
    n_dims = obs.shape[0]
    for d in range(n_dims):
        if not abs(obs[d] * inv_widths[d]) < MAX_TILE_COORDINATE:
            return False
    for k in range(offsets.shape[0]):
        h = _GOLDEN
        for d in range(n_dims):
            c = tile_coordinate(obs[d], inv_widths[d], offsets[k, d], wrap_tiles[d])
            h = _mix64(h ^ (np.uint64(c) + _GOLDEN * np.uint64(d + 1)))
        out_slots[k] = np.int64(hash_tile(k, h) & np.uint64(slot_mask))
    return True


@nb.njit(inline="always", cache=True)
def q_value(theta, slots, stride, action_columns, action):
    """Q(s, a) = theta . phi(s, a) (Eq. 2.8).

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param action: the flat action index a.
    """
    q = 0.0
    for k in range(slots.shape[0]):
        q += theta[slots[k] * stride + action_columns[k, action]]
    return q


@nb.njit(inline="always", cache=True)
def all_q_values(theta, slots, stride, action_columns, columns_are_actions, out_q):
    """Q(s, .) over all actions: the state part of each tiling once, then its row of adjacent action weights.

    Without action tiling (``columns_are_actions``) a row is read contiguously, which the compiler vectorises.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param out_q: written: Q(s, .), (A,) (or (B, A) for a batch).
    """
    n_actions = np.uint64(out_q.shape[0])
    for a in range(n_actions):
        out_q[a] = 0.0
    for k in range(slots.shape[0]):
        row = theta[slots[k] * stride : (slots[k] + 1) * stride]
        if columns_are_actions:
            for a in range(n_actions):
                out_q[a] += row[a]
        else:
            for a in range(n_actions):
                out_q[a] += row[np.uint64(action_columns[k, a])]


@nb.njit(inline="always", cache=True)
def initial_weight(i, initial_low, initial_span, initial_seed):
    """The initial value of weight i: initial_low + initial_span * u_i, u_i uniform in [0, 1) (splitmix64 of the
    seed and i: a counter-based generator, so the value is recomputed rather than stored).

    :param i: a weight index (or, for the heap, a node index).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    """
    if initial_span == 0.0:
        return initial_low
    u = np.float64(_mix64(initial_seed ^ (np.uint64(i) * _GOLDEN)) >> np.uint64(11)) * (1.0 / 9007199254740992.0)
    return initial_low + initial_span * u


@nb.njit(cache=True)
def fill_initial_weights(theta, initial_low, initial_span, initial_seed):
    """theta_i <- its initial value (Alg. 7-14 line 1 with a user-chosen initialisation instead of 0).

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    """
    for i in range(theta.shape[0]):
        theta[i] = initial_weight(i, initial_low, initial_span, initial_seed)


@nb.njit(inline="always", cache=True)
def all_q_values_and_visit_counts(
    theta,
    visits,
    slots,
    stride,
    action_columns,
    columns_are_actions,
    out_q,
    out_w,
    initial_low,
    initial_span,
    initial_seed,
):
    """Q_v(s, .) and W(s, .) = w . phi(s, .) (Eq. 5.1-5.2: how many active features of (s, a) were ever visited) in
    one pass over the same rows.

    Q_v(s, a) is the sum of the weights of the visited features of (s, a) only: the value carried by experience, so
    that Eq. 5.4 *replaces* the unvisited ones by sigma(s') ("the unvisited parameters have been replaced with the
    value of sigma(s')", thesis 5.2.2). An unvisited weight is left out whatever it holds: its initial value, or what
    the residual term of Eq. 5.7-5.9 wrote into phi(s', a) (residual ER-sigma, Alg. 14), which Eq. 5.4's literal
    Q(s', a) + u sigma N would count and then extrapolate again through sigma. Where no unvisited weight was ever
    written (every variant but the residual ones) this is Q(s, a) minus the initial values of its unvisited
    features, bit for bit (each is subtracted as it was added); with zero initial weights, Q(s, a) itself. The
    initial-value arguments are not needed for that and kept for the callers.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param out_q: written: Q_v(s, .), (A,).
    :param out_w: written: W(s, .), (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    """
    n_actions = np.uint64(out_q.shape[0])
    has_initial = initial_low != 0.0 or initial_span != 0.0
    for a in range(n_actions):
        out_q[a] = 0.0
        out_w[a] = 0.0
    for k in range(slots.shape[0]):
        base = slots[k] * stride
        row = theta[base : base + stride]
        visited = visits[base : base + stride]
        if columns_are_actions and not has_initial:
            for a in range(n_actions):
                out_q[a] += row[a] * visited[a]
                out_w[a] += visited[a]
        else:
            # Only non-zero initial values and the residual term of Eq. 5.7-5.9 make an unvisited weight non-zero. A
            # row without such a weight takes the plain sums (leaving out 0.0 is adding it); in the others each
            # weight is added and the unvisited ones are taken out again, branch-free.
            written = False
            for c in range(stride):
                written |= (visited[c] == 0) & (row[c] != 0.0)
            if not written:
                for a in range(n_actions):
                    column = np.uint64(a) if columns_are_actions else np.uint64(action_columns[k, a])
                    out_q[a] += row[column]
                    out_w[a] += visited[column]
                continue
            for a in range(n_actions):
                column = np.uint64(a) if columns_are_actions else np.uint64(action_columns[k, a])
                value = row[column]
                seen = visited[column]
                out_q[a] += value
                out_w[a] += seen
                out_q[a] -= value * np.float64(seen == 0)


@nb.njit(inline="always", cache=True)
def argmax_first(values):
    """The index of the largest of ``values``, the lowest one on ties (a greedy action without a random draw).

    :param values: action values, float64 (A,).
    """
    best = 0
    for a in range(1, values.shape[0]):
        if values[a] > values[best]:
            best = a
    return best


@nb.njit(inline="always", cache=True)
def argmax_random_ties(values, rng):
    """Greedy action, ties broken uniformly at random; a random draw only when there is a tie.

    Three branch-free passes (max, count of maxima, pick) beat one pass with data-dependent branches.

    :param values: action values, float64 (A,).
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    """
    n = np.uint64(values.shape[0])
    best_value = values[0]
    for a in range(n):
        best_value = max(best_value, values[a])
    n_ties = 0
    for a in range(n):
        n_ties += values[a] == best_value
    pick = 0 if n_ties == 1 else random_integer(rng, n_ties)
    for a in range(n):
        if values[a] == best_value:
            if pick == 0:
                return np.int64(a)
            pick -= 1
    return np.int64(0)


@nb.njit(inline="always", cache=True)
def epsilon_greedy(values, epsilon, rng):
    """argmax_a values[a] w.p. 1 - epsilon, a uniform random action w.p. epsilon (Alg. 2 line 8, Alg. 8 line 6).

    :param values: action values, float64 (A,).
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    """
    return epsilon_greedy_explored(values, epsilon, rng)[0]


@nb.njit(inline="always", cache=True)
def epsilon_greedy_explored(values, epsilon, rng):
    """:func:`epsilon_greedy`'s action and whether it was the exploratory draw, from the same random numbers.

    :param values: action values, float64 (A,).
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    """
    if epsilon > 0.0 and random_float(rng) < epsilon:
        return random_integer(rng, values.shape[0]), True
    return argmax_random_ties(values, rng), False


@nb.njit(cache=True)
def select_action(
    theta,
    obs,
    inv_widths,
    offsets,
    wrap_tiles,
    slot_mask,
    stride,
    action_columns,
    columns_are_actions,
    epsilon,
    rng,
    out_slots,
    q_scratch,
):
    """Epsilon-greedy a_k at s_k (Alg. 7 line 8); fills out_slots with the tiles of s_k. Returns -1 for a bad obs.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param obs: the state s, float64 (D,).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param out_slots: written: the state-tile slots, (N,) (or (B, N) for a batch).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    """
    if not state_slots(obs, inv_widths, offsets, wrap_tiles, slot_mask, out_slots):
        return -1
    all_q_values(theta, out_slots, stride, action_columns, columns_are_actions, q_scratch)
    return epsilon_greedy(q_scratch, epsilon, rng)


@nb.njit(cache=True)
def greedy_actions(
    theta,
    observations,
    inv_widths,
    offsets,
    wrap_tiles,
    slot_mask,
    stride,
    action_columns,
    columns_are_actions,
    slots_scratch,
    q_scratch,
    out_actions,
):
    """Greedy action (lowest index on ties) for each row of observations; False if a row is not finite.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param observations: the states, float64 (B, D).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param slots_scratch: scratch for one state's slots, (N,).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param out_actions: written: the greedy action of each row, (B,).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], inv_widths, offsets, wrap_tiles, slot_mask, slots_scratch):
            return False
        all_q_values(theta, slots_scratch, stride, action_columns, columns_are_actions, q_scratch)
        out_actions[i] = argmax_first(q_scratch)
    return True


@nb.njit(cache=True)
def batch_q_values(
    theta,
    observations,
    inv_widths,
    offsets,
    wrap_tiles,
    slot_mask,
    stride,
    action_columns,
    columns_are_actions,
    slots_scratch,
    out_q,
):
    """Q(s, .) for each row of observations into out_q (B, A); False if a row is not finite.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param observations: the states, float64 (B, D).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param slots_scratch: scratch for one state's slots, (N,).
    :param out_q: written: Q(s, .), (A,) (or (B, A) for a batch).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], inv_widths, offsets, wrap_tiles, slot_mask, slots_scratch):
            return False
        all_q_values(theta, slots_scratch, stride, action_columns, columns_are_actions, out_q[i])
    return True


@nb.njit(cache=True)
def mark_visited(visits, slots, stride, action_columns, action):
    """w <- w OR phi(s_k, a_k) (Eq. 5.2).

    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param action: the flat action index a.
    """
    for k in range(slots.shape[0]):
        visits[slots[k] * stride + action_columns[k, action]] = 1


@nb.njit(cache=True)
def mark_visited_tracked(visits, fresh, slots, stride, action_columns, action, new_features, n_new):
    """w <- w OR phi(s_k, a_k) (Eq. 5.2), for a pruned database (thesis 3.5.3): also whether (s_k, a_k) was covered
    before its trajectory began, W(s_k, a_k) = N counting only features visited by earlier trajectories.

    ``fresh`` flags the features first visited by the trajectory in progress and ``new_features[:n_new]`` lists
    them (room for N more is the caller's job), so that a pruned trajectory's marks can be taken back. Returns
    (n_new, covered).

    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param fresh: one bool per weight: first visited by the trajectory in progress.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param action: the flat action index a.
    :param new_features: written: the features first visited by this trajectory, appended after ``n_new``.
    :param n_new: the entries of new_features so far.
    """
    covered = True
    for k in range(slots.shape[0]):
        i = slots[k] * stride + action_columns[k, action]
        if visits[i] == 0 or fresh[i] != 0:
            covered = False
        if visits[i] == 0:
            visits[i] = 1
            fresh[i] = 1
            new_features[n_new] = i
            n_new += 1
    return n_new, covered


#: The watch switched off: kernels given an empty array watch nothing.
NO_WATCH = np.zeros(0, dtype=np.float64)


def new_watch(low: float = -np.inf, high: float = np.inf) -> np.ndarray:
    """A value watch with bounds [low, high], nothing seen yet.

    :param low: the bounds' lower end (default -inf).
    :param high: their upper end (default +inf).
    """
    watch = np.zeros(WATCH_SIZE, dtype=np.float64)
    reset_watch_period(watch)
    watch[WATCH_LOW], watch[WATCH_HIGH] = low, high
    watch[WATCH_FIRST_UPDATE] = -1.0
    watch[WATCH_FIRST_VALUE] = np.nan
    return watch


def reset_watch_period(watch: np.ndarray) -> None:
    """Start a new logging period: minima +inf, maxima -inf, shift sums and counts 0.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    watch[[WATCH_TARGET_MIN, WATCH_Q_MIN]] = np.inf
    watch[[WATCH_TARGET_MAX, WATCH_Q_MAX]] = -np.inf
    watch[[WATCH_SHIFT_SUM, WATCH_SHIFT_COUNT, WATCH_RAISED, WATCH_LOWERED]] = 0.0


@nb.njit(inline="always", cache=True)
def watch_update(watch, target, q_sa):
    """Fold one update's target T and Q(s_t, a_t) into the value watch; True when this is the first value the watch
    ever saw outside [watch[WATCH_LOW], watch[WATCH_HIGH]]. No allocation, no random number; nothing when ``watch``
    is empty (the watch switched off).

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param target: the update's target T.
    :param q_sa: Q(s_t, a_t) before the update.
    """
    if watch.shape[0] == 0:
        return False
    watch[WATCH_TARGET_MIN] = min(watch[WATCH_TARGET_MIN], target)
    watch[WATCH_TARGET_MAX] = max(watch[WATCH_TARGET_MAX], target)
    watch[WATCH_Q_MIN] = min(watch[WATCH_Q_MIN], q_sa)
    watch[WATCH_Q_MAX] = max(watch[WATCH_Q_MAX], q_sa)
    watch[WATCH_UPDATES] += 1.0
    low, high = watch[WATCH_LOW], watch[WATCH_HIGH]
    target_out = target < low or target > high
    q_out = q_sa < low or q_sa > high
    if not (target_out or q_out):
        return False
    watch[WATCH_OUT_OF_RANGE] += np.float64(target_out) + np.float64(q_out)
    if watch[WATCH_FIRST_UPDATE] >= 0.0:
        return False
    watch[WATCH_FIRST_UPDATE] = watch[WATCH_UPDATES] - 1.0
    watch[WATCH_FIRST_VALUE] = target if target_out else q_sa
    return True


@nb.njit(inline="always", cache=True)
def watch_shift(watch, shift):
    """Fold ER-sigma's target shift T_sigma - T (the same transition's target without sigma) into the watch.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param shift: T_sigma - T of one update.
    """
    if watch.shape[0] == 0:
        return
    watch[WATCH_SHIFT_SUM] += shift
    watch[WATCH_SHIFT_COUNT] += 1.0
    watch[WATCH_RAISED] += np.float64(shift > 0.0)
    watch[WATCH_LOWERED] += np.float64(shift < 0.0)


@nb.njit(cache=True)
def watch_batch(watch, targets, values):
    """Fold a batch of targets T_d and values Q(s_d, a_d) (FQI's and LSPI's sweeps over the database) into the
    watch; True when it saw its first value outside the bounds.

    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    :param targets: the targets T_d, (n,).
    :param values: the values Q(s_d, a_d), (n,).
    """
    flagged = False
    for d in range(targets.shape[0]):
        flagged |= watch_update(watch, targets[d], values[d])
    return flagged


@nb.njit(cache=True)
def sarsa_lambda_step(
    theta,
    trace_index,
    trace_value,
    trace_position,
    trace_length,
    slots,
    action,
    reward,
    terminated,
    next_obs,
    next_slots,
    q_scratch,
    inv_widths,
    offsets,
    wrap_tiles,
    slot_mask,
    stride,
    action_columns,
    columns_are_actions,
    step_size,
    gamma,
    trace_decay,
    trace_cutoff,
    epsilon,
    rng,
    watch,
):
    """One step of Sarsa(lambda) with replacing traces (Alg. 2 lines 8-12, Eq. 2.6).

    The trace is sparse: ``trace_index[:n]`` holds the weights with a non-zero trace, ``trace_value[:n]`` their traces,
    ``trace_position[i]`` where weight i sits in that list (-1 if absent); ``trace_length[0]`` is n. Traces that decay
    below ``trace_cutoff`` are dropped. Returns (a_{k+1}, delta, status); a_{k+1} is -1 when s_{k+1} is terminal and
    status reports an s_{k+1} that cannot be tiled (NaN, infinite, too large), a full trace list, or the first value
    outside the value watch's bounds (the step is made all the same).

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param trace_index: the weights with a non-zero trace (first trace_length[0] entries).
    :param trace_value: their traces.
    :param trace_position: each weight's place in trace_index, -1 if absent.
    :param trace_length: the trace's length, a (1,) array changed in place.
    :param slots: the slots of s_k, (N,).
    :param action: a_k.
    :param reward: r_{k+1}.
    :param terminated: whether s' is terminal (no bootstrap from it).
    :param next_obs: the next state s', float64 (D,).
    :param next_slots: written: the slots of s_{k+1}, (N,).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param trace_decay: gamma lambda.
    :param trace_cutoff: traces below it are dropped.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    n_tilings = slots.shape[0]
    q_sa = q_value(theta, slots, stride, action_columns, action)
    next_action = -1
    if terminated:
        target = reward
    else:
        if not state_slots(next_obs, inv_widths, offsets, wrap_tiles, slot_mask, next_slots):
            return -1, np.nan, STATUS_BAD_OBSERVATION
        all_q_values(theta, next_slots, stride, action_columns, columns_are_actions, q_scratch)
        next_action = epsilon_greedy(q_scratch, epsilon, rng)
        target = reward + gamma * q_scratch[next_action]
    delta = target - q_sa
    status = STATUS_OUT_OF_BOUNDS if watch_update(watch, target, q_sa) else STATUS_OK

    # e(s_k, a_k) = phi(s_k, a_k): replacing traces; a weight shared by two tilings (hash collision) gets trace 2.
    n = trace_length[0]
    capacity = trace_index.shape[0]
    for k in range(n_tilings):
        i = slots[k] * stride + action_columns[k, action]
        p = trace_position[i]
        if p < 0:
            if n == capacity:
                return next_action, delta, STATUS_TRACE_FULL
            p = n
            trace_index[n] = i
            trace_position[i] = n
            n += 1
        trace_value[p] = 0.0
    for k in range(n_tilings):
        trace_value[trace_position[slots[k] * stride + action_columns[k, action]]] += 1.0

    # theta <- theta + alpha delta e;  e <- gamma lambda e (dropping traces below the cut-off)
    p = 0
    while p < n:
        i = trace_index[p]
        theta[i] += step_size * delta * trace_value[p]
        decayed = trace_value[p] * trace_decay
        if decayed < trace_cutoff:
            n -= 1
            trace_position[i] = -1
            if p < n:
                moved = trace_index[n]
                trace_index[p] = moved
                trace_value[p] = trace_value[n]
                trace_position[moved] = p
                continue
        else:
            trace_value[p] = decayed
        p += 1
    trace_length[0] = n
    return next_action, delta, status


@nb.njit(cache=True)
def clear_trace(trace_index, trace_position, trace_length):
    """e <- 0 at the start of an episode (Alg. 2 line 5).

    :param trace_index: the weights with a non-zero trace.
    :param trace_position: each weight's place in trace_index, set back to -1.
    :param trace_length: the trace's length, a (1,) array set to 0.
    """
    for p in range(trace_length[0]):
        trace_position[trace_index[p]] = -1
    trace_length[0] = 0


@nb.njit(inline="always", cache=True)
def sigma_of_state(q, w, sigma_kind):
    """sigma(s') from the visited actions at s' (Appendix B; definition 4 is Alg. 10 line 6), with q = Q_v(s', .).

    Actions with W(s', a) = 0 are left out of the per-action ratios. Callers handle the state where no action was
    ever visited (0 is returned for it).

    :param q: Q_v(s', .), (A,).
    :param w: W(s', .), (A,).
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    """
    sum_q = 0.0
    sum_w = 0.0
    worst = np.inf
    best = -np.inf
    for a in range(q.shape[0]):
        sum_q += q[a]
        sum_w += w[a]
        if w[a] > 0.0:
            ratio = q[a] / w[a]
            worst = min(worst, ratio)
            best = max(best, ratio)
    if sum_w == 0.0:
        return 0.0
    average = sum_q / sum_w
    if sigma_kind == SIGMA_WORST:
        return worst
    if sigma_kind == SIGMA_AVERAGE:
        return average
    if sigma_kind == SIGMA_BEST:
        return best
    if sigma_kind == SIGMA_AVERAGE_WORST:
        return 0.5 * (average + worst)
    return 0.5 * (average + best)


@nb.njit(inline="always", cache=True)
def next_state_value(
    theta,
    visits,
    next_slots,
    stride,
    action_columns,
    columns_are_actions,
    n_tilings,
    target_kind,
    sigma_kind,
    epsilon,
    rng,
    q,
    w,
    initial_low,
    initial_span,
    initial_seed,
    want_plain=False,
    unvisited_written=False,
):
    """The bootstrap value at s' and the action a' it belongs to, on sigma-adjusted values for ER-sigma; with
    ``want_plain``, also the value without sigma (the vanilla-ER value of the same a', see below), else that value
    is the returned value itself.

    ER-sigma replaces the values of never-visited features by sigma(s') (Eq. 5.4, Alg. 10 lines 6-9):
    Q~(s', a) = Q_v(s', a) + u(a) * N * sigma(s') with u(a) N = N - W(s', a) (Eq. 5.3), Q_v as in
    :func:`all_q_values_and_visit_counts` (Q itself for zero initial weights, the thesis's setting). When no action at
    s' was ever visited (the last state of an episode cut off by a time limit) there is nothing to judge s' by:
    Q~ = Q, the initial values (0 in the thesis) and whatever generalisation put there.
    Sarsa draws a' epsilon-greedily (Alg. 8 line 6); Q-learning takes the max (Eq. 2.5); Expected Sarsa the
    expectation under the epsilon-greedy policy (a' is then the greedy action).

    The plain value is what vanilla ER would bootstrap from with the same random numbers: Q(s', a') of the same
    exploratory a' when the draw explored, else max_a Q(s', a) (Q-learning and the greedy part of Sarsa; Expected
    Sarsa's expectation on Q). It draws no random number, so results are the same with and without it; ``w`` is
    used as scratch for it when the initial weights are not zero.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param next_slots: state-tile slots of s', (N,).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param n_tilings: the number of tilings N.
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param q: scratch for Q(s', .), float64 (A,).
    :param w: scratch for W(s', .), float64 (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    :param want_plain: also return the value without sigma (default False).
    :param unvisited_written: whether unvisited weights may hold more than their initial values (residual ER-sigma;
        default False).
    """
    sigma = 0.0
    if sigma_kind == SIGMA_NONE:
        all_q_values(theta, next_slots, stride, action_columns, columns_are_actions, q)
    else:
        all_q_values_and_visit_counts(
            theta,
            visits,
            next_slots,
            stride,
            action_columns,
            columns_are_actions,
            q,
            w,
            initial_low,
            initial_span,
            initial_seed,
        )
        sum_w = 0.0
        for a in range(q.shape[0]):
            sum_w += w[a]
        if sum_w == 0.0:
            all_q_values(theta, next_slots, stride, action_columns, columns_are_actions, q)
            want_plain = False  # Q~ = Q: the plain value is the value itself
        else:
            sigma = sigma_of_state(q, w, sigma_kind)
            for a in range(q.shape[0]):
                q[a] += (n_tilings - w[a]) * sigma
    explored = False
    if target_kind == TARGET_SARSA:
        next_action, explored = epsilon_greedy_explored(q, epsilon, rng)
        value = q[next_action]
    else:
        next_action = argmax_first(q)
        value = q[next_action]
        if target_kind == TARGET_EXPECTED_SARSA:
            value = (1.0 - epsilon) * value + epsilon * np.mean(q)
    if not (want_plain and sigma_kind != SIGMA_NONE):
        return value, next_action, value
    # the plain values Q(s', .): undo the sigma terms, which gives Q_v, equal to Q when every unvisited weight is 0;
    # else (initial weights not zero, or ``unvisited_written``: residual ER-sigma's term writes into unvisited
    # features) sum the weights again into w, so that the plain value is vanilla ER's Q(s', .) exactly.
    if initial_low == 0.0 and initial_span == 0.0 and not unvisited_written:
        for a in range(q.shape[0]):
            q[a] -= (n_tilings - w[a]) * sigma
        plain = q
    else:
        all_q_values(theta, next_slots, stride, action_columns, columns_are_actions, w)
        plain = w
    if explored:
        plain_value = plain[next_action]
    else:
        plain_value = plain[argmax_first(plain)]
        if target_kind == TARGET_EXPECTED_SARSA:
            plain_value = (1.0 - epsilon) * plain_value + epsilon * np.mean(plain)
    return value, next_action, plain_value


@nb.njit(inline="always", cache=True)
def replay_update(
    theta,
    visits,
    slots,
    actions,
    rewards,
    p,
    next_slots,
    terminal,
    stride,
    action_columns,
    columns_are_actions,
    target_kind,
    sigma_kind,
    residual_zeta,
    residual_next_action,
    step_size,
    gamma,
    epsilon,
    rng,
    q,
    w,
    initial_low,
    initial_span,
    initial_seed,
    watch,
):
    """One replayed update of transition p; returns (delta, whether the watch saw its first value out of bounds).

    theta <- theta + alpha delta phi(s_t, a_t)                                  (Alg. 8 line 7, Alg. 10 line 9)
    residual: theta <- theta + alpha delta (phi(s_t, a_t) - zeta gamma phi(s_{t+1}, a_t))   (Eq. 5.7-5.9, Alg. 12/14)
    With ``residual_next_action`` the second term uses a_{t+1} instead of a_t: Baird's residual gradient of the
    squared TD error. The value watch sees T and Q(s_t, a_t) before the update, and for ER-sigma the shift
    T_sigma - T of its target over the plain one (:func:`next_state_value`).

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param actions: the flat action of each stored row, (rows,).
    :param rewards: the reward of each stored row, (rows,).
    :param p: the row of the stored transition in the ring of rows.
    :param next_slots: state-tile slots of s', (N,).
    :param terminal: whether s'_p is terminal.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    :param residual_zeta: zeta of the residual update (Eq. 5.9); 0 for plain ER.
    :param residual_next_action: use a_{t+1} instead of a_t in the residual term (Baird's residual gradient).
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param q: scratch for Q(s', .), float64 (A,).
    :param w: scratch for W(s', .), float64 (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    n_tilings = slots.shape[1]
    a = actions[p]
    q_sa = 0.0
    for k in range(n_tilings):
        q_sa += theta[slots[p, k] * stride + action_columns[k, a]]
    target = rewards[p]
    residual_action = a
    watching = watch.shape[0] > 0
    if not terminal:
        value, next_action, plain_value = next_state_value(
            theta,
            visits,
            next_slots,
            stride,
            action_columns,
            columns_are_actions,
            n_tilings,
            target_kind,
            sigma_kind,
            epsilon,
            rng,
            q,
            w,
            initial_low,
            initial_span,
            initial_seed,
            watching,
            residual_zeta > 0.0,
        )
        target += gamma * value
        if residual_next_action:
            residual_action = next_action
        if sigma_kind != SIGMA_NONE:
            watch_shift(watch, gamma * (value - plain_value))
    elif sigma_kind != SIGMA_NONE:
        watch_shift(watch, 0.0)
    delta = target - q_sa
    if not np.isfinite(delta):
        return delta, False
    flagged = watch_update(watch, target, q_sa)
    for k in range(n_tilings):
        theta[slots[p, k] * stride + action_columns[k, a]] += step_size * delta
    if residual_zeta > 0.0 and not terminal:
        for k in range(n_tilings):
            theta[next_slots[k] * stride + action_columns[k, residual_action]] -= (
                step_size * delta * residual_zeta * gamma
            )
    return delta, flagged


@nb.njit(inline="always", cache=True)
def ring_index(i, capacity):
    """i mod capacity for 0 <= i < 2 capacity, without an integer division.

    :param i: an index in [0, 2 capacity).
    :param capacity: the ring's size.
    """
    return i - capacity if i >= capacity else i


@nb.njit(cache=True)
def replay_phase(
    theta,
    visits,
    slots,
    actions,
    rewards,
    transition_trajectory,
    trajectory_start,
    trajectory_length,
    trajectory_terminated,
    trajectory_next_slots,
    oldest_trajectory,
    n_closed_trajectories,
    first_row,
    n_transitions,
    open_trajectory,
    open_length,
    open_next_slots,
    stride,
    action_columns,
    columns_are_actions,
    n_replays,
    order,
    target_kind,
    sigma_kind,
    residual_zeta,
    residual_next_action,
    step_size,
    gamma,
    epsilon,
    replay_rng,
    action_rng,
    q_scratch,
    w_scratch,
    initial_low,
    initial_span,
    initial_seed,
    watch,
):
    """Replay n_replays trajectories drawn uniformly from the stored ones (Alg. 8, 10, 12, 14 lines 1-3).

    The stored trajectories are the closed ones and, when it holds transitions, the open one: the episode in progress,
    as Alg. 8 line 2 draws e' "uniformly distributed over {1, ..., e}" with e the current episode. Its index is
    ``open_trajectory``, its rows follow the closed rows in the ring, and its last transition bootstraps from
    ``open_next_slots``, the tiles of its latest s_{t+1}. ``first_row`` is the oldest stored row and
    ``n_transitions`` counts every stored transition, the open ones included.
    Reversed order replays each from its last sample to its first (t = k..1, the thesis default); forward replays in
    temporal order; uniform replays as many transitions drawn uniformly from all stored transitions (Appendix A).
    Trajectory picks use ``replay_rng`` and exploration ``action_rng``, so variants replay exactly the same
    trajectories. Every update's target and Q(s_t, a_t) go to the value ``watch`` (:func:`watch_update`).
    Returns (updates, sum of |delta|, last delta, status); status is STATUS_OUT_OF_BOUNDS when the watch saw its first
    value outside the bounds in this phase (the phase goes on), STATUS_DIVERGED on a non-finite delta (it stops).

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param actions: the flat action of each stored row, (rows,).
    :param rewards: the reward of each stored row, (rows,).
    :param transition_trajectory: the trajectory of each stored row, (rows,).
    :param trajectory_start: the first row of each trajectory, (trajectories,).
    :param trajectory_length: the rows of each trajectory, (trajectories,).
    :param trajectory_terminated: whether each trajectory ended in a terminal state, (trajectories,).
    :param trajectory_next_slots: the slots of each trajectory's last s', (trajectories, N).
    :param oldest_trajectory: the index of the oldest closed trajectory in the ring of trajectories.
    :param n_closed_trajectories: the number of closed trajectories stored.
    :param first_row: the oldest stored row.
    :param n_transitions: the stored transitions, the open trajectory's included.
    :param open_trajectory: the index of the open trajectory (the episode in progress).
    :param open_length: the rows of the open trajectory (0: none).
    :param open_next_slots: the slots of the open trajectory's latest s', (N,).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param n_replays: trajectories to replay.
    :param order: ORDER_REVERSED, ORDER_FORWARD or ORDER_UNIFORM.
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    :param residual_zeta: zeta of the residual update (Eq. 5.9); 0 for plain ER.
    :param residual_next_action: use a_{t+1} instead of a_t in the residual term (Baird's residual gradient).
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param replay_rng: the generator of the trajectory picks (a xoshiro256** state).
    :param action_rng: the generator of exploratory draws (a xoshiro256** state).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param w_scratch: scratch for W(s', .), float64 (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    capacity = slots.shape[0]
    trajectory_capacity = trajectory_start.shape[0]
    n_trajectories = n_closed_trajectories + (1 if open_length > 0 else 0)
    open_start = ring_index(first_row + n_transitions - open_length, capacity)
    updates = 0
    sum_abs_delta = 0.0
    delta = 0.0
    status = STATUS_OK
    if n_trajectories == 0:
        return updates, sum_abs_delta, delta, status
    for _ in range(n_replays):
        j = ring_index(oldest_trajectory + random_integer(replay_rng, n_trajectories), trajectory_capacity)
        length = open_length if j == open_trajectory else trajectory_length[j]
        for step in range(length):
            if order == ORDER_UNIFORM:
                p = ring_index(first_row + random_integer(replay_rng, n_transitions), capacity)
                jp = transition_trajectory[p]
            else:
                jp = j
            if jp == open_trajectory:
                start, jp_length, end_slots, end_terminal = open_start, open_length, open_next_slots, False
            else:
                start, jp_length = trajectory_start[jp], trajectory_length[jp]
                end_slots, end_terminal = trajectory_next_slots[jp], trajectory_terminated[jp]
            if order == ORDER_UNIFORM:
                t = ring_index(p - start + capacity, capacity)
            else:
                t = length - 1 - step if order == ORDER_REVERSED else step
                p = ring_index(start + t, capacity)
            if t == jp_length - 1:
                next_slots = end_slots
                terminal = end_terminal
            else:
                next_slots = slots[ring_index(p + 1, capacity)]
                terminal = False
            delta, flagged = replay_update(
                theta,
                visits,
                slots,
                actions,
                rewards,
                p,
                next_slots,
                terminal,
                stride,
                action_columns,
                columns_are_actions,
                target_kind,
                sigma_kind,
                residual_zeta,
                residual_next_action,
                step_size,
                gamma,
                epsilon,
                action_rng,
                q_scratch,
                w_scratch,
                initial_low,
                initial_span,
                initial_seed,
                watch,
            )
            updates += 1
            if not np.isfinite(delta):
                return updates, sum_abs_delta, delta, STATUS_DIVERGED
            if flagged:
                status = STATUS_OUT_OF_BOUNDS
            sum_abs_delta += abs(delta)
    return updates, sum_abs_delta, delta, status


# --- Prioritized sweeping (Moore and Atkeson 1993; thesis 3.2, 3.5.4 and 7.2) as a replay order of ER ----------------
# The priority queue is a binary max-heap in preallocated arrays: ``heap_rows[i]`` is the stored row at heap node i,
# ``heap_keys[i]`` its priority |delta|, ``heap_position[row]`` the node of a row (-1: not queued) and
# ``heap_size[0]`` the number of queued rows. A node pops before its children: the higher priority first, on equal
# priorities the lower row (so the order is that of Python's heapq on (-priority, row) pairs).


@nb.njit(inline="always", cache=True)
def _heap_before(heap_rows, heap_keys, i, j):
    """Whether heap node i pops before node j."""
    return heap_keys[i] > heap_keys[j] or (heap_keys[i] == heap_keys[j] and heap_rows[i] < heap_rows[j])


@nb.njit(inline="always", cache=True)
def _heap_swap(heap_rows, heap_keys, heap_position, i, j):
    row_i, key_i = heap_rows[i], heap_keys[i]
    heap_rows[i], heap_keys[i] = heap_rows[j], heap_keys[j]
    heap_rows[j], heap_keys[j] = row_i, key_i
    heap_position[heap_rows[i]] = i
    heap_position[heap_rows[j]] = j


@nb.njit(cache=True)
def heap_sift_up(heap_rows, heap_keys, heap_position, i):
    """Move node i towards the root while it pops before its parent.

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued.
    :param i: a weight index (or, for the heap, a node index).
    """
    while i > 0:
        parent = (i - 1) // 2
        if not _heap_before(heap_rows, heap_keys, i, parent):
            return
        _heap_swap(heap_rows, heap_keys, heap_position, i, parent)
        i = parent


@nb.njit(cache=True)
def heap_sift_down(heap_rows, heap_keys, heap_position, heap_size, i):
    """Move node i towards the leaves while a child pops before it.

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    :param i: a weight index (or, for the heap, a node index).
    """
    size = heap_size[0]
    while True:
        first = i
        for child in (2 * i + 1, 2 * i + 2):
            if child < size and _heap_before(heap_rows, heap_keys, child, first):
                first = child
        if first == i:
            return
        _heap_swap(heap_rows, heap_keys, heap_position, i, first)
        i = first


@nb.njit(cache=True)
def heap_set(heap_rows, heap_keys, heap_position, heap_size, row, priority):
    """Queue `row` with `priority`, or change the priority of a queued row (Moore and Atkeson's "promote").

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    :param row: a stored row.
    :param priority: its priority |delta|.
    """
    i = heap_position[row]
    if i < 0:
        i = heap_size[0]
        heap_size[0] += 1
        heap_rows[i] = row
        heap_keys[i] = priority
        heap_position[row] = i
        heap_sift_up(heap_rows, heap_keys, heap_position, i)
        return
    old = heap_keys[i]
    heap_keys[i] = priority
    if priority > old:
        heap_sift_up(heap_rows, heap_keys, heap_position, i)
    else:
        heap_sift_down(heap_rows, heap_keys, heap_position, heap_size, i)


@nb.njit(cache=True)
def heap_remove(heap_rows, heap_keys, heap_position, heap_size, row):
    """Take `row` out of the queue (nothing if it is not queued).

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    :param row: a stored row.
    """
    i = heap_position[row]
    if i < 0:
        return
    last = heap_size[0] - 1
    if i != last:
        _heap_swap(heap_rows, heap_keys, heap_position, i, last)
    heap_size[0] = last
    heap_position[row] = -1
    if i != last:
        heap_sift_down(heap_rows, heap_keys, heap_position, heap_size, i)
        heap_sift_up(heap_rows, heap_keys, heap_position, i)


@nb.njit(cache=True)
def heap_pop(heap_rows, heap_keys, heap_position, heap_size):
    """(row, priority) of the first node, taken out of the queue; the queue must not be empty.

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    """
    row, priority = heap_rows[0], heap_keys[0]
    heap_remove(heap_rows, heap_keys, heap_position, heap_size, row)
    return row, priority


@nb.njit(cache=True)
def heap_heapify(heap_rows, heap_keys, heap_position, heap_size):
    """Order the first heap_size[0] nodes into a heap (Floyd's bottom-up construction, O(n)).

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    """
    for i in range(heap_size[0]):
        heap_position[heap_rows[i]] = i
    for i in range(heap_size[0] // 2 - 1, -1, -1):
        heap_sift_down(heap_rows, heap_keys, heap_position, heap_size, i)


@nb.njit(cache=True)
def heap_clear(heap_rows, heap_position, heap_size):
    """Empty the queue, leaving every heap_position at -1.

    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    """
    for i in range(heap_size[0]):
        heap_position[heap_rows[i]] = -1
    heap_size[0] = 0


@nb.njit(inline="always", cache=True)
def transition_end(
    p,
    slots,
    transition_trajectory,
    trajectory_start,
    trajectory_length,
    trajectory_terminated,
    trajectory_next_slots,
    open_trajectory,
    open_start,
    open_length,
    open_next_slots,
):
    """(tiles of s_{t+1}, terminal, t) of stored row p: the next row's tiles inside a trajectory, the trajectory's
    stored last s' at its end (the open trajectory's latest s', never terminal).

    :param p: the row of the stored transition in the ring of rows.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param transition_trajectory: the trajectory of each stored row, (rows,).
    :param trajectory_start: the first row of each trajectory, (trajectories,).
    :param trajectory_length: the rows of each trajectory, (trajectories,).
    :param trajectory_terminated: whether each trajectory ended in a terminal state, (trajectories,).
    :param trajectory_next_slots: the slots of each trajectory's last s', (trajectories, N).
    :param open_trajectory: the index of the open trajectory (the episode in progress).
    :param open_start: the first row of the open trajectory.
    :param open_length: the rows of the open trajectory (0: none).
    :param open_next_slots: the slots of the open trajectory's latest s', (N,).
    """
    capacity = slots.shape[0]
    j = transition_trajectory[p]
    if j == open_trajectory:
        start, length, end_slots, end_terminal = open_start, open_length, open_next_slots, False
    else:
        start, length = trajectory_start[j], trajectory_length[j]
        end_slots, end_terminal = trajectory_next_slots[j], trajectory_terminated[j]
    t = ring_index(p - start + capacity, capacity)
    if t == length - 1:
        return end_slots, end_terminal, t
    return slots[ring_index(p + 1, capacity)], False, t


@nb.njit(inline="always", cache=True)
def transition_priority(
    theta,
    visits,
    slots,
    actions,
    rewards,
    p,
    next_slots,
    terminal,
    stride,
    action_columns,
    columns_are_actions,
    priority_target,
    sigma_kind,
    gamma,
    epsilon,
    rng,
    q,
    w,
    initial_low,
    initial_span,
    initial_seed,
):
    """|delta| of stored transition p under the current theta, without an update: the priority of prioritized
    sweeping. ``priority_target`` is never the sampled Sarsa target (the caller passes expected Sarsa instead), so
    no random number is drawn and a priority does not depend on an exploratory draw.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param actions: the flat action of each stored row, (rows,).
    :param rewards: the reward of each stored row, (rows,).
    :param p: the row of the stored transition in the ring of rows.
    :param next_slots: state-tile slots of s', (N,).
    :param terminal: whether s' of the transition is terminal.
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param priority_target: the target of the priority, never TARGET_SARSA (see above).
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param q: scratch for Q(s', .), float64 (A,).
    :param w: scratch for W(s', .), float64 (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    """
    q_sa = 0.0
    for k in range(slots.shape[1]):
        q_sa += theta[slots[p, k] * stride + action_columns[k, actions[p]]]
    target = rewards[p]
    if not terminal:
        value, _, _ = next_state_value(
            theta,
            visits,
            next_slots,
            stride,
            action_columns,
            columns_are_actions,
            slots.shape[1],
            priority_target,
            sigma_kind,
            epsilon,
            rng,
            q,
            w,
            initial_low,
            initial_span,
            initial_seed,
        )
        target += gamma * value
    return abs(target - q_sa)


@nb.njit(cache=True)
def build_predecessor_index(
    slots,
    transition_trajectory,
    trajectory_start,
    trajectory_length,
    trajectory_terminated,
    trajectory_next_slots,
    first_row,
    n_transitions,
    open_trajectory,
    open_start,
    open_length,
    open_next_slots,
    index_start,
    index_rows,
):
    """The index from tile slots to the stored transitions whose s' has that tile (a counting sort).

    Afterwards ``index_rows[index_start[c]:index_start[c + 1]]`` are the rows p, oldest first, with slot c among the
    tiles of s'_p (terminal transitions have no s' and are left out). A row whose s' has slot c in two tilings (a
    hash collision) is listed twice. ``index_start`` has one entry per slot plus one; ``index_rows`` room for
    n_transitions * N rows.

    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param transition_trajectory: the trajectory of each stored row, (rows,).
    :param trajectory_start: the first row of each trajectory, (trajectories,).
    :param trajectory_length: the rows of each trajectory, (trajectories,).
    :param trajectory_terminated: whether each trajectory ended in a terminal state, (trajectories,).
    :param trajectory_next_slots: the slots of each trajectory's last s', (trajectories, N).
    :param first_row: the oldest stored row.
    :param n_transitions: the stored transitions, the open trajectory's included.
    :param open_trajectory: the index of the open trajectory (the episode in progress).
    :param open_start: the first row of the open trajectory.
    :param open_length: the rows of the open trajectory (0: none).
    :param open_next_slots: the slots of the open trajectory's latest s', (N,).
    :param index_start: the predecessor index's start per slot, (slots + 1,) (:func:`build_predecessor_index`).
    :param index_rows: the predecessor index's rows, (n_transitions * N,).
    """
    capacity = slots.shape[0]
    n_slots = index_start.shape[0] - 1
    for c in range(n_slots + 1):
        index_start[c] = 0
    for i in range(n_transitions):
        p = ring_index(first_row + i, capacity)
        next_slots, terminal, _ = transition_end(
            p,
            slots,
            transition_trajectory,
            trajectory_start,
            trajectory_length,
            trajectory_terminated,
            trajectory_next_slots,
            open_trajectory,
            open_start,
            open_length,
            open_next_slots,
        )
        if not terminal:
            for k in range(next_slots.shape[0]):
                index_start[next_slots[k] + 1] += 1
    for c in range(n_slots):
        index_start[c + 1] += index_start[c]
    for i in range(n_transitions):  # index_start[c] runs through slot c's rows, ending at the start of c + 1
        p = ring_index(first_row + i, capacity)
        next_slots, terminal, _ = transition_end(
            p,
            slots,
            transition_trajectory,
            trajectory_start,
            trajectory_length,
            trajectory_terminated,
            trajectory_next_slots,
            open_trajectory,
            open_start,
            open_length,
            open_next_slots,
        )
        if not terminal:
            for k in range(next_slots.shape[0]):
                index_rows[index_start[next_slots[k]]] = p
                index_start[next_slots[k]] += 1
    for c in range(n_slots, 0, -1):
        index_start[c] = index_start[c - 1]
    index_start[0] = 0


@nb.njit(cache=True)
def _requeue(
    q_row,
    theta,
    visits,
    slots,
    actions,
    rewards,
    transition_trajectory,
    trajectory_start,
    trajectory_length,
    trajectory_terminated,
    trajectory_next_slots,
    open_trajectory,
    open_start,
    open_length,
    open_next_slots,
    stride,
    action_columns,
    columns_are_actions,
    priority_target,
    sigma_kind,
    gamma,
    epsilon,
    rng,
    q,
    w,
    initial_low,
    initial_span,
    initial_seed,
    threshold,
    heap_rows,
    heap_keys,
    heap_position,
    heap_size,
):
    """Recompute the |delta| of predecessor q_row and queue it, re-prioritise it, or take it out of the queue when
    it no longer exceeds the threshold."""
    next_slots, terminal, _ = transition_end(
        q_row,
        slots,
        transition_trajectory,
        trajectory_start,
        trajectory_length,
        trajectory_terminated,
        trajectory_next_slots,
        open_trajectory,
        open_start,
        open_length,
        open_next_slots,
    )
    priority = transition_priority(
        theta,
        visits,
        slots,
        actions,
        rewards,
        q_row,
        next_slots,
        terminal,
        stride,
        action_columns,
        columns_are_actions,
        priority_target,
        sigma_kind,
        gamma,
        epsilon,
        rng,
        q,
        w,
        initial_low,
        initial_span,
        initial_seed,
    )
    if priority > threshold:
        heap_set(heap_rows, heap_keys, heap_position, heap_size, q_row, priority)
    else:
        heap_remove(heap_rows, heap_keys, heap_position, heap_size, q_row)


@nb.njit(cache=True)
def prioritized_phase(
    theta,
    visits,
    slots,
    actions,
    rewards,
    transition_trajectory,
    trajectory_start,
    trajectory_length,
    trajectory_terminated,
    trajectory_next_slots,
    oldest_trajectory,
    n_closed_trajectories,
    first_row,
    n_transitions,
    open_trajectory,
    open_length,
    open_next_slots,
    stride,
    action_columns,
    columns_are_actions,
    n_updates,
    threshold,
    predecessors,
    max_predecessors,
    target_kind,
    sigma_kind,
    residual_zeta,
    residual_next_action,
    step_size,
    gamma,
    epsilon,
    action_rng,
    q_scratch,
    w_scratch,
    initial_low,
    initial_span,
    initial_seed,
    heap_rows,
    heap_keys,
    heap_position,
    heap_size,
    index_start,
    index_rows,
    stamp,
    stamp_counter,
    watch,
):
    """One replay phase of prioritized sweeping over the stored transitions (Moore and Atkeson 1993, their Fig. 4
    "prioritized sweeping" loop with the transitions of the database as its model; thesis 3.2: "Another possibility
    is to use Prioritized Sweeping").

    1. Every stored transition p is queued with priority |delta_p| (:func:`transition_priority`) if it exceeds
       ``threshold``. The queue is built anew each phase: under function approximation every update moves the
       errors of other transitions, so priorities kept from an earlier phase would be stale.
    2. Up to ``n_updates`` times: pop the transition with the largest |delta| and replay it with the update of
       :func:`replay_update` (Alg. 8 line 7; ER-sigma, residual and the other targets as in the other orders).
    3. Its predecessors get their |delta| recomputed and are queued (or re-prioritised, or taken out when it fell to
       the threshold or below). First the previous transition of p's trajectory, whose s' is s_p; that is all for
       ``predecessors == PREDECESSORS_TRAJECTORY``. ``PREDECESSORS_TILES`` goes on to the other transitions q whose
       s'_q shares a tile slot with s_p (the update moved Q(s'_q, .), so their targets changed), found through the
       index of :func:`build_predecessor_index`, newest first, taking p's tilings in turn: at most
       ``max_predecessors`` distinct ones per update in all.
    The queue ends the phase early when no transition's |delta| exceeds the threshold. Exploration draws a' from
    ``action_rng`` as in the other orders. Arrays after ``initial_seed`` are the workspace (see sb3_er.er), then the
    value ``watch`` (updates only; priority evaluations are not updates).
    Returns (updates, sum of |delta|, last delta, status, priority evaluations), status as in :func:`replay_phase`.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param visits: the visit vector w (Eq. 5.2), one bool per weight, like theta.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param actions: the flat action of each stored row, (rows,).
    :param rewards: the reward of each stored row, (rows,).
    :param transition_trajectory: the trajectory of each stored row, (rows,).
    :param trajectory_start: the first row of each trajectory, (trajectories,).
    :param trajectory_length: the rows of each trajectory, (trajectories,).
    :param trajectory_terminated: whether each trajectory ended in a terminal state, (trajectories,).
    :param trajectory_next_slots: the slots of each trajectory's last s', (trajectories, N).
    :param oldest_trajectory: the index of the oldest closed trajectory in the ring of trajectories.
    :param n_closed_trajectories: the number of closed trajectories stored.
    :param first_row: the oldest stored row.
    :param n_transitions: the stored transitions, the open trajectory's included.
    :param open_trajectory: the index of the open trajectory (the episode in progress).
    :param open_length: the rows of the open trajectory (0: none).
    :param open_next_slots: the slots of the open trajectory's latest s', (N,).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param n_updates: the most updates of the phase.
    :param threshold: theta of prioritized sweeping: only a |delta| above it is queued.
    :param predecessors: PREDECESSORS_TILES or PREDECESSORS_TRAJECTORY.
    :param max_predecessors: the most distinct predecessors queued per update.
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param sigma_kind: SIGMA_NONE (vanilla ER) or one of the SIGMA_* definitions of Appendix B.
    :param residual_zeta: zeta of the residual update (Eq. 5.9); 0 for plain ER.
    :param residual_next_action: use a_{t+1} instead of a_t in the residual term (Baird's residual gradient).
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param action_rng: the generator of exploratory draws (a xoshiro256** state).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param w_scratch: scratch for W(s', .), float64 (A,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    :param heap_rows: the priority queue's rows by node, (rows,).
    :param heap_keys: the priority of each node, (rows,).
    :param heap_position: the node of each row, -1 for a row not queued, (rows,).
    :param heap_size: the number of queued rows, a (1,) array changed in place.
    :param index_start: the predecessor index's start per slot, (slots + 1,) (:func:`build_predecessor_index`).
    :param index_rows: the predecessor index's rows, (n_transitions * N,).
    :param stamp: workspace: per row, the last update that queued it as a predecessor (rows,).
    :param stamp_counter: workspace: the update counter of ``stamp``, a (1,) array.
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    capacity = slots.shape[0]
    n_tilings = slots.shape[1]
    open_start = ring_index(first_row + n_transitions - open_length, capacity)
    priority_target = TARGET_EXPECTED_SARSA if target_kind == TARGET_SARSA else target_kind
    updates = 0
    evaluations = 0
    sum_abs_delta = 0.0
    delta = 0.0
    status = STATUS_OK
    heap_clear(heap_rows, heap_position, heap_size)
    if n_transitions == 0 or n_updates <= 0:
        return updates, sum_abs_delta, delta, status, evaluations
    if predecessors == PREDECESSORS_TILES:
        build_predecessor_index(
            slots,
            transition_trajectory,
            trajectory_start,
            trajectory_length,
            trajectory_terminated,
            trajectory_next_slots,
            first_row,
            n_transitions,
            open_trajectory,
            open_start,
            open_length,
            open_next_slots,
            index_start,
            index_rows,
        )
    size = 0
    for i in range(n_transitions):
        p = ring_index(first_row + i, capacity)
        next_slots, terminal, _ = transition_end(
            p,
            slots,
            transition_trajectory,
            trajectory_start,
            trajectory_length,
            trajectory_terminated,
            trajectory_next_slots,
            open_trajectory,
            open_start,
            open_length,
            open_next_slots,
        )
        priority = transition_priority(
            theta,
            visits,
            slots,
            actions,
            rewards,
            p,
            next_slots,
            terminal,
            stride,
            action_columns,
            columns_are_actions,
            priority_target,
            sigma_kind,
            gamma,
            epsilon,
            action_rng,
            q_scratch,
            w_scratch,
            initial_low,
            initial_span,
            initial_seed,
        )
        evaluations += 1
        if priority > threshold:
            heap_rows[size] = p
            heap_keys[size] = priority
            size += 1
    heap_size[0] = size
    heap_heapify(heap_rows, heap_keys, heap_position, heap_size)

    while updates < n_updates and heap_size[0] > 0:
        p, _ = heap_pop(heap_rows, heap_keys, heap_position, heap_size)
        next_slots, terminal, t = transition_end(
            p,
            slots,
            transition_trajectory,
            trajectory_start,
            trajectory_length,
            trajectory_terminated,
            trajectory_next_slots,
            open_trajectory,
            open_start,
            open_length,
            open_next_slots,
        )
        delta, flagged = replay_update(
            theta,
            visits,
            slots,
            actions,
            rewards,
            p,
            next_slots,
            terminal,
            stride,
            action_columns,
            columns_are_actions,
            target_kind,
            sigma_kind,
            residual_zeta,
            residual_next_action,
            step_size,
            gamma,
            epsilon,
            action_rng,
            q_scratch,
            w_scratch,
            initial_low,
            initial_span,
            initial_seed,
            watch,
        )
        updates += 1
        if not np.isfinite(delta):
            heap_clear(heap_rows, heap_position, heap_size)
            return updates, sum_abs_delta, delta, STATUS_DIVERGED, evaluations
        if flagged:
            status = STATUS_OUT_OF_BOUNDS
        sum_abs_delta += abs(delta)

        # the predecessors of p, each once per update (stamped with this update's number)
        stamp_counter[0] += 1
        mark = stamp_counter[0]
        examined = 0
        if t > 0 and max_predecessors > 0:  # the previous transition of p's trajectory: its s' is s_p
            q_row = ring_index(p + capacity - 1, capacity)
            stamp[q_row] = mark
            _requeue(
                q_row,
                theta,
                visits,
                slots,
                actions,
                rewards,
                transition_trajectory,
                trajectory_start,
                trajectory_length,
                trajectory_terminated,
                trajectory_next_slots,
                open_trajectory,
                open_start,
                open_length,
                open_next_slots,
                stride,
                action_columns,
                columns_are_actions,
                priority_target,
                sigma_kind,
                gamma,
                epsilon,
                action_rng,
                q_scratch,
                w_scratch,
                initial_low,
                initial_span,
                initial_seed,
                threshold,
                heap_rows,
                heap_keys,
                heap_position,
                heap_size,
            )
            evaluations += 1
            examined += 1
        if predecessors == PREDECESSORS_TRAJECTORY:
            continue
        depth = 0
        more = True
        while more and examined < max_predecessors:  # depth-th newest row of each of p's tile lists in turn
            more = False
            for k in range(n_tilings):
                begin, end = index_start[slots[p, k]], index_start[slots[p, k] + 1]
                if end - begin <= depth:
                    continue
                more = True
                q_row = index_rows[end - 1 - depth]
                if stamp[q_row] == mark:
                    continue
                stamp[q_row] = mark
                _requeue(
                    q_row,
                    theta,
                    visits,
                    slots,
                    actions,
                    rewards,
                    transition_trajectory,
                    trajectory_start,
                    trajectory_length,
                    trajectory_terminated,
                    trajectory_next_slots,
                    open_trajectory,
                    open_start,
                    open_length,
                    open_next_slots,
                    stride,
                    action_columns,
                    columns_are_actions,
                    priority_target,
                    sigma_kind,
                    gamma,
                    epsilon,
                    action_rng,
                    q_scratch,
                    w_scratch,
                    initial_low,
                    initial_span,
                    initial_seed,
                    threshold,
                    heap_rows,
                    heap_keys,
                    heap_position,
                    heap_size,
                )
                evaluations += 1
                examined += 1
                if examined >= max_predecessors:
                    break
            depth += 1
    heap_clear(heap_rows, heap_position, heap_size)
    return updates, sum_abs_delta, delta, status, evaluations


@nb.njit(cache=True)
def weight_statistics(theta, initial_low, initial_span, initial_seed):
    """(mean |theta| over the touched weights, share of touched weights): a weight is touched when it differs from its
    initial value (:func:`initial_weight`). No temporary array.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    """
    total = 0.0
    touched = 0
    for i in range(theta.shape[0]):
        if theta[i] != initial_weight(i, initial_low, initial_span, initial_seed):
            total += abs(theta[i])
            touched += 1
    if touched == 0:
        return 0.0, 0.0
    return total / touched, touched / theta.shape[0]


# --- Batch views, FQI, LSPI and Dyna (sb3_er.fqi, sb3_er.lspi, sb3_er.dyna; thesis chapter 3) ----------------------
# A binary design matrix Phi (n, f) over the f weights a data set touches is given by its active ``columns`` (n, N):
# row d has a one at each columns[d, k] (a column repeated within a row, a hash collision, counts twice).


@nb.njit(cache=True)
def batch_state_slots(observations, inv_widths, offsets, wrap_tiles, slot_mask, out_slots):
    """Hashed state-tile slots (B, N) of each row of observations (B, D); False if a row is not finite.

    :param observations: the states, float64 (B, D).
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param out_slots: written: the slots, (B, N).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], inv_widths, offsets, wrap_tiles, slot_mask, out_slots[i]):
            return False
    return True


@nb.njit(cache=True)
def greedy_next_values(
    theta, next_slots, terminal, stride, action_columns, columns_are_actions, q_scratch, out_values, out_actions
):
    """max_a Q(s'_d, a) and its argmax (lowest index on ties) for each transition d (FQI's Eq. 3.1, LSPI's greedy
    policy at s'); 0 and -1 where s'_d is terminal.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param next_slots: the slots of each s'_d, (n, N).
    :param terminal: whether each s'_d is terminal, (n,).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param out_values: written: max_a Q(s'_d, a), (n,).
    :param out_actions: written: the greedy action of each row, (B,).
    """
    for d in range(next_slots.shape[0]):
        if terminal[d]:
            out_values[d] = 0.0
            out_actions[d] = -1
            continue
        all_q_values(theta, next_slots[d], stride, action_columns, columns_are_actions, q_scratch)
        best = argmax_first(q_scratch)
        out_values[d] = q_scratch[best]
        out_actions[d] = best


@nb.njit(cache=True)
def features_dot(x, columns, out):
    """out = Phi x: out[d] = sum_k x[columns[d, k]] (the fitted values of the n samples).

    :param x: the weights of the fit, (features,).
    :param columns: the active feature columns of each sample, (n, N).
    :param out: written: Phi x, (n,).
    """
    for d in range(columns.shape[0]):
        total = 0.0
        for k in range(columns.shape[1]):
            total += x[columns[d, k]]
        out[d] = total


@nb.njit(cache=True)
def features_transpose_dot(y, columns, out):
    """out = Phi^T y: out[j] = sum of y[d] over the samples d with feature j active (with multiplicity).

    :param y: one value per sample, (n,).
    :param columns: the active feature columns of each sample, (n, N).
    :param out: written: Phi^T y, (features,).
    """
    for j in range(out.shape[0]):
        out[j] = 0.0
    for d in range(columns.shape[0]):
        for k in range(columns.shape[1]):
            out[columns[d, k]] += y[d]


@nb.njit(cache=True)
def ridge_normal_matvec(x, columns, ridge, out):
    """out = (Phi^T Phi + ridge I) x: the matrix of the ridge normal equations of FQI's least-squares fit.

    :param x: a weight vector, (features,).
    :param columns: the active feature columns of each sample, (n, N).
    :param ridge: the ridge term lambda.
    :param out: written: the product, (features,).
    """
    for j in range(out.shape[0]):
        out[j] = ridge * x[j]
    for d in range(columns.shape[0]):
        total = 0.0
        for k in range(columns.shape[1]):
            total += x[columns[d, k]]
        for k in range(columns.shape[1]):
            out[columns[d, k]] += total


@nb.njit(inline="always", cache=True)
def one_step_update(
    theta,
    slots,
    action,
    reward,
    continuation,
    next_slots,
    stride,
    action_columns,
    columns_are_actions,
    target_kind,
    step_size,
    gamma,
    epsilon,
    rng,
    q,
    watch,
):
    """One single-sample update (thesis Eq. 3.10, Alg. 5 line 4) on (s, a, r, s'); returns (delta, whether the value
    watch saw its first value outside the bounds).

    theta <- theta + alpha delta phi(s, a) / N with delta = r + gamma c v(s') - Q(s, a), where v(s') = max_a Q(s', a)
    for Q-learning (T*) or Q(s', a') with a' epsilon-greedy for Sarsa (T^pi), and c is the probability that s' is not
    terminal (0 or 1 for a real transition; a model's prediction may lie between). c = 0 skips s' altogether.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param slots: state-tile slots: (N,) of one state, or (rows, N) of the stored transitions.
    :param action: the flat action index a.
    :param reward: the reward r.
    :param continuation: c, the probability that s' is not terminal.
    :param next_slots: state-tile slots of s', (N,).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param q: scratch for Q(s', .), float64 (A,).
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    q_sa = q_value(theta, slots, stride, action_columns, action)
    target = reward
    if continuation > 0.0:
        all_q_values(theta, next_slots, stride, action_columns, columns_are_actions, q)
        if target_kind == TARGET_Q_LEARNING:
            value = q[argmax_first(q)]
        else:
            value = q[epsilon_greedy(q, epsilon, rng)]
        target += gamma * continuation * value
    delta = target - q_sa
    if not np.isfinite(delta):
        return delta, False
    flagged = watch_update(watch, target, q_sa)
    for k in range(slots.shape[0]):
        theta[slots[k] * stride + action_columns[k, action]] += step_size * delta
    return delta, flagged


@nb.njit(cache=True)
def dyna_step(
    theta,
    slots,
    action,
    reward,
    terminated,
    next_obs,
    next_slots,
    plan_slots,
    plan_actions,
    plan_rewards,
    plan_continuation,
    plan_next_slots,
    plan_start,
    plan_count,
    inv_widths,
    offsets,
    wrap_tiles,
    slot_mask,
    stride,
    action_columns,
    columns_are_actions,
    target_kind,
    step_size,
    gamma,
    epsilon,
    rng,
    q_scratch,
    watch,
):
    """One real step of Dyna (Sutton 1991; thesis 3.4 and Alg. 3-5): the direct update on (s_k, a_k, r_{k+1}, s_{k+1}),
    then ``plan_count`` planning updates on the model's predicted transitions ``plan_start ...`` (rows with a negative
    ``plan_continuation`` were not covered by the model and are skipped). Fills next_slots with the tiles of s_{k+1}.

    Returns (delta of the direct update, planning updates made, sum of their |delta|, status); both kinds of update
    go to the value ``watch``, and status is STATUS_OUT_OF_BOUNDS when it saw its first value outside the bounds.

    :param theta: the weights, float64 (stride * number of state-tile slots,), changed in place by the learning kernels.
    :param slots: the slots of s_k, (N,).
    :param action: a_k.
    :param reward: r_{k+1}.
    :param terminated: whether s_{k+1} is terminal.
    :param next_obs: s_{k+1}, float64 (D,).
    :param next_slots: written: the slots of s_{k+1}, (N,).
    :param plan_slots: the planned transitions' slots of s, (M, N).
    :param plan_actions: their actions, (M,).
    :param plan_rewards: their predicted rewards, (M,).
    :param plan_continuation: their predicted probability that s' is not terminal (negative: not covered), (M,).
    :param plan_next_slots: their slots of the predicted s', (M, N).
    :param plan_start: the first planned row to use.
    :param plan_count: planning updates to make.
    :param inv_widths: 1 / tile width per state dimension, (D,).
    :param offsets: tiling displacements in tile units, (N, D).
    :param wrap_tiles: tiles per period of each periodic dimension, (D,) (0: not periodic).
    :param slot_mask: number of state-tile slots minus one (a power of two minus one).
    :param stride: weights per state-tile slot (the action columns of one slot).
    :param action_columns: column of each (tiling, action) within a slot's row, int (N, A).
    :param columns_are_actions: True when actions are not tiled (column a is action a).
    :param target_kind: TARGET_SARSA, TARGET_Q_LEARNING or TARGET_EXPECTED_SARSA.
    :param step_size: alpha / N, the step of each active weight.
    :param gamma: the discount factor.
    :param epsilon: the exploration rate of the epsilon-greedy policy.
    :param rng: a xoshiro256** state (4 uint64, from :func:`new_rng_state`), advanced in place.
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param watch: the value watch (:func:`new_watch`; an empty array switches it off), updated in place.
    """
    continuation = 0.0
    if not terminated:
        if not state_slots(next_obs, inv_widths, offsets, wrap_tiles, slot_mask, next_slots):
            return np.nan, 0, 0.0, STATUS_BAD_OBSERVATION
        continuation = 1.0
    delta, flagged = one_step_update(
        theta,
        slots,
        action,
        reward,
        continuation,
        next_slots,
        stride,
        action_columns,
        columns_are_actions,
        target_kind,
        step_size,
        gamma,
        epsilon,
        rng,
        q_scratch,
        watch,
    )
    if not np.isfinite(delta):
        return delta, 0, 0.0, STATUS_DIVERGED
    status = STATUS_OUT_OF_BOUNDS if flagged else STATUS_OK
    updates = 0
    sum_abs_delta = 0.0
    for p in range(plan_start, plan_start + plan_count):
        if plan_continuation[p] < 0.0:
            continue
        planned, flagged = one_step_update(
            theta,
            plan_slots[p],
            plan_actions[p],
            plan_rewards[p],
            plan_continuation[p],
            plan_next_slots[p],
            stride,
            action_columns,
            columns_are_actions,
            target_kind,
            step_size,
            gamma,
            epsilon,
            rng,
            q_scratch,
            watch,
        )
        updates += 1
        if not np.isfinite(planned):
            return planned, updates, sum_abs_delta, STATUS_DIVERGED
        if flagged:
            status = STATUS_OUT_OF_BOUNDS
        sum_abs_delta += abs(planned)
    return delta, updates, sum_abs_delta, status


@nb.njit(cache=True)
def initial_weights_at(indices, initial_low, initial_span, initial_seed, out):
    """out[j] <- the initial value of weight indices[j] (:func:`initial_weight`), for a whole index array at once.

    :param indices: weight indices, (n,).
    :param initial_low: the initial weights' lower end.
    :param initial_span: the initial weights' range (0: every weight starts at initial_low).
    :param initial_seed: the seed of the initial weights' hash (uint64).
    :param out: written: their initial values, (n,).
    """
    for j in range(indices.shape[0]):
        out[j] = initial_weight(indices[j], initial_low, initial_span, initial_seed)

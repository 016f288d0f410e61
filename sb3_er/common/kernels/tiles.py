"""Tile coding in the kernels: hashed tile slots of a state (Eq. 2.9), Q(s, a) = theta . phi(s, a) (Eq. 2.8), the
visited part of Q for ER-sigma (Eq. 5.1-5.2), and the initial weights.

The layout of a tile coder (:class:`~sb3_er.common.kernels.bundles.TileLayout`) puts all actions of one (tiling,
state tile) next to each other: computing the state part of each tiling once and reading its row of action weights is
the hot path, since every update needs Q(s', .) over all actions.
"""

import numpy as np

from sb3_er.common.kernels._jit import inline, kernel
from sb3_er.common.kernels.rng import _GOLDEN, mix64

#: Largest |x / width| a tile coordinate may have: beyond it the int64 coordinate would overflow.
MAX_TILE_COORDINATE = 2.0**62


@inline
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


@inline
def hash_tile(tiling, coords_hash):
    """Final slot hash of one tiling given the running hash of its coordinates.

    :param tiling: the tiling's index k.
    :param coords_hash: the running hash of its coordinates.
    """
    return mix64(coords_hash ^ (np.uint64(tiling) * _GOLDEN))


@kernel
def state_slots(obs, layout, out_slots):
    """Hashed state-tile slot of obs in each tiling; False if an entry of obs is NaN, infinite or so large that its
    tile coordinate would overflow (|x / width| >= MAX_TILE_COORDINATE).

    :param obs: the state s, float64 (D,).
    :param layout: the TileLayout.
    :param out_slots: written: the state-tile slots, (N,).
    """
    n_dims = obs.shape[0]
    for d in range(n_dims):
        if not abs(obs[d] * layout.inv_widths[d]) < MAX_TILE_COORDINATE:
            return False
    for k in range(layout.offsets.shape[0]):
        h = _GOLDEN
        for d in range(n_dims):
            c = tile_coordinate(obs[d], layout.inv_widths[d], layout.offsets[k, d], layout.wrap_tiles[d])
            h = mix64(h ^ (np.uint64(c) + _GOLDEN * np.uint64(d + 1)))
        out_slots[k] = np.int64(hash_tile(k, h) & np.uint64(layout.slot_mask))
    return True


@kernel
def batch_state_slots(observations, layout, out_slots):
    """Hashed state-tile slots (B, N) of each row of observations (B, D); False if a row is not finite.

    :param observations: the states, float64 (B, D).
    :param layout: the TileLayout.
    :param out_slots: written: the slots, (B, N).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], layout, out_slots[i]):
            return False
    return True


@inline
def feature(layout, slots, k, action):
    """The index of the active feature of tiling k in phi(s, a): ``slots[k] * stride + action_columns[k, a]``.

    :param layout: the TileLayout.
    :param slots: the state-tile slots of s, (N,).
    :param k: the tiling.
    :param action: the flat action index a.
    """
    return slots[k] * layout.stride + layout.action_columns[k, action]


@inline
def q_value(theta, slots, layout, action):
    """Q(s, a) = theta . phi(s, a) (Eq. 2.8).

    :param theta: the weights (Weights.theta).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param action: the flat action index a.
    """
    q = 0.0
    for k in range(slots.shape[0]):
        q += theta[feature(layout, slots, k, action)]
    return q


@inline
def log_change(weights, i):
    """Log that weight i changed, once until the target copy's next refresh (nothing without a target copy).

    :param weights: the Weights.
    :param i: a weight index.
    """
    if weights.changed_flag.shape[0] > 0 and weights.changed_flag[i] == 0:
        weights.changed_flag[i] = 1
        weights.changed[weights.n_changed[0]] = i
        weights.n_changed[0] += 1


@inline
def add_to_features(weights, slots, layout, action, change):
    """theta_i <- theta_i + change for each active feature i of phi(s, a): the step of every update rule.

    :param weights: the Weights; theta changes in place (and the change log, with a target copy).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param action: the flat action index a.
    :param change: what each active weight gains (alpha delta / N for the semi-gradient).
    """
    theta = weights.theta
    for k in range(slots.shape[0]):
        i = feature(layout, slots, k, action)
        theta[i] += change
        log_change(weights, i)


@inline
def average_features_toward(weights, slots, layout, action, step, target):
    """theta_i <- theta_i + step (target - N theta_i) for each active feature i of phi(s, a): Gordon's (1995)
    averager step. With step = alpha / N each weight moves the share alpha of the way to target / N, so Q(s, a), their
    sum, moves by alpha (target - Q(s, a)) as under the semi-gradient step (without hash collisions), while every
    weight stays a convex combination of its own start and the targets / N it was moved towards (for alpha <= 1).

    :param weights: the Weights; theta changes in place (and the change log, with a target copy).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param action: the flat action index a.
    :param step: the step per weight (alpha / N).
    :param target: the target T the update moves Q(s, a) towards.
    """
    theta = weights.theta
    n_tilings = slots.shape[0]
    for k in range(n_tilings):
        i = feature(layout, slots, k, action)
        theta[i] += step * (target - n_tilings * theta[i])
        log_change(weights, i)


@inline
def project_features(weights, slots, layout, action, low, high):
    """theta_i <- min(max(theta_i, low / N), high / N) for each active feature i of phi(s, a): the projection of the
    weights an update moved onto the box whose sums are the values [low, high] (projected TD). Returns whether it
    moved a weight.

    :param weights: the Weights; theta changes in place (the change log already holds what the update moved).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param action: the flat action index a.
    :param low: the lower end of the values, value_low.
    :param high: their upper end, value_high.
    """
    theta = weights.theta
    n_tilings = slots.shape[0]
    low, high = low / n_tilings, high / n_tilings
    moved = False
    for k in range(n_tilings):
        i = feature(layout, slots, k, action)
        projected = min(max(theta[i], low), high)
        moved |= projected != theta[i]
        theta[i] = projected
    return moved


@kernel
def refresh_target(weights):
    """target <- theta, on the weights that changed since the last refresh (the start of a replay phase: Chen,
    Clarke and Maguluri's target network, refreshed periodically); nothing without a target copy.

    :param weights: the Weights.
    """
    theta, target, flag, changed = weights.theta, weights.target, weights.changed_flag, weights.changed
    for j in range(weights.n_changed[0]):
        i = changed[j]
        target[i] = theta[i]
        flag[i] = 0
    weights.n_changed[0] = 0


@inline
def overlap(layout, slots_a, action_a, slots_b, action_b):
    """phi(s_a, a_a)^T phi(s_b, a_b): the active features the two share, counted with multiplicity (a weight two
    tilings share counts for each pair).

    :param layout: the TileLayout.
    :param slots_a: the tiles of s_a, (N,).
    :param action_a: a_a.
    :param slots_b: the tiles of s_b, (N,).
    :param action_b: a_b.
    """
    shared = 0.0
    for k in range(slots_a.shape[0]):
        i = feature(layout, slots_a, k, action_a)
        for j in range(slots_b.shape[0]):
            shared += np.float64(feature(layout, slots_b, j, action_b) == i)
    return shared


@inline
def all_q_values(theta, slots, layout, out_q):
    """Q(s, .) over all actions: the state part of each tiling once, then its row of adjacent action weights.

    Without action tiling (``columns_are_actions``) a row is read contiguously, which the compiler vectorises.

    :param theta: the weights (Weights.theta).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param out_q: written: Q(s, .), (A,).
    """
    n_actions = np.uint64(out_q.shape[0])
    stride = layout.stride
    for a in range(n_actions):
        out_q[a] = 0.0
    for k in range(slots.shape[0]):
        row = theta[slots[k] * stride : (slots[k] + 1) * stride]
        if layout.columns_are_actions:
            for a in range(n_actions):
                out_q[a] += row[a]
        else:
            for a in range(n_actions):
                out_q[a] += row[np.uint64(layout.action_columns[k, a])]


@inline
def visited_q_values(theta, visits, slots, layout, has_initial, out_q, out_w):
    """Q_v(s, .) and W(s, .) = w . phi(s, .) (Eq. 5.1-5.2: how many active features of (s, a) were ever visited) in
    one pass over the same rows.

    Q_v(s, a) is the sum of the weights of the visited features of (s, a) only: the value carried by experience, so
    that Eq. 5.4 *replaces* the unvisited ones by sigma(s') ("the unvisited parameters have been replaced with the
    value of sigma(s')", thesis 5.2.2). An unvisited weight is left out whatever it holds: its initial value, or what
    the residual term of Eq. 5.7-5.9 wrote into phi(s', a) (residual ER-sigma, Alg. 14), which Eq. 5.4's literal
    Q(s', a) + u sigma N would count and then extrapolate again through sigma. Where no unvisited weight was ever
    written (every variant but the residual ones) this is Q(s, a) minus the initial values of its unvisited
    features, bit for bit (each is subtracted as it was added); with zero initial weights, Q(s, a) itself.

    :param theta: the weights (Weights.theta).
    :param visits: w (Trajectories.visits).
    :param slots: the state-tile slots of s, (N,).
    :param layout: the TileLayout.
    :param has_initial: whether the initial weights may be non-zero.
    :param out_q: written: Q_v(s, .), (A,).
    :param out_w: written: W(s, .), (A,).
    """
    n_actions = np.uint64(out_q.shape[0])
    stride = layout.stride
    columns_are_actions = layout.columns_are_actions
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
                    column = np.uint64(a) if columns_are_actions else np.uint64(layout.action_columns[k, a])
                    out_q[a] += row[column]
                    out_w[a] += visited[column]
                continue
            for a in range(n_actions):
                column = np.uint64(a) if columns_are_actions else np.uint64(layout.action_columns[k, a])
                value = row[column]
                seen = visited[column]
                out_q[a] += value
                out_w[a] += seen
                out_q[a] -= value * np.float64(seen == 0)


@kernel
def mark_visited(visits, slots, stride, action_columns, action):
    """w <- w OR phi(s_k, a_k) (Eq. 5.2; Alg. 9 line 10). Called once per stored step, so it takes the two fields of
    the layout it needs rather than the whole TileLayout.

    :param visits: w (Trajectories.visits), changed in place.
    :param slots: the state-tile slots of s_k, (N,).
    :param stride: TileLayout.stride.
    :param action_columns: TileLayout.action_columns.
    :param action: a_k.
    """
    for k in range(slots.shape[0]):
        visits[slots[k] * stride + action_columns[k, action]] = 1


@kernel
def mark_visited_tracked(visits, fresh, slots, stride, action_columns, action, new_features, n_new):
    """w <- w OR phi(s_k, a_k) (Eq. 5.2), for a pruned database (thesis 3.5.3): also whether (s_k, a_k) was covered
    before its trajectory began, W(s_k, a_k) = N counting only features visited by earlier trajectories.

    ``fresh`` flags the features first visited by the trajectory in progress and ``new_features[:n_new]`` lists
    them (room for N more is the caller's job), so that a pruned trajectory's marks can be taken back. Returns
    (n_new, covered).

    :param visits: w (Trajectories.visits), changed in place.
    :param fresh: one uint8 per weight: first visited by the trajectory in progress.
    :param slots: the state-tile slots of s_k, (N,).
    :param stride: TileLayout.stride.
    :param action_columns: TileLayout.action_columns.
    :param action: a_k.
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


@inline
def initial_weight(i, initial_low, initial_span, initial_seed):
    """The initial value of weight i: initial_low + initial_span * u_i, u_i uniform in [0, 1) (splitmix64 of the
    seed and i: a counter-based generator, so the value is recomputed rather than stored).

    :param i: a weight index.
    :param initial_low: Weights.initial_low.
    :param initial_span: Weights.initial_span.
    :param initial_seed: Weights.initial_seed.
    """
    if initial_span == 0.0:
        return initial_low
    u = np.float64(mix64(initial_seed ^ (np.uint64(i) * _GOLDEN)) >> np.uint64(11)) * (1.0 / 9007199254740992.0)
    return initial_low + initial_span * u


@kernel
def fill_initial_weights(weights):
    """theta_i <- its initial value (Alg. 7-14 line 1 with a user-chosen initialisation instead of 0).

    :param weights: the Weights; theta is overwritten.
    """
    theta = weights.theta
    for i in range(theta.shape[0]):
        theta[i] = initial_weight(i, weights.initial_low, weights.initial_span, weights.initial_seed)


@kernel
def initial_weights_at(indices, weights, out):
    """out[j] <- the initial value of weight indices[j], for a whole index array at once.

    :param indices: weight indices, (n,).
    :param weights: the Weights (only how they started is read).
    :param out: written: their initial values, (n,).
    """
    for j in range(indices.shape[0]):
        out[j] = initial_weight(indices[j], weights.initial_low, weights.initial_span, weights.initial_seed)


@kernel
def weight_statistics(weights):
    """(mean |theta| over the touched weights, share of touched weights): a weight is touched when it differs from its
    initial value (:func:`initial_weight`). No temporary array.

    :param weights: the Weights.
    """
    theta = weights.theta
    total = 0.0
    touched = 0
    if weights.initial_span == 0.0:  # every weight starts at initial_low: a branch-free pass the compiler vectorises
        low = weights.initial_low
        for i in range(theta.shape[0]):
            changed = theta[i] != low
            total += abs(theta[i]) * changed
            touched += changed
    else:
        for i in range(theta.shape[0]):
            if theta[i] != initial_weight(i, weights.initial_low, weights.initial_span, weights.initial_seed):
                total += abs(theta[i])
                touched += 1
    if touched == 0:
        return 0.0, 0.0
    return total / touched, touched / theta.shape[0]

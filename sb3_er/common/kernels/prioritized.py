"""Prioritized sweeping (Moore and Atkeson 1993; thesis 3.2, 3.5.4 and 7.2) as a replay order of ER: stored
transitions replayed one at a time by their |delta| from a priority queue, the predecessors of each replayed one
re-queued. The queue is a binary max-heap in the preallocated arrays of a
:class:`~sb3_er.common.kernels.bundles.PriorityQueue`."""

import numpy as np

from sb3_er.common.kernels._jit import helper, inline, kernel
from sb3_er.common.kernels.bundles import (
    PREDECESSORS_TILES,
    PREDECESSORS_TRAJECTORY,
    SIGMA_NONE,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_OUT_OF_BOUNDS,
    TARGET_EXPECTED_SARSA,
    TARGET_SARSA,
    UpdateRule,
)
from sb3_er.common.kernels.replay import er_sigma_td_error, er_td_error, replayed_update, ring_index, transition_end


@inline
def _heap_before(queue, i, j):
    """Whether heap node i pops before node j."""
    keys, rows = queue.keys, queue.rows
    return keys[i] > keys[j] or (keys[i] == keys[j] and rows[i] < rows[j])


@inline
def _heap_swap(queue, i, j):
    rows, keys = queue.rows, queue.keys
    row_i, key_i = rows[i], keys[i]
    rows[i], keys[i] = rows[j], keys[j]
    rows[j], keys[j] = row_i, key_i
    queue.position[rows[i]] = i
    queue.position[rows[j]] = j


@kernel
def heap_sift_up(queue, i):
    """Move node i towards the root while it pops before its parent.

    :param queue: the PriorityQueue.
    :param i: a heap node.
    """
    while i > 0:
        parent = (i - 1) // 2
        if not _heap_before(queue, i, parent):
            return
        _heap_swap(queue, i, parent)
        i = parent


@kernel
def heap_sift_down(queue, i):
    """Move node i towards the leaves while a child pops before it.

    :param queue: the PriorityQueue.
    :param i: a heap node.
    """
    size = queue.size[0]
    while True:
        first = i
        for child in (2 * i + 1, 2 * i + 2):
            if child < size and _heap_before(queue, child, first):
                first = child
        if first == i:
            return
        _heap_swap(queue, i, first)
        i = first


@kernel
def heap_set(queue, row, priority):
    """Queue `row` with `priority`, or change the priority of a queued row (Moore and Atkeson's "promote").

    :param queue: the PriorityQueue.
    :param row: a stored row.
    :param priority: its priority |delta|.
    """
    i = queue.position[row]
    if i < 0:
        i = queue.size[0]
        queue.size[0] += 1
        queue.rows[i] = row
        queue.keys[i] = priority
        queue.position[row] = i
        heap_sift_up(queue, i)
        return
    old = queue.keys[i]
    queue.keys[i] = priority
    if priority > old:
        heap_sift_up(queue, i)
    else:
        heap_sift_down(queue, i)


@kernel
def heap_remove(queue, row):
    """Take `row` out of the queue (nothing if it is not queued).

    :param queue: the PriorityQueue.
    :param row: a stored row.
    """
    i = queue.position[row]
    if i < 0:
        return
    last = queue.size[0] - 1
    if i != last:
        _heap_swap(queue, i, last)
    queue.size[0] = last
    queue.position[row] = -1
    if i != last:
        heap_sift_down(queue, i)
        heap_sift_up(queue, i)


@kernel
def heap_pop(queue):
    """(row, priority) of the first node, taken out of the queue; the queue must not be empty.

    :param queue: the PriorityQueue.
    """
    row, priority = queue.rows[0], queue.keys[0]
    heap_remove(queue, row)
    return row, priority


@kernel
def heap_heapify(queue):
    """Order the first queue.size[0] nodes into a heap (Floyd's bottom-up construction, O(n)).

    :param queue: the PriorityQueue.
    """
    for i in range(queue.size[0]):
        queue.position[queue.rows[i]] = i
    for i in range(queue.size[0] // 2 - 1, -1, -1):
        heap_sift_down(queue, i)


@kernel
def heap_clear(queue):
    """Empty the queue, leaving every position at -1.

    :param queue: the PriorityQueue.
    """
    for i in range(queue.size[0]):
        queue.position[queue.rows[i]] = -1
    queue.size[0] = 0


@kernel
def build_predecessor_index(data, queue):
    """The index from tile slots to the stored transitions whose s' has that tile (a counting sort).

    Afterwards ``queue.index_rows[queue.index_start[c]:queue.index_start[c + 1]]`` are the rows p, oldest first, with
    slot c among the tiles of s'_p (terminal transitions have no s' and are left out). A row whose s' has slot c in
    two tilings (a hash collision) is listed twice.

    :param data: the Trajectories.
    :param queue: the PriorityQueue: index_start (one entry per slot plus one) and index_rows (room for
        n_transitions * N rows) are written.
    """
    capacity = data.slots.shape[0]
    index_start, index_rows = queue.index_start, queue.index_rows
    n_slots = index_start.shape[0] - 1
    for c in range(n_slots + 1):
        index_start[c] = 0
    for i in range(data.n_transitions):
        next_slots, terminal, _ = transition_end(data, ring_index(data.first_row + i, capacity))
        if not terminal:
            for k in range(next_slots.shape[0]):
                index_start[next_slots[k] + 1] += 1
    for c in range(n_slots):
        index_start[c + 1] += index_start[c]
    for i in range(data.n_transitions):  # index_start[c] runs through slot c's rows, ending at the start of c + 1
        p = ring_index(data.first_row + i, capacity)
        next_slots, terminal, _ = transition_end(data, p)
        if not terminal:
            for k in range(next_slots.shape[0]):
                index_rows[index_start[next_slots[k]]] = p
                index_start[next_slots[k]] += 1
    for c in range(n_slots, 0, -1):
        index_start[c] = index_start[c - 1]
    index_start[0] = 0


@helper
def transition_priority(weights, data, p, layout, priority_rule, rng, scratch, no_watch):
    """|delta| of stored transition p under the current theta, without an update: the priority of prioritized
    sweeping, from the TD error of the rule's algorithm (ER's or ER-sigma's; the residual direction does not change
    delta). ``priority_rule`` never has the sampled Sarsa target (Expected Sarsa instead), so no random number is
    drawn and a priority does not depend on an exploratory draw.

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param layout: the TileLayout.
    :param priority_rule: the UpdateRule of priorities.
    :param rng: the xoshiro256** state of exploration (not advanced).
    :param scratch: the Scratch.
    :param no_watch: an empty watch array (priority evaluations are not updates).
    """
    next_slots, terminal, _ = transition_end(data, p)
    if priority_rule.sigma_kind == SIGMA_NONE:
        delta = er_td_error(weights, data, p, next_slots, terminal, layout, priority_rule, rng, scratch, no_watch)[0]
    else:
        delta = er_sigma_td_error(
            weights, data, p, next_slots, terminal, layout, priority_rule, rng, scratch, no_watch
        )[0]
    return abs(delta)


@helper
def _requeue(weights, data, q_row, layout, priority_rule, rng, scratch, no_watch, threshold, queue):
    """Recompute the |delta| of predecessor q_row and queue it, re-prioritise it, or take it out of the queue when it
    no longer exceeds the threshold."""
    priority = transition_priority(weights, data, q_row, layout, priority_rule, rng, scratch, no_watch)
    if priority > threshold:
        heap_set(queue, q_row, priority)
    else:
        heap_remove(queue, q_row)


@kernel
def prioritized_phase(weights, data, layout, rule, sweep, action_rng, scratch, queue, watch):
    """One replay phase of prioritized sweeping over the stored transitions (Moore and Atkeson 1993, their Fig. 4
    "prioritized sweeping" loop with the transitions of the database as its model; thesis 3.2: "Another possibility
    is to use Prioritized Sweeping").

    1. Every stored transition p is queued with priority |delta_p| (:func:`transition_priority`) if it exceeds
       ``sweep.threshold``. The queue is built anew each phase: under function approximation every update moves the
       errors of other transitions, so priorities kept from an earlier phase would be stale.
    2. Up to ``sweep.n_updates`` times: pop the transition with the largest |delta| and replay it with the rule's
       update (:func:`~sb3_er.common.kernels.replay.replayed_update`).
    3. Its predecessors get their |delta| recomputed and are queued (or re-prioritised, or taken out when it fell to
       the threshold or below). First the previous transition of p's trajectory, whose s' is s_p; that is all for
       PREDECESSORS_TRAJECTORY. PREDECESSORS_TILES goes on to the other transitions q whose s'_q shares a tile slot
       with s_p (the update moved Q(s'_q, .), so their targets changed), found through the index of
       :func:`build_predecessor_index`, newest first, taking p's tilings in turn: at most ``sweep.max_predecessors``
       distinct ones per update in all.

    The queue ends the phase early when no transition's |delta| exceeds the threshold. Exploration draws a' from
    ``action_rng`` as in the other orders; the value watch sees updates only (priority evaluations are not updates).
    Returns (updates, sum of |delta|, last delta, status, priority evaluations), status as in
    :func:`~sb3_er.common.kernels.replay.replay_phase`.

    :param weights: the Weights.
    :param data: the Trajectories.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param sweep: the Sweep: budget, threshold and predecessors.
    :param action_rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param queue: the PriorityQueue workspace.
    :param watch: the value watch array (empty: off).
    """
    capacity = data.slots.shape[0]
    n_tilings = data.slots.shape[1]
    priority_target = TARGET_EXPECTED_SARSA if rule.target_kind == TARGET_SARSA else rule.target_kind
    priority_rule = UpdateRule(
        priority_target,
        rule.sigma_kind,
        rule.residual_zeta,
        rule.residual_next_action,
        rule.step_size,
        rule.gamma,
        rule.epsilon,
        rule.truncate,
        rule.value_low,
        rule.value_high,
        False,  # a priority is not an update: it moves no step-size bound
        rule.step_cap,
        rule.averager,
        rule.project,
    )
    no_watch = watch[:0]
    threshold, max_predecessors = sweep.threshold, sweep.max_predecessors
    updates = 0
    evaluations = 0
    sum_abs_delta = 0.0
    delta = 0.0
    status = STATUS_OK
    heap_clear(queue)
    if data.n_transitions == 0 or sweep.n_updates <= 0:
        return updates, sum_abs_delta, delta, status, evaluations
    if sweep.predecessors == PREDECESSORS_TILES:
        build_predecessor_index(data, queue)
    size = 0
    for i in range(data.n_transitions):
        p = ring_index(data.first_row + i, capacity)
        priority = transition_priority(weights, data, p, layout, priority_rule, action_rng, scratch, no_watch)
        evaluations += 1
        if priority > threshold:
            queue.rows[size] = p
            queue.keys[size] = priority
            size += 1
    queue.size[0] = size
    heap_heapify(queue)

    stamp, index_start, index_rows = queue.stamp, queue.index_start, queue.index_rows
    while updates < sweep.n_updates and queue.size[0] > 0:
        p, _ = heap_pop(queue)
        next_slots, terminal, t = transition_end(data, p)
        delta, flagged = replayed_update(
            weights, data, p, next_slots, terminal, layout, rule, action_rng, scratch, watch
        )
        updates += 1
        if not np.isfinite(delta):
            heap_clear(queue)
            return updates, sum_abs_delta, delta, STATUS_DIVERGED, evaluations
        if flagged:
            status = STATUS_OUT_OF_BOUNDS
        sum_abs_delta += abs(delta)

        # the predecessors of p, each once per update (stamped with this update's number)
        queue.stamp_counter[0] += 1
        mark = queue.stamp_counter[0]
        examined = 0
        if t > 0 and max_predecessors > 0:  # the previous transition of p's trajectory: its s' is s_p
            q_row = ring_index(p + capacity - 1, capacity)
            stamp[q_row] = mark
            _requeue(weights, data, q_row, layout, priority_rule, action_rng, scratch, no_watch, threshold, queue)
            evaluations += 1
            examined += 1
        if sweep.predecessors == PREDECESSORS_TRAJECTORY:
            continue
        depth = 0
        more = True
        while more and examined < max_predecessors:  # depth-th newest row of each of p's tile lists in turn
            more = False
            for k in range(n_tilings):
                begin, end = index_start[data.slots[p, k]], index_start[data.slots[p, k] + 1]
                if end - begin <= depth:
                    continue
                more = True
                q_row = index_rows[end - 1 - depth]
                if stamp[q_row] == mark:
                    continue
                stamp[q_row] = mark
                _requeue(weights, data, q_row, layout, priority_rule, action_rng, scratch, no_watch, threshold, queue)
                evaluations += 1
                examined += 1
                if examined >= max_predecessors:
                    break
            depth += 1
    heap_clear(queue)
    return updates, sum_abs_delta, delta, status, evaluations

"""Experience replay of stored trajectories (thesis Alg. 8, 10, 12, 14): the four update rules, each beside the
algorithm it follows, and the replay phase that loops over the stored trajectories and calls one of them.

Each rule is two functions: its TD error (the algorithm's target and delta, line by line) and its update, which steps
theta along the semi-gradient phi(s_t, a_t) (ER, ER-sigma) or the residual-gradient direction
phi(s_t, a_t) - zeta gamma phi(s_{t+1}, a) (residual ER, residual ER-sigma). Every update's target T and Q(s_t, a_t)
go to the value watch, and for ER-sigma the shift T_sigma - T of its target over vanilla ER's target of the same
transition (:func:`er_sigma_td_error`).
"""

import numpy as np

from sb3_er.common.kernels._jit import helper, inline, kernel
from sb3_er.common.kernels.bundles import (
    ORDER_REVERSED,
    ORDER_UNIFORM,
    SIGMA_AVERAGE,
    SIGMA_AVERAGE_WORST,
    SIGMA_BEST,
    SIGMA_NONE,
    SIGMA_WORST,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_OUT_OF_BOUNDS,
    TARGET_EXPECTED_SARSA,
    TARGET_SARSA,
)
from sb3_er.common.kernels.policy import argmax_first, epsilon_greedy_explored
from sb3_er.common.kernels.rng import random_integer
from sb3_er.common.kernels.tiles import (
    add_to_features,
    all_q_values,
    average_features_toward,
    overlap,
    project_features,
    q_value,
    visited_q_values,
)
from sb3_er.common.kernels.watch import watch_projection, watch_shift, watch_truncation, watch_update


@inline
def ring_index(i, capacity):
    """i mod capacity for 0 <= i < 2 capacity, without an integer division.

    :param i: an index in [0, 2 capacity).
    :param capacity: the ring's size.
    """
    return i - capacity if i >= capacity else i


@inline
def bootstrap(q, rule, rng):
    """The value at s' that the target bootstraps from, given the action values ``q`` at s': (value, a', explored).

    Sarsa (the thesis's) draws a' epsilon-greedily (Alg. 8 line 6) and takes q[a']; Q-learning takes the max (Eq. 2.5,
    a' the greedy action); Expected Sarsa the expectation under the epsilon-greedy policy (a' the greedy action).
    ``explored`` says whether Sarsa's a' was the exploratory draw.

    :param q: action values at s', (A,).
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place (Sarsa only).
    """
    if rule.target_kind == TARGET_SARSA:
        next_action, explored = epsilon_greedy_explored(q, rule.epsilon, rng)
        return q[next_action], next_action, explored
    next_action = argmax_first(q)
    value = q[next_action]
    if rule.target_kind == TARGET_EXPECTED_SARSA:
        value = (1.0 - rule.epsilon) * value + rule.epsilon * np.mean(q)
    return value, next_action, False


@inline
def truncated(value, rule, watch):
    """The bootstrapped value, truncated to the possible returns [value_low, value_high] when ``rule.truncate`` (Chen,
    Clarke and Maguluri 2023: with a target network, truncation makes linear Q-learning stable); each truncation is
    counted in the watch.

    :param value: the value at s' the target bootstraps from.
    :param rule: the UpdateRule.
    :param watch: the value watch array (empty: off).
    """
    if not rule.truncate:
        return value
    clamped = min(max(value, rule.value_low), rule.value_high)
    if clamped != value:
        watch_truncation(watch)
    return clamped


@inline
def sigma_of_state(q, w, sigma_kind):
    """sigma(s') from the visited actions at s' (Appendix B; definition 4 is Alg. 10 line 6), with q = Q_v(s', .) and
    w = W(s', .). Actions with W(s', a) = 0 are left out of the per-action ratios; the caller handles the state where
    no action was ever visited (0 is returned for it).

    :param q: Q_v(s', .), (A,).
    :param w: W(s', .), (A,).
    :param sigma_kind: one of the SIGMA_* definitions.
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


@inline
def er_td_error(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """Vanilla ER's TD error of stored transition p, Alg. 8 lines 5-7: (delta, T, Q(s_t, a_t), a_{t+1}).

    - line 5: the sample (s_t, a_t, s_{t+1}, r_{t+1}) is row p; s_{t+1}'s tiles are ``next_slots``;
    - line 6: a_{t+1} <- epsilon-greedy on Q(s_{t+1}, .) (or the rule's other targets, :func:`bootstrap`);
    - line 7: delta = r_{t+1} + gamma Q(s_{t+1}, a_{t+1}) - Q(s_t, a_t); at a terminal s_{t+1}, r_{t+1} - Q(s_t, a_t).

    Q(s_{t+1}, .) is read from ``weights.target`` (theta itself, or the target copy), and the stabilizer of
    truncation clamps the bootstrapped value (:func:`truncated`); T is the target before truncation, for the watch.

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (unused here; kept so that every rule takes the same arguments).
    """
    q_sa = q_value(weights.theta, data.slots[p], layout, data.actions[p])
    target = data.rewards[p]
    next_action = data.actions[p]
    if terminal:
        return target - q_sa, target, q_sa, next_action
    all_q_values(weights.target, next_slots, layout, scratch.q)
    value, next_action, _ = bootstrap(scratch.q, rule, rng)  # line 6
    used = target + rule.gamma * truncated(value, rule, watch)
    target += rule.gamma * value
    return used - q_sa, target, q_sa, next_action  # line 7


@inline
def er_sigma_td_error(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """ER-sigma's TD error of stored transition p, Alg. 10 lines 5-9: (delta, T_sigma, Q(s_t, a_t), a_{t+1}).

    - line 5: the sample (s_t, a_t, s_{t+1}, r_{t+1}) is row p; s_{t+1}'s tiles are ``next_slots``;
    - line 6: sigma(s_{t+1}) from the visited features at s_{t+1}: Q_v(s', a) = the sum of the visited active weights
      of (s', a) and W(s', a) = phi(s', a)^T w (Eq. 5.1-5.2; Appendix B's definition ``rule.sigma_kind``, definition
      4 in the thesis);
    - line 7: u(a) = (N - W(s', a)) / N, the share of unvisited features;
    - line 8: a_{t+1} <- epsilon-greedy on Q~(s', a) = Q_v(s', a) + u(a) N sigma (Eq. 5.4: the unvisited weights
      replaced by sigma);
    - line 9: delta = r_{t+1} + gamma Q~(s', a_{t+1}) - Q(s_t, a_t).

    When no action at s' was ever visited (the last state of an episode cut off by a time limit) there is nothing to
    judge s' by: Q~ = Q, the initial values (0 in the thesis) and whatever generalisation put there. Q(s', .) and
    Q_v(s', .) are read from ``weights.target`` (theta itself, or the target copy); truncation clamps Q~(s', a_{t+1})
    (:func:`truncated`), and T_sigma is returned before truncation, for the watch.

    With the value watch on, the shift T_sigma - T over vanilla ER's target of the same transition goes to the watch:
    T takes Q(s', .) without sigma and the same random numbers (the same exploratory a' when the draw explored, else
    the greedy action of Q), so results are the same with and without the watch.

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off), which takes the target shift.
    """
    theta = weights.target  # Q(s', .) is read from the target copy, when there is one
    q_sa = q_value(weights.theta, data.slots[p], layout, data.actions[p])
    target = data.rewards[p]
    next_action = data.actions[p]
    if terminal:
        watch_shift(watch, 0.0)
        return target - q_sa, target, q_sa, next_action
    q, w = scratch.q, scratch.w
    n_tilings = data.slots.shape[1]
    has_initial = weights.initial_low != 0.0 or weights.initial_span != 0.0
    visited_q_values(theta, data.visits, next_slots, layout, has_initial, q, w)
    sum_w = 0.0
    for a in range(q.shape[0]):
        sum_w += w[a]
    sigma = 0.0
    if sum_w == 0.0:
        all_q_values(theta, next_slots, layout, q)  # nothing visited at s': Q~ = Q
    else:
        sigma = sigma_of_state(q, w, rule.sigma_kind)  # line 6
        for a in range(q.shape[0]):
            q[a] += (n_tilings - w[a]) * sigma  # lines 7-8: Q~(s', a) = Q_v(s', a) + u(a) N sigma
    value, next_action, explored = bootstrap(q, rule, rng)  # line 8
    used = target + rule.gamma * truncated(value, rule, watch)  # line 9
    target += rule.gamma * value

    if watch.shape[0] > 0:
        plain_value = value
        if sum_w != 0.0:
            plain_value = _value_without_sigma(
                theta, next_slots, layout, rule, has_initial, q, w, sigma, next_action, explored
            )
        watch_shift(watch, rule.gamma * (value - plain_value))
    return used - q_sa, target, q_sa, next_action


@helper
def _value_without_sigma(theta, next_slots, layout, rule, has_initial, q, w, sigma, next_action, explored):
    """Vanilla ER's bootstrap value at s' with ER-sigma's random numbers, for the watch's target shift: Q(s', a') of
    the same exploratory a' when the draw explored, else the greedy value (Expected Sarsa's expectation on Q).
    Undoing the sigma terms of ``q`` gives Q_v, equal to Q when every unvisited weight is 0; otherwise (non-zero
    initial weights, or the residual term writing into unvisited features) the weights are summed again into ``w``.
    Draws no random number."""
    n_tilings = next_slots.shape[0]
    if not has_initial and not rule.residual_zeta > 0.0:
        for a in range(q.shape[0]):
            q[a] -= (n_tilings - w[a]) * sigma
        plain = q
    else:
        all_q_values(theta, next_slots, layout, w)
        plain = w
    if explored:
        return plain[next_action]
    value = plain[argmax_first(plain)]
    if rule.target_kind == TARGET_EXPECTED_SARSA:
        value = (1.0 - rule.epsilon) * value + rule.epsilon * np.mean(plain)
    return value


@inline
def step_size(weights, layout, rule, slots, action, next_slots, next_action, terminal, residual_action):
    """The step per active weight: ``rule.step_size`` (alpha / N), or with ``rule.step_bound`` at most Dabney and
    Barto's (2012) alpha-bound, min(step_cap, 1 / |(gamma phi' - phi)^T d|) over the run, for the direction
    d = phi(s_t, a_t) - zeta gamma phi(s_{t+1}, a) of the update (zeta 0 for the semi-gradient) and phi' =
    phi(s_{t+1}, a_{t+1}) of the bootstrap (none at a terminal s_{t+1} or with a target copy, which the update does not
    move). A larger step would carry the updated transition's own TD error past zero. With binary features and
    alpha / N per weight, (phi - gamma phi')^T phi = N - gamma o for o features shared by s_t and s_{t+1}, so the
    semi-gradient replay update binds only for alpha > 1 / (1 - gamma o / N): never at alpha <= 1 without hash
    collisions. Residual updates bind sooner, traces (Sarsa(lambda)) far sooner.

    :param weights: the Weights.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param slots: the tiles of s_t.
    :param action: a_t.
    :param next_slots: the tiles of s_{t+1}.
    :param next_action: a_{t+1}, the bootstrap's action.
    :param terminal: whether s_{t+1} is terminal.
    :param residual_action: the action of the residual term.
    """
    if not rule.step_bound:
        return rule.step_size
    return _bounded_step_size(weights, layout, rule, slots, action, next_slots, next_action, terminal, residual_action)


@helper
def _bounded_step_size(weights, layout, rule, slots, action, next_slots, next_action, terminal, residual_action):
    """:func:`step_size` with ``rule.step_bound``: the bound's arithmetic, a call of its own off the hot path."""
    # (gamma phi' - phi)^T d with d = phi - zeta gamma phi_r (phi = phi(s_t, a_t), phi_r = phi(s_{t+1}, a_residual),
    # phi' = phi(s_{t+1}, a_{t+1})); the phi' terms only where the update moves the bootstrap (no target copy)
    zeta_gamma = 0.0 if terminal else rule.residual_zeta * rule.gamma
    product = -overlap(layout, slots, action, slots, action)
    if zeta_gamma != 0.0:
        product += zeta_gamma * overlap(layout, slots, action, next_slots, residual_action)
    if not terminal and weights.changed_flag.shape[0] == 0:
        product += rule.gamma * overlap(layout, next_slots, next_action, slots, action)
        if zeta_gamma != 0.0:
            product -= zeta_gamma * rule.gamma * overlap(layout, next_slots, next_action, next_slots, residual_action)
    if product != 0.0:
        rule.step_cap[0] = min(rule.step_cap[0], 1.0 / abs(product))
    return min(rule.step_size, rule.step_cap[0])


@inline
def semi_gradient_step(
    weights, slots, action, next_slots, next_action, terminal, layout, rule, delta, target, q_sa, watch
):
    """theta <- theta + alpha delta phi(s_t, a_t) (Alg. 8 line 7, Alg. 10 line 9): each of the N active weights by
    alpha delta / N (:func:`step_size`). With ``rule.averager`` each active weight moves instead towards its share of
    the target used, delta + Q(s_t, a_t) (:func:`~sb3_er.common.kernels.tiles.average_features_toward`). With
    ``rule.project`` the moved weights are then projected onto [value_low / N, value_high / N]
    (:func:`~sb3_er.common.kernels.tiles.project_features`). The watch
    sees T and Q(s_t, a_t) first. A non-finite delta changes nothing and is returned for the phase to stop. Returns
    (delta, whether the watch saw its first value out of bounds).

    :param weights: the Weights; theta changes in place.
    :param slots: the tiles of s_t, (N,).
    :param action: a_t.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param next_action: a_{t+1}.
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param delta: the TD error.
    :param target: its target T.
    :param q_sa: Q(s_t, a_t) before the update.
    :param watch: the value watch array (empty: off).
    """
    if not np.isfinite(delta):
        return delta, False
    flagged = watch_update(watch, target, q_sa)
    step = step_size(weights, layout, rule, slots, action, next_slots, next_action, terminal, action)
    if rule.averager:
        average_features_toward(weights, slots, layout, action, step, delta + q_sa)
    else:
        add_to_features(weights, slots, layout, action, step * delta)
    if rule.project and project_features(weights, slots, layout, action, rule.value_low, rule.value_high):
        watch_projection(watch)
    return delta, flagged


@inline
def residual_step(weights, slots, action, next_slots, next_action, terminal, layout, rule, delta, target, q_sa, watch):
    """The residual-gradient step (Eq. 5.7-5.9; Alg. 12 line 7, Alg. 14 line 9):
    theta <- theta + alpha delta (phi(s_t, a_t) - zeta gamma phi(s_{t+1}, a)), with a = a_t (the thesis's) or, with
    ``rule.residual_next_action``, a_{t+1} (Baird's residual gradient of the squared TD error). No second term at a
    terminal s_{t+1}. With ``rule.project`` the weights of both terms are then projected onto [value_low / N,
    value_high / N]. Returns what :func:`semi_gradient_step` returns.

    :param weights: the Weights; theta changes in place.
    :param slots: the tiles of s_t, (N,).
    :param action: a_t.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param next_action: a_{t+1}.
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param delta: the TD error.
    :param target: its target T.
    :param q_sa: Q(s_t, a_t) before the update.
    :param watch: the value watch array (empty: off).
    """
    if not np.isfinite(delta):
        return delta, False
    flagged = watch_update(watch, target, q_sa)
    residual_action = next_action if rule.residual_next_action else action
    step = step_size(weights, layout, rule, slots, action, next_slots, next_action, terminal, residual_action)
    add_to_features(weights, slots, layout, action, step * delta)
    if not terminal:
        add_to_features(weights, next_slots, layout, residual_action, -(step * delta * rule.residual_zeta * rule.gamma))
    if rule.project:
        moved = project_features(weights, slots, layout, action, rule.value_low, rule.value_high)
        if not terminal:
            moved |= project_features(weights, next_slots, layout, residual_action, rule.value_low, rule.value_high)
        if moved:
            watch_projection(watch)
    return delta, flagged


@helper
def er_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """Vanilla ER's update of stored transition p (Alg. 8 lines 5-7): :func:`er_td_error`, then
    theta <- theta + alpha delta phi(s_t, a_t). Returns (delta, whether the watch saw its first value out of bounds).

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    delta, target, q_sa, next_action = er_td_error(
        weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch
    )
    return semi_gradient_step(
        weights,
        data.slots[p],
        data.actions[p],
        next_slots,
        next_action,
        terminal,
        layout,
        rule,
        delta,
        target,
        q_sa,
        watch,
    )


@helper
def er_sigma_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """ER-sigma's update of stored transition p (Alg. 10 lines 5-9): :func:`er_sigma_td_error`, then
    theta <- theta + alpha delta phi(s_t, a_t). Returns (delta, whether the watch saw its first value out of bounds).

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    delta, target, q_sa, next_action = er_sigma_td_error(
        weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch
    )
    return semi_gradient_step(
        weights,
        data.slots[p],
        data.actions[p],
        next_slots,
        next_action,
        terminal,
        layout,
        rule,
        delta,
        target,
        q_sa,
        watch,
    )


@helper
def residual_er_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """Residual-gradient ER's update of stored transition p (Alg. 12 lines 5-7): vanilla ER's TD error
    (:func:`er_td_error`; Alg. 12 line 6's s_t is read as s_{t+1}, a typo) along the residual direction
    (:func:`residual_step`). Returns (delta, whether the watch saw its first value out of bounds).

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    delta, target, q_sa, next_action = er_td_error(
        weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch
    )
    return residual_step(
        weights,
        data.slots[p],
        data.actions[p],
        next_slots,
        next_action,
        terminal,
        layout,
        rule,
        delta,
        target,
        q_sa,
        watch,
    )


@helper
def residual_er_sigma_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """Residual ER-sigma's update of stored transition p (Alg. 14 lines 5-9): ER-sigma's TD error
    (:func:`er_sigma_td_error`; line 8's s_t read as s_{t+1}) along the residual direction (:func:`residual_step`).
    Returns (delta, whether the watch saw its first value out of bounds).

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    delta, target, q_sa, next_action = er_sigma_td_error(
        weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch
    )
    return residual_step(
        weights,
        data.slots[p],
        data.actions[p],
        next_slots,
        next_action,
        terminal,
        layout,
        rule,
        delta,
        target,
        q_sa,
        watch,
    )


@inline
def replayed_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch):
    """The update of the rule's algorithm: ER (Alg. 8), ER-sigma (Alg. 10), residual ER (Alg. 12) or residual
    ER-sigma (Alg. 14), by ``rule.sigma_kind`` and ``rule.residual_zeta``.

    :param weights: the Weights.
    :param data: the Trajectories.
    :param p: the row of the transition.
    :param next_slots: the tiles of s_{t+1}, (N,).
    :param terminal: whether s_{t+1} is terminal.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    if rule.sigma_kind == SIGMA_NONE:
        if rule.residual_zeta > 0.0:
            return residual_er_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch)
        return er_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch)
    if rule.residual_zeta > 0.0:
        return residual_er_sigma_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch)
    return er_sigma_update(weights, data, p, next_slots, terminal, layout, rule, rng, scratch, watch)


@inline
def transition_end(data, p):
    """(tiles of s_{t+1}, terminal, t) of stored row p: the next row's tiles inside a trajectory, the trajectory's
    stored last s' at its end (the open trajectory's latest s', never terminal).

    :param data: the Trajectories.
    :param p: the row of the stored transition.
    """
    capacity = data.slots.shape[0]
    j = data.transition_trajectory[p]
    if j == data.open_trajectory:
        start, length, end_slots, end_terminal = data.open_start, data.open_length, data.open_next_slots, False
    else:
        start, length = data.trajectory_start[j], data.trajectory_length[j]
        end_slots, end_terminal = data.trajectory_next_slots[j], data.trajectory_terminated[j]
    t = ring_index(p - start + capacity, capacity)
    if t == length - 1:
        return end_slots, end_terminal, t
    return data.slots[ring_index(p + 1, capacity)], False, t


@kernel
def replay_phase(weights, data, layout, rule, replay, action_rng, scratch, watch):
    """One replay phase (Alg. 8, 10, 12, 14 lines 1-4): K = ``replay.n_trajectories`` times, a stored trajectory
    drawn uniformly (line 2; the open one, the episode in progress, included) is replayed with the rule's update.

    Reversed order replays each from its last sample to its first (line 4: t = k..1, the thesis's); forward in
    temporal order; uniform replays as many single transitions drawn uniformly from all stored ones (Appendix A).
    Trajectory picks use ``replay.picks_rng`` and exploration ``action_rng``, so variants replay exactly the same
    trajectories. Returns (updates, sum of |delta|, last delta, status); status is STATUS_OUT_OF_BOUNDS when the
    watch saw its first value outside the bounds in this phase (the phase goes on), STATUS_DIVERGED on a non-finite
    delta (it stops there).

    :param weights: the Weights.
    :param data: the Trajectories.
    :param layout: the TileLayout.
    :param rule: the UpdateRule.
    :param replay: the Replay: how many trajectories, in which order, with which generator of picks.
    :param action_rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch.
    :param watch: the value watch array (empty: off).
    """
    capacity = data.slots.shape[0]
    trajectory_capacity = data.trajectory_start.shape[0]
    open_trajectory, open_length = data.open_trajectory, data.open_length
    n_trajectories = data.n_closed_trajectories + (1 if open_length > 0 else 0)
    picks_rng, order = replay.picks_rng, replay.order
    updates = 0
    sum_abs_delta = 0.0
    delta = 0.0
    status = STATUS_OK
    if n_trajectories == 0:
        return updates, sum_abs_delta, delta, status
    for _ in range(replay.n_trajectories):
        if 0 <= replay.max_updates <= updates:
            break
        j = ring_index(data.oldest_trajectory + random_integer(picks_rng, n_trajectories), trajectory_capacity)
        length = open_length if j == open_trajectory else data.trajectory_length[j]
        for step in range(length):
            if order == ORDER_UNIFORM:
                p = ring_index(data.first_row + random_integer(picks_rng, data.n_transitions), capacity)
                jp = data.transition_trajectory[p]
            else:
                jp = j
            if jp == open_trajectory:
                start, jp_length, end_slots, end_terminal = data.open_start, open_length, data.open_next_slots, False
            else:
                start, jp_length = data.trajectory_start[jp], data.trajectory_length[jp]
                end_slots, end_terminal = data.trajectory_next_slots[jp], data.trajectory_terminated[jp]
            if order == ORDER_UNIFORM:
                t = ring_index(p - start + capacity, capacity)
            else:
                t = length - 1 - step if order == ORDER_REVERSED else step
                p = ring_index(start + t, capacity)
            if t == jp_length - 1:
                next_slots = end_slots
                terminal = end_terminal
            else:
                next_slots = data.slots[ring_index(p + 1, capacity)]
                terminal = False
            delta, flagged = replayed_update(
                weights, data, p, next_slots, terminal, layout, rule, action_rng, scratch, watch
            )
            updates += 1
            if not np.isfinite(delta):
                return updates, sum_abs_delta, delta, STATUS_DIVERGED
            if flagged:
                status = STATUS_OUT_OF_BOUNDS
            sum_abs_delta += abs(delta)
    return updates, sum_abs_delta, delta, status

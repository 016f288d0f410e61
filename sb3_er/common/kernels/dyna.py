"""Dyna (Sutton 1991; thesis 3.4 and Alg. 3-5): after each real step, the direct update and the planning updates on
the model's predicted transitions, in one kernel call."""

import numpy as np

from sb3_er.common.kernels._jit import helper, kernel
from sb3_er.common.kernels.bundles import (
    STATUS_BAD_OBSERVATION,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_OUT_OF_BOUNDS,
    TARGET_Q_LEARNING,
    Plan,
    TileLayout,
    Transition,
    UpdateRule,
    Weights,
)
from sb3_er.common.kernels.policy import argmax_first, epsilon_greedy
from sb3_er.common.kernels.tiles import add_to_features, all_q_values, q_value, state_slots
from sb3_er.common.kernels.watch import watch_update


@helper
def one_step_update(weights, slots, action, reward, continuation, next_slots, layout, rule, rng, q, watch):
    """One single-sample update (thesis Eq. 3.10, Alg. 5 line 4) on (s, a, r, s'); returns (delta, whether the value
    watch saw its first value outside the bounds).

    theta <- theta + alpha delta phi(s, a) / N with delta = r + gamma c v(s') - Q(s, a), where v(s') = max_a Q(s', a)
    for Q-learning (T*) or Q(s', a') with a' epsilon-greedy for Sarsa (T^pi), and c is the probability that s' is not
    terminal (0 or 1 for a real transition; a model's prediction may lie between). c = 0 skips s' altogether.

    :param weights: the Weights; theta changes in place.
    :param slots: the tiles of s, (N,).
    :param action: a.
    :param reward: r.
    :param continuation: c, the probability that s' is not terminal.
    :param next_slots: the tiles of s', (N,).
    :param layout: the TileLayout.
    :param rule: the UpdateRule (target_kind, step_size, gamma, epsilon).
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param q: scratch for Q(s', .), float64 (A,).
    :param watch: the value watch array (empty: off).
    """
    q_sa = q_value(weights.theta, slots, layout, action)
    target = reward
    if continuation > 0.0:
        all_q_values(weights.target, next_slots, layout, q)
        if rule.target_kind == TARGET_Q_LEARNING:
            value = q[argmax_first(q)]
        else:
            value = q[epsilon_greedy(q, rule.epsilon, rng)]
        target += rule.gamma * continuation * value
    delta = target - q_sa
    if not np.isfinite(delta):
        return delta, False
    flagged = watch_update(watch, target, q_sa)
    add_to_features(weights, slots, layout, action, rule.step_size * delta)
    return delta, flagged


@kernel
def dyna_step(weights, layout, rule, transition, plan, rng, scratch, watch):
    """One real step of Dyna (Sutton 1991; thesis 3.4 and Alg. 3-5): the direct update on the real transition
    (s_k, a_k, r_{k+1}, s_{k+1}), then ``plan.count`` planning updates on the model's predicted transitions from row
    ``plan.start`` (rows the model did not cover are skipped). Fills the transition's next_slots with the tiles of
    s_{k+1}. Called once per environment step: every bundle is a plain tuple in its field order.

    Returns (delta of the direct update, planning updates made, sum of their |delta|, status); both kinds of update
    go to the value watch, and status is STATUS_OUT_OF_BOUNDS when it saw its first value outside the bounds.

    :param weights: the Weights (a plain tuple).
    :param layout: the TileLayout (a plain tuple).
    :param rule: the UpdateRule (a plain tuple).
    :param transition: the Transition (a plain tuple).
    :param plan: the Plan (a plain tuple).
    :param rng: the xoshiro256** state of exploration, advanced in place.
    :param scratch: the Scratch (a plain tuple).
    :param watch: the value watch array (empty: off).
    """
    weights, layout, rule = Weights(*weights), TileLayout(*layout), UpdateRule(*rule)
    transition, plan = Transition(*transition), Plan(*plan)
    q = scratch[0]
    continuation = 0.0
    if not transition.terminated:
        if not state_slots(transition.next_obs, layout, transition.next_slots):
            return np.nan, 0, 0.0, STATUS_BAD_OBSERVATION
        continuation = 1.0
    delta, flagged = one_step_update(
        weights,
        transition.slots,
        transition.action,
        transition.reward,
        continuation,
        transition.next_slots,
        layout,
        rule,
        rng,
        q,
        watch,
    )
    if not np.isfinite(delta):
        return delta, 0, 0.0, STATUS_DIVERGED
    status = STATUS_OUT_OF_BOUNDS if flagged else STATUS_OK
    updates = 0
    sum_abs_delta = 0.0
    for p in range(plan.start, plan.start + plan.count):
        if plan.continuation[p] < 0.0:
            continue
        planned, flagged = one_step_update(
            weights,
            plan.slots[p],
            plan.actions[p],
            plan.rewards[p],
            plan.continuation[p],
            plan.next_slots[p],
            layout,
            rule,
            rng,
            q,
            watch,
        )
        updates += 1
        if not np.isfinite(planned):
            return planned, updates, sum_abs_delta, STATUS_DIVERGED
        if flagged:
            status = STATUS_OUT_OF_BOUNDS
        sum_abs_delta += abs(planned)
    return delta, updates, sum_abs_delta, status

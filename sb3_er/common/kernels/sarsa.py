"""Online Sarsa(lambda) with replacing traces (thesis Alg. 2, Eq. 2.6): the baseline of every experiment, and the
online learning between LEO's replay phases."""

import numpy as np

from sb3_er.common.kernels._jit import helper, kernel
from sb3_er.common.kernels.bundles import (
    STATUS_BAD_OBSERVATION,
    STATUS_OK,
    STATUS_OUT_OF_BOUNDS,
    STATUS_TRACE_FULL,
    TileLayout,
    Trace,
    Transition,
    UpdateRule,
    Weights,
)
from sb3_er.common.kernels.policy import epsilon_greedy
from sb3_er.common.kernels.replay import truncated
from sb3_er.common.kernels.tiles import all_q_values, feature, log_change, q_value, state_slots
from sb3_er.common.kernels.watch import watch_update


@kernel
def sarsa_lambda_step(weights, trace, layout, rule, transition, rng, scratch, watch):
    """One step of Sarsa(lambda) with replacing traces, Alg. 2 lines 8-12:

    - line 8: a_{k+1} <- epsilon-greedy on Q(s_{k+1}, .) (none when s_{k+1} is terminal);
    - line 10: delta = r_{k+1} + gamma Q(s_{k+1}, a_{k+1}) - Q(s_k, a_k) (r_{k+1} alone at a terminal s_{k+1});
    - line 9: e(s_k, a_k) = 1 on the N active features (a weight shared by two tilings, a hash collision, gets 2);
    - line 11: theta <- theta + alpha delta e, each active weight by step_size = alpha / N times its trace;
    - line 12: e <- gamma lambda e, dropping traces that fall below ``trace.cutoff``.

    Q(s_{k+1}, .) is read from ``weights.target`` (theta, or the target copy of a replaying learner); the stabilizers
    of the rule (truncation, the step-size bound) apply as in replay; the watch sees the target before truncation.

    Called once per environment step, so every bundle is a plain tuple in its field order (``tuple(bundle)``).
    Returns (a_{k+1}, delta, status): a_{k+1} is -1 at a terminal s_{k+1}; status reports an s_{k+1} that cannot be
    tiled (NaN, infinite, too large), a full trace list, or the first value outside the value watch's bounds (the
    step is made all the same).

    :param weights: the Weights (a plain tuple).
    :param trace: the Trace (a plain tuple).
    :param layout: the TileLayout (a plain tuple).
    :param rule: the UpdateRule (a plain tuple): step_size, gamma and epsilon are read.
    :param transition: the Transition (a plain tuple); its next_slots are written.
    :param rng: the xoshiro256** state of exploration (4 uint64), advanced in place.
    :param scratch: the Scratch (a plain tuple).
    :param watch: the value watch array (empty: off), updated in place.
    """
    weights, trace, layout = Weights(*weights), Trace(*trace), TileLayout(*layout)
    rule, transition = UpdateRule(*rule), Transition(*transition)
    theta, slots, action = weights.theta, transition.slots, transition.action
    q = scratch[0]
    q_sa = q_value(theta, slots, layout, action)
    next_action = -1
    if transition.terminated:
        target = used = transition.reward
    else:
        if not state_slots(transition.next_obs, layout, transition.next_slots):
            return -1, np.nan, STATUS_BAD_OBSERVATION
        all_q_values(weights.target, transition.next_slots, layout, q)
        next_action = epsilon_greedy(q, rule.epsilon, rng)  # line 8
        target = transition.reward + rule.gamma * q[next_action]
        used = transition.reward + rule.gamma * truncated(q[next_action], rule, watch)
    delta = used - q_sa  # line 10
    status = STATUS_OUT_OF_BOUNDS if watch_update(watch, target, q_sa) else STATUS_OK

    # line 9, e(s_k, a_k) = phi(s_k, a_k): replacing traces
    n = trace.length[0]
    capacity = trace.index.shape[0]
    for k in range(slots.shape[0]):
        i = feature(layout, slots, k, action)
        p = trace.position[i]
        if p < 0:
            if n == capacity:
                return next_action, delta, STATUS_TRACE_FULL
            p = n
            trace.index[n] = i
            trace.position[i] = n
            n += 1
        trace.value[p] = 0.0
    for k in range(slots.shape[0]):
        trace.value[trace.position[feature(layout, slots, k, action)]] += 1.0

    # line 11, theta <- theta + alpha delta e; line 12, e <- gamma lambda e (dropping traces below the cut-off)
    step_size = rule.step_size
    if rule.step_bound:
        step_size = _bounded_step(weights, trace, layout, rule, slots, action, transition, next_action)
    p = 0
    while p < n:
        i = trace.index[p]
        theta[i] += step_size * delta * trace.value[p]
        log_change(weights, i)
        decayed = trace.value[p] * trace.decay
        if decayed < trace.cutoff:
            n -= 1
            trace.position[i] = -1
            if p < n:
                moved = trace.index[n]
                trace.index[p] = moved
                trace.value[p] = trace.value[n]
                trace.position[moved] = p
                continue
        else:
            trace.value[p] = decayed
        p += 1
    trace.length[0] = n
    return next_action, delta, status


@helper
def _bounded_step(weights, trace, layout, rule, slots, action, transition, next_action):
    """Dabney and Barto's (2012) alpha-bound on the step per weight: step_cap <- min(step_cap, 1 / |e^T (gamma phi' -
    phi)|), with e the trace after line 9, phi = phi(s_k, a_k) and phi' = phi(s_{k+1}, a_{k+1}) (left out at a terminal
    s_{k+1} or with a target copy, which the step does not move); the step is min(step_size, step_cap). The products
    read the sparse trace at the N active features of each."""
    e_phi = 0.0
    for k in range(slots.shape[0]):
        e_phi += trace.value[trace.position[feature(layout, slots, k, action)]]
    product = -e_phi
    if next_action >= 0 and weights.changed_flag.shape[0] == 0:
        for k in range(slots.shape[0]):
            p = trace.position[feature(layout, transition.next_slots, k, next_action)]
            if p >= 0:
                product += rule.gamma * trace.value[p]
    if product != 0.0:
        rule.step_cap[0] = min(rule.step_cap[0], 1.0 / abs(product))
    return min(rule.step_size, rule.step_cap[0])


@kernel
def clear_trace(trace):
    """e <- 0 at the start of an episode (Alg. 2 line 5).

    :param trace: the Trace (a plain tuple, as :func:`sarsa_lambda_step` takes it).
    """
    trace = Trace(*trace)
    for p in range(trace.length[0]):
        trace.position[trace.index[p]] = -1
    trace.length[0] = 0

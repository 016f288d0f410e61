"""Action choice: greedy and epsilon-greedy over a state's action values (Alg. 2 line 8, Alg. 7 line 8, Alg. 8 line
6), for acting, for the next action of an update, and for ``predict``."""

import numpy as np

from sb3_er.common.kernels._jit import inline, kernel
from sb3_er.common.kernels.bundles import TileLayout
from sb3_er.common.kernels.rng import random_float, random_integer
from sb3_er.common.kernels.tiles import all_q_values, state_slots


@inline
def argmax_first(values):
    """The index of the largest of ``values``, the lowest one on ties (a greedy action without a random draw).

    :param values: action values, float64 (A,).
    """
    best = 0
    for a in range(1, values.shape[0]):
        if values[a] > values[best]:
            best = a
    return best


@inline
def argmax_random_ties(values, rng):
    """Greedy action, ties broken uniformly at random; a random draw only when there is a tie.

    Three branch-free passes (max, count of maxima, pick) beat one pass with data-dependent branches.

    :param values: action values, float64 (A,).
    :param rng: a xoshiro256** state (4 uint64), advanced in place.
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


@inline
def epsilon_greedy_explored(values, epsilon, rng):
    """argmax_a values[a] w.p. 1 - epsilon, a uniform random action w.p. epsilon (Alg. 2 line 8, Alg. 8 line 6), and
    whether it was the exploratory draw.

    :param values: action values, float64 (A,).
    :param epsilon: the exploration rate.
    :param rng: a xoshiro256** state (4 uint64), advanced in place.
    """
    if epsilon > 0.0 and random_float(rng) < epsilon:
        return random_integer(rng, values.shape[0]), True
    return argmax_random_ties(values, rng), False


@inline
def epsilon_greedy(values, epsilon, rng):
    """:func:`epsilon_greedy_explored`'s action alone.

    :param values: action values, float64 (A,).
    :param epsilon: the exploration rate.
    :param rng: a xoshiro256** state (4 uint64), advanced in place.
    """
    return epsilon_greedy_explored(values, epsilon, rng)[0]


@kernel
def select_action(theta, obs, layout, epsilon, rng, out_slots, q_scratch):
    """Epsilon-greedy a_k at s_k (Alg. 7 line 8); fills out_slots with the tiles of s_k. Returns -1 for an obs that
    cannot be tiled. Called once per environment step: ``layout`` is a plain tuple (``tuple(TileLayout)``).

    :param theta: the weights (Weights.theta).
    :param obs: the state s_k, float64 (D,).
    :param layout: the TileLayout as a plain tuple.
    :param epsilon: the exploration rate.
    :param rng: a xoshiro256** state (4 uint64), advanced in place.
    :param out_slots: written: the state-tile slots of s_k, (N,).
    :param q_scratch: scratch for Q(s_k, .), float64 (A,).
    """
    layout = TileLayout(*layout)
    if not state_slots(obs, layout, out_slots):
        return -1
    all_q_values(theta, out_slots, layout, q_scratch)
    return epsilon_greedy(q_scratch, epsilon, rng)


@kernel
def greedy_actions(theta, observations, layout, slots_scratch, q_scratch, out_actions):
    """Greedy action (lowest index on ties) for each row of observations; False if a row cannot be tiled.

    :param theta: the weights (Weights.theta).
    :param observations: the states, float64 (B, D).
    :param layout: the TileLayout.
    :param slots_scratch: scratch for one state's slots, (N,).
    :param q_scratch: scratch for Q(s, .), float64 (A,).
    :param out_actions: written: the greedy action of each row, (B,).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], layout, slots_scratch):
            return False
        all_q_values(theta, slots_scratch, layout, q_scratch)
        out_actions[i] = argmax_first(q_scratch)
    return True


@kernel
def batch_q_values(theta, observations, layout, slots_scratch, out_q):
    """Q(s, .) for each row of observations into out_q (B, A); False if a row cannot be tiled.

    :param theta: the weights (Weights.theta).
    :param observations: the states, float64 (B, D).
    :param layout: the TileLayout.
    :param slots_scratch: scratch for one state's slots, (N,).
    :param out_q: written: Q(s, .) of each row, (B, A).
    """
    for i in range(observations.shape[0]):
        if not state_slots(observations[i], layout, slots_scratch):
            return False
        all_q_values(theta, slots_scratch, layout, out_q[i])
    return True

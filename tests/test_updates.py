"""Single updates of every rule against hand computation with dense feature vectors (thesis Alg. 2, 8, 10, 12, 14)."""

import kernel_bundles as bundles
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er.common import kernels
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.kernels.tiles import visited_q_values
from sb3_er.common.tile_coding import TileCoder

N_TILINGS = 2
N_ACTIONS = 3
GAMMA = 0.9
ALPHA = 0.5


def tiny_coder() -> TileCoder:
    """1-D states, 2 tilings of width 1, 3 actions, a memory large enough that the states used here do not collide."""
    return TileCoder([1.0], [N_ACTIONS], n_tilings=N_TILINGS, memory_size=2**16)


def phi(coder: TileCoder, s: float, a: int) -> np.ndarray:
    """Dense binary feature vector phi(s, a) (with multiplicity where tilings collide)."""
    return np.bincount(coder.feature_indices(np.array([s]), a), minlength=coder.n_weights).astype(np.float64)


def q(theta, coder, s, a) -> float:
    return float(theta @ phi(coder, s, a))


def one_transition_buffer(coder, s, a, r, s_next, terminated=False):
    buffer = TrajectoryReplayBuffer(8, coder)
    buffer.add(np.array([s]), coder.slots(np.array([s])), a, r, np.array([s_next]))
    buffer.close_trajectory(np.array([s_next]), terminated)
    return buffer


def run_replay(
    theta,
    buffer,
    *,
    target=kernels.TARGET_SARSA,
    sigma=kernels.SIGMA_NONE,
    zeta=0.0,
    epsilon=0.0,
    residual_next_action=False,
    initial=kernels.ZERO_INITIAL,
):
    update_rule = bundles.rule(
        ALPHA / buffer.tile_coder.n_tilings, GAMMA, epsilon, target, sigma, zeta, residual_next_action
    )
    return bundles.replay_phase(theta, buffer, update_rule, initial=initial)


@pytest.fixture
def coder():
    c = tiny_coder()
    features = {(s, a): tuple(c.feature_indices(np.array([s]), a)) for s in (0.2, 1.7, 5.3) for a in range(3)}
    all_indices = [i for f in features.values() for i in f]
    assert len(set(all_indices)) == len(all_indices), "the fixture's states must not collide"
    return c


def seeded_theta(coder, values: dict) -> np.ndarray:
    """Weights such that each (s, a) in values has its own two features set to half the given Q."""
    theta = np.zeros(coder.n_weights)
    for (s, a), value in values.items():
        theta[coder.feature_indices(np.array([s]), a)] = value / N_TILINGS
    return theta


def test_er_sarsa_update_alg8(coder):
    """theta <- theta + alpha (r + gamma Q(s', a') - Q(s, a)) phi(s, a) / N with a' greedy (epsilon = 0)."""
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (1.7, 0): 1.0, (1.7, 2): 4.0})
    expected = theta + ALPHA / N_TILINGS * (3.0 + GAMMA * 4.0 - 2.0) * phi(coder, 0.2, 1)
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, 1.7)
    updates, sum_abs_delta, delta, status = run_replay(theta, buffer)
    assert (updates, status) == (1, kernels.STATUS_OK)
    assert delta == pytest.approx(3.0 + GAMMA * 4.0 - 2.0)
    np.testing.assert_allclose(theta, expected)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (3.0 + 3.6 - 2.0))


def test_terminal_transition_targets_reward_only(coder):
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (1.7, 2): 4.0})
    buffer = one_transition_buffer(coder, 0.2, 1, -5.0, 1.7, terminated=True)
    run_replay(theta, buffer)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (-5.0 - 2.0))


def test_q_learning_and_expected_sarsa_targets(coder):
    values = {(0.2, 1): 2.0, (1.7, 0): 1.0, (1.7, 1): -2.0, (1.7, 2): 4.0}
    epsilon = 0.3
    theta = seeded_theta(coder, values)
    run_replay(theta, one_transition_buffer(coder, 0.2, 1, 3.0, 1.7), target=kernels.TARGET_Q_LEARNING, epsilon=epsilon)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (3.0 + GAMMA * 4.0 - 2.0))

    theta = seeded_theta(coder, values)
    run_replay(
        theta, one_transition_buffer(coder, 0.2, 1, 3.0, 1.7), target=kernels.TARGET_EXPECTED_SARSA, epsilon=epsilon
    )
    expectation = (1 - epsilon) * 4.0 + epsilon * (1.0 - 2.0 + 4.0) / 3
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (3.0 + GAMMA * expectation - 2.0))


SIGMA_CASES = {
    # Q(s', a) / W(s', a) over the visited actions: a0 -> 1.0 / 2 = 0.5, a1 -> -3.0 / 1 = -3.0; a2 never visited.
    # average = (1.0 - 3.0 + 0.0) / (2 + 1 + 0) = -2/3.
    kernels.SIGMA_WORST: -3.0,
    kernels.SIGMA_AVERAGE: -2.0 / 3.0,
    kernels.SIGMA_BEST: 0.5,
    kernels.SIGMA_AVERAGE_WORST: 0.5 * (-2.0 / 3.0 - 3.0),
    kernels.SIGMA_AVERAGE_BEST: 0.5 * (-2.0 / 3.0 + 0.5),
}


@pytest.mark.parametrize("sigma_kind", sorted(SIGMA_CASES))
def test_er_sigma_update_alg10(coder, sigma_kind):
    """Q~(s', a) = Q(s', a) + (N - W(s', a)) sigma(s'); a' = argmax Q~; target r + gamma Q~(s', a') (Eq. 5.3-5.4)."""
    s_next = 1.7
    theta = np.zeros(coder.n_weights)
    f0 = coder.feature_indices(np.array([s_next]), 0)
    f1 = coder.feature_indices(np.array([s_next]), 1)
    theta[f0] = 0.5  # Q(s', a0) = 1.0, both features visited: W = 2
    theta[f1[0]] = -3.0  # Q(s', a1) = -3.0, one feature visited: W = 1
    theta[coder.feature_indices(np.array([0.2]), 1)] = 1.0  # Q(s, a) = 2.0
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, s_next)
    buffer.visits[f0] = 1
    buffer.visits[f1[0]] = 1

    sigma = SIGMA_CASES[sigma_kind]
    adjusted = np.array([1.0 + 0 * sigma, -3.0 + 1 * sigma, 0.0 + 2 * sigma])
    expected_target = 3.0 + GAMMA * adjusted.max()
    run_replay(theta, buffer, sigma=sigma_kind)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (expected_target - 2.0))


def test_sigma_without_any_visited_action_falls_back_to_plain_values(coder):
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (5.3, 2): 1.0})
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, 5.3)
    buffer.visits[:] = 0
    run_replay(theta, buffer, sigma=kernels.SIGMA_AVERAGE_WORST)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 + ALPHA * (3.0 + GAMMA * 1.0 - 2.0))


@pytest.mark.parametrize("zeta", [1.0, 0.4])
def test_residual_update_alg12(coder, zeta):
    """theta <- theta + alpha delta (phi(s, a) - zeta gamma phi(s', a)) / N, with the stored action a (Eq. 5.7-5.9)."""
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (1.7, 0): 1.0, (1.7, 2): 4.0})
    delta = 3.0 + GAMMA * 4.0 - 2.0
    direction = phi(coder, 0.2, 1) - zeta * GAMMA * phi(coder, 1.7, 1)
    expected = theta + ALPHA / N_TILINGS * delta * direction
    run_replay(theta, one_transition_buffer(coder, 0.2, 1, 3.0, 1.7), zeta=zeta)
    np.testing.assert_allclose(theta, expected)
    assert q(theta, coder, 1.7, 1) == pytest.approx(-zeta * GAMMA * ALPHA * delta)


def test_residual_gradient_with_the_next_action(coder):
    """Baird's residual gradient: theta <- theta + alpha delta (phi(s, a) - zeta gamma phi(s', a')) / N, a' = argmax."""
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (1.7, 0): 1.0, (1.7, 2): 4.0})
    delta = 3.0 + GAMMA * 4.0 - 2.0
    expected = theta + ALPHA / N_TILINGS * delta * (phi(coder, 0.2, 1) - GAMMA * phi(coder, 1.7, 2))
    run_replay(theta, one_transition_buffer(coder, 0.2, 1, 3.0, 1.7), zeta=1.0, residual_next_action=True)
    np.testing.assert_allclose(theta, expected)
    assert q(theta, coder, 1.7, 2) == pytest.approx(4.0 - GAMMA * ALPHA * delta)


def test_residual_er_sigma_update_alg14(coder):
    s_next = 1.7
    theta = np.zeros(coder.n_weights)
    f0 = coder.feature_indices(np.array([s_next]), 0)
    theta[f0] = 0.5  # Q(s', a0) = 1, W = 2; a1, a2 unvisited: sigma = average_worst = (1/2 + 1/2) / 2 = 0.5
    theta[coder.feature_indices(np.array([0.2]), 1)] = 1.0
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, s_next)
    buffer.visits[f0] = 1
    adjusted = np.array([1.0, 0.0 + 2 * 0.5, 0.0 + 2 * 0.5])  # ties: a' is one of them, every tie has Q~ = 1.0
    delta = 3.0 + GAMMA * adjusted.max() - 2.0
    expected = theta + ALPHA / N_TILINGS * delta * (phi(coder, 0.2, 1) - GAMMA * phi(coder, s_next, 1))
    run_replay(theta, buffer, sigma=kernels.SIGMA_AVERAGE_WORST, zeta=1.0)
    np.testing.assert_allclose(theta, expected)


def sarsa_lambda_step(coder, theta, trace, s, a, r, s_next, terminated, lam):
    next_slots = np.zeros(coder.n_tilings, dtype=np.int64)
    transition = (coder.slots(np.array([s])), a, float(r), terminated, np.array([s_next]), next_slots)
    return kernels.sarsa_lambda_step(
        tuple(bundles.weights(theta)),
        (*trace, GAMMA * lam, 1e-6),
        tuple(coder.layout),
        tuple(bundles.rule(ALPHA / coder.n_tilings, GAMMA)),
        transition,
        kernels.new_rng_state(0),
        tuple(bundles.scratch(coder.n_actions)),
        kernels.NO_WATCH,
    )


def empty_trace(coder, capacity=64):
    return (
        np.zeros(capacity, np.int64),
        np.zeros(capacity),
        np.full(coder.n_weights, -1, np.int32),
        np.zeros(1, np.int64),
    )


def test_sarsa_lambda_two_steps_alg2(coder):
    """Two steps of Alg. 2 with replacing traces, followed by hand with dense e and theta."""
    lam = 0.8
    theta = seeded_theta(coder, {(1.7, 2): 4.0, (5.3, 0): 1.0})
    trace = empty_trace(coder)
    e = np.zeros(coder.n_weights)
    expected = theta.copy()

    a1, delta1, _ = sarsa_lambda_step(coder, theta, trace, 0.2, 1, 3.0, 1.7, False, lam)
    e = phi(coder, 0.2, 1)
    d1 = 3.0 + GAMMA * 4.0 - 0.0
    expected += ALPHA / N_TILINGS * d1 * e
    e *= GAMMA * lam
    assert a1 == 2 and delta1 == pytest.approx(d1)

    a2, delta2, _ = sarsa_lambda_step(coder, theta, trace, 1.7, 2, -1.0, 5.3, False, lam)
    e = np.maximum(e, phi(coder, 1.7, 2))
    d2 = -1.0 + GAMMA * 1.0 - 4.0
    expected += ALPHA / N_TILINGS * d2 * e
    assert a2 == 0 and delta2 == pytest.approx(d2)
    np.testing.assert_allclose(theta, expected)
    # the first state-action pair also moved through its decayed trace
    assert q(theta, coder, 0.2, 1) == pytest.approx(ALPHA * d1 + ALPHA * d2 * GAMMA * lam)


def test_sarsa_lambda_replaces_rather_than_accumulates(coder):
    lam = 1.0
    theta = np.zeros(coder.n_weights)
    trace = empty_trace(coder)
    sarsa_lambda_step(coder, theta, trace, 0.2, 1, 0.0, 0.2, False, lam)
    sarsa_lambda_step(coder, theta, trace, 0.2, 1, 0.0, 0.2, False, lam)
    trace_index, trace_value, _, trace_length = trace
    values = dict(zip(trace_index[: trace_length[0]].tolist(), trace_value[: trace_length[0]].tolist(), strict=True))
    for i in coder.feature_indices(np.array([0.2]), 1):
        assert values[i] == pytest.approx(GAMMA * lam)  # reset to 1 on the second visit, then decayed once


def test_sarsa_lambda_terminal_step(coder):
    theta = seeded_theta(coder, {(0.2, 1): 2.0, (1.7, 2): 4.0})
    next_action, delta, _ = sarsa_lambda_step(coder, theta, empty_trace(coder), 0.2, 1, -50.0, 1.7, True, 0.9)
    assert next_action == -1
    assert delta == pytest.approx(-52.0)
    assert q(theta, coder, 0.2, 1) == pytest.approx(2.0 - ALPHA * 52.0)


def test_colliding_tilings_update_like_the_gradient():
    """With one slot, both tilings share every weight: phi has a 2 there, and the update follows that gradient."""
    coder = TileCoder([1.0], [2], n_tilings=2, memory_size=8)
    assert coder.n_slots == 1
    i = coder.feature_indices(np.array([0.3]), 1)
    assert i[0] == i[1]
    theta = np.zeros(coder.n_weights)
    theta[i[0]] = 1.0  # Q(s, a1) = 2 (counted in both tilings)
    buffer = one_transition_buffer(coder, 0.3, 1, 1.0, 0.3, terminated=True)
    run_replay(theta, buffer)
    delta = 1.0 - 2.0
    assert theta[i[0]] == pytest.approx(1.0 + 2 * ALPHA / 2 * delta)  # dense: phi_i = 2
    assert q(theta, coder, 0.3, 1) == pytest.approx(2.0 + 2 * ALPHA * delta)

    theta = np.zeros(coder.n_weights)
    trace = empty_trace(coder)
    sarsa_lambda_step(coder, theta, trace, 0.3, 1, 1.0, 0.3, True, 0.9)
    assert theta[i[0]] == pytest.approx(2 * ALPHA / 2 * 1.0)  # replacing trace e_i = phi_i = 2


# Q_v and W (Eq. 5.1-5.2) against a dense reference on both layouts (actions as columns; actions tiled, as LEO's
# voltages), with unvisited weights that are zero (every weight the non-residual variants leave unvisited) or not
# (initial values, the residual term): Q_v sums the visited features' weights only, W counts them.
@settings(max_examples=60, deadline=None)
@given(tiled=st.booleans(), written=st.sampled_from(["none", "some", "all"]), seed=st.integers(0, 2**16))
def test_visited_values_and_counts_match_a_dense_sum(tiled, written, seed):
    rng = np.random.default_rng(seed)
    if tiled:
        coder = TileCoder([0.5, 0.5], [5, 5], n_tilings=4, memory_size=2**12, action_tile_widths=[2.0, 2.0])
    else:
        coder = TileCoder([0.5, 0.5], [6], n_tilings=4, memory_size=2**12)
    assert coder.columns_are_actions is not tiled
    visits = (rng.random(coder.n_weights) < 0.5).astype(np.uint8)
    theta = np.where(visits == 1, rng.normal(size=coder.n_weights), 0.0)
    if written != "none":
        unvisited = np.flatnonzero(visits == 0)
        chosen = unvisited if written == "all" else rng.choice(unvisited, size=max(1, len(unvisited) // 50))
        theta[chosen] = rng.normal(size=len(chosen)) * 10.0
    obs = rng.uniform(-3.0, 3.0, 2)
    slots = coder.slots(obs)
    out_q, out_w = np.full(coder.n_actions, np.nan), np.full(coder.n_actions, np.nan)
    visited_q_values(theta, visits, slots, coder.layout, False, out_q, out_w)
    for a in range(coder.n_actions):
        features = coder.feature_indices(obs, a)
        assert out_w[a] == visits[features].sum()
        assert out_q[a] == pytest.approx(float((theta[features] * visits[features]).sum()), rel=1e-12, abs=1e-12)

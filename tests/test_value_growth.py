"""Thesis 5.3.1 and Figure 5.6, a self-affecting sample: the kernels' replay against the hand computation.

One stored transition (s, a, r, s'), s' sharing k of the N tiles of s, f = k / N, one action, alpha on Q, discount
gamma, residual factor zeta. Each replay moves Q(s, a) by p alpha delta and the bootstrap value at s' by q alpha
delta, so delta_{n+1} = (1 - alpha (p - gamma q)) delta_n:

    vanilla ER   p = 1, q = f      (the shared tiles move Q(s', a) by f of Q(s, a)'s change)
    ER-sigma     p = 1, q = 1      (sigma(s') = mean weight of the k visited tiles, given to the N - k others)
    residual ER  p = 1 - zeta gamma f, q = f - zeta gamma   (phi(s, a) - zeta gamma phi(s', a), Eq. 5.7-5.9)
    residual ER-sigma  p = 1 - zeta gamma f, q = 1 - zeta gamma  (its term on the unvisited tiles of s' is replaced
                                                       by sigma like their other values)

The values are computed here from these formulas, independently of the module's ``closed_form``.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er.experiments import value_growth as vg

GAMMA, ALPHA = 0.98, 0.25


def hand_values(variant, reward, q_state, q_next, n, n_tilings, shared, alpha=ALPHA, gamma=GAMMA, zeta=1.0):
    """Q_n(s, a) for n = 0..n by iterating the two-number recursion (Q(s, a), bootstrap value) by hand."""
    f = shared / n_tilings
    sigma, residual = {
        "ER": (False, False),
        "ER-σ": (True, False),
        "residual ER": (False, True),
        "residual ER-σ": (True, True),
    }[variant]
    z = zeta if residual else 0.0
    p = 1 - z * gamma * f
    q = (1 - z * gamma) if sigma else (f - z * gamma)
    d, e = q_state, q_next
    out = [d]
    for _ in range(n):
        delta = reward + gamma * e - d
        d, e = d + p * alpha * delta, e + q * alpha * delta
        out.append(d)
    return np.array(out)


@pytest.mark.parametrize("case", ["a", "b"])
@pytest.mark.parametrize("variant", list(vg.VARIANTS))
def test_kernels_replay_the_hand_computation(variant, case):
    values = vg.CASES[case]
    sample = vg.self_affecting_model(variant, case)
    got = vg.replay_values(sample, 300)
    want = hand_values(variant, values["reward"], values["q_state"], values["q_next"], 300, 4, 3)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(vg.closed_form(variant, case, 300), want, rtol=1e-12, atol=1e-12)


def test_figure_5_6_findings():
    """Many times the target (a), negative turning positive (b); the residual variants damp both (Table 5.2)."""
    limit = {(v, c): vg.limit_value(v, c) for v in vg.VARIANTS for c in vg.CASES}
    # (a): the initial target is 10; vanilla ER ends at 10 / (1 - 0.98 * 3/4), ER-sigma at 10 / (1 - 0.98)
    assert limit["ER", "a"] == pytest.approx(10 / (1 - 0.98 * 0.75))
    assert limit["ER-σ", "a"] == pytest.approx(500.0)
    # (b): from -10 with r = -1 and Q(s', a) = -5 (delta_0 = 4.1), vanilla ER ends positive, ER-sigma far more so
    assert limit["ER", "b"] == pytest.approx(-10 + 4.1 / (1 - 0.98 * 0.75))
    assert 0 < limit["ER", "b"] < limit["ER-σ", "b"] == pytest.approx(195.0)
    for residual in ("residual ER", "residual ER-σ"):
        assert 0 < limit[residual, "a"] < limit["ER", "a"]
        assert limit[residual, "a"] < 2 * 10  # within twice the initial target
        assert limit[residual, "b"] < 0  # stays negative
    sample = vg.self_affecting_model("ER", "b")
    assert vg.replay_values(sample, 100)[-1] > 0


@settings(max_examples=25, deadline=None)
@given(
    st.integers(2, 16).flatmap(lambda n: st.tuples(st.just(n), st.integers(1, n - 1))),
    st.sampled_from(list(vg.VARIANTS)),
    st.sampled_from(["a", "b"]),
)
def test_any_overlap(tiling, variant, case):
    n_tilings, shared = tiling
    values = vg.CASES[case]
    got = vg.replay_values(vg.self_affecting_model(variant, case, n_tilings=n_tilings, shared=shared), 40)
    want = hand_values(variant, values["reward"], values["q_state"], values["q_next"], 40, n_tilings, shared)
    np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-11)


@given(st.integers(2, 32).flatmap(lambda n: st.tuples(st.just(n), st.integers(1, n - 1))))
def test_er_sigma_makes_any_overlap_a_full_self_loop(tiling):
    """Whatever share of tiles s' shares, ER-sigma's value tends to r / (1 - gamma) (case a), vanilla's only to
    r / (1 - gamma f)."""
    n_tilings, shared = tiling
    assert vg.limit_value("ER-σ", "a", n_tilings, shared) == pytest.approx(10 / (1 - GAMMA))
    assert vg.limit_value("ER", "a", n_tilings, shared) == pytest.approx(10 / (1 - GAMMA * shared / n_tilings))


@pytest.mark.parametrize("variant", ["ER", "ER-σ"])
def test_target_comparison_is_the_target_replay_moves_to(variant):
    """The instrumented target of the stored sample is the one the kernel's next update moves Q(s, a) towards:
    Q_1 = Q_0 + alpha (T - Q_0) (no residual term)."""
    sample = vg.self_affecting_model(variant, "b")
    comparison = vg.target_comparison(sample.model)
    before = sample.q_state()
    sample.model.replay(1)
    target = before + (sample.q_state() - before) / ALPHA
    column = "target_sigma" if variant == "ER-σ" else "target_vanilla"
    assert comparison[column][0] == pytest.approx(target, rel=1e-12)
    assert comparison["q_sa"][0] == pytest.approx(before)
    assert comparison["w_chosen"][0] == 3 and comparison["w_total"][0] == 3
    assert comparison["overlap_sigma"][0] == pytest.approx(0.75)
    assert not comparison["no_action_visited"][0]
    # by hand: vanilla r + gamma Q(s', a) = -1 + 0.98 * -5; sigma r + gamma (4/3) * (3 shared weights of -5/4)
    assert comparison["target_vanilla"][0] == pytest.approx(-1 + 0.98 * -5)
    assert comparison["target_sigma"][0] == pytest.approx(-1 + 0.98 * (4 / 3) * (3 * -1.25))


def test_replay_gain_of_a_self_loop_and_the_model_left_unchanged():
    """With s' = s and every reward 0, each replay multiplies Q by 1 - alpha (1 - gamma): the gain per phase of one
    replayed trajectory. The model's weights, rewards, generators and counters are as before."""
    sample = vg.self_affecting_model("ER", "a", n_tilings=4, shared=4)
    model = sample.model
    features = model.policy.tile_coder.feature_indices(sample.state, 0)
    model.policy.theta_array[features] = 1.0
    state = (
        model.policy.theta_array.copy(),
        model.replay_buffer.rewards.copy(),
        model.replay_rng.copy(),
        model.action_rng.copy(),
        model.replay_updates,
        model.replay_phases,
    )
    assert vg.replay_gain(model, n_phases=20, n_trajectories=1, skip=5) == pytest.approx(1 - ALPHA * (1 - GAMMA))
    np.testing.assert_array_equal(model.policy.theta_array, state[0])
    np.testing.assert_array_equal(model.replay_buffer.rewards, state[1])
    np.testing.assert_array_equal(model.replay_rng, state[2])
    np.testing.assert_array_equal(model.action_rng, state[3])
    assert (model.replay_updates, model.replay_phases) == state[4:]


def test_bad_requests():
    with pytest.raises(ValueError, match="unknown variant"):
        vg.self_affecting_model("DQN")
    with pytest.raises(ValueError, match="unknown case"):
        vg.self_affecting_model("ER", "c")
    with pytest.raises(ValueError, match="shared"):
        vg.self_affecting_model("ER", "a", n_tilings=4, shared=5)
    with pytest.raises(ValueError, match="shared < n_tilings"):
        vg.self_affecting_model("ER", "b", n_tilings=4, shared=4)


def test_residual_er_sigma_replaces_what_the_residual_term_wrote():
    """Residual ER-sigma writes -zeta gamma alpha delta / N into every tile of phi(s', a), the unvisited ones too.
    Eq. 5.4 replaces unvisited values by sigma(s'): those writes must not count as experience. Counted (Eq. 5.4's
    literal Q(s', a) + u sigma N), sigma spreads them over the N - k unvisited tiles again, q becomes
    1 - zeta gamma / f and with 1 tile of 16 shared (alpha 0.2, gamma 0.99) every replay multiplied delta by
    1 - alpha (p - gamma q) = -2.1: the sample diverged. Replaced, it converges to the closed form's limit."""
    sample = vg.self_affecting_model("residual ER-σ", "a", n_tilings=16, shared=1, learning_rate=0.2, gamma=0.99)
    model = sample.model
    coder = model.policy.tile_coder
    got = vg.replay_values(sample, 400)
    unvisited = np.setdiff1d(coder.feature_indices(sample.next_state, 0), coder.feature_indices(sample.state, 0))
    assert np.all(model.policy.theta_array[unvisited] < 0)  # the residual term wrote into them
    assert not model.replay_buffer.visits[unvisited].any()
    want = hand_values("residual ER-σ", 10.0, 0.0, 0.0, 400, 16, 1, alpha=0.2, gamma=0.99)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
    assert abs(got[-1] - vg.limit_value("residual ER-σ", "a", 16, 1, gamma=0.99)) < 1e-6
    # the target seen by the instrument: r + gamma * 16 * (the one shared, visited weight)
    shared = np.intersect1d(coder.feature_indices(sample.next_state, 0), coder.feature_indices(sample.state, 0))
    comparison = vg.target_comparison(model)
    assert comparison["target_sigma"][0] == pytest.approx(10 + 0.99 * 16 * model.policy.theta_array[shared].sum())


def test_the_value_watch_sees_figure_5_6_leave_the_possible_returns():
    """Case (b) pays -1 per step: every return is -50, every value in [-50, -5] with the initial values. Vanilla ER's
    value turns positive, so the watch counts it; the replay gain's replays stay unseen."""
    sample = vg.self_affecting_model("ER", "b")
    model = sample.model
    assert model.value_bounds == pytest.approx((-50.0, -5.0))
    vg.replay_values(sample, 2)
    assert model.values_out_of_range == 0  # -10 rising towards -5: still possible
    vg.replay_values(sample, 1)  # the third phase bootstraps from a shared tile already past -5
    first = model.value_excursion
    assert model.values_out_of_range > 0 and first["value"] > first["high"] + first["margin"]
    assert first["where"].endswith("replay phase 3")
    vg.replay_values(sample, 100)
    assert sample.q_state() > 0 and model.values_out_of_range > 0
    seen = model.values_out_of_range
    vg.replay_gain(model, n_phases=12, n_trajectories=1, skip=2)
    assert model.values_out_of_range == seen

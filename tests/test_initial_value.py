"""TileQ's initial_value: where Q starts, reproducibly, and how ER-sigma treats the initial values (Eq. 5.4)."""

import kernel_bundles as bundles
import numpy as np
import pytest
from conftest import LineWalkEnv
from test_updates import ALPHA, GAMMA, N_TILINGS, one_transition_buffer, q, run_replay, tiny_coder

from sb3_er import ER, ERSigma, SarsaLambda
from sb3_er.common import kernels

OBSERVATIONS = np.linspace(0.0, 10.0, 57)[:, None]


def model(initial_value, seed=0, algo=SarsaLambda, **kwargs):
    return algo(
        "TileQ",
        LineWalkEnv(),
        seed=seed,
        policy_kwargs=dict(n_tilings=16, memory_size=2**16, initial_value=initial_value),
        **kwargs,
    )


def test_a_constant_starts_every_q_value_there():
    values = model(-3.0).policy.q_values(OBSERVATIONS)
    np.testing.assert_array_equal(values, -3.0)  # 16 weights of -3/16 each: exact in binary


def test_a_range_starts_q_uniformly_inside_it():
    policy = model((0.0, 1.0)).policy
    weights = policy.theta_array
    assert weights.min() >= 0.0 and weights.max() < 1.0 / 16
    assert weights.mean() == pytest.approx(1.0 / 32, rel=0.01)  # U(0, 1/16) over 2^16 weights
    values = policy.q_values(OBSERVATIONS)
    assert values.min() >= 0.0 and values.max() <= 1.0
    assert values.std() == pytest.approx(np.sqrt(16 / 12) / 16, rel=0.3)  # a sum of 16 U(0, 1/16)


def test_the_draw_is_seeded_and_survives_save_and_load(tmp_path):
    first, again, other = model((0.0, 1.0), seed=4), model((0.0, 1.0), seed=4), model((0.0, 1.0), seed=5)
    np.testing.assert_array_equal(first.policy.theta_array, again.policy.theta_array)
    assert not np.array_equal(first.policy.theta_array, other.policy.theta_array)
    first.save(tmp_path / "model")
    loaded = SarsaLambda.load(tmp_path / "model")
    assert loaded.policy.initial_value_seed == first.policy.initial_value_seed
    indices = np.arange(0, first.policy.theta_array.size, 97)
    np.testing.assert_array_equal(loaded.policy.initial_weights(indices), first.policy.theta_array[indices])


def test_memory_fill_and_weight_mean_count_touched_weights_only():
    fresh = model((-1.0, 1.0))
    assert kernels.weight_statistics(fresh.policy.weights) == (0.0, 0.0)
    fresh.learn(200)
    mean_abs, fill = kernels.weight_statistics(fresh.policy.weights)
    touched = fresh.policy.theta_array != fresh.policy.initial_weights(np.arange(fresh.policy.theta_array.size))
    assert fill == pytest.approx(touched.mean()) and 0 < fill < 0.05
    assert mean_abs == pytest.approx(np.abs(fresh.policy.theta_array[touched]).mean())


@pytest.mark.parametrize("bad", [(1.0, 0.0), (0.0, np.inf), "high", (1.0, 2.0, 3.0)])
def test_bad_initial_values_are_named(bad):
    with pytest.raises(ValueError, match="initial_value"):
        model(bad)


# ER-sigma: the initial values of unvisited features are replaced by sigma(s') (Eq. 5.4's intent, "provided theta is
# initialised with zeros ... not required"): Q~ is computed from what experience put into the visited features.


def _sigma_case(initial):
    """The test_updates ER-sigma case (s' = 1.7: a0 both features visited, Q 1.0; a1 one feature visited, -3.0; a2
    none), every other weight at its initial value. Returns Q(s, a) after one replayed update."""
    coder = tiny_coder()
    theta = np.zeros(coder.n_weights)
    kernels.fill_initial_weights(bundles.weights(theta, initial))
    f0 = coder.feature_indices(np.array([1.7]), 0)
    f1 = coder.feature_indices(np.array([1.7]), 1)
    f_sa = coder.feature_indices(np.array([0.2]), 1)
    theta[f0] = 0.5
    theta[f1[0]] = -3.0
    theta[f_sa] = 1.0  # Q(s, a) = 2.0
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, 1.7)
    buffer.visits[f0] = 1
    buffer.visits[f1[0]] = 1
    coder_q = q(theta, coder, 1.7, 2)
    run_replay(theta, buffer, sigma=kernels.SIGMA_AVERAGE_WORST, initial=initial)
    return q(theta, coder, 0.2, 1), coder_q


def test_er_sigma_ignores_the_initial_values_of_unvisited_features():
    sigma = 0.5 * (-2.0 / 3.0 - 3.0)  # by hand, as in test_updates: average -2/3, worst -3
    target = 3.0 + GAMMA * max(1.0, -3.0 + sigma, 2 * sigma)
    expected = 2.0 + ALPHA * (target - 2.0)
    for initial in [kernels.ZERO_INITIAL, (0.75, 0.0, np.uint64(0)), (-2.0, 4.0, np.uint64(9))]:
        updated, q_unvisited_action = _sigma_case(initial)
        assert updated == pytest.approx(expected)
        if initial[0] != 0.0:
            assert q_unvisited_action != pytest.approx(2 * sigma)  # plain Q at a2 is the prior, not sigma


def test_er_sigma_at_a_state_with_no_visited_action_uses_the_initial_values():
    coder = tiny_coder()
    initial = (0.75, 0.0, np.uint64(0))  # every weight 0.75: Q = 1.5 everywhere
    theta = np.full(coder.n_weights, 0.75)
    buffer = one_transition_buffer(coder, 0.2, 1, 3.0, 5.3)
    buffer.visits[coder.feature_indices(np.array([5.3]), 0)] = 0  # nothing visited at s' = 5.3
    run_replay(theta, buffer, sigma=kernels.SIGMA_AVERAGE_WORST, initial=initial)
    assert q(theta, coder, 0.2, 1) == pytest.approx(1.5 + ALPHA * (3.0 + GAMMA * 1.5 - 1.5))


def test_er_models_take_initial_values_through_policy_kwargs():
    er = model(2.0, algo=ER, n_replays=5)
    assert er.policy.q_values(OBSERVATIONS[:3]) == pytest.approx(2.0)
    er.learn(300)
    sigma = model((-1.0, 0.0), algo=ERSigma, n_replays=5).learn(300)
    assert np.isfinite(sigma.policy.theta_array).all()
    assert N_TILINGS == 2  # the hand cases above use the 2-tiling coder of test_updates


# --- the draw's seed: the seed's, whatever else uses NumPy's global generator (issue 37) ------------------------------


def test_a_seeded_draw_is_the_one_sb3s_seeding_gave_the_global_generator():
    """SB3's set_random_seed(seed) seeds NumPy's global generator; the policy's seed is its first randint(0, 2^62) after
    that (the value every seeded model drew so far, so seeded runs keep their weights)."""
    for seed in (0, 1, 4, 2**32 - 1):
        np.random.seed(seed)  # noqa: NPY002 (the global generator, as SB3 seeds it)
        expected = int(np.random.randint(0, 2**62))  # noqa: NPY002
        assert model((0.0, 1.0), seed=seed).policy.initial_value_seed == expected


class _BusyEnv(LineWalkEnv):
    """An env whose wrap periods, read while the model is built (after SB3 seeds NumPy's global generator and before
    the policy exists), draw from the global generator, as another thread building a model at that moment would."""

    @property
    def wrap_periods(self):
        np.random.random(3)  # noqa: NPY002
        return None


def test_the_seeded_draw_ignores_other_users_of_the_global_generator():
    kwargs = dict(seed=3, policy_kwargs=dict(n_tilings=4, memory_size=2**12, initial_value=(0.0, 1.0)))
    busy = SarsaLambda("TileQ", _BusyEnv(), **kwargs)
    quiet = SarsaLambda("TileQ", LineWalkEnv(), **kwargs)
    np.testing.assert_array_equal(busy.policy.theta_array, quiet.policy.theta_array)


def test_models_built_at_once_in_threads_with_one_seed_start_alike():
    import threading

    n_threads = 6
    barrier = threading.Barrier(n_threads)
    weights = [None] * n_threads

    def build(index):
        barrier.wait()
        weights[index] = model((0.0, 1.0), seed=11).policy.theta_array.copy()

    threads = [threading.Thread(target=build, args=(i,)) for i in range(n_threads)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for other in weights[1:]:
        np.testing.assert_array_equal(other, weights[0])
    np.testing.assert_array_equal(weights[0], model((0.0, 1.0), seed=11).policy.theta_array)


def test_unseeded_models_draw_fresh_seeds_whatever_the_global_generator_holds():
    seeds = set()
    for _ in range(3):
        np.random.seed(0)  # noqa: NPY002 (a user's global seeding does not fix an unseeded model's start)
        seeds.add(model((0.0, 1.0), seed=None).policy.initial_value_seed)
    assert len(seeds) == 3

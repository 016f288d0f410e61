"""Tile coding: Eq. 2.9 offsets, wrapping, hashing, action tiling, memory statistics, bad settings."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er.common.tile_coding import TileCoder, tiling_offsets


def test_offsets_follow_eq_2_9():
    """A_k^d = r_d (k - 1)(1 + 2(d - 1)) / K with 1-based k, d; in tile units for 4 tilings and 3 dimensions."""
    offsets = tiling_offsets(4, 3)
    for k in range(1, 5):
        for d in range(1, 4):
            assert offsets[k - 1, d - 1] == pytest.approx((k - 1) * (1 + 2 * (d - 1)) / 4)


def test_coordinates_by_hand():
    coder = TileCoder([0.5, 2.0], [3], n_tilings=4)
    # tiling k shifts dimension 0 by k/4 and dimension 1 by 3k/4 tile widths
    coords = coder.coordinates(np.array([0.3, -1.0]))
    expected = [[math.floor(0.3 / 0.5 + k / 4), math.floor(-1.0 / 2.0 + 3 * k / 4)] for k in range(4)]
    assert coords.tolist() == expected


def test_wrapped_dimension_is_periodic_with_whole_tiles():
    coder = TileCoder([0.33, 0.33], [7], n_tilings=16, wrap_periods=[2 * math.pi, None])
    assert coder.wrap_tiles.tolist() == [19, 0]
    assert 1 / coder.inv_widths[0] == pytest.approx(2 * math.pi / 19)
    for angle in (-3.0, 0.1, 3.1):
        np.testing.assert_array_equal(
            coder.slots(np.array([angle, 1.0])), coder.slots(np.array([angle + 2 * math.pi, 1.0]))
        )
    # just either side of pi are neighbours, not opposite ends of the table
    assert np.any(coder.slots(np.array([math.pi - 0.01, 0.0])) == coder.slots(np.array([-math.pi + 0.01, 0.0])))


def test_hashing_is_deterministic_across_instances():
    obs = np.array([0.123, -4.5, 7.0])
    a = TileCoder([0.1, 0.5, 1.0], [5], n_tilings=8, memory_size=2**20)
    b = TileCoder([0.1, 0.5, 1.0], [5], n_tilings=8, memory_size=2**20)
    np.testing.assert_array_equal(a.slots(obs), b.slots(obs))
    assert np.all((a.slots(obs) >= 0) & (a.slots(obs) < a.n_slots))


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-100, 100, allow_nan=False),
    y=st.floats(-100, 100, allow_nan=False),
    dx=st.floats(-0.5, 0.5),
)
def test_same_tile_same_slot_and_generalisation(x, y, dx):
    """Per tiling: equal coordinates give equal slots; nearby points share most tilings (generalisation)."""
    coder = TileCoder([1.0, 1.0], [2], n_tilings=16, memory_size=2**24)
    p, q = np.array([x, y]), np.array([x + dx / 16, y])
    same = np.all(coder.coordinates(p) == coder.coordinates(q), axis=1)
    slots_p, slots_q = coder.slots(p), coder.slots(q)
    assert np.all(slots_p[same] == slots_q[same])
    assert same.sum() >= 16 - 1  # a shift of at most 1/32 tile crosses a boundary in at most one tiling


def test_distinct_tiles_rarely_collide_in_a_large_memory():
    coder = TileCoder([0.1, 0.1], [3], n_tilings=16, memory_size=2**22)
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 40), np.linspace(-1, 1, 40)), -1).reshape(-1, 2)
    report = coder.memory_report(grid)
    assert report["distinct_tiles"] > 16 * 400
    assert report["collision_rate"] < 0.01
    assert report["fill"] == pytest.approx(report["slots_used"] / coder.n_slots)


def test_small_memory_reports_collisions():
    coder = TileCoder([0.1, 0.1], [3], n_tilings=16, memory_size=8 * 256)
    assert coder.n_slots == 256
    grid = np.random.default_rng(0).uniform(-5, 5, size=(500, 2))
    report = coder.memory_report(grid)
    assert report["slots_used"] <= 256
    assert report["collision_rate"] > 0.5


def test_weight_layout_keeps_actions_of_one_tile_adjacent():
    coder = TileCoder([1.0], [5], n_tilings=4, memory_size=2**12)
    obs = np.array([0.4])
    rows = np.stack([coder.feature_indices(obs, a) for a in range(5)], axis=1)
    np.testing.assert_array_equal(rows - rows[:, :1], np.tile(np.arange(5), (4, 1)))
    assert coder.stride == 8  # 5 actions padded to a whole 64-byte cache line
    assert coder.n_weights == coder.n_slots * 8 and coder.n_weights <= 2**12


def test_action_tiling_generalises_over_neighbouring_levels():
    """LEO's voltages: 7 levels k * 10.6919 / 3 V tiled with width 6.67 V share tiles with their neighbours."""
    levels = np.arange(-3, 4) * 10.6919 / 3
    coder = TileCoder([1.0], [7, 7, 7], n_tilings=16, action_values=[levels] * 3, action_tile_widths=[6.67] * 3)
    assert coder.stride < 343
    columns = coder.action_columns
    flat = lambda i, j, k: np.ravel_multi_index((i, j, k), (7, 7, 7))  # noqa: E731
    shared_neighbour = np.mean(columns[:, flat(3, 3, 3)] == columns[:, flat(4, 3, 3)])
    shared_far = np.mean(columns[:, flat(0, 3, 3)] == columns[:, flat(6, 3, 3)])
    assert 0.2 < shared_neighbour < 1.0
    assert shared_far == 0.0
    # within one tiling, voltages in the same 6.67 V tile share a column
    for k in range(16):
        offset = k * (1 + 2 * 1) / 16  # action dimension 0 is displacement dimension 1 after the single state dim
        tiles = np.floor(levels / 6.67 + offset)
        same = tiles[3] == tiles[4]
        assert (columns[k, flat(3, 0, 0)] == columns[k, flat(4, 0, 0)]) == same


def test_config_round_trip():
    coder = TileCoder([0.2, 0.3], [4, 2], n_tilings=8, wrap_periods=[None, 6.0], action_tile_widths=[2.0, 1.0])
    again = TileCoder(**coder.config())
    np.testing.assert_array_equal(again.action_columns, coder.action_columns)
    np.testing.assert_array_equal(again.slots(np.array([0.5, 1.0])), coder.slots(np.array([0.5, 1.0])))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(tile_widths=[0.0]), "tile_widths"),
        (dict(tile_widths=[float("inf")]), "tile_widths"),
        (dict(tile_widths=[1.0], n_tilings=0), "n_tilings"),
        (dict(tile_widths=[1.0], wrap_periods=[1.0, 2.0]), "wrap_periods"),
        (dict(tile_widths=[1.0], action_values=[[1.0, 2.0]]), "action_values"),
        (dict(tile_widths=[1.0], action_tile_widths=[1.0, 1.0]), "action_tile_widths"),
        (dict(tile_widths=[1.0], memory_size=4), "memory_size"),
    ],
)
def test_bad_settings_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TileCoder(action_nvec=[3], **kwargs)


def test_non_finite_observation_is_rejected():
    coder = TileCoder([1.0, 1.0], [2])
    with pytest.raises(ValueError, match="NaN or infinite"):
        coder.slots(np.array([0.0, np.nan]))


# --- large action sets: state slots, expected collisions and the warning (issue 37) ----------------------------------


@pytest.mark.parametrize(
    "nvec, memory_size, stride, slots",
    [
        ([2], 2**22, 8, 2**19),  # a row of 2 actions fills one cache line of 8 weights
        ([15], 2**22, 16, 2**18),  # the walker's 15 accelerations: two lines
        ([343], 2**22, 344, 8192),  # 4,194,304 // 344 = 12,192, down to a power of two
        ([20, 20, 20], 2**22, 8000, 512),  # 4,194,304 // 8,000 = 524
        ([100_000], 2**22, 100_000, 32),  # 4,194,304 // 100,000 = 41
    ],
)
def test_state_slots_are_memory_over_stride_rounded_down_to_a_power_of_two(nvec, memory_size, stride, slots):
    coder = TileCoder([1.0], nvec, n_tilings=4, memory_size=memory_size)
    assert (coder.stride, coder.n_slots, coder.n_weights) == (stride, slots, slots * stride)


@pytest.mark.parametrize(
    "memory_size, actions, distinct_tiles, measured_rate",
    [  # results/measured/table_size: memory_report of one pendulum (7 actions) and one walker run (15 actions)
        (2**22, 7, 64_982, 0.0600),
        (2**18, 7, 57_713, 0.5294),
        (2**16, 7, 64_044, 0.8721),
        (2**22, 15, 29_569, 0.0545),
        (2**18, 15, 40_445, 0.6303),
        (2**16, 15, 46_347, 0.9116),
    ],
)
def test_expected_collision_rate_matches_the_measured_runs(memory_size, actions, distinct_tiles, measured_rate):
    coder = TileCoder([1.0], [actions], n_tilings=16, memory_size=memory_size)
    assert coder.expected_collision_rate(distinct_tiles) == pytest.approx(measured_rate, abs=0.003)


def test_expected_collision_rate_by_hand():
    coder = TileCoder([1.0], [2], n_tilings=1, memory_size=16)  # 2 slots of 8 weights
    # 2 keys into 2 slots: both in one slot with probability 1/2, so E[slots used] = 1.5 and the rate 1 - 1.5 / 2
    assert coder.expected_collision_rate(2) == pytest.approx(0.25)
    assert coder.expected_collision_rate(1) == pytest.approx(0.0)
    # 3 keys: E[used] = 2 (1 - 1/8) = 1.75
    assert coder.expected_collision_rate(3) == pytest.approx(1 - 1.75 / 3)
    with pytest.raises(ValueError, match="n_tiles"):
        coder.expected_collision_rate(0)


def test_expected_collision_rate_agrees_with_the_hash_on_random_states():
    coder = TileCoder([1.0, 1.0], [3], n_tilings=4, memory_size=2**13)  # 1,024 slots
    observations = np.random.default_rng(0).uniform(-1e4, 1e4, size=(600, 2))  # 2,400 distinct tiles, nearly surely
    report = coder.memory_report(observations)
    assert report["distinct_tiles"] == 2400
    assert report["collision_rate"] == pytest.approx(coder.expected_collision_rate(2400), abs=0.03)


def test_state_tiles_in_box_by_hand():
    # one dimension, width 1, [0, 10]: tiling 0 spans tiles 0..10 (11), tiling 1 (offset 1/2) floor(0.5)..floor(10.5)
    coder = TileCoder([1.0], [2], n_tilings=2)
    assert coder.state_tiles_in_box([0.0], [10.0]) == 22
    # two dimensions, widths 1 and 2 over [0, 4] x [0, 4], 2 tilings: offsets (0, 0) and (1/2, 3/2)
    coder = TileCoder([1.0, 2.0], [2], n_tilings=2)
    assert coder.state_tiles_in_box([0.0, 0.0], [4.0, 4.0]) == 5 * 3 + 5 * 3  # (4 + 1) (2 + 1); (4 - 0 + 1) (3 - 1 + 1)
    assert coder.state_tiles_in_box([0.0, 0.0], [np.inf, 4.0]) == math.inf
    # a wrapped dimension holds one period's tiles whatever its bounds
    coder = TileCoder([0.5], [2], n_tilings=1, wrap_periods=[2.0])
    assert coder.state_tiles_in_box([-100.0], [100.0]) == 4
    assert coder.state_tiles_in_box([-np.inf], [np.inf]) == 4


def test_slots_for_is_the_fewest_power_of_two_under_the_rate():
    coder = TileCoder([1.0], [2], n_tilings=1)
    for n_tiles, rate in ((1000, 0.1), (65_536, 0.1), (10, 0.5)):
        slots = coder.slots_for(n_tiles, rate)
        assert slots & (slots - 1) == 0
        assert _uniform_rate(n_tiles, slots) <= rate < _uniform_rate(n_tiles, slots // 2)


def _uniform_rate(n_tiles, slots):
    """1 - E[slots used] / n_tiles for n_tiles keys thrown uniformly into slots (written out, not the package's)."""
    if slots < 1:
        return 1.0
    return 1.0 - slots * (1.0 - (1.0 - 1.0 / slots) ** n_tiles) / n_tiles


def _box_env(action_space, observation_space=None):
    import gymnasium as gym
    from gymnasium import spaces

    class Env(gym.Env):
        def __init__(self):
            self.observation_space = observation_space or spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
            self.action_space = action_space

        def reset(self, *, seed=None, options=None):
            return np.zeros(self.observation_space.shape, np.float32), {}

        def step(self, action):
            return np.zeros(self.observation_space.shape, np.float32), 0.0, True, False, {}

    return Env()


@pytest.mark.parametrize(
    "action_space, policy_kwargs, slots",
    [
        ("box3", dict(action_bins=20), 512),
        ("discrete", {}, 32),
    ],
)
def test_a_large_action_set_warns_with_the_collision_rate_and_a_memory_size(action_space, policy_kwargs, slots):
    from gymnasium import spaces

    from sb3_er import SarsaLambda
    from sb3_er.common.tile_coding import HashCollisionWarning

    space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32) if action_space == "box3" else spaces.Discrete(100_000)
    with pytest.warns(HashCollisionWarning) as caught:
        model = SarsaLambda("TileQ", _box_env(space), policy_kwargs=policy_kwargs)
    coder = model.policy.tile_coder
    assert coder.n_slots == slots
    message = str(caught[0].message)
    # the tiles covering [-1, 1]^3 (generic rule: 10 tiles of 0.2 per dimension, 16 tilings), at most 4,096 per tiling
    n_tiles = min(coder.state_tiles_in_box([-1.0] * 3, [1.0] * 3), 4096 * 16)
    assert f"{slots:,} state-tile slots" in message
    assert f"about {100 * _uniform_rate(n_tiles, slots):.0f} %" in message
    suggested = coder.slots_for(n_tiles, 0.1) * coder.stride
    assert f"memory_size={suggested} " in message
    # the suggestion holds: a table of that size would keep the expected rate under 10 %
    assert _uniform_rate(n_tiles, suggested // coder.stride) <= 0.1


@pytest.mark.parametrize(
    "env_id, policy_kwargs",
    [
        ("CartPole-v1", {}),
        ("Acrobot-v1", {}),
        ("Pendulum-v1", {}),
        ("Pendulum-v1", dict(action_bins=20)),
        ("sb3_er/SimplestWalker-v0", {}),
        ("sb3_er/Leo-v0", {}),
    ],
)
def test_default_tables_do_not_warn(env_id, policy_kwargs):
    import warnings

    from sb3_er import SarsaLambda
    from sb3_er.common.tile_coding import HashCollisionWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", HashCollisionWarning)
        SarsaLambda("TileQ", env_id, policy_kwargs=policy_kwargs)


def test_a_small_memory_size_chosen_for_few_actions_does_not_warn():
    """The warning is about long rows: a small table of short rows is the user's choice (memory_report measures it)."""
    import warnings

    from gymnasium import spaces

    from sb3_er import SarsaLambda
    from sb3_er.common.tile_coding import HashCollisionWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", HashCollisionWarning)
        SarsaLambda("TileQ", "CartPole-v1", policy_kwargs=dict(memory_size=2**12))
        SarsaLambda("TileQ", _box_env(spaces.Discrete(15)), policy_kwargs=dict(memory_size=2**10))

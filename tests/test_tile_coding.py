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

"""Trajectory buffer: segmentation, FIFO eviction of whole trajectories, the visit vector w, pickling, replay order."""

import pickle

import kernel_bundles as bundles
import numpy as np
import pytest

from sb3_er.common import kernels
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.tile_coding import TileCoder


def chain_coder() -> TileCoder:
    """Tabular over integer states 0..20: one tiling of width 1, 2 actions."""
    return TileCoder([1.0], [2], n_tilings=1, memory_size=2**12)


def add_chain(buffer, states, actions, rewards, next_state, terminated):
    for s, a, r, s_next in zip(states, actions, rewards, [*states[1:], next_state], strict=True):
        buffer.add(np.array([s], float), buffer.tile_coder.slots(np.array([s], float)), a, r, np.array([s_next], float))
    buffer.close_trajectory(np.array([next_state], float), terminated)


def test_trajectories_are_kept_apart_with_their_end_kind():
    buffer = TrajectoryReplayBuffer(100, chain_coder())
    add_chain(buffer, [0, 1, 2], [0, 1, 0], [-1, -1, 5], 3, terminated=True)
    add_chain(buffer, [3, 4], [1, 1], [-1, -1], 5, terminated=False)
    assert buffer.n_trajectories == 2 and buffer.n_transitions == 5
    first, second = buffer.trajectories()
    assert first["observations"][:, 0].tolist() == [0, 1, 2] and first["terminated"]
    assert second["rewards"].tolist() == [-1, -1] and not second["terminated"] and second["next_obs"][0] == 5


def test_empty_trajectory_is_not_closed():
    buffer = TrajectoryReplayBuffer(10, chain_coder())
    assert not buffer.close_trajectory(np.array([0.0]), True)
    assert buffer.n_trajectories == 0


def test_whole_trajectories_are_evicted_oldest_first():
    buffer = TrajectoryReplayBuffer(6, chain_coder())
    add_chain(buffer, [0, 1, 2], [0] * 3, [0] * 3, 3, True)
    add_chain(buffer, [10, 11], [0] * 2, [0] * 2, 12, True)
    add_chain(buffer, [20, 21, 22], [1] * 3, [0] * 3, 23, False)  # needs 2 more rows: evicts the whole first one
    kept = [t["observations"][:, 0].tolist() for t in buffer.trajectories()]
    assert kept == [[10, 11], [20, 21, 22]]
    assert buffer.n_transitions == 5
    add_chain(buffer, [30, 31, 32, 33], [0] * 4, [0] * 4, 34, True)
    assert [t["observations"][0, 0] for t in buffer.trajectories()] == [30]


def test_trajectory_longer_than_the_buffer_is_an_error():
    buffer = TrajectoryReplayBuffer(3, chain_coder())
    with pytest.raises(ValueError, match="longer than buffer_size"):
        add_chain(buffer, [0, 1, 2, 3], [0] * 4, [0] * 4, 4, True)


def test_visit_vector_marks_stored_state_actions():
    coder = TileCoder([1.0], [3], n_tilings=4, memory_size=2**12)
    buffer = TrajectoryReplayBuffer(10, coder)
    buffer.add(np.array([0.5]), coder.slots(np.array([0.5])), 2, 0.0, np.array([0.7]))
    expected = np.zeros(coder.n_weights, np.uint8)
    expected[coder.feature_indices(np.array([0.5]), 2)] = 1
    np.testing.assert_array_equal(buffer.visits, expected)


def test_pickle_round_trip_keeps_everything_and_is_compact():
    buffer = TrajectoryReplayBuffer(10_000, chain_coder())
    add_chain(buffer, [0, 1, 2], [0, 1, 0], [-1, -1, 5], 3, True)
    add_chain(buffer, [5, 6], [1, 0], [1, 2], 7, False)
    buffer.add(np.array([9.0]), buffer.tile_coder.slots(np.array([9.0])), 1, 0.5, np.array([9.5]))  # open
    data = pickle.dumps(buffer)
    assert len(data) < 50_000
    again = pickle.loads(data)
    assert again.capacity == buffer.capacity and again.open_length == 1
    for a, b in zip(again.trajectories(), buffer.trajectories(), strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_array_equal(again.visits, buffer.visits)
    add_chain(again, [10], [0], [0], 11, True)
    assert again.trajectories()[-1]["observations"][:, 0].tolist() == [9, 10]


def test_pickle_after_wrap_around():
    buffer = TrajectoryReplayBuffer(5, chain_coder())
    for start in (0, 10, 20, 30):
        add_chain(buffer, [start, start + 1], [0, 0], [0, 0], start + 2, True)
    again = pickle.loads(pickle.dumps(buffer))
    assert [t["observations"][:, 0].tolist() for t in again.trajectories()] == [[20, 21], [30, 31]]


def replay_once(buffer, order):
    coder = buffer.tile_coder
    theta = np.zeros(coder.n_weights)
    bundles.replay_phase(theta, buffer, bundles.rule(1.0, 1.0), order=order)
    return [theta[coder.feature_indices(np.array([float(s)]), 0)].sum() for s in range(5)]


def test_reversed_replay_backs_up_the_final_reward_in_one_pass():
    """Lin (1992), thesis 4.1: with alpha = 1 and gamma = 1, one reversed replay carries the goal reward to the start;
    one forward replay only updates the last step."""
    buffer = TrajectoryReplayBuffer(100, chain_coder())
    add_chain(buffer, [0, 1, 2, 3, 4], [0] * 5, [0, 0, 0, 0, 10], 5, terminated=True)
    assert replay_once(buffer, kernels.ORDER_REVERSED) == [10, 10, 10, 10, 10]
    assert replay_once(buffer, kernels.ORDER_FORWARD) == [0, 0, 0, 0, 10]


def test_the_open_episode_is_replayed_and_bootstraps_from_its_latest_state():
    """Alg. 8 line 2 draws e' from {1, ..., e}: the episode in progress is replayable, its last sample bootstrapping
    from the latest s'. Chain 0 -> 1 -> 2 -> 3 (rewards 0, 0, 5), still open at s' = 3, where Q(3, 0) = 2."""
    buffer = TrajectoryReplayBuffer(100, chain_coder())
    for s, r in zip([0, 1, 2], [0.0, 0.0, 5.0], strict=True):
        buffer.add(np.array([float(s)]), buffer.tile_coder.slots(np.array([float(s)])), 0, r, np.array([s + 1.0]))
    assert buffer.n_trajectories == 0 and buffer.n_stored_trajectories == 1
    coder = buffer.tile_coder
    theta = np.zeros(coder.n_weights)
    theta[coder.feature_indices(np.array([3.0]), 0)] = 2.0
    bundles.replay_phase(theta, buffer, bundles.rule(1.0, 1.0), order=kernels.ORDER_REVERSED)
    # alpha 1, gamma 1, reversed: Q(2) = 5 + Q(3) = 7, then Q(1) = 0 + 7, Q(0) = 7 (not terminal: s' = 3 bootstraps)
    assert [theta[coder.feature_indices(np.array([float(s)]), 0)].sum() for s in range(3)] == [7.0, 7.0, 7.0]
    buffer.close_trajectory(np.array([3.0]), terminated=False)
    assert buffer.n_stored_trajectories == 1  # the same episode, now closed

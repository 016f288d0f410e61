"""The pruned database of thesis 3.5.3 (``TrajectoryReplayBuffer(prune="coverage")``): which trajectories are dropped,
by hand; w after a drop; pickling the open trajectory; the share reported to the logger."""

import pickle

import numpy as np
import pandas as pd
import pytest
from chain_mdp import ChainEnv
from stable_baselines3.common.logger import configure

from sb3_er import ER, FQI, TileCoder
from sb3_er.common.buffers import TrajectoryReplayBuffer


def store(buffer, states, actions, terminated=False):
    """Add one trajectory through `states` with `actions` and close it; returns whether it was kept."""
    coder = buffer.tile_coder
    for s, a in zip(states, actions, strict=True):
        obs = np.array([float(s)])
        buffer.add(obs, coder.slots(obs), int(a), 0.0, obs + 1.0)
    return buffer.close_trajectory(np.array([float(states[-1]) + 1.0]), terminated)


def test_tabular_coverage_by_hand():
    """One tiling of width 1: a sample is covered when its (s, a) was stored by an earlier trajectory.

    [0, 1, 2] right: nothing stored yet, kept. [0, 1, 2, 3] right: 3 of 4 covered (0.75 < 0.9), kept.
    [1, 0, 1, 2] right: 4 of 4, dropped. [5, 5, 5, 5] left: (5, left) is new, and the trajectory's own repeats of it
    do not count, 0 of 4, kept. [3, 2, 6] right, right, left: (3, right) and (2, right) covered, (6, left) not, 2 of 3
    (0.67), kept. [6, 6] right: (6, right) new, kept."""
    coder = TileCoder([1.0], [2], n_tilings=1, memory_size=2**10)
    buffer = TrajectoryReplayBuffer(100, coder, prune="coverage", prune_threshold=0.9)
    kept = [
        store(buffer, [0, 1, 2], [1, 1, 1]),
        store(buffer, [0, 1, 2, 3], [1, 1, 1, 1]),
        store(buffer, [1, 0, 1, 2], [1, 1, 1, 1]),
        store(buffer, [5, 5, 5, 5], [0, 0, 0, 0]),
        store(buffer, [3, 2, 6], [1, 1, 0]),
        store(buffer, [6, 6], [1, 1]),
    ]
    assert kept == [True, True, False, True, True, True]
    assert (buffer.n_trajectories, buffer.n_transitions) == (5, 3 + 4 + 4 + 3 + 2)
    assert (buffer.n_pruned_trajectories, buffer.n_pruned_transitions) == (1, 4)
    assert buffer.pruned_share() == pytest.approx(1 / 6)
    assert [t["observations"][:, 0].tolist() for t in buffer.trajectories()] == [
        [0, 1, 2],
        [0, 1, 2, 3],
        [5, 5, 5, 5],
        [3, 2, 6],
        [6, 6],
    ]


def test_threshold_and_unmarking_by_hand():
    """With threshold 0.75, [0, 1, 2, 7] right is 3 of 4 covered and dropped: (7, right), which only it visited,
    is unmarked in w, so that [7] right afterwards is new and kept."""
    coder = TileCoder([1.0], [2], n_tilings=1, memory_size=2**10)
    buffer = TrajectoryReplayBuffer(100, coder, prune="coverage", prune_threshold=0.75)
    assert store(buffer, [0, 1, 2], [1, 1, 1])
    visited_before = buffer.visits.copy()
    assert not store(buffer, [0, 1, 2, 7], [1, 1, 1, 1])
    np.testing.assert_array_equal(buffer.visits, visited_before)
    assert store(buffer, [7], [1])
    assert buffer.visits[coder.feature_indices(np.array([7.0]), 1)].all()


def test_coverage_needs_every_tiling():
    """Two tilings of width 2 (tiling 0: floor(x / 2), tiling 1 displaced by half a tile: floor(x / 2 + 1/2)), one
    action. Tiles (t0, t1): x = 0 (0, 0), 1 (0, 1), 2 (1, 1), 3 (1, 2), 4 (2, 2). A sample is covered only when both
    of its tiles were visited before. [0] kept; [1, 2]: (0, 1) and (1, 1) lack t1 = 1 and t0 = 1, 0 of 2, kept;
    [3]: t1 = 2 new, kept; [0, 1, 2, 3]: 4 of 4, dropped; [4, 1]: 1 of 2, kept."""
    coder = TileCoder([2.0], [1], n_tilings=2, memory_size=2**10)
    buffer = TrajectoryReplayBuffer(100, coder, prune="coverage")
    kept = [
        store(buffer, [0], [0]),
        store(buffer, [1, 2], [0, 0]),
        store(buffer, [3], [0]),
        store(buffer, [0, 1, 2, 3], [0, 0, 0, 0]),
        store(buffer, [4, 1], [0, 0]),
    ]
    assert kept == [True, True, True, False, True]
    assert (buffer.n_transitions, buffer.n_pruned_transitions) == (6, 4)


def test_without_pruning_every_trajectory_is_kept():
    coder = TileCoder([1.0], [2], n_tilings=1, memory_size=2**10)
    buffer = TrajectoryReplayBuffer(100, coder)
    assert all(store(buffer, [0, 1], [1, 1]) for _ in range(3))
    assert buffer.n_trajectories == 3 and buffer.pruned_share() == 0.0


def test_pickle_keeps_the_open_trajectory_and_the_counts():
    """A buffer pickled mid-trajectory decides the same after unpickling: the open trajectory's own marks stay its
    own (they do not count as coverage), and the pruning counts survive."""
    coder = TileCoder([1.0], [2], n_tilings=1, memory_size=2**10)
    buffer = TrajectoryReplayBuffer(100, coder, prune="coverage", prune_threshold=0.5)
    store(buffer, [0, 1], [1, 1])
    store(buffer, [0, 1], [1, 1])
    for s in (4, 4):
        obs = np.array([float(s)])
        buffer.add(obs, coder.slots(obs), 0, 0.0, obs)
    copy = pickle.loads(pickle.dumps(buffer))
    for b in (buffer, copy):
        obs = np.array([0.0])
        b.add(obs, coder.slots(obs), 1, 0.0, obs)  # (4, left) twice is its own; (0, right) covered: 1 of 3 < 0.5
        assert b.close_trajectory(obs, False)
    for name in ("visits", "fresh"):
        np.testing.assert_array_equal(getattr(copy, name), getattr(buffer, name))
    assert (copy.n_closed_total, copy.n_pruned_trajectories, copy.n_transitions) == (3, 1, 5)


def test_pruned_share_reaches_the_logger(tmp_path):
    """ER with replay_buffer_kwargs=dict(prune="coverage") logs train/buffer_fill and train/pruned_share (to every
    output format, TensorBoard included); on the chain, whose states are soon all covered, some trajectories go."""
    model = ER(
        "TileQ",
        ChainEnv(n_states=5),
        replay_buffer_kwargs={"prune": "coverage", "prune_threshold": 0.8},
        n_replays=2,
        exploration_rate=0.3,
        policy_kwargs={"memory_size": 2**12},
        seed=0,
    )
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(1500, log_interval=10)
    model.dump_logs()
    progress = pd.read_csv(tmp_path / "progress.csv")
    buffer = model.replay_buffer
    assert progress["train/pruned_share"].iloc[-1] == pytest.approx(buffer.pruned_share())
    assert 0.0 < buffer.pruned_share() < 1.0
    assert progress["train/buffer_fill"].iloc[-1] == pytest.approx(buffer.n_transitions / buffer.capacity)


def test_batch_methods_take_the_option_and_bad_options_are_refused():
    model = FQI("TileQ", ChainEnv(), replay_buffer_kwargs={"prune": "coverage"})
    assert model.replay_buffer.prune == "coverage"
    for kwargs, message in [
        ({"prune": "evenly"}, "prune must be one of"),
        ({"prune_threshold": 0.0}, "prune_threshold"),
        ({"size": 3}, "unknown"),
    ]:
        with pytest.raises(ValueError, match=message):
            ER("TileQ", ChainEnv(), replay_buffer_kwargs=kwargs)

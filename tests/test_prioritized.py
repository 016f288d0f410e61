"""Prioritized sweeping as ER's replay order (Moore and Atkeson 1993; thesis 3.2 and 7.2): the heap kernel against
Python's heapq, a reward backed up a hand-built chain in fewer updates than uniform replay and no more than reversed
trajectories, the predecessor index by hand, the ER variants, save/load and the errors."""

import heapq

import numpy as np
import pytest
from chain_mdp import ChainEnv
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er import ER, ERSigma, ResidualER, ResidualERSigma
from sb3_er.common import kernels
from sb3_er.common.buffers import TrajectoryReplayBuffer

# --- the heap against heapq ---------------------------------------------------------------------------------------


def _heap(capacity):
    """A PriorityQueue with room for ``capacity`` rows and no predecessor index."""
    no_index = np.zeros(0, dtype=np.int64)
    return kernels.PriorityQueue(
        rows=np.zeros(capacity, dtype=np.int64),
        keys=np.zeros(capacity),
        position=np.full(capacity, -1, dtype=np.int64),
        size=np.zeros(1, dtype=np.int64),
        index_start=no_index,
        index_rows=no_index,
        stamp=no_index,
        stamp_counter=np.zeros(1, dtype=np.int64),
    )


# priorities drawn from few values, so that ties (broken by the lower row) are common
priorities = st.sampled_from([0.0, 0.5, 1.0, 2.0, 3.5]) | st.floats(0.0, 100.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(priorities, min_size=1, max_size=60))
def test_heapify_then_pop_gives_heapqs_order(keys):
    """Floyd's construction and repeated pops give heapq's order on (-priority, row)."""
    queue = _heap(len(keys))
    rows, values, position, size = queue.rows, queue.keys, queue.position, queue.size
    rows[:] = np.arange(len(keys))[::-1]  # rows in no particular order
    values[:] = [keys[row] for row in rows]
    size[0] = len(keys)
    kernels.heap_heapify(queue)
    reference = [(-key, row) for row, key in enumerate(keys)]
    heapq.heapify(reference)
    while reference:
        negative, row = heapq.heappop(reference)
        assert kernels.heap_pop(queue) == (row, -negative)
    assert size[0] == 0 and np.all(position == -1)


operations = st.lists(
    st.one_of(
        st.tuples(st.just("set"), st.integers(0, 19), priorities),
        st.tuples(st.just("remove"), st.integers(0, 19), st.just(0.0)),
        st.tuples(st.just("pop"), st.just(0), st.just(0.0)),
    ),
    max_size=120,
)


@settings(max_examples=80, deadline=None)
@given(operations)
def test_set_remove_pop_against_heapq(ops):
    """Queueing, re-prioritising (up and down), removing and popping in any order: every pop returns what heapq
    (with lazy deletion of outdated entries) pops, and heap_position always names each queued row's node."""
    queue = _heap(20)
    rows, values, position, size = queue.rows, queue.keys, queue.position, queue.size
    reference, current = [], {}
    for op, row, key in ops:
        if op == "set":
            kernels.heap_set(queue, row, key)
            current[row] = key
            heapq.heappush(reference, (-key, row))
        elif op == "remove":
            kernels.heap_remove(queue, row)
            current.pop(row, None)
        elif current:
            while True:  # skip entries that were re-prioritised or removed since they were pushed
                negative, expected = heapq.heappop(reference)
                if current.get(expected) == -negative:
                    break
            assert kernels.heap_pop(queue) == (expected, -negative)
            del current[expected]
        assert size[0] == len(current)
        assert {int(rows[i]): float(values[i]) for i in range(size[0])} == current
        assert all(position[rows[i]] == i for i in range(size[0]))
        assert np.count_nonzero(position >= 0) == size[0]


# --- a reward backed up a chain ------------------------------------------------------------------------------------

N_STATES = 11  # states 0..10; entering 10 pays the reward and ends the episode
GAMMA = 0.9


def chain_model(order, seed=0, **kwargs):
    """Tabular ER on the chain (one tiling of width 1), alpha = 1 and the Q-learning target, so that one update
    backs a value up by one state exactly, holding a hand-built database: four wandering trajectories that never
    reach the goal (time limits) and one straight walk from state 0 to the goal."""
    env = ChainEnv(n_states=N_STATES)
    model = ER(
        "TileQ",
        env,
        replay_order=order,
        learning_rate=1.0,
        gamma=GAMMA,
        exploration_rate=0.0,
        target="q_learning",
        policy_kwargs={"n_tilings": 1, "memory_size": 2**10},
        seed=seed,
        **kwargs,
    )
    coder = model.policy.tile_coder
    buffer = TrajectoryReplayBuffer(1000, coder)
    rng = np.random.default_rng(1)
    walks = [list(rng.integers(0, 2, size=12)) for _ in range(4)]
    walks.insert(2, [1] * (N_STATES - 1))
    for start, walk in zip([3, 0, 0, 5, 2], walks, strict=True):
        s = start
        for a in walk:
            s_next = max(s - 1, 0) if a == 0 else s + 1
            reward, terminated = (1.0, True) if s_next == N_STATES - 1 else (0.0, False)
            obs = np.array([float(s)])
            buffer.add(obs, coder.slots(obs), int(a), reward, np.array([float(s_next)]))
            s = s_next
            if terminated:
                break
        buffer.close_trajectory(np.array([float(s)]), terminated)
    model.replay_buffer = buffer
    return model


def updates_until_start_learns(model, limit=20_000):
    """Replayed updates until Q(0, right) > 0: the goal's reward has been backed up to the start state."""
    start = np.array([0.0])
    while model.policy.q_values(start)[0, 1] <= 0.0:
        model.replay(1)
        assert model.replay_updates < limit, "the reward never reached the start"
    return model.replay_updates


def test_prioritized_sweeping_backs_the_reward_up_the_chain_fastest():
    """Updates until the goal's reward reaches the start, one phase of the default budget for prioritized sweeping.

    With the trajectory's predecessors the queue holds only the goal transition at first and each update queues the
    transition before it: 10 updates, one per state of the goal path, the least possible. With the tile predecessors
    every stored transition into an updated state is queued too (the wandering ones among them), by |delta|: more
    updates, as the values of those states are learned on the way. Reversed trajectories need the goal trajectory
    drawn among five (and whole trajectories replayed); uniform samples need the ten goal-path transitions drawn in
    reversed order among 58. Both are averaged over 10 seeds of the replay generator."""
    n_goal_path = N_STATES - 1
    by_trajectory = updates_until_start_learns(chain_model("prioritized", predecessors="trajectory"))
    by_tiles = updates_until_start_learns(chain_model("prioritized", predecessors="tiles"))
    reversed_updates = [updates_until_start_learns(chain_model("reversed", seed)) for seed in range(10)]
    uniform_updates = [updates_until_start_learns(chain_model("uniform", seed)) for seed in range(10)]
    assert by_trajectory == n_goal_path == min(reversed_updates)
    assert by_trajectory <= by_tiles <= np.mean(reversed_updates)
    assert by_tiles < min(uniform_updates) and np.mean(reversed_updates) < np.mean(uniform_updates)
    # the whole value function: after the sweeps, Q(s, right) = gamma^(9 - s) on the goal path, as value iteration
    model = chain_model("prioritized", prioritized_updates=200)
    model.replay(1)
    q_right = model.policy.q_values(np.arange(N_STATES - 1, dtype=np.float64)[:, None])[:, 1]
    np.testing.assert_allclose(q_right, GAMMA ** np.arange(N_STATES - 2, -1, -1), rtol=1e-12)


def test_phase_budget_matches_the_other_orders_and_threshold_ends_it_early():
    """By default a phase makes round(K x mean stored trajectory length) updates; with a threshold no |delta|
    exceeds, it makes none."""
    model = chain_model("prioritized", priority_threshold=0.0)
    buffer = model.replay_buffer
    assert model.replay(3)["updates"] == round(3 * buffer.n_transitions / buffer.n_stored_trajectories)
    model = chain_model("prioritized", priority_threshold=1.0)
    assert model.replay(3)["updates"] == 0


def test_predecessor_index_by_hand():
    """The index lists, per tile slot, the stored transitions whose s' has it, oldest first; terminal ones have
    no s' and are not listed."""
    model = chain_model("prioritized")
    buffer = model.replay_buffer
    data = buffer.replay_data()
    coder = model.policy.tile_coder
    queue = _heap(0)._replace(
        index_start=np.zeros(coder.slot_mask + 2, dtype=np.int64),
        index_rows=np.zeros(data.n_transitions, dtype=np.int64),
    )
    kernels.build_predecessor_index(data, queue)
    index_start, index_rows = queue.index_start, queue.index_rows
    expected = {}
    row = 0
    for trajectory in buffer.trajectories():
        states = [*trajectory["observations"][:, 0], trajectory["next_obs"][0]]
        for t in range(len(trajectory["actions"])):
            last = t == len(trajectory["actions"]) - 1
            if not (last and trajectory["terminated"]):
                expected.setdefault(int(coder.slots(np.array([states[t + 1]]))[0]), []).append(row)
            row += 1
    for slot in range(coder.slot_mask + 1):
        assert index_rows[index_start[slot] : index_start[slot + 1]].tolist() == expected.get(slot, [])


# --- the ER variants, learning, save/load, errors -------------------------------------------------------------------


@pytest.mark.parametrize("algo", [ER, ERSigma, ResidualER, ResidualERSigma])
@pytest.mark.parametrize("predecessors", ["tiles", "trajectory"])
def test_every_er_variant_replays_prioritized(algo, predecessors):
    """ER, ER-sigma, residual ER and residual ER-sigma all replay in priority order, with 16 tilings."""
    model = algo(
        "TileQ", ChainEnv(n_states=8), replay_order="prioritized", predecessors=predecessors, n_replays=3, seed=0
    )
    model.learn(300)
    assert model.replay_updates > 0 and model.priority_evaluations > model.replay_updates
    assert np.all(np.isfinite(model.policy.theta_array))


def test_prioritized_learns_the_chain():
    """Greedy from every start state after 600 steps: always right."""
    model = ER(
        "TileQ", ChainEnv(n_states=8), replay_order="prioritized", n_replays=10, exploration_rate=0.2, gamma=0.9, seed=0
    ).learn(600)
    states = np.arange(7, dtype=np.float64)[:, None]
    np.testing.assert_array_equal(model.predict(states, deterministic=True)[0], np.ones(7))


def test_save_load_continues_exactly(tmp_path):
    """The settings, the generators and (with save_replay_buffer) the database survive save/load: a reloaded model
    continues exactly as the original (the queue is rebuilt at every phase, so there is nothing else to keep)."""
    settings_ = {
        "replay_order": "prioritized",
        "predecessors": "trajectory",
        "priority_threshold": 0.01,
        "max_predecessors": 4,
        "prioritized_updates": 50,
        "n_replays": 2,
        "seed": 3,
    }
    model = ER("TileQ", ChainEnv(n_states=8), **settings_).learn(200)
    model.save(tmp_path / "model")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = ER.load(tmp_path / "model", env=ChainEnv(n_states=8))
    loaded.load_replay_buffer(tmp_path / "buffer")
    for name in ("replay_order", "predecessors", "priority_threshold", "max_predecessors", "prioritized_updates"):
        assert getattr(loaded, name) == getattr(model, name)
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)
    for m in (model, loaded):
        m.replay(2)
    np.testing.assert_array_equal(loaded.policy.theta_array, model.policy.theta_array)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"predecessors": "model"}, "predecessors must be one of"),
        ({"priority_threshold": -1.0}, "priority_threshold"),
        ({"max_predecessors": -1}, "max_predecessors"),
        ({"prioritized_updates": 2.5}, "prioritized_updates"),
    ],
)
def test_bad_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ER("TileQ", ChainEnv(), replay_order="prioritized", **kwargs)

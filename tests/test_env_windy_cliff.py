"""Windy cliff grid world (thesis 5.1, our reading) against hand-enumerated transitions and wind statistics."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from sb3_er_envs.windy_cliff import WindyCliffEnv

N, NE, E, SE, S, SW, W, NW = range(8)
WIDTH, HEIGHT, FIRST_WINDY_ROW = 10, 7, 4


@pytest.fixture
def env():
    return WindyCliffEnv()


def only_outcome(env, cell, action):
    (outcome,) = env.transition_distribution(cell, action)
    assert outcome.probability == 1.0
    return outcome


def test_king_moves_from_an_inner_calm_cell(env):
    expected = {N: (4, 3), NE: (5, 3), E: (5, 2), SE: (5, 1), S: (4, 1), SW: (3, 1), W: (3, 2), NW: (3, 3)}
    for action, next_cell in expected.items():
        outcome = only_outcome(env, (4, 2), action)
        assert outcome.next_cell == next_cell
        assert (outcome.reward, outcome.fell, outcome.goal_reached) == (-1.0, False, False)


def test_moves_into_the_west_or_south_edge_keep_that_coordinate(env):
    expected = {N: (0, 1), NE: (1, 1), E: (1, 0), SE: (1, 0), S: (0, 0), SW: (0, 0), W: (0, 0), NW: (0, 1)}
    for action, next_cell in expected.items():
        assert only_outcome(env, (0, 0), action).next_cell == next_cell


def test_stepping_follows_the_king_moves(env):
    env.reset(seed=0)
    path = [(NE, (1, 1)), (NE, (2, 2)), (E, (3, 2)), (SE, (4, 1)), (S, (4, 0)), (NW, (3, 1)), (W, (2, 1)), (SW, (1, 0))]
    for action, cell in path:
        observation, reward, terminated, truncated, info = env.step(action)
        np.testing.assert_array_equal(observation, cell)
        assert (reward, terminated, truncated) == (-1.0, False, False)
        assert info == {"fell": False, "goal_reached": False}


def test_every_action_in_the_wind_stays_or_goes_one_north_with_probability_half(env):
    for y in range(FIRST_WINDY_ROW, HEIGHT - 1):
        for x in range(WIDTH - 1):
            for action in range(8):
                outcomes = {o.next_cell: o for o in env.transition_distribution((x, y), action)}
                assert set(outcomes) == {(x, y), (x, y + 1)}
                assert all(o.probability == 0.5 and o.reward == -1.0 and not o.fell for o in outcomes.values())


def test_the_top_row_blows_off_the_cliff_with_probability_half(env):
    for x in range(WIDTH - 1):
        for action in range(8):
            outcomes = sorted(env.transition_distribution((x, HEIGHT - 1), action), key=lambda o: o.fell)
            assert [(o.probability, o.reward, o.fell) for o in outcomes] == [(0.5, -1.0, False), (0.5, -50.0, True)]
            assert outcomes[0].next_cell == (x, HEIGHT - 1)


def test_the_wind_area_is_doomed_to_fall(env):
    """Thesis 5.1: once above the striped line, no sequence of actions leads anywhere but into the wind or the cliff."""
    for y in range(FIRST_WINDY_ROW, HEIGHT):
        for x in range(WIDTH - 1):
            for action in range(8):
                for outcome in env.transition_distribution((x, y), action):
                    assert outcome.fell or outcome.next_cell[1] >= FIRST_WINDY_ROW
                    assert not outcome.goal_reached


def test_north_from_the_last_calm_row_enters_the_wind_without_falling(env):
    outcome = only_outcome(env, (2, FIRST_WINDY_ROW - 1), N)
    assert outcome.next_cell == (2, FIRST_WINDY_ROW) and not outcome.fell


@pytest.mark.parametrize("action", [N, E, SW])
def test_wind_frequencies_do_not_depend_on_the_action(action):
    env = WindyCliffEnv()
    trials, blown = 4000, 0
    env.reset(seed=1234 + action)
    for _ in range(trials):
        env.reset(options={"cell": (3, 5)})
        observation, reward, *_ = env.step(action)
        blown += int(observation[1] == 6)
        assert tuple(observation) in {(3.0, 5.0), (3.0, 6.0)} and reward == -1.0
    # Binomial(4000, 1/2): standard deviation 31.6; 4.5 of them fail a correct env with probability below 1e-5.
    assert abs(blown - trials / 2) < 4.5 * np.sqrt(trials / 4)


def test_falling_ends_the_episode_with_minus_fifty(env):
    env.reset(seed=3, options={"cell": (5, HEIGHT - 1)})
    for _ in range(200):
        observation, reward, terminated, truncated, info = env.step(S)
        if terminated:
            break
        assert reward == -1.0 and tuple(observation) == (5.0, HEIGHT - 1)
    assert terminated and not truncated
    assert reward == -50.0 and info == {"fell": True, "goal_reached": False}


def test_goal_payout_is_linear_from_zero_south_to_fifty_north(env):
    assert [env.goal_payout(y) for y in range(HEIGHT)] == pytest.approx([0, 50 / 6, 100 / 6, 25, 200 / 6, 250 / 6, 50])
    cases = {
        ((8, 0), E): ((9, 0), 0.0),
        ((8, 0), SE): ((9, 0), 0.0),
        ((8, 1), SE): ((9, 0), 0.0),
        ((8, 2), E): ((9, 2), 50 / 3),
        ((8, 3), E): ((9, 3), 25.0),
        ((8, 3), NE): ((9, 4), 100 / 3),
    }
    for (cell, action), (goal_cell, payout) in cases.items():
        outcome = only_outcome(env, cell, action)
        assert outcome.next_cell == goal_cell and outcome.goal_reached and not outcome.fell
        assert outcome.reward == pytest.approx(payout)


def test_stepping_into_the_goal_terminates(env):
    env.reset(seed=0, options={"cell": (8, 3)})
    observation, reward, terminated, truncated, info = env.step(NE)
    np.testing.assert_array_equal(observation, (9, 4))
    assert reward == pytest.approx(100 / 3) and terminated and not truncated
    assert info == {"fell": False, "goal_reached": True}


def optimal_start_value(env, horizon):
    """Finite-horizon undiscounted value iteration over the enumerated transition distribution."""
    cells = [(x, y) for x in range(env.goal_column) for y in range(env.height)]
    value = dict.fromkeys(cells, 0.0)
    for _ in range(horizon):
        value = {
            cell: max(
                sum(
                    o.probability * (o.reward + (0.0 if o.fell or o.goal_reached else value[o.next_cell]))
                    for o in env.transition_distribution(cell, action)
                )
                for action in range(8)
            )
            for cell in cells
        }
    return value[env.start_cell]


def test_best_return_is_the_diagonal_dash_to_the_lowest_windy_goal_cell(env):
    """By hand: 8 steps at -1 from (0, 0) to (8, 3), then NE into (9, 4) paying 50 * 4/6."""
    assert optimal_start_value(env, horizon=env.max_episode_steps) == pytest.approx(-8 + 50 * 4 / 6)


def test_time_limit_truncates_after_100_steps(env):
    env.reset(seed=0)
    for step in range(1, 101):
        observation, reward, terminated, truncated, _ = env.step(W)
        assert reward == -1.0 and not terminated
        assert truncated == (step == 100)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), actions=st.lists(st.integers(0, 7), min_size=1, max_size=120))
def test_every_step_is_one_of_the_enumerated_outcomes(seed, actions):
    env = WindyCliffEnv()
    observation, _ = env.reset(seed=seed)
    for action in actions:
        cell = tuple(int(c) for c in observation)
        support = {(o.next_cell, o.reward, o.fell, o.goal_reached) for o in env.transition_distribution(cell, action)}
        observation, reward, terminated, truncated, info = env.step(action)
        assert env.observation_space.contains(observation)
        assert (tuple(int(c) for c in observation), reward, info["fell"], info["goal_reached"]) in support
        assert terminated == (info["fell"] or info["goal_reached"])
        if terminated or truncated:
            break


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_reset_with_a_seed_reproduces_the_episode(seed):
    actions = np.random.default_rng(seed).integers(0, 8, size=100)

    def trajectory():
        env = WindyCliffEnv()
        observations = [env.reset(seed=seed)[0]]
        for action in actions:
            observation, _, terminated, truncated, _ = env.step(action)
            observations.append(observation)
            if terminated or truncated:
                break
        return np.array(observations)

    np.testing.assert_array_equal(trajectory(), trajectory())


def test_other_sizes_move_the_wind_and_goal():
    env = WindyCliffEnv(width=5, height=4, wind_rows=1, wind_probability=1.0)
    assert env.observation_space.high.tolist() == [4.0, 3.0]
    (outcome,) = env.transition_distribution((1, 3), W)
    assert outcome.fell and outcome.probability == 1.0
    assert only_outcome(env, (3, 2), NE).reward == pytest.approx(50.0)


def test_passes_the_gymnasium_and_sb3_env_checkers():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gymnasium_check_env(gymnasium.make("sb3_er/WindyCliff-v0", render_mode="rgb_array").unwrapped)
        sb3_check_env(WindyCliffEnv())


def test_render_draws_the_agent_in_its_cell():
    env = WindyCliffEnv(render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert image.dtype == np.uint8 and image.shape == (16 * (HEIGHT + 1), 16 * WIDTH, 3)
    start_centre = (16 * HEIGHT + 8, 8)
    assert image[start_centre].tolist() == [30, 30, 30]
    env.step(NE)
    image = env.render()
    assert image[start_centre].tolist() != [30, 30, 30]
    assert image[16 * (HEIGHT - 1) + 8, 16 + 8].tolist() == [30, 30, 30]


def test_thesis_attributes():
    env = WindyCliffEnv()
    np.testing.assert_array_equal(env.tile_widths, [2.0, 2.0])
    assert env.wrap_periods is None and env.dt == 1.0 and env.action_space.n == 8


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"width": 1}, "width"),
        ({"height": 0}, "height"),
        ({"wind_rows": 7}, "wind_rows"),
        ({"wind_probability": 1.5}, "wind_probability"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_parameters_are_named(kwargs, word):
    with pytest.raises(ValueError, match=word):
        WindyCliffEnv(**kwargs)


def test_bad_actions_and_cells_are_named(env):
    env.reset(seed=0)
    for action in (8, -1, 2.5, "2", None, np.array([2])):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    for cell in ((9, 0), (0, 7), (1, 2, 3), (0.5, 1)):
        with pytest.raises(ValueError, match="cell"):
            env.reset(options={"cell": cell})

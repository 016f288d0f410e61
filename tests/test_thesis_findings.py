"""The thesis's qualitative findings on hand-built replay data, with analytic expectations (sections 5.2 and 5.3)."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from sb3_er import ER, ERSigma, ResidualER

GAMMA = 0.98


class LineEnv(gym.Env):
    """Only a container for spaces and tile widths: the tests fill the replay buffer by hand."""

    def __init__(self, n_actions):
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(1,), dtype=np.float64)
        self.action_space = spaces.Discrete(n_actions)

    def reset(self, *, seed=None, options=None):
        return np.zeros(1), {}

    def step(self, action):
        return np.zeros(1), 0.0, True, False, {}


def model_with_trajectory(algo, n_actions, n_tilings, transitions, next_state, terminated, **kwargs):
    model = algo(
        "TileQ",
        LineEnv(n_actions),
        learning_rate=0.25,
        gamma=GAMMA,
        exploration_rate=0.0,
        policy_kwargs=dict(n_tilings=n_tilings, tile_widths=[1.0], memory_size=2**12),
        seed=0,
        **kwargs,
    )
    coder = model.policy.tile_coder
    next_states = [s for s, _, _ in transitions[1:]] + [next_state]
    for (s, a, r), s_next in zip(transitions, next_states, strict=True):
        obs = np.array([s])
        model.replay_buffer.add(obs, coder.slots(obs), a, r, np.array([s_next]))
    model.replay_buffer.close_trajectory(np.array([next_state]), terminated)
    return model


def q(model, s):
    return model.policy.q_values(np.array([[s]]))[0]


@pytest.mark.parametrize("n_tilings", [1, 16])
def test_er_sigma_back_propagates_a_fall_that_vanilla_er_forgets(n_tilings):
    """Thesis 5.2.1: at s1 only the action that fell was ever tried; vanilla ER backs up the optimistic 0 of the untried
    actions to s0, ER-sigma replaces them by sigma(s1) and backs up the punishment."""
    trajectory = [(0.0, 0, -1.0), (5.0, 1, -50.0)]
    results = {}
    for algo in (ER, ERSigma):
        model = model_with_trajectory(algo, 3, n_tilings, trajectory, 6.0, terminated=True)
        model.replay(200)
        results[algo.__name__] = q(model, 0.0)[0]
        assert q(model, 5.0)[1] == pytest.approx(-50.0, abs=1e-6)
    assert results["ER"] == pytest.approx(-1.0, abs=1e-6)  # -1 + gamma * max(0, -50, 0)
    assert results["ERSigma"] == pytest.approx(-1.0 + GAMMA * -50.0, abs=1e-6)


def test_self_affecting_state_grows_under_er_and_not_under_residual_er():
    """Thesis 5.3 (Fig. 5.6a): s and s' share one of two tiles; replaying (s, a, r = 10, s') over and over.

    Vanilla ER updates only phi(s, a), so the shared weight also raises Q(s', a), its own target: it settles where
    Q(s) = 2 r / (2 - gamma), about twice the one-step target r. Residual ER (Eq. 5.7-5.8) also pushes Q(s', a) down
    and settles where Q(s) = (2 - gamma) r / (2 - 2 gamma + 2 gamma^2), below r.
    """
    r = 10.0
    s, s_next = 0.2, 0.6  # tiling 0: the same tile; tiling 1 (displaced by half a tile): neighbouring tiles
    vanilla = model_with_trajectory(ER, 1, 2, [(s, 0, r)], s_next, terminated=False)
    residual = model_with_trajectory(ResidualER, 1, 2, [(s, 0, r)], s_next, terminated=False)
    coder = vanilla.policy.tile_coder
    assert (coder.coordinates(np.array([s])) == coder.coordinates(np.array([s_next]))).tolist() == [[True], [False]]
    vanilla.replay(3000)
    residual.replay(3000)

    assert q(vanilla, s)[0] == pytest.approx(2 * r / (2 - GAMMA), rel=1e-6)
    assert q(vanilla, s_next)[0] == pytest.approx(r / (2 - GAMMA), rel=1e-6)
    theta_only_s = r / (2 - 2 * GAMMA + 2 * GAMMA**2)
    assert q(residual, s)[0] == pytest.approx((2 - GAMMA) * theta_only_s, rel=1e-6)
    assert q(residual, s_next)[0] == pytest.approx((1 - 2 * GAMMA) * theta_only_s, rel=1e-6)
    assert q(residual, s)[0] < r < q(vanilla, s)[0]

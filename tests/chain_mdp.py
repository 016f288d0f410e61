"""A deterministic chain MDP with its value-iteration Q*, and hand-built databases, for the Dyna, FQI and LSPI tests."""

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_er.common.buffers import TrajectoryReplayBuffer

GOAL_REWARD = 10.0
STEP_REWARD = -1.0


def chain_step(n_states: int, s: int, a: int) -> tuple[int, float, bool]:
    """Action 0 moves left (staying at 0), action 1 right; entering the last state pays GOAL_REWARD and terminates."""
    s_next = max(s - 1, 0) if a == 0 else s + 1
    if s_next == n_states - 1:
        return s_next, GOAL_REWARD, True
    return s_next, STEP_REWARD, False


def chain_q_star(n_states: int, gamma: float, sweeps: int = 2000) -> np.ndarray:
    """Q*(s, a) for the non-terminal states 0..n_states-2 by value iteration, (n_states - 1, 2)."""
    q = np.zeros((n_states - 1, 2))
    for _ in range(sweeps):
        new = np.empty_like(q)
        for s in range(n_states - 1):
            for a in range(2):
                s_next, r, terminal = chain_step(n_states, s, a)
                new[s, a] = r if terminal else r + gamma * q[s_next].max()
        q = new
    return q


class ChainEnv(gym.Env):
    """The chain as a Gymnasium env: observation [s] (s = 0..n_states-1), Discrete(2), tile width 1, random start
    state among the non-terminal ones, ``max_steps`` time limit."""

    def __init__(self, n_states: int = 5, max_steps: int = 20):
        self.n_states = n_states
        self.max_steps = max_steps
        self.observation_space = spaces.Box(0.0, float(n_states - 1), shape=(1,), dtype=np.float64)
        self.action_space = spaces.Discrete(2)
        self.tile_widths = np.array([1.0])

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = int(self.np_random.integers(0, self.n_states - 1))
        self.steps = 0
        return np.array([float(self.state)]), {}

    def step(self, action):
        self.state, reward, terminated = chain_step(self.n_states, self.state, int(action))
        self.steps += 1
        return np.array([float(self.state)]), reward, terminated, self.steps >= self.max_steps, {}


def chain_database(model, n_states: int, repeats=lambda s, a: 1) -> TrajectoryReplayBuffer:
    """A buffer holding every (s, a) of the chain ``repeats(s, a)`` times, each transition its own trajectory."""
    coder = model.policy.tile_coder
    buffer = TrajectoryReplayBuffer(1000, coder)
    for s in range(n_states - 1):
        for a in range(2):
            s_next, r, terminal = chain_step(n_states, s, a)
            for _ in range(repeats(s, a)):
                obs = np.array([float(s)])
                buffer.add(obs, coder.slots(obs), a, r, np.array([float(s_next)]))
                buffer.close_trajectory(np.array([float(s_next)]), terminal)
    return buffer


def dense_features(coder, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Dense phi (n, n_weights), with multiplicity where tilings collide."""
    rows = [
        np.bincount(coder.feature_indices(o, a), minlength=coder.n_weights)
        for o, a in zip(observations, actions, strict=True)
    ]
    return np.array(rows, dtype=np.float64)


def random_database(model, n: int, seed: int, low: float = 0.0, high: float = 5.0):
    """n random transitions (each its own trajectory) on continuous 1-D states; every fourth one terminal.

    Returns the buffer and the arrays (observations, actions, rewards, next observations, terminal)."""
    rng = np.random.default_rng(seed)
    coder = model.policy.tile_coder
    observations = rng.uniform(low, high, size=(n, 1))
    actions = rng.integers(0, coder.n_actions, size=n)
    rewards = rng.normal(size=n)
    next_observations = np.clip(observations + rng.normal(0.0, 0.7, size=(n, 1)), low, high - 1e-9)
    terminal = np.arange(n) % 4 == 3
    buffer = TrajectoryReplayBuffer(10 * n, coder)
    for i in range(n):
        buffer.add(
            observations[i], coder.slots(observations[i]), int(actions[i]), float(rewards[i]), next_observations[i]
        )
        buffer.close_trajectory(next_observations[i], bool(terminal[i]))
    return buffer, (observations, actions, rewards, next_observations, terminal)

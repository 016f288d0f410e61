"""SarsaLambda on GRL's compass-walker walk task with GRL's learner settings learns to walk as fast as GRL does.

GRL (github wcaarls/grl, cfg/compass_walker/sarsa_walk.yaml): Sarsa(lambda), alpha 0.4 on Q, gamma 0.99, lambda 0.92,
epsilon 0.05, replacing traces, 16 tilings, weights drawn from U[0, 1] and averaged over the 16 active tiles (so Q starts
in [0, 1]); a greedy test episode of 1001 steps from Garcia's fixed point. Measured with GRL: after 50 learning episodes
the greedy test walks without a fall in 15 of 15 runs (walker_readings.md).
"""

import inspect

import pytest
from stable_baselines3.common.callbacks import BaseCallback

from sb3_er import SarsaLambda, TileQPolicy
from sb3_er_envs.compass_walker import TEST_EPISODE_STEPS, CompassWalkerEnv

HAS_INITIAL_VALUE = "initial_value" in inspect.signature(TileQPolicy.__init__).parameters


class StopAfterEpisodes(BaseCallback):
    """Stops learn() once ``n_episodes`` episodes have ended, after their last transition was learned."""

    def __init__(self, n_episodes: int):
        super().__init__()
        self.n_episodes = n_episodes
        self.finished = 0

    def _on_step(self) -> bool:
        if self.finished >= self.n_episodes:
            return False
        self.finished += int(self.locals["dones"][0])
        return True


def greedy_test_walks(model) -> bool:
    """GRL's test episode: greedy, from Garcia's fixed point, 1001 control steps; True if it ends without a fall."""
    env = CompassWalkerEnv(episode_steps=TEST_EPISODE_STEPS, initial_state_variation=0.0)
    observation, _ = env.reset()
    while True:
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated:
            return False
        if truncated:
            return True


@pytest.mark.slow
@pytest.mark.skipif(not HAS_INITIAL_VALUE, reason="needs TileQ's policy_kwargs initial_value (GRL's U[0, 1] weights)")
def test_sarsa_lambda_walks_grls_task_after_50_episodes():
    walks = []
    for seed in range(5):
        model = SarsaLambda(
            "TileQ",
            CompassWalkerEnv(),
            learning_rate=0.4,
            gamma=0.99,
            trace_lambda=0.92,
            exploration_rate=0.05,
            seed=seed,
            policy_kwargs=dict(n_tilings=16, initial_value=(0.0, 1.0)),
        )
        stop = StopAfterEpisodes(50)
        model.learn(total_timesteps=50 * 500 + 1, callback=stop)
        assert stop.finished == 50
        walks.append(greedy_test_walks(model))
    assert sum(walks) >= 4, f"greedy 1001-step tests without a fall per seed: {walks}"

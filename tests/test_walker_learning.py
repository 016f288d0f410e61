"""SarsaLambda on GRL's compass-walker walk task with GRL's learner settings learns to walk as fast as GRL does.

GRL (github wcaarls/grl, cfg/compass_walker/sarsa_walk.yaml): Sarsa(lambda), alpha 0.4 on Q, gamma 0.99, lambda 0.92,
epsilon 0.05, replacing traces, 16 tilings, weights drawn from U[0, 1] and averaged over the 16 active tiles (so Q
starts in [0, 1]); a greedy test episode of 1001 steps from Garcia's fixed point. Measured with GRL: after 50 learning
episodes the greedy test walks without a fall in 15 of 15 runs (the simplest-walker docs page).

Also the gait figure and animation tools (sb3_er.experiments.gait) on tiny models.
"""

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import pytest
from stable_baselines3.common.callbacks import BaseCallback

import sb3_er_envs  # noqa: F401  (registers the ids)
from sb3_er import SarsaLambda
from sb3_er.experiments.gait import gait_trace, plot_gait, save_walker_gif
from sb3_er_envs.compass_walker import TEST_EPISODE_STEPS, CompassWalkerEnv
from sb3_er_envs.simplest_walker import GARCIA_FIXED_POINT, SimplestWalkerEnv


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


# --- Gait figures (thesis Figures 4.6 / 6.3) and animations, on tiny models ------------------------------------------


class PassivePolicy:
    """A stand-in model: always the zero hip acceleration."""

    def __init__(self, zero_index: int):
        self.zero_index = zero_index

    def predict(self, observation, deterministic=False):
        return np.array(self.zero_index), None


def test_gait_trace_of_passive_walking_follows_the_env():
    env = SimplestWalkerEnv()
    trace = gait_trace(PassivePolicy(7), env, seconds=8.0)
    assert len(trace) == 41 and not trace.fell
    np.testing.assert_allclose(trace.time, 0.2 * np.arange(41), rtol=0, atol=1e-12)
    assert trace.stance_angle[0] == 0.1534 and trace.hip_angle[0] == 0.3068 and trace.swing_foot_height[0] == 0.0
    reference = SimplestWalkerEnv()
    reference.reset(options={"state": GARCIA_FIXED_POINT})
    for k in range(1, 41):
        _, _, _, _, info = reference.step(7)
        assert trace.stance_angle[k] == reference.state[0] and trace.hip_angle[k] == reference.state[1]
        assert trace.swing_foot_height[k] == info["swing_foot_height"]
        assert trace.distances[k] == info["distance"]
    assert trace.distances[0] == 0.0 and trace.distance == pytest.approx(info["distance"])
    assert trace.distance > 0.5  # two footsteps in 8 s


def test_gait_figure_and_gif_of_a_freshly_built_sarsa_lambda(tmp_path):
    walker = gym.make("sb3_er/SimplestWalker-v0")
    model = SarsaLambda("TileQ", walker, seed=0)
    traces = {
        "Sarsa(lambda), untrained": gait_trace(model, walker, seconds=6.0),
        "passive": gait_trace(PassivePolicy(7), SimplestWalkerEnv(), seconds=6.0),
        "GRL task, passive": gait_trace(PassivePolicy(1), CompassWalkerEnv(), seconds=6.0),
    }
    for trace in traces.values():
        assert 2 <= len(trace) <= 31 and len(trace.stance_angle) == len(trace.swing_foot_height) == len(trace)
        assert np.all(np.isfinite(trace.hip_angle))
    figure = plot_gait(traces, tmp_path / "gait.png")
    assert figure.stat().st_size > 10_000

    gif = save_walker_gif(model, tmp_path / "walk.gif", seconds=2.0, fps=10.0)
    frames = imageio.mimread(gif)
    assert len(frames) in range(2, 12) and frames[0].shape[:2] == (240, 320)
    passive = save_walker_gif(PassivePolicy(7), tmp_path / "passive.gif", seconds=2.0)
    assert len(imageio.mimread(passive)) == 11


def test_gait_tools_refuse_bad_requests(tmp_path):
    with pytest.raises(ValueError, match="seconds"):
        gait_trace(PassivePolicy(7), SimplestWalkerEnv(), seconds=0.0)
    with pytest.raises(ValueError, match="walker"):
        gait_trace(PassivePolicy(0), gym.make("CartPole-v1"), seconds=1.0)
    with pytest.raises(ValueError, match="rgb_array"):
        save_walker_gif(PassivePolicy(7), tmp_path / "x.gif", env=SimplestWalkerEnv())
    with pytest.raises(ValueError, match="at least one"):
        plot_gait({}, tmp_path / "empty.png")

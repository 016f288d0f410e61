"""SB3's test_deterministic for every algorithm: two models with the same seed, trained alike, then acting with
exploration (predict with deterministic=False) on their own envs, take the same actions and receive the same rewards,
on SB3's choice of envs for discrete and Box actions. (Bit-identical weights of seeded runs: test_run.py.)"""

import numpy as np
import pytest
from sb3_cases import ALGOS, ENV_IDS, model

CASES = [(algo, kind) for algo in ALGOS for kind in ENV_IDS]


@pytest.mark.parametrize("algo, kind", CASES, ids=[f"{algo.__name__}-{kind}" for algo, kind in CASES])
def test_sb3_deterministic_training_common(algo, kind):
    actions, rewards, weights = [[], []], [[], []], []
    for run in range(2):
        agent = model(algo, ENV_IDS[kind], seed=0).learn(500)
        weights.append(agent.policy.theta_array.copy())
        env = agent.get_env()
        obs = env.reset()
        for _ in range(100):
            action, _ = agent.predict(obs, deterministic=False)
            obs, reward, _, _ = env.step(action)
            actions[run].append(action)
            rewards[run].append(reward)
    np.testing.assert_array_equal(weights[0], weights[1])
    np.testing.assert_array_equal(np.array(actions[0]), np.array(actions[1]))
    np.testing.assert_array_equal(np.array(rewards[0]), np.array(rewards[1]))
    assert len({float(np.sum(a)) for a in actions[0]}) > 1  # the exploring actions vary, so the match says something

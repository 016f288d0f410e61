"""SB3's test_identity behaviours for every algorithm: each learns SB3's identity envs (reward 1 when the action names
the state; 100-step episodes) to an evaluation of at least 90 of 100, with Discrete, MultiDiscrete and Box actions.
TileQ tiles Box observations, so the discrete identities are observed one-hot (gymnasium's FlattenObservation); the raw
Discrete and MultiDiscrete observations and MultiBinary actions are refused by name."""

import numpy as np
import pytest
from gymnasium.wrappers import FlattenObservation
from sb3_cases import ALGOS, model
from stable_baselines3.common.envs import IdentityEnv, IdentityEnvBox, IdentityEnvMultiBinary, IdentityEnvMultiDiscrete
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_er import SarsaLambda

DIM = 4
ENVS = {
    "discrete": (lambda: FlattenObservation(IdentityEnv(DIM)), 1200),
    "multidiscrete": (lambda: FlattenObservation(IdentityEnvMultiDiscrete(DIM)), 3000),
    "box": (lambda: IdentityEnvBox(eps=0.5), 1000),
}
#: Optimistic initial values, above the largest return 1 / (1 - gamma) = 1.67: an action not yet tried looks better
#: than one that paid nothing, so the 16 joint actions of the MultiDiscrete identity are all tried.
KWARGS = dict(gamma=0.4, seed=3, policy_kwargs=dict(n_tilings=4, memory_size=2**14, initial_value=2.0))


@pytest.mark.parametrize("kind", list(ENVS))
@pytest.mark.parametrize("algo", ALGOS)
def test_sb3_identity(algo, kind):
    """SB3's test_discrete and test_continuous."""
    make, steps = ENVS[kind]
    env = DummyVecEnv([make])
    agent = model(algo, env, **KWARGS).learn(steps)
    evaluate_policy(agent, env, n_eval_episodes=20, reward_threshold=90, warn=False)
    single = make()
    obs, _ = single.reset(seed=0)
    action, _ = agent.predict(obs)
    assert np.shape(action) == single.action_space.shape and single.action_space.contains(action)


@pytest.mark.parametrize(
    "env, message",
    [
        (IdentityEnv(DIM), r"needs a flat Box observation space, got Discrete\(4\)"),
        (IdentityEnvMultiDiscrete(DIM), r"needs a flat Box observation space, got MultiDiscrete"),
        (
            FlattenObservation(IdentityEnvMultiBinary(DIM)),
            r"needs a Discrete, MultiDiscrete or Box action space, got MultiBinary\(4\)",
        ),
    ],
    ids=["discrete observations", "multidiscrete observations", "multibinary actions"],
)
@pytest.mark.parametrize("algo", ALGOS)
def test_spaces_tile_coding_cannot_take_are_refused_by_name(algo, env, message):
    with pytest.raises(ValueError, match=message):
        model(algo, env)


@pytest.mark.parametrize(
    "kind, make, steps",
    [("discrete", lambda: IdentityEnv(DIM), 1200), ("multidiscrete", lambda: IdentityEnvMultiDiscrete(DIM), 3000)],
)
def test_the_refusal_of_table_indices_gives_code_that_learns(kind, make, steps):
    """The error for a Discrete or MultiDiscrete observation suggests a wrapper and tile widths; run exactly the code it
    gives: each state gets a tile of its own, and the identity is learnt as well as under the one-hot encoding."""
    import re

    import gymnasium

    with pytest.raises(ValueError) as refusal:
        model(SarsaLambda, make())
    message = str(refusal.value)
    wrapper, policy_kwargs = re.search(r"e\.g\. env = (.+) and policy_kwargs=(dict\(.+\))\.$", message).groups()
    env = eval(wrapper, {"gymnasium": gymnasium, "np": np, "env": make()})
    kwargs = dict(KWARGS, policy_kwargs={**KWARGS["policy_kwargs"], **eval(policy_kwargs)})
    agent = model(SarsaLambda, DummyVecEnv([lambda: env]), **kwargs).learn(steps)
    evaluate_policy(agent, agent.get_env(), n_eval_episodes=20, reward_threshold=90, warn=False)

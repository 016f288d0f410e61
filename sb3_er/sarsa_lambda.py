"""Sarsa(lambda) on tile-coded Q (thesis Alg. 2), the baseline of every thesis experiment."""

from stable_baselines3.common.type_aliases import GymEnv

from sb3_er.common.base_class import TileQAlgorithm
from sb3_er.common.docstrings import inherit_parameters
from sb3_er.common.policies import TileQPolicy


@inherit_parameters
class SarsaLambda(TileQAlgorithm):
    """Online Sarsa(lambda) with epsilon-greedy acting and sparse replacing traces (Alg. 2, Eq. 2.6).

    :param trace_lambda: the trace decay lambda (thesis: 0.92 for the pendulum and the walker, 0.859 for LEO).
    """

    def __init__(
        self,
        policy: str | type[TileQPolicy] = "TileQ",
        env: GymEnv | str | None = None,
        trace_lambda: float = 0.92,
        **kwargs,
    ):
        super().__init__(policy, env, trace_lambda=trace_lambda, **kwargs)

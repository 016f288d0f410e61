"""Sarsa(lambda) on tile-coded Q (thesis Alg. 2), the baseline of every thesis experiment."""

from typing import Any

from stable_baselines3.common.type_aliases import GymEnv, Schedule

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
        learning_rate: float | Schedule = 0.2,
        gamma: float = 0.99,
        exploration_rate: float = 0.05,
        trace_cutoff: float = 0.01,
        value_watch: bool = True,
        value_bound_action: str = "warn",
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: str = "cpu",
        _init_setup_model: bool = True,
    ):
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            gamma=gamma,
            exploration_rate=exploration_rate,
            trace_lambda=trace_lambda,
            trace_cutoff=trace_cutoff,
            value_watch=value_watch,
            value_bound_action=value_bound_action,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=_init_setup_model,
        )

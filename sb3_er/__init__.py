"""sb3-er: tile-coded linear RL with experience replay for Stable-Baselines3.

Sarsa(lambda), experience replay (ER), ER-sigma, residual-gradient ER and residual ER-sigma from "Sample-Efficient
Reinforcement Learning for Walking Robots" (2013), as SB3 algorithms on the "TileQ" policy.
"""

from sb3_er.common.base_class import DivergenceError, ValueBoundWarning
from sb3_er.common.buffers import TrajectoryReplayBuffer
from sb3_er.common.policies import TileQPolicy
from sb3_er.common.tile_coding import TileCoder
from sb3_er.common.value_bounds import RewardBounds, ValueBoundError
from sb3_er.dyna import Dyna
from sb3_er.er import ER, ERSigma, ResidualER, ResidualERSigma
from sb3_er.fqi import FQI
from sb3_er.lspi import LSPI
from sb3_er.sarsa_lambda import SarsaLambda

__version__ = "0.1.0"

__all__ = [
    "ER",
    "DivergenceError",
    "Dyna",
    "ERSigma",
    "FQI",
    "LSPI",
    "ResidualER",
    "ResidualERSigma",
    "RewardBounds",
    "SarsaLambda",
    "TileCoder",
    "TileQPolicy",
    "TrajectoryReplayBuffer",
    "ValueBoundError",
    "ValueBoundWarning",
]

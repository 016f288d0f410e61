"""sb3-er: tile-coded linear RL with experience replay for Stable-Baselines3.

Sarsa(lambda), experience replay (ER), ER-sigma, residual-gradient ER and residual ER-sigma from "Sample-Efficient
Reinforcement Learning for Walking Robots" (2013), as SB3 algorithms on the "TileQ" policy.

The names below are imported when first used (PEP 562), so that ``import sb3_er`` costs nothing and a run imports only
the modules it uses: ``from sb3_er import SarsaLambda`` loads neither Dyna's nearest-neighbour model (scipy.spatial)
nor the least-squares solvers of FQI and LSPI (scipy.sparse).
"""

import importlib
from typing import Any

__version__ = "0.1.0"

#: public name -> the module that defines it
_MODULES = {
    "DivergenceError": "sb3_er.common.base_class",
    "ValueBoundWarning": "sb3_er.common.base_class",
    "TrajectoryReplayBuffer": "sb3_er.common.buffers",
    "TileQPolicy": "sb3_er.common.policies",
    "TileCoder": "sb3_er.common.tile_coding",
    "RewardBounds": "sb3_er.common.value_bounds",
    "ValueBoundError": "sb3_er.common.value_bounds",
    "Dyna": "sb3_er.dyna",
    "ER": "sb3_er.er",
    "ERSigma": "sb3_er.er",
    "ResidualER": "sb3_er.er",
    "ResidualERSigma": "sb3_er.er",
    "FQI": "sb3_er.fqi",
    "LSPI": "sb3_er.lspi",
    "SarsaLambda": "sb3_er.sarsa_lambda",
}

__all__ = sorted(_MODULES, key=str.lower)


def __getattr__(name: str) -> Any:
    module = _MODULES.get(name)
    if module is None:
        raise AttributeError(f"module 'sb3_er' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_MODULES})

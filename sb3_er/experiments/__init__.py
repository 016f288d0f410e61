"""The thesis's experiments: protocols as SB3 callbacks, metrics, tables, figures and `sb3-er reproduce`."""

from sb3_er.experiments.metrics import (
    end_performance,
    mean_confidence_interval,
    relative_difference,
    rise_time,
    summarize_curves,
)
from sb3_er.experiments.protocols import EpisodeReturnProtocol, GreedyDistanceProtocol
from sb3_er.experiments.specs import EXPERIMENTS, Experiment

__all__ = [
    "EXPERIMENTS",
    "EpisodeReturnProtocol",
    "Experiment",
    "GreedyDistanceProtocol",
    "end_performance",
    "mean_confidence_interval",
    "relative_difference",
    "rise_time",
    "summarize_curves",
]

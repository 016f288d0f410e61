"""The four thesis experiments: environment, protocol, run length, axes and the thesis's table (DESIGN.md 5-6)."""

from __future__ import annotations

from dataclasses import dataclass, field

from sb3_er.experiments import thesis


@dataclass(frozen=True)
class Experiment:
    """One thesis experiment as `sb3-er reproduce` runs it.

    ``protocol`` is ``"episodes"`` (the return of every learning episode, run length ``default_budget`` episodes) or
    ``"walking"`` (greedy distance every ``eval_interval`` s of learning time over ``eval_runs`` runs, run length
    ``default_budget`` s of learning time). ``rise_time_scale`` converts the x axis to the table's rise-time unit.
    ``success_threshold`` is the performance that counts as a learned gait: a mean curve that never reaches it has no
    end performance (the thesis's "NA").
    """

    name: str
    env_id: str
    title: str
    protocol: str
    default_budget: float
    x_column: str
    x_label: str
    performance_column: str
    performance_label: str
    rise_time_unit: str
    rise_time_scale: float = 1.0
    eval_interval: float = 0.0
    eval_runs: int = 0
    success_threshold: float | None = None
    has_falls: bool = False
    thesis_table: dict = field(default_factory=dict)
    thesis_caption: str = ""

    @property
    def budget_unit(self) -> str:
        return "episodes" if self.protocol == "episodes" else "s of learning time"


def _episodic(**settings) -> Experiment:
    return Experiment(
        protocol="episodes",
        x_column="episode",
        x_label="episode",
        performance_column="return",
        performance_label="return of the learning episode",
        rise_time_unit="episodes",
        **settings,
    )


def _walking(**settings) -> Experiment:
    return Experiment(
        protocol="walking",
        x_column="learning_time_s",
        x_label="learning time [s]",
        performance_column="distance",
        has_falls=True,
        **settings,
    )


EXPERIMENTS: dict[str, Experiment] = {
    "gridworld": _episodic(
        name="gridworld",
        env_id="sb3_er/WindyCliff-v0",
        title="Windy cliff grid world",
        default_budget=100,
        has_falls=True,
        thesis_caption="The thesis gives no table for the grid world (section 5.1 shows value functions only).",
    ),
    "pendulum": _episodic(
        name="pendulum",
        env_id="sb3_er/PendulumSwingup-v0",
        title="Inverted pendulum swing-up",
        default_budget=100,
        thesis_table=thesis.PENDULUM,
        thesis_caption="Thesis Table 6.1: rise time in episodes, end performance as accumulated reward.",
    ),
    "walker": _walking(
        name="walker",
        env_id="sb3_er/SimplestWalker-v0",
        title="Simplest walker",
        default_budget=5000.0,
        performance_label="distance walked in 100 s [m] (mean of 10 greedy runs)",
        rise_time_unit="s",
        eval_interval=100.0,
        eval_runs=10,
        success_threshold=1.0,
        thesis_table=thesis.WALKER,
        thesis_caption="Thesis Table 6.2: rise time in seconds, end performance in meters.",
    ),
    "leo": _walking(
        name="leo",
        env_id="sb3_er/Leo-v0",
        title="LEO",
        default_budget=12000.0,
        performance_label="distance walked in a greedy 25 s run [m]",
        rise_time_unit="min",
        rise_time_scale=60.0,
        eval_interval=200.0,
        eval_runs=1,
        success_threshold=0.5,
        thesis_table=thesis.LEO,
        thesis_caption="Thesis Table 6.3: rise time in minutes, end performance in meters.",
    ),
}

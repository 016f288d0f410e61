"""The four thesis experiments: environment, protocol, run length, axes and the thesis's table (thesis sections 4.2,
5.1 and 6.1)."""

from __future__ import annotations

from dataclasses import dataclass, field

from sb3_er.common.docstrings import inherit_parameters
from sb3_er.experiments import thesis


@dataclass(frozen=True)
class Experiment:
    """One thesis experiment as `sb3-er reproduce` runs it.

    ``protocol`` is ``"episodes"`` (the return of every learning episode, run length ``default_budget`` episodes) or
    ``"walking"`` (greedy distance every ``eval_interval`` s of learning time over ``eval_runs`` runs, run length
    ``default_budget`` s of learning time). ``rise_time_scale`` converts the x axis to the table's rise-time unit.
    ``success_threshold`` is the performance that counts as a learned gait: a mean curve that never reaches it has no
    end performance (the thesis's "NA"). ``zoo_configs``: the algorithms' settings start from their
    ``zoo_configs/<algo>.yml`` entry for ``env_id`` (else from the class defaults, and the runs' ``algo_kwargs`` carry
    every setting: the framework experiment's MountainCar).

    :param name: the experiment's name in ``sb3-er reproduce``, e.g. "walker".
    :param env_id: the Gymnasium id of its env.
    :param title: its name in tables and figures.
    :param protocol: "episodes" or "walking" (see above); an analysis keeps its settings here too.
    :param default_budget: default run length, in episodes or seconds of learning time.
    :param x_column: the records' column of the learning curves' x axis, e.g. "learning_time_s".
    :param x_label: its axis label.
    :param performance_column: the records' column of the performance, e.g. "distance".
    :param performance_label: its axis label.
    :param rise_time_unit: the unit of the table's rise time, e.g. "min".
    :param rise_time_scale: x units per rise-time unit (default 1; LEO's seconds to minutes: 60).
    :param eval_interval: seconds of learning time between greedy evaluations ("walking" only; default 0).
    :param eval_runs: greedy runs per evaluation ("walking" only; default 0).
    :param success_threshold: the performance of a learned gait; None (default) for none.
    :param has_falls: whether the env reports falls (a falls column and figure; default False).
    :param thesis_table: the thesis's numbers of the table, by algorithm and metric (default none).
    :param thesis_caption: the caption of the thesis's table (default "").
    :param zoo_configs: whether the settings start from the zoo configs (default True).
    :param random_performance: the uniformly random policy's mean performance in the table's metric (what a run that
        learned nothing is worth), as measured by ``benchmarks/random_policy.py`` and committed in
        ``results/measured/random_policy/scores.json`` (4 significant digits); None (default) where not measured.
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
    zoo_configs: bool = True
    random_performance: float | None = None

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
        random_performance=-54130.0,
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
        thesis_caption="Thesis Table 6.2: rise time in seconds of learning time, end performance in meters walked in "
        "100 s (ours: the mean of 10 greedy 100 s runs).",
        random_performance=0.5205,
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
        thesis_caption="Thesis Table 6.3: rise time in minutes of learning time, end performance in meters walked in "
        "a greedy 25 s run.",
        random_performance=0.08725,
    ),
}


@inherit_parameters
@dataclass(frozen=True)
class Analysis(Experiment):
    """A thesis analysis that is no learning run under a protocol: `sb3-er reproduce replay-order` (Appendix A) and
    `sb3-er reproduce pessimistic` (Figure 5.5).

    Each run (one seed) is done by the function registered for ``task`` in
    :data:`sb3_er.experiments.runner.TASKS`. ``unit`` is the unit of the run length (``budget``), and ``settings``
    (sorted ``(name, value)`` pairs) holds the analysis's other settings. :meth:`with_settings` also writes them into
    ``protocol``, the protocol name that every run's version record keeps, so that a resume with other settings is
    refused like one with another configuration.

    :param task: the key of the run's function in :data:`sb3_er.experiments.runner.TASKS`.
    :param unit: the unit of the run length ``budget``.
    :param settings: the analysis's other settings as sorted ``(name, value)`` pairs (default none).
    """

    task: str = ""
    unit: str = ""
    settings: tuple = ()

    @property
    def budget_unit(self) -> str:
        return self.unit

    def setting(self, name: str):
        """The value of setting `name`; KeyError naming the known settings otherwise.

        :param name: the setting's name.
        """
        settings = dict(self.settings)
        if name not in settings:
            raise KeyError(f"{self.name} has no setting {name!r}; it has {sorted(settings)}")
        return settings[name]

    def with_settings(self, **settings) -> Analysis:
        """A copy with `settings` replacing those of the same name; ``protocol`` names all of them."""
        import dataclasses

        merged = tuple(sorted({**dict(self.settings), **settings}.items()))
        protocol = f"{self.task}(" + ", ".join(f"{name}={value!r}" for name, value in merged) + ")"
        return dataclasses.replace(self, settings=merged, protocol=protocol)


def _analyses() -> dict[str, Experiment]:
    import dataclasses

    replay_order = Analysis(
        name="replay-order",
        env_id="sb3_er/PendulumSwingup-v0",
        title="Inverted pendulum: replay orders on one Sarsa(λ) database per seed (Appendix A)",
        protocol="replay_order",
        default_budget=300_000,
        x_column="replayed_updates",
        x_label="replayed updates (samples)",
        performance_column="return",
        performance_label="return of a greedy 15 s episode",
        rise_time_unit="replayed updates",
        task="replay_order",
        unit="replayed updates",
    ).with_settings(database_episodes=200, eval_every=75_000)
    pessimistic = Analysis(
        name="pessimistic",
        env_id="sb3_er/WindyCliff-v0",
        title="Windy cliff: pessimistic initialisation against ER-σ on the same data and replays (Figure 5.5)",
        protocol="pessimistic",
        default_budget=30,
        x_column="phase",
        x_label="replay phases (10 × the stored trajectories each)",
        performance_column="positive_cells",
        performance_label="cells with V > 0",
        rise_time_unit="phases",
        task="pessimistic",
        unit="replay phases",
    ).with_settings(initial_value=-50.0)
    sigma = dataclasses.replace(
        EXPERIMENTS["walker"],
        name="sigma",
        title="Simplest walker: ER-σ with the five σ definitions of Appendix B",
        thesis_table={},
        thesis_caption="Thesis Appendix B, Figure B.1: definition 4 (between the worst case and the average) performs "
        "best; performance drops greatly towards the best case. The thesis prints no numbers.",
    )
    return {"replay-order": replay_order, "sigma": sigma, "pessimistic": pessimistic}


ANALYSES: dict[str, Experiment] = _analyses()
"""`sb3-er reproduce` analyses beside the four experiments: Appendix A (``replay-order``), Appendix B (``sigma``, the
walker experiment run once per σ definition) and Figure 5.5 (``pessimistic``)."""

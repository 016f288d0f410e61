"""`sb3-er reproduce sigma-regime`: which way ER-σ moves its targets, per reading."""

import numpy as np
import pandas as pd
import pytest

from sb3_er.cli import main
from sb3_er.experiments.runner import run_csv_path
from sb3_er.experiments.sigma_regime import READINGS, reproduce_sigma_regime, summarize_regime


def _tiny_study(out_dir, n_seeds=1, budget=4, readings=("gridworld", "pendulum-3.3")):
    """The thesis's ER-σ on `readings`, `budget` episodes, `n_seeds` seeds."""
    return reproduce_sigma_regime(
        n_seeds=n_seeds,
        budget=budget,
        readings=list(readings),
        learners=["er_sigma"],
        n_workers=1,
        out_dir=out_dir,
        show_progress=False,
    )


def test_a_tiny_run_writes_phases_and_the_summary(tmp_path):
    result = _tiny_study(tmp_path)
    frame = pd.read_csv(run_csv_path(tmp_path / "gridworld", "er_sigma", 0))
    assert len(frame) == 4  # one replay phase per episode (the grid world replays at each episode's end)
    assert frame["updates"].gt(0).all() and frame["phase"].tolist() == [1, 2, 3, 4]
    assert ((frame["sigma_raised"] + frame["sigma_lowered"]).between(0.0, 1.0)).all()
    text = result.table_markdown.read_text()
    assert "| windy cliff grid world | ER-σ | results/measured/gridworld | 4 episodes | 4 |" in text
    assert "pendulum, earlier default (velocity tiles 3.3 rad/s, goal 0.1 rad and 1 rad/s)" in text
    again = _tiny_study(tmp_path)
    assert (again.runs_done, again.runs_skipped) == (0, 2)


def test_the_summary_weights_phases_by_their_updates():
    frames = {
        0: pd.DataFrame(
            {
                "updates": [10, 30],
                "sigma_shift": [1.0, -1.0],
                "sigma_raised": [1.0, 0.0],
                "sigma_lowered": [0.0, 1.0],
                "values_out_of_range": [0, 3],
                "diverged": False,
            }
        ),
        1: pd.DataFrame(
            {
                "updates": [20],
                "sigma_shift": [np.nan],
                "sigma_raised": [np.nan],
                "sigma_lowered": [np.nan],
                "values_out_of_range": [0],
                "diverged": False,
            }
        ),
    }
    summary = summarize_regime(frames)
    assert summary["mean_shift"] == pytest.approx((10 - 30) / 40)
    assert summary["raised"] == pytest.approx(0.25) and summary["lowered"] == pytest.approx(0.75)
    assert (summary["left_bounds"], summary["runs"], summary["phases"]) == (1, 2, 3)


def test_a_budget_for_readings_of_two_units_is_refused(tmp_path):
    with pytest.raises(ValueError, match="one unit"):
        reproduce_sigma_regime(n_seeds=1, budget=4, readings=["gridworld", "walker"], out_dir=tmp_path)
    with pytest.raises(SystemExit):
        main(["reproduce", "sigma-regime", "--readings", "nowhere"])
    assert set(READINGS) >= {"walker-optimistic", "pendulum-0.33"}


def test_each_reading_is_its_tables_reading():
    """A reading that names a table's results folder runs that table's env settings and length (the folder's pinned
    settings.json when committed), and the CLI offers every reading."""
    import json
    from pathlib import Path

    from sb3_er.cli import SIGMA_REGIME_READINGS
    from sb3_er.experiments.specs import EXPERIMENTS

    assert set(SIGMA_REGIME_READINGS) == set(READINGS)
    measured = Path(__file__).resolve().parents[1] / "results" / "measured"
    tables = {
        "table_6_1": "pendulum",
        "table_6_1_earlier_default": "pendulum",
        "table_6_2": "walker",
        "table_6_2_earlier_default": "walker",
        "gridworld": "gridworld",
        "table_6_3": "leo",
    }
    for name, reading in READINGS.items():
        if not reading.results:
            continue
        experiment = EXPERIMENTS[tables[reading.results]]
        assert reading.env_id == experiment.env_id, name
        assert reading.budget == experiment.default_budget, name
        pinned = measured / reading.results / "settings.json"
        if pinned.is_file():
            settings = json.loads(pinned.read_text())
            assert settings.get("env_kwargs", {}) == dict(reading.env_kwargs), name


def test_running_one_reading_keeps_the_rows_of_the_others(tmp_path):
    """The summary covers the folder: a later command for one reading keeps the earlier readings' rows, lengths and
    runs, and says how many runs each row has when they differ."""
    _tiny_study(tmp_path, n_seeds=2, budget=3, readings=["gridworld"])
    result = _tiny_study(tmp_path, budget=2, readings=["pendulum-3.3"])
    text = result.table_markdown.read_text()
    gridworld = next(line for line in text.splitlines() if line.startswith("| windy cliff grid world"))
    assert "| 3 episodes | 6 |" in gridworld and gridworld.endswith("of 2 |")  # 2 runs of 3 episodes
    pendulum = next(line for line in text.splitlines() if line.startswith("| pendulum, earlier default"))
    assert "| 2 episodes |" in pendulum and pendulum.endswith("of 1 |")
    assert "the runs per reading and learner are counted" in text.splitlines()[0]
    assert list(pd.read_csv(tmp_path / "summary.csv")["reading"]) == ["gridworld", "pendulum-3.3"]


def test_the_stable_learner_has_its_own_rows_and_holds_its_values_inside(tmp_path):
    """Each reading runs ER-σ under the thesis's preset and under the stable one, in folders of their own; the stable
    learner's runs record the preset, and on the grid world, where the thesis's ER-σ of seed 1 leaves the possible
    returns at its 8th episode (the committed study's run), the projection keeps every value inside."""
    import json

    from sb3_er.cli import SIGMA_REGIME_LEARNERS
    from sb3_er.experiments.sigma_regime import LEARNERS

    assert SIGMA_REGIME_LEARNERS == LEARNERS
    result = reproduce_sigma_regime(
        n_seeds=1, first_seed=1, budget=10, readings=["gridworld"], n_workers=2, out_dir=tmp_path, show_progress=False
    )
    folder = tmp_path / "gridworld"
    for learner, preset in zip(LEARNERS, ("thesis", "stable"), strict=True):
        record = json.loads(run_csv_path(folder, learner, 1).with_suffix(".json").read_text())
        assert record["config"]["algorithm_kwargs"]["preset"] == preset
    summary = pd.read_csv(result.table_csv).set_index("learner")
    assert summary.loc["er_sigma", "left_bounds"] == 1
    assert summary.loc["er_sigma_stable", "left_bounds"] == 0
    assert "| ER-σ (stable) |" in result.table_markdown.read_text()

"""`sb3-er reproduce framework` (thesis Table 3.1, measured): a tiny run writes its table and resumes; the level and
update counts by hand; the command line."""

import numpy as np
import pandas as pd
import pytest
from chain_mdp import ChainEnv

from sb3_er import ER, FQI, Dyna, SarsaLambda
from sb3_er.cli import _analysis_options, reproduce_parser
from sb3_er.experiments.framework import (
    METHODS,
    PROBLEMS,
    TABLE_3_1,
    reproduce_framework,
    samples_to_level,
    value_updates,
)


def test_tiny_reproduction_writes_table_3_1_and_resumes(tmp_path):
    """Every method on the grid world and MountainCar, one seed of 2 episodes: the per-run CSVs with the protocol's
    columns, summary.md with the thesis's rows (NFQ and KADP named out of scope) and one measured table per problem,
    summary.csv with a row per (problem, method); a second call finds every run finished."""
    result = reproduce_framework(
        n_seeds=1, budget=2, problems=["gridworld", "mountaincar"], n_workers=1, show_progress=False, out_dir=tmp_path
    )
    assert (result.runs_done, result.runs_skipped) == (14, 0)
    run = pd.read_csv(tmp_path / "mountaincar" / "runs" / "er_prioritized" / "seed_0.csv")
    assert run.columns.tolist() == [
        "episode",
        "timesteps",
        "return",
        "length",
        "updates",
        "cpu_time_s",
        "wall_time_s",
        "diverged",
    ]
    assert run["timesteps"].tolist() == [200, 400] and run["updates"].iloc[-1] > 0
    text = result.table_markdown.read_text()
    for row in TABLE_3_1:
        assert f"| {row} |" in text
    assert text.count("out of scope") == 2
    for name in ("gridworld", "mountaincar"):
        assert f"({PROBLEMS[name].env_id})" in text
    measured = text.split("\n## ")[1:]
    assert len(measured) == 2
    for section in measured:
        assert all(f"\n| {method.label} |" in section for method in METHODS.values())
    table = pd.read_csv(result.table_csv)
    assert len(table) == 14 and set(table["method"]) == set(METHODS)
    again = reproduce_framework(
        n_seeds=1, budget=2, problems=["gridworld", "mountaincar"], n_workers=1, show_progress=False, out_dir=tmp_path
    )
    assert (again.runs_done, again.runs_skipped) == (0, 14)
    with pytest.raises(ValueError, match="holds runs made with"):
        reproduce_framework(n_seeds=1, budget=3, problems=["gridworld"], n_workers=1, out_dir=tmp_path)


def test_samples_to_level_by_hand():
    """The steps at the end of the first episode whose last-10 mean return reaches the level."""
    returns = [-200.0] * 10 + [-100.0] * 10
    frame = pd.DataFrame({"return": returns, "timesteps": np.cumsum([200] * 10 + [100] * 10)})
    # the mean of episodes k-9..k is -200 + 10 (k - 9) for k = 9..19: -150 first at k = 14 (0-based)
    assert samples_to_level(frame, -150.0) == 2000 + 5 * 100
    assert np.isnan(samples_to_level(frame, -50.0))
    assert np.isnan(samples_to_level(frame.iloc[:5], -250.0))


def test_value_updates_by_hand():
    """One update per step for Sarsa(lambda); ER's replayed samples; Dyna's direct and planning updates; FQI's
    samples times sweeps of every fit."""
    env = ChainEnv(n_states=5)
    sarsa = SarsaLambda("TileQ", env, seed=0).learn(50)
    assert value_updates(sarsa) == 50
    er = ER("TileQ", env, n_replays=3, seed=0).learn(50)
    assert value_updates(er) == er.replay_updates > 0
    dyna = Dyna("TileQ", env, planning_steps=2, seed=0).learn(50)
    assert value_updates(dyna) == 50 + dyna.planning_updates
    fqi = FQI("TileQ", env, fit_every=1, n_iterations=3, seed=0)
    fqi.learn(50)
    assert fqi.fits > 0 and value_updates(fqi) == fqi.sample_backups
    fqi.sample_backups = 0
    fqi.fit()
    assert value_updates(fqi) == 3 * fqi.replay_buffer.n_closed_transitions


def test_command_line_options():
    parser = reproduce_parser()
    args = parser.parse_args(["framework", "--seeds", "2", "--problems", "pendulum", "--methods", "er", "lspi"])
    assert _analysis_options(parser, args) == {"problems": ["pendulum"], "methods": ["er", "lspi"]}
    with pytest.raises(SystemExit):
        parser.parse_args(["framework", "--methods", "nfq"])
    args = parser.parse_args(["pendulum", "--problems", "pendulum"])
    with pytest.raises(SystemExit):
        _analysis_options(parser, args)

"""The readings rule's score (sb3_er.experiments.screen) against hand computations, and a screen end to end."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from sb3_er.experiments.screen import Candidate, relative_error, run_screen, score, write_screen_summary
from sb3_er.experiments.thesis import PENDULUM, WALKER


def test_the_score_sums_the_relative_errors_of_the_printed_figures():
    # walker: rise 1500 s, end 11.7 m, falls 74. Ours 1200 s, 12.87 m, 111 falls: 20 % + 10 % + 50 %.
    result = score({"rise_time": 1200.0, "end_performance": 12.87, "falls": 111.0}, WALKER["sarsa_lambda"])
    assert result["rise_time_error"] == pytest.approx(0.2)
    assert result["end_performance_error"] == pytest.approx(0.1)
    assert result["falls_error"] == pytest.approx(0.5)
    assert result["score"] == pytest.approx(0.8) and result["within_50"]  # 50 % exactly is within


def test_negative_returns_use_the_magnitude_and_the_pendulum_has_no_falls():
    # pendulum: rise 22, end -16730. Ours 33 episodes, -25095: 50 % + 50 %; falls are not in Table 6.1.
    result = score({"rise_time": 33.0, "end_performance": -25095.0, "falls": 3.0}, PENDULUM["sarsa_lambda"])
    assert set(result) == {"rise_time_error", "end_performance_error", "score", "within_50"}
    assert result["score"] == pytest.approx(1.0) and result["within_50"]
    assert not score({"rise_time": 34.0, "end_performance": -16730.0}, PENDULUM["sarsa_lambda"])["within_50"]


def test_a_figure_that_was_not_measured_ranks_last():
    assert relative_error(float("nan"), 11.7) == math.inf and relative_error(None, 74) == math.inf
    result = score({"rise_time": 1500.0, "end_performance": float("nan"), "falls": 74.0}, WALKER["sarsa_lambda"])
    assert result["score"] == math.inf and not result["within_50"]
    with pytest.raises(ValueError, match="non-zero"):
        relative_error(1.0, 0.0)


def test_the_bootstrap_interval_of_identical_seeds_is_the_score_itself():
    from sb3_er.experiments.screen import bootstrap_score_interval
    from sb3_er.experiments.specs import EXPERIMENTS
    from sb3_er.experiments.summary import Curves

    x = np.arange(1.0, 11.0)
    curve = np.linspace(-50000.0, -16730.0, 10)  # rises linearly: 90 % of the way at episode 10 (error 10/22 - 1)
    same = Curves(x, np.tile(curve, (4, 1)), np.zeros((4, 10)), (0, 1, 2, 3), (), 1.0)
    low, high = bootstrap_score_interval(EXPERIMENTS["pendulum"], same, PENDULUM["sarsa_lambda"], resamples=50)
    assert low == high == pytest.approx(abs(10 - 22) / 22)
    varied = Curves(x, np.stack([curve, curve - 8000.0]), np.zeros((2, 10)), (0, 1), (), 1.0)
    low, high = bootstrap_score_interval(EXPERIMENTS["pendulum"], varied, PENDULUM["sarsa_lambda"], resamples=200)
    assert low == pytest.approx(12 / 22) and high == pytest.approx(12 / 22 + 8000 / 16730)  # both seeds' own scores


def test_a_screen_ranks_its_candidates_and_writes_its_summary(tmp_path):
    candidates = [Candidate("weak", {"max_torque": 0.3}, "0.3 N m"), Candidate("printed", {}, "defaults")]
    run_screen("pendulum", candidates, tmp_path, n_seeds=2, budget=2)
    table = write_screen_summary("pendulum", candidates, tmp_path, "A screen", n_seeds=2)
    assert list(table["rank"]) == [1, 2] and table["score"].is_monotonic_increasing
    assert set(table["candidate"]) == {"weak", "printed"} and set(table["seeds"]) == {2}
    for row in table.itertuples():  # each score is recomputed from the row's own figures
        expected = abs(row.rise_time - 22) / 22 + abs(row.end_performance + 16730) / 16730
        if math.isnan(row.rise_time):  # a mean curve that never rose in its 2 episodes has no rise: ranked last
            expected = math.inf
        assert row.score == pytest.approx(expected)
        assert row.score_low <= row.score_high and row.score_high > 0
    text = (tmp_path / "summary.md").read_text()
    assert "| 1 | " + table["candidate"][0] + " |" in text and "rise time 22" in text
    written = pd.read_csv(tmp_path / "summary.csv")
    assert list(written["candidate"]) == list(table["candidate"])
    assert written["score"].tolist() == pytest.approx(table["score"].tolist())
    with pytest.raises(ValueError, match="distinct names"):
        run_screen("pendulum", candidates + candidates[:1], tmp_path)

    # a record that predates checksums (format 1) is checked and sealed once, as a resume would
    from sb3_er.experiments import records
    from sb3_er.experiments.runner import run_csv_path
    from sb3_er.experiments.screen import seal_finished_runs

    path = run_csv_path(tmp_path / "weak", "sarsa_lambda", 1)
    legacy = {
        key: value for key, value in records.read_record(path).items() if key not in (records.CHECKSUM_FIELD, "files")
    }
    records.record_path(path).write_text(json.dumps({**legacy, "format": 1}))
    assert seal_finished_runs("pendulum", candidates, tmp_path, n_seeds=2) == 1
    assert records.check_sealed(records.read_record(path), path) is None
    assert seal_finished_runs("pendulum", candidates, tmp_path, n_seeds=2) == 0


def test_the_rule_keeps_a_printed_value_only_when_a_candidate_with_it_comes_within_50_percent():
    from sb3_er.experiments.screen import decide

    fall, reward = "fall: printed", "reward: printed"
    candidates = [
        Candidate("printed_everything", {}, "", frozenset({fall, reward})),  # misses: the printed reward fails
        Candidate("printed_fall", {}, "", frozenset({fall})),  # within 50 %, second best
        Candidate("open_fall", {}, "", frozenset()),  # the best score, but drops a printed value that stays
        Candidate("other_width", {}, "", frozenset({fall}), check=True),  # a check chooses nothing
    ]
    table = pd.DataFrame(
        {
            "candidate": ["other_width", "open_fall", "printed_fall", "printed_everything"],
            "score": [0.1, 0.3, 0.4, 2.0],
            "within_50": [True, True, True, False],
            "seeds": 10,
        }
    )
    decision = decide(table, candidates)
    assert decision.kept == {fall: "printed_fall", reward: None}
    assert decision.winner == "printed_fall"
    nothing_passes = table.assign(within_50=False)
    assert decide(nothing_passes, candidates).winner == "open_fall"  # then the nearest candidate, whatever it keeps
    assert decide(table.assign(seeds=9), candidates).winner is None  # too few seeds decide nothing


def test_tiling_screen_command_runs_the_chosen_jobs_in_order_and_refuses_unknown_names(tmp_path):
    from sb3_er.experiments.screen import tiling_screen_command

    candidates = {"A-v0": {"a1": {}, "a2": {}}, "B-v0": {"b1": {}}}
    calls, summaries = [], []
    screen = tmp_path / "screen"
    command = dict(
        description="test",
        candidates=candidates,
        run_one=lambda *job: calls.append(job),
        summarize=summaries.append,
        out_dir=screen,
    )
    tiling_screen_command(**command, argv=["--seeds", "0", "1"])
    assert calls == [
        ("A-v0", "a1", 0, screen),
        ("A-v0", "a1", 1, screen),
        ("A-v0", "a2", 0, screen),
        ("A-v0", "a2", 1, screen),
        ("B-v0", "b1", 0, screen),
        ("B-v0", "b1", 1, screen),
    ]
    calls.clear()
    tiling_screen_command(**command, seeds_outermost=True, argv=["--seeds", "0", "1", "--candidates", "a2", "b1"])
    assert [job[:3] for job in calls] == [("A-v0", "a2", 0), ("B-v0", "b1", 0), ("A-v0", "a2", 1), ("B-v0", "b1", 1)]
    calls.clear()
    tiling_screen_command(**command, argv=["--envs", "B-v0", "--out", str(tmp_path / "elsewhere")])
    assert calls == [("B-v0", "b1", 0, tmp_path / "elsewhere")] and not summaries
    tiling_screen_command(**command, argv=["--summarize"])
    assert summaries == [screen] and len(calls) == 1
    with pytest.raises(SystemExit):  # a1 is A-v0's, not B-v0's: no silent empty screen
        tiling_screen_command(**command, argv=["--envs", "B-v0", "--candidates", "a1"])

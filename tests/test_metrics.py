"""Metrics of thesis section 6.1 against hand-computed values and the thesis's own table arithmetic."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_er.experiments.metrics import (
    end_performance,
    mean_confidence_interval,
    relative_difference,
    rise_time,
    summarize_curves,
)
from sb3_er.experiments.specs import EXPERIMENTS
from sb3_er.experiments.summary import Curves, markdown_table, summary_table


def _curves(x, performance, falls, diverged=()):
    performance = np.array(performance, dtype=float)
    seeds = tuple(range(len(performance)))
    return Curves(np.array(x, dtype=float), performance, np.array(falls, dtype=float), seeds, tuple(diverged), 1.0)


def test_confidence_interval_matches_hand_computed_student_t():
    # mean 2.5, sample sd sqrt(5/3), se = sd / 2, t(0.975, df=3) = 3.182446
    mean, half_width = mean_confidence_interval([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5)
    assert half_width == pytest.approx(3.182446 * math.sqrt(5.0 / 3.0) / 2.0, rel=1e-5)


def test_confidence_interval_per_point_of_curves():
    curves = np.array([[0.0, 10.0], [2.0, 10.0]])
    mean, half_width = mean_confidence_interval(curves)
    # two seeds: sd of (0, 2) is sqrt(2), se = 1, t(0.975, df=1) = 12.7062
    np.testing.assert_allclose(mean, [1.0, 10.0])
    np.testing.assert_allclose(half_width, [12.7062, 0.0], rtol=1e-4)


def test_single_seed_has_no_interval_and_bad_confidence_is_refused():
    _, half_width = mean_confidence_interval([[3.0, 4.0]])
    assert np.isnan(half_width).all()
    with pytest.raises(ValueError, match="confidence"):
        mean_confidence_interval([1.0, 2.0], confidence=1.5)


def test_rise_time_of_a_distance_curve():
    # end performance 10, 90% of it is 9: first reached at x = 200 (9.5), not at 100 (2)
    x = [0, 100, 200, 300, 400]
    assert rise_time(x, [0.0, 2.0, 9.5, 10.0, 8.0]) == 200


def test_rise_time_of_negative_returns_measures_from_the_first_value():
    # from -100 up to the best -10: 90% of the way is -19; -20 is short of it, -10 at episode 4 reaches it
    assert rise_time([1, 2, 3, 4, 5], [-100.0, -50.0, -20.0, -10.0, -12.0]) == 4


def test_rise_time_against_a_given_end_never_reached_is_nan():
    assert math.isnan(rise_time([0, 1, 2], [0.0, 1.0, 2.0], end=100.0))
    assert math.isnan(rise_time([0, 1, 2], [0.0, 1.0, 2.0], end=float("nan")))
    with pytest.raises(ValueError, match="shape"):
        rise_time([0, 1], [0.0, 1.0, 2.0])


def test_end_performance_is_the_best_mean_or_na_without_a_gait():
    assert end_performance([1.0, 7.0, 5.0]) == 7.0
    assert end_performance([1.0, 7.0, 5.0], success_threshold=6.0) == 7.0
    assert math.isnan(end_performance([0.1, 0.3, 0.2], success_threshold=1.0))


def test_relative_difference_reproduces_the_thesis_tables():
    # Table 6.1: vanilla-ER end performance -4065 against Sarsa(lambda) -1.673e4 is printed as +76 %
    assert round(relative_difference(-4065, -1.673e4)) == 76
    # Table 6.2: ER-sigma falls 44 against 74 is printed as -41 %, rise time 3400 against 1500 as +126 %
    assert round(relative_difference(44, 74)) == -41
    assert round(relative_difference(3400, 1500)) == 127  # the thesis truncates 126.7 to 126
    assert math.isnan(relative_difference(1.0, 0.0))


def test_summary_of_hand_made_walker_curves():
    x = np.array([0.0, 100.0, 200.0, 300.0])
    distance = np.array([[0.0, 4.0, 10.0, 11.0], [0.0, 2.0, 8.0, 13.0]])  # mean 0, 3, 9, 12
    falls = np.array([[0, 5, 7, 8], [0, 3, 4, 4]])
    summary = summarize_curves(x, distance, falls, success_threshold=1.0)
    assert summary.end_performance == pytest.approx(12.0)
    assert summary.rise_time == 300.0  # 90% of 12 is 10.8; the mean 9 at 200 s falls short
    assert summary.end_performance_ci == pytest.approx(12.7062 * 1.0, rel=1e-4)  # sd of (11, 13) = sqrt 2, se = 1
    assert summary.falls == pytest.approx(6.0)
    assert summary.n_seeds == 2


def test_summary_table_puts_the_thesis_numbers_beside_ours():
    walker = EXPERIMENTS["walker"]
    x = np.array([0.0, 100.0, 200.0])
    curves = {
        "sarsa_lambda": _curves(x, [[0.0, 5.0, 10.0], [0.0, 5.0, 10.0]], [[0, 4, 8], [0, 4, 8]]),
        "er_sigma": _curves(x, [[0.0, 10.0, 10.0], [0.0, 10.0, 10.0]], [[0, 2, 4], [0, 2, 4]]),
    }
    table = summary_table(walker, curves, budget=200.0)
    er_sigma_falls = table[(table.algorithm == "ER-σ") & (table.metric == "Falls")].iloc[0]
    assert er_sigma_falls.difference_with_sarsa_lambda == "-50 %"
    assert er_sigma_falls.thesis_average == "44"
    assert er_sigma_falls.thesis_difference == "-41 %"  # computed from 44 and 74, as printed
    text = markdown_table(walker, table)
    assert "| ER-σ | Rise time [s] | 100 | -50 % | 500 | -67 % |" in text
    # header, rule, four metrics and the value watch's row for each of two algorithms
    assert text.count("\n") == 1 + 5 * 2
    assert "|  | Runs whose values left the possible returns | not measured | — | — | — |" in text


def test_no_gait_shows_na_and_a_rise_time_beyond_the_run():
    leo = EXPERIMENTS["leo"]
    curves = {"er": _curves([0.0, 6000.0, 12000.0], [[0.0, 0.1, 0.2]], [[0, 50, 90]])}
    row = summary_table(leo, curves, budget=12000.0).set_index("metric")
    assert row.loc["Rise time [min]", "average_text"] == ">200"
    assert row.loc["End performance", "average_text"] == "NA"
    assert row.loc["End performance", "thesis_average"] == "NA"


@settings(max_examples=50, deadline=None)
@given(
    curve=st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=2, max_size=30),
    scale=st.floats(0.01, 100.0),
    shift=st.floats(-1e3, 1e3),
)
def test_rise_time_is_invariant_to_positive_affine_rescaling(curve, scale, shift):
    curve = np.array(curve)
    x = np.arange(len(curve)) * 10.0
    original = rise_time(x, curve)
    rescaled = rise_time(x, scale * curve + shift)
    if curve.max() <= curve[0]:  # a curve that never rises above its first value has no rise
        assert math.isnan(original)
        return
    assert original <= x[np.argmax(curve)]
    # rescaling may move values that sit exactly on the threshold by rounding; compare away from ties
    threshold = curve[0] + 0.9 * (curve.max() - curve[0])
    if np.min(np.abs(curve - threshold)) > 1e-6 * (1 + np.abs(curve).max()):
        assert rescaled == original


def test_a_curve_that_never_rises_has_no_rise_and_no_settling():
    """A mean curve that never rises above its first value (every run counted as learning nothing, such as a diverged
    run at the random policy's score throughout) learned nothing: no rise at its first point, no settling."""
    from sb3_er.experiments.metrics import settling_time

    x = np.arange(1.0, 11.0)
    for curve in (np.full(10, -54_130.0), np.linspace(-100.0, -200.0, 10)):
        assert math.isnan(rise_time(x, curve)) and math.isnan(settling_time(x, curve))
    summary = summarize_curves(x, np.full((3, 10), -54_130.0))
    assert math.isnan(summary.rise_time) and summary.end_performance == -54_130.0


def test_thesis_differences_are_computed_from_the_thesis_averages():
    from sb3_er.experiments.summary import thesis_difference

    walker, leo = EXPERIMENTS["walker"], EXPERIMENTS["leo"]
    # (150 - 74) / 74 = +103 %, printed +51 %; (140 - 74) / 74 = +89 %, printed +48 %
    assert thesis_difference(walker, "er", "falls") == "+103 % (printed +51 %)"
    assert thesis_difference(walker, "residual_er", "falls") == "+89 % (printed +48 %)"
    assert thesis_difference(walker, "er_sigma", "falls") == "-41 %"  # (44 - 74) / 74 agrees with the print
    # (9 - 22) / 22 is -59 %, printed -60 %: within rounding, the printed figure (the findings quote it too)
    assert thesis_difference(EXPERIMENTS["pendulum"], "er_sigma", "rise_time") == "-60 %"
    assert thesis_difference(leo, "er", "falls") == ">+63 % (printed >+93 %)"  # (6170 - 3792) / 3792
    assert thesis_difference(walker, "sarsa_lambda", "falls") == "-"


def test_settling_time_does_not_move_with_the_run_length_once_the_plateau_is_reached():
    from sb3_er.experiments.metrics import settling_time

    # cost 1000 + 9000 exp(-x/10): within 10 % of the plateau's cost 1000 when 9000 exp(-x/10) <= 100, x >= 10 ln 90
    for horizon in (100, 200, 400):
        x = np.arange(horizon + 1, dtype=float)
        returns = -(1000.0 + 9000.0 * np.exp(-x / 10.0))
        assert settling_time(x, returns) == np.ceil(10 * np.log(90))  # 45, whatever the horizon
    # a plateau with one lucky evaluation at x = 150: the thesis's rise time (90 % of the best value) moves from 12 to
    # 18 when the run is long enough to contain it (100 (1 - exp(-x/5)) >= 97.2 -> x >= 17.9), the settling time stays
    x = np.arange(201, dtype=float)
    distance = 100.0 * (1.0 - np.exp(-x / 5.0))
    distance[150] += 8.0
    assert (rise_time(x[:101], distance[:101]), rise_time(x, distance)) == (12.0, 18.0)
    assert settling_time(x[:101], distance[:101]) == settling_time(x, distance) == 12.0  # 5 ln 10 = 11.5


def test_settling_time_of_a_curve_that_never_settles_or_has_no_plateau():
    from sb3_er.experiments.metrics import settling_time

    assert np.isnan(settling_time([0.0, 1.0, 2.0], [0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="tolerance"):
        settling_time([0.0, 1.0], [1.0, 2.0], tolerance=1.5)


def _write_run(folder, algo, seed, returns, out_of_range, diverged=False):
    import pandas as pd

    from sb3_er.experiments.runner import run_csv_path

    path = run_csv_path(folder, algo, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame(
        {
            "episode": np.arange(1, len(returns) + 1),
            "return": returns,
            "cumulative_falls": 0,
            "wall_time_s": 1.0,
            "diverged": diverged,
        }
    )
    if out_of_range is not None:
        frame["values_out_of_range"] = out_of_range
    frame.to_csv(path, index=False)


def _write_walker_run(folder, algo, seed, distances, falls, out_of_range=0, diverged=False):
    """A walker run's CSV, one row every 100 s of learning time from 0."""
    import pandas as pd

    from sb3_er.experiments.runner import run_csv_path

    path = run_csv_path(folder, algo, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(
        {
            "learning_time_s": 100.0 * np.arange(len(distances)),
            "distance": distances,
            "cumulative_falls": falls,
            "wall_time_s": 1.0,
            "values_out_of_range": out_of_range,
            "diverged": diverged,
        }
    ).to_csv(path, index=False)


def test_a_diverged_run_counts_as_learning_nothing(tmp_path):
    """Residual ER: one complete run ending at -10 and two that diverged after 2 and 1 episodes. Every run is averaged:
    each diverged run at the random policy's committed score throughout (-54,130), so the mean curve's best is
    (-10 - 2 * 54,130) / 3 = -36,090; the runs that stayed inside alone end at -10, in rows of their own."""
    from sb3_er.experiments.summary import load_curves

    pendulum = EXPERIMENTS["pendulum"]
    assert pendulum.random_performance == -54_130.0
    for seed in (0, 1):
        _write_run(tmp_path, "sarsa_lambda", seed, [-100.0, -50.0, -20.0, -20.0], [0, 0, 0, 0])
    _write_run(tmp_path, "residual_er", 0, [-100.0, -10.0, -10.0, -10.0], [0, 0, 0, 0])
    _write_run(tmp_path, "residual_er", 1, [-100.0, -80.0], [0, 3], diverged=True)
    _write_run(tmp_path, "residual_er", 2, [-90.0], [2], diverged=True)
    curves = {
        algo: load_curves(pendulum, tmp_path, algo, range(3), budget=4) for algo in ("sarsa_lambda", "residual_er")
    }
    residual = curves["residual_er"]
    assert residual.seeds == (0,) and residual.diverged_seeds == (1, 2)
    every = residual.all_runs()
    assert every.seeds == (0, 1, 2) and every.performance.shape == (3, 4)
    np.testing.assert_array_equal(every.performance[1:], -54_130.0)
    table = summary_table(pendulum, curves, budget=4).set_index(["algorithm", "metric"])
    assert table.loc[("residual ER", "End performance"), "average"] == pytest.approx(-36_090.0)
    assert table.loc[("residual ER", "End performance"), "seeds"] == 3
    # rise time is measured on the mean curve, which still rises at episode 2 (the complete run's rise)
    assert table.loc[("residual ER", "Rise time [episodes]"), "average"] == 2.0
    assert table.loc[("residual ER", "Diverged runs"), "average_text"] == "2 of 3"
    assert table.loc[("residual ER", "End performance (inside only)"), "average"] == -10.0
    assert table.loc[("residual ER", "End performance (inside only)"), "difference_with_sarsa_lambda"] == "+50 %"
    assert ("Sarsa(λ)", "End performance (inside only)") not in table.index


def test_a_diverged_walker_run_falls_on_at_its_last_rate(tmp_path):
    """A walker run that diverged at 200 s after 0, 3, 7 falls goes on at its last interval's 4 falls per 100 s to the
    budget's 500 s (11, 15, 19), at the random policy's distance throughout; a run that left the possible returns but
    walked counts with its own curve."""
    from sb3_er.experiments.summary import load_curves

    walker = EXPERIMENTS["walker"]
    _write_walker_run(tmp_path, "er_sigma", 0, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0], [0, 2, 4, 5, 6, 6])
    _write_walker_run(tmp_path, "er_sigma", 1, [0.0, 1.0, 3.0, 5.0, 7.0, 9.0], [0, 5, 6, 7, 8, 9], out_of_range=12)
    _write_walker_run(tmp_path, "er_sigma", 2, [0.0, 0.4, 0.2], [0, 3, 7], diverged=True)
    curves = load_curves(walker, tmp_path, "er_sigma", range(3), budget=500.0)
    assert curves.seeds == (0,) and curves.out_of_bounds_seeds == (1,) and curves.diverged_seeds == (2,)
    every = curves.all_runs()
    np.testing.assert_array_equal(every.cumulative_falls[2], [0, 3, 7, 11, 15, 19])
    np.testing.assert_array_equal(every.performance[2], walker.random_performance)
    np.testing.assert_array_equal(every.performance[1], [0.0, 1.0, 3.0, 5.0, 7.0, 9.0])
    table = summary_table(walker, {"er_sigma": curves}, budget=500.0).set_index(["algorithm", "metric"])
    assert table.loc[("ER-σ", "Falls"), "average"] == pytest.approx((6 + 9 + 19) / 3)
    assert table.loc[("ER-σ", "Falls (inside only)"), "average"] == 6.0
    assert table.loc[("ER-σ", "End performance"), "average"] == pytest.approx(
        (10.0 + 9.0 + walker.random_performance) / 3
    )


def test_every_run_diverged_counts_to_the_end_of_the_budget(tmp_path):
    """No complete run: the counted curves reach the budget, one evaluation interval apart, and never rise."""
    from sb3_er.experiments.summary import load_curves

    walker = EXPERIMENTS["walker"]
    _write_walker_run(tmp_path, "er", 0, [0.0, 0.3], [0, 2], diverged=True)
    curves = load_curves(walker, tmp_path, "er", [0], budget=400.0)
    np.testing.assert_array_equal(curves.all_runs().x, [0.0, 100.0, 200.0, 300.0, 400.0])
    np.testing.assert_array_equal(curves.all_runs().cumulative_falls[0], [0, 2, 4, 6, 8])
    table = summary_table(walker, {"er": curves}, budget=400.0).set_index(["algorithm", "metric"])
    assert table.loc[("vanilla-ER", "Rise time [s]"), "average_text"] == ">400"
    assert table.loc[("vanilla-ER", "End performance"), "average_text"] == "NA"  # no gait: below the success level


def test_runs_that_all_diverged_before_their_first_record_count_to_the_budget(tmp_path):
    """Every run of a row diverged before its first evaluation (header-only CSVs): the row is counted over the whole
    budget at the random policy's score, never rises and has no falls; a walker budget that is not a multiple of the
    evaluation interval ends at the budget, as a finished run's last evaluation does."""
    import pandas as pd

    from sb3_er.experiments.runner import run_csv_path
    from sb3_er.experiments.summary import load_curves

    pendulum, walker = EXPERIMENTS["pendulum"], EXPERIMENTS["walker"]
    for seed in (0, 1):
        _write_run(tmp_path, "sarsa_lambda", seed, [-100.0, -50.0, -20.0], [0, 0, 0])
        path = run_csv_path(tmp_path, "er", seed)
        path.parent.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(columns=["episode", "return", "cumulative_falls", "wall_time_s", "values_out_of_range"]).assign(
            diverged=pd.Series(dtype=bool)
        ).to_csv(path, index=False)
    curves = {algo: load_curves(pendulum, tmp_path, algo, range(2), budget=3) for algo in ("sarsa_lambda", "er")}
    np.testing.assert_array_equal(curves["er"].all_runs().x, [1.0, 2.0, 3.0])
    table = summary_table(pendulum, curves, budget=3).set_index(["algorithm", "metric"])
    assert table.loc[("vanilla-ER", "End performance"), "average"] == pendulum.random_performance
    assert table.loc[("vanilla-ER", "Rise time [episodes]"), "average_text"] == ">3"
    assert math.isnan(table.loc[("vanilla-ER", "Settling time [episodes]"), "average"])
    assert table.loc[("vanilla-ER", "Diverged runs"), "average_text"] == "2 of 2"
    assert table.loc[("vanilla-ER", "Runs whose values left the possible returns"), "average_text"] == "0 of 2"
    assert table.loc[("vanilla-ER", "End performance (inside only)"), "seeds"] == 0
    _write_walker_run(tmp_path, "er_sigma", 0, [0.0], [0], diverged=True)
    walker_curves = load_curves(walker, tmp_path, "er_sigma", [0], budget=450.0)
    np.testing.assert_array_equal(walker_curves.all_runs().x, [0.0, 100.0, 200.0, 300.0, 400.0, 450.0])


def test_without_a_random_score_diverged_runs_are_left_out_and_say_so(tmp_path):
    from sb3_er.experiments.summary import load_curves

    gridworld = EXPERIMENTS["gridworld"]
    assert gridworld.random_performance is None
    frame_dir = tmp_path
    _write_run(frame_dir, "er", 0, [-100.0, -20.0], [0, 0])
    _write_run(frame_dir, "er", 1, [-100.0], [0], diverged=True)
    curves = {"er": load_curves(gridworld, frame_dir, "er", range(2), budget=2)}
    assert curves["er"].all_runs().seeds == (0,)
    table = summary_table(gridworld, curves, budget=2).set_index(["algorithm", "metric"])
    assert table.loc[("vanilla-ER", "Diverged runs"), "average_text"].startswith("1 of 2 (left out: ")
    assert table.loc[("vanilla-ER", "End performance"), "seeds"] == 1


def test_runs_whose_values_left_the_bounds_are_counted_and_averaged_with_their_own_curves(tmp_path):
    """Two Sarsa(lambda) runs, and three ER-sigma runs of which one left the possible returns at its third episode:
    counted, averaged with its own curve, and left out of the "(inside only)" rows only."""
    from sb3_er.experiments.summary import load_curves

    pendulum = EXPERIMENTS["pendulum"]
    for seed in (0, 1):
        _write_run(tmp_path, "sarsa_lambda", seed, [-100.0, -50.0, -10.0, -10.0], [0, 0, 0, 0])
    _write_run(tmp_path, "er_sigma", 0, [-100.0, -20.0, -20.0, -20.0], [0, 0, 0, 0])
    _write_run(tmp_path, "er_sigma", 1, [-100.0, -20.0, -20.0, -20.0], [0, 0, 0, 0])
    _write_run(tmp_path, "er_sigma", 2, [-100.0, -80.0, -90.0, -80.0], [0, 0, 5, 9])
    curves = {algo: load_curves(pendulum, tmp_path, algo, range(3)) for algo in ("sarsa_lambda", "er_sigma")}
    assert curves["er_sigma"].out_of_bounds_seeds == (2,) and curves["er_sigma"].seeds == (0, 1)
    table = summary_table(pendulum, curves, budget=4).set_index(["algorithm", "metric"])
    assert table.loc[("ER-σ", "Runs whose values left the possible returns"), "average_text"] == "1 of 3"
    assert table.loc[("Sarsa(λ)", "Runs whose values left the possible returns"), "average_text"] == "0 of 2"
    assert table.loc[("ER-σ", "End performance"), "average"] == pytest.approx(-40.0)  # (-20-20-80)/3
    assert table.loc[("ER-σ", "End performance (inside only)"), "average"] == -20.0
    assert ("Sarsa(λ)", "End performance (inside only)") not in table.index


def test_runs_before_the_watch_say_not_measured(tmp_path):
    from sb3_er.experiments.summary import load_curves

    pendulum = EXPERIMENTS["pendulum"]
    _write_run(tmp_path, "er", 0, [-100.0, -20.0], None)
    _write_run(tmp_path, "er", 1, [-100.0, -20.0], [0, 0])
    curves = {"er": load_curves(pendulum, tmp_path, "er", range(2))}
    table = summary_table(pendulum, curves, budget=2).set_index(["algorithm", "metric"])
    assert table.loc[("vanilla-ER", "Runs whose values left the possible returns"), "average_text"] == (
        "0 of 2 (1 not measured)"
    )
    _write_run(tmp_path, "er", 1, [-100.0, -20.0], None)
    curves = {"er": load_curves(pendulum, tmp_path, "er", range(2))}
    table = summary_table(pendulum, curves, budget=2).set_index(["algorithm", "metric"])
    assert table.loc[("vanilla-ER", "Runs whose values left the possible returns"), "average_text"] == "not measured"

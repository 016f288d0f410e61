"""The verdict rule of the thesis findings on hand-made seed tables: a clear win, a clear loss, an interval across
zero (issue: each finding judged by one rule)."""

import json
import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sb3_er.experiments.findings import judge, table_findings, thesis_sign, write_findings
from sb3_er.experiments.specs import EXPERIMENTS
from sb3_er.experiments.summary import Curves, format_figure

PENDULUM = EXPERIMENTS["pendulum"]
X = np.arange(1, 11, dtype=float)


def _curves(ends, rise_at):
    """One curve per seed: -1000 until episode `rise_at`, then its end value."""
    rows = np.array([[(-1000.0 if x < rise else end) for x in X] for end, rise in zip(ends, rise_at, strict=True)])
    seeds = tuple(range(len(ends)))
    return Curves(X, rows, np.zeros_like(rows), seeds, (), 1.0, (), ())


def test_printed_signs():
    assert [thesis_sign(t) for t in ("-67 %", "+76 %", ">+25 %", "0 %", "-")] == [-1, 1, 1, 0, None]


def test_signed_figures_in_one_notation():
    shown_with = ((-700, 2800), (2800, 2800), (14_912, 15_031), (-3.4352, 4.7))
    signed = [format_figure(v, s, signed=True) for v, s in shown_with]
    assert signed == ["-700", "+2800", "+14,900", "-3.44"]
    assert [format_figure(v, 33, signed=True, whole=True) for v in (-8, -33, 1)] == ["-8", "-33", "+1"]  # episodes
    assert [format_figure(v) for v in (-49_312.0, 1_234_567.0, 3e12, 512.4, 12.34, 1.234, float("nan"))] == [
        "-49,300",
        "1,230,000",
        "3e+12",
        "512",
        "12.3",
        "1.23",
        "NA",
    ]  # the tables' figures, unsigned


@given(st.floats(-1e8, 1e8), st.floats(0, 1e8))
def test_a_signed_figure_is_its_value_at_the_precision_of_its_scale(value, scale):
    text = format_figure(value, scale, signed=True)
    assert re.fullmatch(r"[+-](\d{1,3}(,\d{3})+|\d+)(\.\d+)?", text), text  # no exponent, one sign
    shown = max(abs(value), scale)
    # the largest figure keeps three significant digits: the rounding error is under half a unit of its third
    step = (
        10.0 ** (math.floor(math.log10(shown)) - 2)
        if shown >= 1e4
        else (1.0 if shown >= 100 else (0.1 if shown >= 10 else 0.01))
    )
    assert abs(float(text.replace(",", "")) - value) <= step / 2 * (1 + 1e-9)


def test_the_rule():
    assert judge(-1, -5.0, -1.0) is True  # the thesis's sign, interval clear of zero
    assert judge(-1, 1.0, 5.0) is False  # the other sign, clear
    assert judge(-1, -1.0, 2.0) is None  # across zero: inconclusive
    assert judge(0, 1.0, 2.0) is False  # the thesis saw no difference, ours is clear
    assert judge(1, float("nan"), float("nan")) is None


def _verdicts(ours):
    reference = _curves([-500.0, -520.0, -480.0, -510.0, -490.0], [6, 6, 6, 6, 6])
    findings = table_findings(PENDULUM, {"sarsa_lambda": reference, "er": ours}, budget=10, n_resamples=400)
    return {f["metric"]: f for f in findings}


def test_a_clear_win_holds():
    """ER rises at episode 2 against 6 and ends at -100 against -500: the thesis's -50 % and +76 % hold."""
    found = _verdicts(_curves([-100.0, -110.0, -90.0, -105.0, -95.0], [2, 2, 2, 2, 2]))
    assert found["rise_time"]["holds"] is True and found["end_performance"]["holds"] is True
    assert found["end_performance"]["ci95"][0] > 0 and "bootstrap CI" in found["end_performance"]["evidence"]


def test_a_clear_loss_does_not_hold():
    found = _verdicts(_curves([-900.0, -910.0, -890.0, -905.0, -895.0], [9, 9, 9, 9, 9]))
    assert found["rise_time"]["holds"] is False and found["end_performance"]["holds"] is False


def test_an_interval_across_zero_is_inconclusive():
    found = _verdicts(_curves([-100.0, -900.0, -480.0, -300.0, -700.0], [6, 6, 6, 6, 6]))
    assert found["end_performance"]["holds"] is None
    low, high = found["end_performance"]["ci95"]
    assert low < 0 < high


def test_the_findings_file_is_what_the_docs_read(tmp_path):
    found = list(_verdicts(_curves([-100.0] * 5, [2] * 5)).values())
    path = write_findings(tmp_path, "Table 6.1", found, regime="sigma lowers 12 % of targets")
    data = json.loads(path.read_text())
    assert data["thesis"] == "Table 6.1" and data["sigma_regime"].startswith("sigma lowers")
    assert all(set(f) >= {"claim", "holds", "evidence"} for f in data["findings"])
    assert data["findings"][0]["claim"].startswith("vanilla-ER's")


def test_a_metric_undefined_in_most_resamples_states_no_interval(tmp_path):
    """An algorithm that learns no gait has no end performance: the finding is inconclusive, its evidence says why
    instead of printing a NaN interval, and findings.json stays strict JSON."""
    walker = EXPERIMENTS["walker"]
    x = np.linspace(200.0, 5000.0, 25)
    walking = np.tile(np.linspace(0.0, 40.0, x.size), (5, 1))
    curves = {
        "sarsa_lambda": Curves(x, walking, np.zeros_like(walking), tuple(range(5)), (), 1.0, (), ()),
        "er_sigma": Curves(x, np.zeros_like(walking), np.zeros_like(walking), tuple(range(5)), (), 1.0, (), ()),
    }
    found = {
        f["metric"]: f
        for f in table_findings(walker, curves, budget=5000.0, n_resamples=200)
        if f.get("algorithm") == "er_sigma"
    }
    end = found["end_performance"]
    assert end["holds"] is None and end["ci95"] == [None, None]
    assert "no interval" in end["evidence"] and "200 bootstrap resamples" in end["evidence"]
    path = write_findings(tmp_path, "Table 6.2", list(found.values()))
    json.loads(path.read_text(), parse_constant=lambda name: (_ for _ in ()).throw(ValueError(name)))


def test_a_printed_na_is_judged_as_learning_no_gait():
    """Thesis Table 6.3 prints NA for vanilla ER's end performance on LEO: the finding "learns no gait" holds for
    curves that never reach the success level, does not hold for curves that walk."""
    leo = EXPERIMENTS["leo"]
    x = np.linspace(200.0, 12000.0, 20)
    walking = np.tile(np.linspace(0.0, 6.0, x.size), (5, 1))
    reference = Curves(x, walking, np.zeros_like(walking), tuple(range(5)), (), 1.0, (), ())
    for performance, expected in ((np.full_like(walking, 0.1), True), (walking, False)):
        ours = Curves(x, performance, np.zeros_like(walking), tuple(range(5)), (), 1.0, (), ())
        found = [
            f
            for f in table_findings(leo, {"sarsa_lambda": reference, "er": ours}, budget=12000.0, n_resamples=200)
            if f["metric"] == "no_gait"
        ]
        assert len(found) == 1 and found[0]["holds"] is expected, found
        assert found[0]["claim"].startswith("vanilla-ER learns no gait")


def test_an_algorithm_whose_every_run_left_the_bounds_says_so():
    reference = _curves([-500.0] * 5, [6] * 5)
    empty = Curves(X, np.zeros((0, X.size)), np.zeros((0, X.size)), (), (), 1.0, out_of_bounds_seeds=(0, 1, 2, 3, 4))
    found = table_findings(PENDULUM, {"sarsa_lambda": reference, "residual_er": empty}, budget=10, n_resamples=50)
    residual = [f for f in found if "residual ER's" in f["claim"]]
    assert residual and all(f["holds"] is None for f in residual)
    assert all(
        "no run that stayed inside: 5 left the possible returns and 0 diverged" in f["evidence"] for f in residual
    )


def test_a_side_with_fewer_than_five_averaged_runs_gets_no_verdict():
    # The clear win above, but only one of ER's runs left in (four left the possible returns): one run resamples to
    # itself, so an interval that looks clear would show Sarsa(lambda)'s spread only.
    reference = _curves([-500.0, -520.0, -480.0, -510.0, -490.0], [6, 6, 6, 6, 6])
    for n, verdict in ((1, None), (4, None), (5, True)):
        ours = _curves([-100.0, -110.0, -90.0, -105.0, -95.0][:n], [2] * n)
        ours = Curves(
            ours.x, ours.performance, ours.cumulative_falls, ours.seeds, (), 1.0, out_of_bounds_seeds=tuple(range(n, 5))
        )
        found = {
            f["metric"]: f
            for f in table_findings(PENDULUM, {"sarsa_lambda": reference, "er": ours}, budget=10, n_resamples=400)
        }
        assert found["end_performance"]["holds"] is verdict, n
        if verdict is None:
            evidence = found["end_performance"]["evidence"]
            assert f"vanilla-ER has {n} averaged run" in evidence and f"{5 - n} left the possible returns" in evidence
            assert "bootstrap CI" in evidence  # the interval is still shown, for what it is


# --- every run judged (issue: the thesis's question, answered) ---


def _every_run(inside: Curves, left: np.ndarray, left_falls: np.ndarray, kind: str) -> Curves:
    """`inside`'s runs plus runs that left the possible returns (``kind="left"``) or diverged (``"diverged"``, their
    rows already counted as learning nothing), as :func:`sb3_er.experiments.summary.load_curves` builds them."""
    n = len(inside.seeds)
    extra = tuple(range(n, n + len(left)))
    return Curves(
        inside.x,
        inside.performance,
        inside.cumulative_falls,
        inside.seeds,
        extra if kind == "diverged" else (),
        1.0,
        extra if kind == "left" else (),
        (),
        np.vstack([inside.performance, left]),
        np.vstack([inside.cumulative_falls, left_falls]),
        inside.seeds + extra,
    )


def test_a_finding_changes_verdict_when_the_diverged_runs_come_back():
    """ER's five runs that stayed inside end at -100 against Sarsa(λ)'s -500: the thesis's +76 % holds on them. Its
    five diverged runs count as learning nothing (the random policy's -54,130 throughout): on every run the mean ends
    far below Sarsa(λ)'s, and the finding does not hold; the verdict on the runs that stayed inside is kept beside."""
    pendulum = EXPERIMENTS["pendulum"]
    inside = _curves([-100.0, -110.0, -90.0, -105.0, -95.0], [2] * 5)
    random_runs = np.full((5, X.size), pendulum.random_performance)
    ours = _every_run(inside, random_runs, np.zeros_like(random_runs), "diverged")
    found = _verdicts(ours)["end_performance"]
    assert found["holds"] is False and found["difference"] < -20_000
    assert found["inside_only"]["holds"] is True
    assert "every run counted (vanilla-ER: 5 diverged (counted as learning nothing))" in found["evidence"]
    assert "over 10 and 5 seeds" in found["evidence"]


def test_runs_that_left_the_bounds_but_walked_give_a_verdict_the_runs_inside_cannot():
    """ER-σ on the walker: 2 runs stayed inside and 8 left the possible returns, all falling 30 times against
    Sarsa(λ)'s 60. Inside only, 2 runs are too few for a verdict; on every run the thesis's "fewer falls" holds."""
    walker = EXPERIMENTS["walker"]
    x = np.linspace(0.0, 5000.0, 26)
    distance = np.linspace(0.0, 10.0, x.size)

    def runs(n, final_falls):
        falls = np.array([np.linspace(0.0, f, x.size) for f in final_falls])
        return np.tile(distance, (n, 1)), falls

    performance, falls = runs(5, [58, 59, 60, 61, 62])
    reference = Curves(x, performance, falls, tuple(range(5)), (), 1.0, (), ())
    performance, falls = runs(2, [30, 31])
    inside = Curves(x, performance, falls, (0, 1), (), 1.0, (), ())
    left, left_falls = runs(8, [29, 30, 31, 30, 29, 31, 30, 30])
    ours = _every_run(inside, left, left_falls, "left")
    found = {
        f["metric"]: f
        for f in table_findings(walker, {"sarsa_lambda": reference, "er_sigma": ours}, budget=5000.0, n_resamples=400)
        if f.get("algorithm") == "er_sigma"
    }
    assert found["falls"]["holds"] is True and found["falls"]["difference"] == pytest.approx(30.0 - 60.0, abs=0.5)
    assert found["falls"]["inside_only"]["holds"] is None
    assert "ER-σ has 2 averaged runs" in found["falls"]["inside_only"]["evidence"]
    assert "8 left the possible returns (counted with their own curves)" in found["falls"]["evidence"]


def test_without_runs_left_out_there_is_no_second_verdict():
    found = _verdicts(_curves([-100.0, -110.0, -90.0, -105.0, -95.0], [2] * 5))
    assert all("inside_only" not in f for f in found.values())


def test_a_row_of_diverged_runs_never_rises_in_any_resample():
    """Six runs that learned and six that diverged (each the random policy's score throughout): a resample of diverged
    runs only has a flat mean curve, which has no rise (not a rise at its first point), so ER's "faster rise" cannot
    hold on them."""
    pendulum = EXPERIMENTS["pendulum"]
    random_runs = np.full((6, X.size), pendulum.random_performance)
    empty = Curves(X, np.zeros((0, X.size)), np.zeros((0, X.size)), (), tuple(range(6)), 1.0)
    ours = _every_run(empty, random_runs, np.zeros_like(random_runs), "diverged")
    found = _verdicts(ours)
    assert found["rise_time"]["holds"] is not True and found["rise_time"]["difference"] > 0
    assert found["end_performance"]["holds"] is False


def test_the_evidence_on_all_runs_counts_the_runs_that_diverged():
    """Three runs judged, one of them diverged and counted: the all-runs message names it, not "0 diverged"."""
    pendulum = EXPERIMENTS["pendulum"]
    inside = _curves([-100.0, -110.0], [2, 2])
    random_run = np.full((1, X.size), pendulum.random_performance)
    found = _verdicts(_every_run(inside, random_run, np.zeros_like(random_run), "diverged"))["end_performance"]
    assert (
        found["holds"] is None
        and "vanilla-ER has 3 averaged runs (0 left the possible returns, 1 diverged)" in (found["evidence"])
    )

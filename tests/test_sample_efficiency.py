"""benchmarks/sample_efficiency.py: the summary's arithmetic and the goal's checks on hand-made run records, the task
table's figures recomputed from the committed results they cite, and (slow) one tiny run end to end.

Speed and sample-efficiency targets are measured by the benchmark, never asserted here.
"""

import csv
import importlib.util
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "sample_efficiency.py"
MEASURED = ROOT / "results" / "measured"


def load_benchmark():
    spec = importlib.util.spec_from_file_location("sample_efficiency_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


se = load_benchmark()
CARTPOLE, WALKER = "CartPole-v1", "sb3_er/SimplestWalker-v0"


def run(task=CARTPOLE, method="sarsa_lambda", seed=0, samples=None, final=100.0, diverged=False, **extra):
    """A hand-made run record with the fields the summary reads."""
    spec = se.TASKS[task]
    record = {
        "task": task,
        "method": method,
        "seed": seed,
        "budget": spec.budget,
        "eval_interval": spec.eval_interval,
        "eval_episodes": spec.eval_episodes,
        "final_episodes": spec.final_episodes,
        "algorithm": se.METHODS[method][0],
        "kwargs": {},
        "samples_to_target": samples,
        "final_mean": None if diverged else final,
        "diverged": diverged,
        "diverged_at_step": 1234 if diverged else None,
        "largest_excursion": 0.0,
        "values_out_of_range": 0,
        "learn_cpu_s": 2.0,
        "steps": 100_000,
        "curve": [],
    }
    record.update(extra)
    return record


# --- the median with infinite seeds and the confidence interval ---


def test_median_counts_a_seed_that_never_reaches_the_target_as_infinite():
    assert se.median_with_infinity([10, 30, 20]) == 20
    assert se.median_with_infinity([10, None, 20]) == 20  # one of three never: the middle one is still finite
    assert se.median_with_infinity([10, None, None]) == math.inf  # two of three never
    assert se.median_with_infinity([10, 20, 30, None]) == 25  # even: the middle two averaged
    assert se.median_with_infinity([10, 20, None, None]) == math.inf  # half never: the middle pair holds infinity
    with pytest.raises(ValueError, match="no seeds"):
        se.median_with_infinity([])


@given(st.lists(st.one_of(st.none(), st.integers(1, 10**6)), min_size=1, max_size=21))
@settings(max_examples=200, deadline=None)
def test_the_median_is_infinite_exactly_when_half_the_seeds_or_more_never_reach_it(samples):
    n, never = len(samples), samples.count(None)
    median = se.median_with_infinity(samples)
    # odd n: the middle element is infinite once more than half never reach; even n: once half do
    assert math.isinf(median) == (2 * never >= n + n % 2)
    if not math.isinf(median):
        reached = sorted(value for value in samples if value is not None)
        assert reached[0] <= median <= reached[-1]


def test_the_final_return_interval_is_students_t_at_95_percent():
    mean, half_width = se.mean_ci([1.0, 2.0, 3.0])
    # sd 1, standard error 1/sqrt(3), t(0.975, 2 degrees of freedom) = 4.303 (any t table)
    assert mean == 2.0 and half_width == pytest.approx(4.303 / math.sqrt(3), rel=1e-3)
    assert se.mean_ci([5.0]) == (5.0, None)  # one run: no interval
    assert se.mean_ci([]) == (None, None)


def test_first_reaching_smoothed_needs_a_full_window():
    returns = [-10, 0, -10, 0, 0, 0]
    assert se.first_reaching_smoothed(returns, -1.0, 3) == 6  # mean of episodes 3-5 is -3.3; of 4-6 is 0
    assert se.first_reaching_smoothed(returns, -4.0, 3) == 4  # episodes 2-4: -3.3
    assert se.first_reaching_smoothed([0.0], -1.0, 3) is None  # no full window
    assert se.first_reaching_smoothed(returns, 1.0, 1) is None


# --- the summary of one method on one task ---


def test_summary_of_hand_made_runs():
    runs = [
        run(seed=0, samples=20_000, final=400.0, largest_excursion=0.5, values_out_of_range=3, learn_cpu_s=1.0),
        run(seed=1, samples=None, final=500.0, largest_excursion=2.0, learn_cpu_s=3.0),
        run(seed=2, samples=10_000, diverged=True, largest_excursion=1e6, values_out_of_range=9, learn_cpu_s=2.0),
    ]
    figures = se.summarize_runs(se.TASKS[CARTPOLE], runs)
    assert figures["samples_to_target"] == 20_000 and not figures["samples_to_target_infinite"]
    assert figures["reached"] == 2 and figures["runs"] == 3
    # the diverged run has no final return: mean and CI over the other two, 450 ± t(0.975, 1) * 50 = 450 ± 635.3
    assert figures["final_mean"] == 450.0 and figures["final_runs"] == 2
    assert figures["final_ci95"] == pytest.approx(12.706 * 50.0, rel=1e-3)
    assert figures["diverged"] == 1 and figures["diverged_runs"] == [{"seed": 2, "step": 1234}]
    assert figures["largest_excursion_max"] == 1e6 and figures["largest_excursion_median"] == 2.0
    assert figures["runs_outside_returns"] == 2 and figures["values_out_of_range_max"] == 9
    assert figures["learn_cpu_s_median"] == 2.0 and figures["learn_cpu_s_total"] == 6.0
    assert figures["cpu_s_per_1000_steps"] == pytest.approx(6.0 / 300.0)


def test_summary_without_excursions_says_so_and_a_peer_has_no_value_watch():
    sarsa = [run(seed=seed, samples=1000, largest_excursion=None) for seed in range(2)]
    dqn = [run(method="dqn", seed=0, samples=1000, largest_excursion=None, values_out_of_range=None)]
    summary = se.summarize(sarsa + dqn)
    assert summary[CARTPOLE]["sarsa_lambda"]["largest_excursion_max"] is None
    assert se.excursion_text(summary[CARTPOLE]["sarsa_lambda"]) == "not recorded"
    assert se.excursion_text(summary[CARTPOLE]["dqn"]) == "no value watch"


def test_a_peer_without_settings_for_a_task_says_no_peer_settings():
    summary = se.summarize([run(method="dqn"), run(task="Pendulum-v1")])
    assert summary["Pendulum-v1"]["dqn"] == {"applies": False, "note": se.NO_PEER_SETTINGS}
    assert summary[CARTPOLE]["dqn"]["applies"] is True
    assert "| no peer settings |" in se.markdown_summary(summary, se.goal(summary, "er_sigma"), "Code: -", [])


def test_runs_of_one_pair_with_other_settings_are_not_summarized_together():
    runs = [run(seed=0), run(seed=1, eval_interval=999)]
    with pytest.raises(se.RunsFileError, match="mix"):
        se.summarize(runs)


# --- the goal's checks, passing and failing ---

ALL_TASKS = list(se.TASKS)


def suite(ours_samples, sarsa_samples=None, seeds=3, **ours_extra):
    """Sarsa(lambda) and ER-sigma on every task, 3 seeds each (or `seeds`), with the given samples to the target per
    task."""
    runs = []
    for env_id in ALL_TASKS:
        reference = (sarsa_samples or {}).get(env_id, 10_000)
        for seed in range(seeds):
            runs.append(run(env_id, "sarsa_lambda", seed, samples=reference, final=100.0 + seed))
            runs.append(
                run(env_id, "er_sigma", seed, samples=ours_samples.get(env_id, reference), final=101.0, **ours_extra)
            )
    return runs


def test_samples_check_passes_with_half_on_six_tasks_and_fails_with_five():
    half = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    summary = se.summarize(suite(half))
    check = se.check_samples(summary, "er_sigma")
    assert check["holds"] is True and check["tasks_at_half"] == 6
    five = {env_id: 5_000 for env_id in ALL_TASKS[:5]}
    check = se.check_samples(se.summarize(suite(five)), "er_sigma")
    assert check["holds"] is False and check["tasks_at_half"] == 5


def test_samples_check_fails_beyond_sarsas_median_plus_one_interval():
    ours = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    ours[ALL_TASKS[6]] = 10_000 + se.TASKS[ALL_TASKS[6]].eval_interval  # exactly at the limit: allowed
    assert se.check_samples(se.summarize(suite(ours)), "er_sigma")["holds"] is True
    ours[ALL_TASKS[6]] += 1
    check = se.check_samples(se.summarize(suite(ours)), "er_sigma")
    assert check["holds"] is False and check["tasks_over_limit"] == [ALL_TASKS[6]]
    # never reaching a target that Sarsa(lambda) reaches is over the limit too
    ours = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    ours[CARTPOLE] = None
    assert se.check_samples(se.summarize(suite(ours)), "er_sigma")["tasks_over_limit"] == [CARTPOLE]


def test_samples_check_reaching_a_target_sarsa_never_reaches_counts_as_half():
    sarsa = {env_id: None for env_id in ALL_TASKS[:6]}
    ours = {env_id: 90_000 for env_id in ALL_TASKS[:6]}
    check = se.check_samples(se.summarize(suite(ours, sarsa)), "er_sigma")
    assert check["holds"] is True and check["tasks"][CARTPOLE]["ratio"] is None


def test_samples_check_is_not_judged_while_tasks_are_missing():
    half = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    runs = [r for r in suite(half) if r["task"] != ALL_TASKS[8]]
    check = se.check_samples(se.summarize(runs), "er_sigma")
    assert check["holds"] is None  # 6 of 8 measured at half, but the ninth could still be over the limit


def test_stability_check():
    summary = se.summarize(suite({}))
    assert se.check_stability(summary, "er_sigma")["holds"] is True  # no excursion on either side
    diverged = suite({})
    diverged[1]["diverged"], diverged[1]["final_mean"] = True, None
    check = se.check_stability(se.summarize(diverged), "er_sigma")
    assert check["holds"] is False and check["tasks"][ALL_TASKS[0]]["diverged"] == 1
    flagged = {"values_out_of_range": 4, "first_value_excursion": {"margin": 0.05}}
    larger = suite({}, largest_excursion=0.15, **flagged)  # Sarsa(lambda)'s is 0.0
    check = se.check_stability(se.summarize(larger), "er_sigma")
    assert check["holds"] is False and check["tasks"][CARTPOLE]["largest_excursion"] == 0.15
    assert check["tasks"][CARTPOLE]["excursion_beyond_margin"] == pytest.approx(0.10)
    # rounding: a sum of 16 projected weights 4.5e-13 above V_max, which the watch did not count (inside the margin)
    rounding = suite({}, largest_excursion=4.547e-13)
    check = se.check_stability(se.summarize(rounding), "er_sigma")
    assert check["holds"] is True and check["tasks"][CARTPOLE]["largest_excursion"] == 4.547e-13
    unrecorded = suite({}, largest_excursion=None)
    assert se.check_stability(se.summarize(unrecorded), "er_sigma")["holds"] is None


def test_excursion_beyond_the_margin_from_a_runs_record():
    assert se.excursion_beyond_margin(run(largest_excursion=None)) is None  # not recorded
    assert se.excursion_beyond_margin(run(largest_excursion=0.04)) == 0.0  # the watch counted nothing beyond it
    flagged = run(largest_excursion=2.0, values_out_of_range=7, first_value_excursion={"margin": 0.05})
    assert se.excursion_beyond_margin(flagged) == pytest.approx(1.95)
    # no bounds (the watch's count is -1), or no first flag recorded: the excursion as recorded, no margin known
    assert se.excursion_beyond_margin(run(largest_excursion=3.0, values_out_of_range=-1)) == 3.0
    assert se.excursion_beyond_margin(run(largest_excursion=3.0, values_out_of_range=2)) == 3.0
    margin_unknown = run(largest_excursion=3.0, values_out_of_range=2, first_value_excursion={"margin": None})
    assert se.excursion_beyond_margin(margin_unknown) == 3.0
    assert se.excursion_beyond_margin(run(largest_excursion=math.nan, values_out_of_range=5)) == math.inf
    # Sarsa(lambda) 12.5 beyond the bounds with a margin of 0.05 against ours inside it: ours holds
    sarsa = run(largest_excursion=12.5, values_out_of_range=30, first_value_excursion={"margin": 0.05})
    figures = se.summarize_runs(se.TASKS[CARTPOLE], [sarsa])
    assert figures["excursion_beyond_margin_max"] == pytest.approx(12.45) and figures["largest_excursion_max"] == 12.5


def test_final_return_check_at_the_lower_end_of_sarsas_interval():
    # Sarsa(lambda)'s finals 100, 101, 102: mean 101, sd 1, half-width t(0.975, 2) / sqrt(3) = 2.484
    low = 101.0 - 4.303 / math.sqrt(3)
    runs = suite({})
    for record in runs:
        if record["method"] == "er_sigma":
            record["final_mean"] = low + 0.01
    assert se.check_final_return(se.summarize(runs), "er_sigma")["holds"] is True
    for record in runs:
        if record["method"] == "er_sigma" and record["task"] == CARTPOLE:
            record["final_mean"] = low - 0.01
    check = se.check_final_return(se.summarize(runs), "er_sigma")
    assert check["holds"] is False and check["tasks"][CARTPOLE]["holds"] is False
    assert check["tasks"][CARTPOLE]["sarsa_lower_end"] == pytest.approx(low, abs=1e-3)


def walker_run(method, seed, distances, falls):
    x = [100.0 * index for index in range(len(distances))]
    return run(
        WALKER,
        method,
        seed,
        samples=None,
        final=distances[-1],
        curve=[[a, b] for a, b in zip(x, distances, strict=True)],
        cumulative_falls=[0] * (len(distances) - 1) + [falls],
    )


def test_walker_check_rise_in_a_third_of_sarsas_time_with_fewer_falls():
    # Sarsa(lambda) rises to 90 % of its end (10 m) at 300 s; ours at 100 s, a third
    sarsa = [walker_run("sarsa_lambda", seed, [0, 0, 0, 10, 10], 50) for seed in range(3)]
    ours = [walker_run("er_sigma", seed, [0, 10, 10, 10, 10], 20) for seed in range(3)]
    check = se.check_walker(se.summarize(sarsa + ours), "er_sigma")
    assert (check["rise_time"], check["sarsa_rise_time"]) == (100.0, 300.0)
    assert check["holds"] is True
    slower = [walker_run("er_sigma", seed, [0, 0, 10, 10, 10], 20) for seed in range(3)]  # 200 s > 300 s / 3
    assert se.check_walker(se.summarize(sarsa + slower), "er_sigma")["holds"] is False
    as_many_falls = [walker_run("er_sigma", seed, [0, 10, 10, 10, 10], 50) for seed in range(3)]
    assert se.check_walker(se.summarize(sarsa + as_many_falls), "er_sigma")["holds"] is False
    assert se.check_walker(se.summarize(sarsa), "er_sigma")["holds"] is None  # not measured


def test_goal_and_the_machine_readable_summary(tmp_path):
    runs = suite({env_id: 5_000 for env_id in ALL_TASKS[:6]}, seeds=se.DEFAULT_SEEDS)
    runs_file = {"format": se.FORMAT, "commands": ["python benchmarks/sample_efficiency.py --jobs 2"], "runs": runs}
    data = se.write_summary(runs_file, tmp_path, goal_method="er_sigma")
    written = json.loads((tmp_path / "summary.json").read_text())
    assert written == json.loads(json.dumps(data))
    assert (
        set(written["tasks"]) == set(se.TASKS) and written["tasks"][CARTPOLE]["er_sigma"]["samples_to_target"] == 5000
    )
    assert written["goal"]["method"] == "er_sigma" and written["goal"]["samples"]["holds"] is True
    assert written["goal"]["stability"]["holds"] is True and written["goal"]["walker"]["holds"] is None
    entry = next(e for e in written["benchmarks"] if "CartPole-v1" in e["task"])
    assert {score["algorithm"] for score in entry["scores"]} == {"sarsa_lambda", "er_sigma"}
    assert [e["env_id"] for e in written["benchmarks"]] == list(se.TASKS)  # the docs match the thesis's tables by it
    text = (tmp_path / "summary.md").read_text()
    assert "python benchmarks/sample_efficiency.py --jobs 2" in text and "| samples | yes |" in text
    assert (tmp_path / se.FIGURE).read_bytes()[:4] == b"\x89PNG"
    assert se.default_goal_method(written["tasks"]) == "er_sigma"


def test_every_methods_goal_checks_side_by_side(tmp_path):
    """Two methods beside Sarsa(lambda): one at half its samples on six tasks, one that leaves the possible returns
    further than Sarsa(lambda) on CartPole-v1 and is over the limit on another task; the overview names each."""
    fast = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    runs = suite(fast)
    for r in suite({ALL_TASKS[7]: 50_000}, largest_excursion=0.0):
        if r["method"] == "er_sigma":
            r = {**r, "method": "er_sigma_truncate"}
            if r["task"] == CARTPOLE:
                r["largest_excursion"], r["values_out_of_range"] = 3.0, 12
                r["first_value_excursion"] = {"margin": 0.05}
            runs.append(r)
    overview = se.goal_overview(se.summarize(runs))
    assert list(overview) == ["er_sigma", "er_sigma_truncate"]
    assert overview["er_sigma"]["holds"] is None  # the walker's rise was not measured in these hand-made runs
    assert overview["er_sigma"]["samples"]["tasks_at_half"] == 6
    truncated = overview["er_sigma_truncate"]
    assert truncated["stability"]["tasks"][CARTPOLE]["holds"] is False
    assert truncated["samples"]["tasks_over_limit"] == [ALL_TASKS[7]] and truncated["holds"] is False
    runs_file = {"format": se.FORMAT, "commands": [], "runs": runs}
    se.write_summary(runs_file, tmp_path, goal_method="er_sigma")
    text = (tmp_path / "summary.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| ER-σ + truncation |"))
    assert f"1 of 9 ({CARTPOLE})" in row and f"0 of 9; 1 ({ALL_TASKS[7]})" in row


# --- resumption ---


def test_finished_runs_are_skipped_and_other_settings_refused(tmp_path):
    path = tmp_path / "runs.json"
    configs = se.plan_runs([CARTPOLE], ["sarsa_lambda"], [0, 1])
    figures = {"samples_to_target": None, "final_mean": 20.0, "diverged": False, "learn_cpu_s": 1.0, "curve": []}
    finished = [{**configs[0], **figures}]
    se.write_runs(path, finished, ["python benchmarks/sample_efficiency.py"])
    assert se.read_runs(path) == finished
    assert se.pending_runs(configs, se.read_runs(path), path) == configs[1:]
    other = se.plan_runs([CARTPOLE], ["sarsa_lambda"], [0, 1], eval_interval=100)
    with pytest.raises(se.RunsFileError, match="eval_interval 2500, now 100"):
        se.pending_runs(other, finished, path)
    smaller = se.plan_runs([CARTPOLE], ["sarsa_lambda"], [0], scale=0.01)
    assert smaller[0]["budget"] == 1000 and se.pending_runs(smaller, finished, path) == smaller


def test_a_damaged_or_foreign_runs_file_is_an_error_naming_it(tmp_path):
    from sb3_er.experiments.files import DamagedFileError

    path = tmp_path / "runs.json"
    path.write_text('{"format": 1, "runs": [')
    with pytest.raises(DamagedFileError, match="runs.json"):
        se.read_runs(path)
    path.write_text("[]")
    with pytest.raises(se.RunsFileError, match="no runs file"):
        se.read_runs(path)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda runs: runs.append(dict(runs[0])), r"runs\[2\] repeats runs\[0\] \(sarsa_lambda on CartPole-v1"),
        (lambda runs: runs[1].pop("final_mean"), r"runs\[1\] lacks \['final_mean'\]"),
        (lambda runs: runs.__setitem__(1, None), r"runs\[1\] is no run record"),
        (lambda runs: runs[0].update(samples_to_target="abc"), r"runs\[0\] has bad values of \['samples_to_target'\]"),
        (lambda runs: runs[0].update(diverged="no"), r"runs\[0\] has bad values of \['diverged'\]"),
        (lambda runs: runs[1].update(task="Foo-v0"), r"runs\[1\] is of an unknown task or method \('Foo-v0'"),
        (lambda runs: runs[1].update(method="foo"), r"runs\[1\] is of an unknown task or method"),
    ],
)
def test_a_run_record_the_summary_cannot_read_is_an_error_naming_it(tmp_path, change, message):
    """A repeated run (it would count as a second seed), a missing or bad figure, an unknown task or method (it would
    be left out of every table): each named by its place in the file, before any summary is written."""
    path = tmp_path / "runs.json"
    runs = [run(seed=0), run(seed=1)]
    change(runs)
    se.write_runs(path, runs, [])
    with pytest.raises(se.RunsFileError, match=message):
        se.read_runs(path)


def test_a_part_of_the_benchmark_is_not_judged_as_the_whole(tmp_path):
    """Fewer seeds than the benchmark's, or a budget scaled down: a check that would hold is not judged, one that fails
    still fails, and the summary says what the runs lack; the full protocol is judged."""
    half = {env_id: 5_000 for env_id in ALL_TASKS[:6]}
    runs_file = {"format": se.FORMAT, "commands": [], "runs": suite(half, seeds=se.DEFAULT_SEEDS)}
    assert se.write_summary(runs_file, tmp_path, "er_sigma")["goal"]["samples"]["holds"] is True
    assert se.protocol_deviations(runs_file["runs"]) == []
    for runs, lack in [
        (suite(half, seeds=2), f"as few as 2 seeds per task and method, of {se.DEFAULT_SEEDS}"),
        (
            [{**r, "budget": r["budget"] * 0.03} for r in suite(half, seeds=se.DEFAULT_SEEDS)],
            "another budget than the task's on " + ", ".join(sorted(ALL_TASKS)),
        ),
    ]:
        data = se.write_summary({**runs_file, "runs": runs}, tmp_path, "er_sigma")
        assert data["goal"]["samples"]["holds"] is None and data["goals"]["er_sigma"]["samples"]["holds"] is None
        assert data["goal"]["partial"] == [lack]
        assert "These runs are a part of the benchmark, not the whole (" + lack in (tmp_path / "summary.md").read_text()
    five = {env_id: 5_000 for env_id in ALL_TASKS[:5]}  # a failure stays one
    data = se.write_summary({**runs_file, "runs": suite(five, seeds=2)}, tmp_path, "er_sigma")
    assert data["goal"]["samples"]["holds"] is False


@pytest.mark.parametrize(
    "arguments",
    [
        ["--seeds", "0"],
        ["--seeds", "-3"],
        ["--first-seed", "-5"],
        ["--jobs", "0"],
        ["--scale", "0"],
        ["--scale", "-1"],
        ["--eval-interval", "0"],
        ["--eval-interval", "-100"],
        ["--eval-episodes", "0"],
        ["--final-episodes", "0"],
    ],
)
def test_a_count_or_scale_out_of_range_is_refused_when_the_command_line_is_read(arguments, capsys):
    with pytest.raises(SystemExit) as exit_info:
        se._parser().parse_args(arguments)
    assert exit_info.value.code == 2 and "must be" in capsys.readouterr().err


def test_smoke_runs_stay_out_of_the_committed_runs_file_and_a_summary_goes_beside_its_runs(tmp_path, capsys):
    with pytest.raises(SystemExit, match="not the benchmark's own protocol"):
        se.main(["--tasks", CARTPOLE, "--methods", "sarsa_lambda", "--seeds", "1", "--scale", "0.01"])
    with pytest.raises(SystemExit, match="no runs file"):
        se.main(["--summarize", "--json", str(tmp_path / "none.json")])
    with pytest.raises(SystemExit, match="summarizes every run of its --json file"):
        se.main(["--summarize", "--methods", "sarsa_lambda"])
    path = tmp_path / "smoke" / "runs.json"
    path.parent.mkdir()
    se.write_runs(path, [run(seed=0), run(method="er_sigma", seed=0)], [])
    assert se.main(["--summarize", "--json", str(path)]) == 0
    assert (path.parent / "summary.md").is_file() and (path.parent / se.FIGURE).is_file()
    text = (path.parent / "summary.md").read_text()
    assert "a part of the benchmark" in capsys.readouterr().out
    # the summary names the command that makes it again, and says why its checks are not judged
    assert f"this summary by `python benchmarks/sample_efficiency.py --summarize --json {path}`" in text
    assert "against Sarsa(λ): not judged (a part of the benchmark)." in text
    elsewhere = tmp_path / "elsewhere"
    assert se.main(["--summarize", "--json", str(path), "--out", str(elsewhere)]) == 0
    assert f"--summarize --json {path} --out {elsewhere}`" in (elsewhere / "summary.md").read_text()


# --- tasks and methods ---


def test_methods_run_only_on_the_tasks_they_apply_to():
    assert all(se.applies("sarsa_lambda", task) and se.applies("er_sigma", task) for task in se.TASKS.values())
    dqn = [env_id for env_id, task in se.TASKS.items() if se.applies("dqn", task)]
    sac = [env_id for env_id, task in se.TASKS.items() if se.applies("sac", task)]
    assert dqn == ["CartPole-v1", "MountainCar-v0", "Acrobot-v1"]
    assert sac == ["Pendulum-v1", "MountainCarContinuous-v0"]
    configs = se.plan_runs(list(se.TASKS), ["dqn", "sac"], [0])
    assert {(c["task"], c["method"]) for c in configs} == {(t, "dqn") for t in dqn} | {(t, "sac") for t in sac}


def test_a_method_whose_class_lacks_an_argument_is_left_out_with_the_reason(monkeypatch):
    monkeypatch.setitem(se.METHODS, "er_sigma_bogus", ("ERSigma", {"no_such_option": 1}))
    assert "ERSigma takes no no_such_option" in se.method_unavailable("er_sigma_bogus")
    assert se.method_unavailable("er_sigma") is None and se.method_unavailable("dqn") is None
    monkeypatch.setattr(se, "DEFAULT_METHODS", ("sarsa_lambda", "er_sigma_bogus"))
    assert se._chosen_methods(None) == (
        ["sarsa_lambda"],
        ["er_sigma_bogus left out: ERSigma takes no no_such_option yet"],
    )
    with pytest.raises(SystemExit, match="er_sigma_bogus cannot run"):
        se._chosen_methods(["er_sigma_bogus"])


def test_the_walker_replays_as_table_6_2_runs_it():
    """The literal ER-sigma row with the task's replay protocol resolves to the zoo's Table 6.2 entry's replay
    settings, and a stable row keeps its preset's stabilizers there."""
    import sb3_er_envs  # noqa: F401  (registers the walker's id)
    from sb3_er import ERSigma

    zoo = yaml.safe_load((ROOT / "zoo_configs" / "er_sigma.yml").read_text())[WALKER]
    literal = ERSigma("TileQ", WALKER, **se.model_kwargs("er_sigma", se.TASKS[WALKER]))
    assert (literal.replay_trigger, literal.replay_unit) == (zoo["replay_trigger"], zoo["replay_unit"])
    assert literal.stabilizers["n_replays"] == zoo["n_replays"]
    assert not any(literal.stabilizers[name] for name in ("truncate_targets", "target_copy", "step_size_bound"))
    stable = ERSigma("TileQ", WALKER, **se.model_kwargs("er_sigma_stable", se.TASKS[WALKER]))
    assert (
        stable.replay_trigger == "segment"
        and stable.stabilizers == ERSigma("TileQ", WALKER, preset="stable").stabilizers
    )  # the task sets when to replay, not the preset's stabilizers or volume
    assert se.model_kwargs("sarsa_lambda", se.TASKS[WALKER]) == {}  # Sarsa(lambda) does not replay
    assert se.model_kwargs("er_sigma", se.TASKS[CARTPOLE]) == {"preset": "thesis"}


# --- the task table's figures, recomputed from the committed results it cites ---


def test_every_evaluation_interval_is_at_most_a_tenth_of_sarsas_median():
    for task in se.TASKS.values():
        assert task.eval_interval <= task.sarsa_samples / 10, task.env_id
        assert task.budget % task.eval_interval == 0 or task.protocol == "episodes", task.env_id


def test_sarsas_samples_on_gymnasiums_tasks_are_the_committed_peers_runs():
    for folder in ("peers", "peers_continuous"):
        for env_id in {r["env"] for r in json.loads((MEASURED / folder / "peers.json").read_text())}:
            runs = [
                r
                for r in json.loads((MEASURED / folder / "peers.json").read_text())
                if r["env"] == env_id and r["method"] == "sarsa_lambda"
            ]
            task = se.TASKS[env_id]
            assert {r["target"] for r in runs} == {task.target}
            assert se.median_with_infinity([r["steps_to_target"] for r in runs]) == task.sarsa_samples, env_id


def dmc_sarsa_runs(name):
    folder = MEASURED / "dmc_targets" / "runs" / name / "sarsa_lambda"
    return [json.loads(path.read_text()) for path in sorted(folder.glob("seed_*.json"))]


@pytest.mark.parametrize("name", ["cartpole-swingup-v0", "pendulum-swingup-v0"])
def test_dm_control_targets_are_90_percent_of_sarsas_median_end(name):
    task = se.TASKS[f"dm_control/{name}"]
    runs = dmc_sarsa_runs(name)
    assert len(runs) == 5
    assert task.target == math.floor(0.9 * statistics.median(r["reached"] for r in runs))
    firsts = [next((p["steps"] for p in r["curve"] if p["mean_return"] >= task.target), None) for r in runs]
    assert se.median_with_infinity(firsts) == task.sarsa_samples
    # the committed curve has a point every 50,000 steps: a tenth of the earliest the median could be
    assert task.eval_interval <= (task.sarsa_samples - runs[0]["every"]) / 10


def csv_curves(folder, column):
    paths = sorted((MEASURED / folder / "runs" / "sarsa_lambda").glob("seed_*.csv"))
    paths = [p for p in paths if p.stem.removeprefix("seed_").isdigit()]
    rows = [list(csv.DictReader(path.open())) for path in paths]
    return [[float(row[column]) for row in table] for table in rows], rows


def test_the_pendulum_target_is_the_level_of_table_6_1s_sarsa_rise_time():
    task = se.TASKS["sb3_er/PendulumSwingup-v0"]
    curves, _ = csv_curves("table_6_1", "return")
    assert len(curves) == 20
    mean = [statistics.fmean(column) for column in zip(*curves, strict=True)]
    level = mean[0] + 0.9 * (max(mean) - mean[0])
    assert task.target == round(level, -3)
    firsts = [se.first_reaching_smoothed(curve, task.target, task.smoothing) for curve in curves]
    assert se.median_with_infinity(firsts) == task.sarsa_samples


def test_the_walker_target_is_90_percent_of_table_6_2s_sarsa_end():
    task = se.TASKS[WALKER]
    distances, rows = csv_curves("table_6_2", "distance")
    assert len(distances) == 20
    mean = [statistics.fmean(column) for column in zip(*distances, strict=True)]
    assert task.target == pytest.approx(0.9 * round(max(mean), 1))
    times = [[float(row["learning_time_s"]) for row in table] for table in rows]
    firsts = [
        next((t for t, d in zip(ts, ds, strict=True) if d >= task.target), None)
        for ts, ds in zip(times, distances, strict=True)
    ]
    assert se.median_with_infinity(firsts) == task.sarsa_samples


# --- end to end ---


@pytest.mark.slow
def test_a_tiny_run_end_to_end_through_the_worker(tmp_path):
    runs, out = tmp_path / "runs.json", tmp_path / "out"
    tiny = ["--tasks", CARTPOLE, WALKER, "--methods", "sarsa_lambda", "er_sigma", "--seeds", "1", "--scale", "0.02"]
    tiny += ["--eval-interval", "1000", "--eval-episodes", "2", "--final-episodes", "2", "--json", str(runs)]
    first = subprocess.run(
        [sys.executable, str(SCRIPT), *tiny], check=False, capture_output=True, text=True, timeout=600
    )
    assert first.returncode == 0, first.stderr[-3000:]
    assert "4 to run" in first.stderr and "| CartPole-v1 (to 450) | ER-σ |" in first.stdout
    assert "warming up: 4 short runs" in first.stderr
    records = {(r["task"], r["method"]): r for r in se.read_runs(runs)}
    cartpole = records[(CARTPOLE, "sarsa_lambda")]
    assert cartpole["budget"] == 2000 and [x for x, _ in cartpole["curve"]] == [1000, 2000]
    assert len(cartpole["final_returns"]) == 2 and cartpole["steps"] == 2000 and cartpole["learn_cpu_s"] > 0
    assert cartpole["code_version"]["sb3_er_version"]
    walker = records[(WALKER, "er_sigma")]
    assert walker["kwargs"] == {"replay_trigger": "segment", "preset": "thesis"} and walker["budget"] == 100
    assert [x for x, _ in walker["curve"]] == [0.0, 100.0] and isinstance(walker["falls"], int)
    again = subprocess.run(
        [sys.executable, str(SCRIPT), *tiny], check=False, capture_output=True, text=True, timeout=600
    )
    assert again.returncode == 0 and "4 of 4 runs already" in again.stderr and "warming up" not in again.stderr
    summarized = subprocess.run(
        [sys.executable, str(SCRIPT), "--summarize", "--json", str(runs), "--out", str(out)],
        check=False,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert summarized.returncode == 0, summarized.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tasks"][WALKER]["er_sigma"]["runs"] == 1 and (out / se.FIGURE).is_file()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGKILL"])
def test_a_worker_ends_with_the_benchmark_killed_alone(tmp_path, signal_name):
    """A signal to the benchmark's process alone (not its group, as Ctrl-C sends) ends its running worker too, so
    that no orphan runs on to print a result nobody reads; the runs file stays what the finished runs made."""
    import os
    import signal

    from processes import alive, tree, wait_for

    runs_file = tmp_path / "runs.json"
    command = [sys.executable, str(SCRIPT), "--tasks", CARTPOLE, "--methods", "sarsa_lambda", "--seeds", "1"]
    command += ["--no-warm-up", "--json", str(runs_file)]
    benchmark = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        workers = wait_for(
            lambda: [pid for pid, line in tree(benchmark.pid).items() if "--worker" in line], "the worker to start"
        )
        os.kill(benchmark.pid, getattr(signal, signal_name))
        benchmark.wait(timeout=30)
        wait_for(lambda: not alive(workers), f"the worker to end after {signal_name} to the benchmark", timeout=10)
    finally:
        benchmark.kill()
        benchmark.wait()
        for pid in alive(locals().get("workers", [])):
            os.kill(pid, signal.SIGKILL)
    assert not runs_file.exists() or json.loads(runs_file.read_text())["runs"] == []


def test_a_second_writer_of_a_runs_file_is_told_the_benchmarks_own_option(tmp_path):
    """The folder lock's refusal names the benchmark's way to write elsewhere (--json), not sb3-er reproduce's
    --out, which the benchmark does not take for its runs."""
    from sb3_er.experiments.files import FolderLock, FolderLockedError

    arguments = ["--tasks", CARTPOLE, "--methods", "sarsa_lambda", "--seeds", "1", "--no-warm-up"]
    with FolderLock(tmp_path), pytest.raises(FolderLockedError) as refusal:
        se.main([*arguments, "--json", str(tmp_path / "runs.json")])
    assert "--json FILE" in str(refusal.value) and "--out" not in str(refusal.value)
    assert not (tmp_path / "runs.json").exists()

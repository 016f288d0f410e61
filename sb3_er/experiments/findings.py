"""The thesis's findings of Tables 6.1-6.3, each judged by one rule, into a machine-readable ``findings.json``.

A finding is the sign of a difference the thesis prints: an algorithm's rise time, end performance or falls against
Sarsa(λ)'s (Tables 6.1-6.3, their "difference" columns). Ours is the same difference, measured on the mean curves of
our seeds with the fixed metrics of thesis 6.1, and its 95 % confidence interval comes from a bootstrap over seeds
(each algorithm's seeds resampled with replacement, the metric recomputed on the resampled mean curve, the 2.5 and
97.5 percentiles of the differences). The rule:

- **holds** when our difference has the thesis's sign and its interval excludes zero;
- **does not hold** when the interval excludes zero with the other sign, or when the thesis prints no difference
  (0 %) and ours is clear;
- **inconclusive** (``holds: null``) when the interval includes zero.

A rise time that the mean curve never reaches counts as the run's end (the thesis prints such rise times as ">");
an algorithm that learns no gait has no end performance, and its difference is then undefined (inconclusive). Where
the thesis prints NA (no gait learned), the finding is "learns no gait", judged on the same bootstrap: it holds when
the resampled mean curve stays below the success level in at least 97.5 % of the resamples, does not hold when it
stays below in at most 2.5 %, and is inconclusive in between.

Every run is judged, as the thesis averaged every run it made. A run whose values left the possible returns still
walked or fell: it counts with its own measured curve. A run whose Q-function diverged counts as a run that learned
nothing: its performance is the random policy's committed score throughout (``Experiment.random_performance``; so its
rise is "> budget" and its end that score), and its falls go on at its last recorded rate to the end of the budget
(:func:`sb3_er.experiments.summary.diverged_run_curves`). Where some run of either side left the possible returns or
diverged, the same rule on the runs that stayed inside is written beside the verdict (``inside_only``), not instead
of it: leaving those runs out flatters the replay learners, since they are the runs that went wrong.

Each side needs at least ``MIN_AVERAGED_RUNS`` averaged runs (5) for a verdict, else the finding is inconclusive:
resampling n runs with replacement gives C(2n - 1, n) distinct resamples, and a side's own 2.5 % tail needs at least
40 of them (C(9, 5) = 126; C(7, 4) = 35 is too few), so with fewer runs the interval would show the other side's
spread only (one run resamples to itself: a "clear" interval over one ER-σ run and 20 Sarsa(λ) runs says nothing
about ER-σ's seeds).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from sb3_er.experiments import files
from sb3_er.experiments.records import counted
from sb3_er.experiments.specs import Experiment
from sb3_er.experiments.summary import Curves, format_figure, summarize, thesis_text
from sb3_er.experiments.thesis import ALGORITHM_LABELS, row_algorithm

REFERENCE = "sarsa_lambda"
METRICS = {"rise_time": "rise time", "end_performance": "end performance", "falls": "falls"}
#: Lower is better for these metrics; higher for end performance.
LOWER_IS_BETTER = {"rise_time": True, "end_performance": False, "falls": True}
N_RESAMPLES = 2000
#: The fewest averaged runs a side of a finding needs for a verdict (module docstring).
MIN_AVERAGED_RUNS = 5


def _too_few(algo: str, curves: Curves, source: Curves | None = None) -> str:
    """Why `algo`'s averaged runs are too few for a verdict ("" when there are enough); `source`: the curves as loaded,
    whose counts of runs that left or diverged the message names (default: `curves`)."""
    n = len(curves.seeds)
    if n >= MIN_AVERAGED_RUNS:
        return ""
    source = curves if source is None else source
    left, diverged = len(source.out_of_bounds_seeds), len(source.diverged_seeds)
    return (
        f"{ALGORITHM_LABELS.get(algo, algo)} has {counted(n, 'averaged run')} "
        f"({left} left the possible returns, {diverged} diverged), fewer than the {MIN_AVERAGED_RUNS} a bootstrap "
        "verdict needs"
    )


def thesis_sign(text: str) -> int | None:
    """The sign of a printed difference ("-67 %" -> -1, ">+25 %" -> +1, "0 %" -> 0); None for "-" (no figure).

    :param text: the thesis table's printed difference.
    """
    match = re.search(r"([+-]?)(\d+(?:\.\d+)?)\s*%", text)
    if match is None:
        return None
    if float(match.group(2)) == 0.0:
        return 0
    return -1 if match.group(1) == "-" else 1


def metric_value(experiment: Experiment, curves: Curves, metric: str, run_end: float) -> float:
    """One metric of the mean curve of `curves` (rise time beyond the run: the run's end).

    :param experiment: the experiment (its metrics and thesis table).
    :param curves: one algorithm's learning curves (rows: seeds).
    :param metric: the metric, a field of the curves' summary (e.g. "rise_time").
    :param run_end: the run's length, the rise time of a curve that never rises.
    """
    summary = summarize(experiment, curves)
    if summary is None:
        return math.nan
    value = getattr(summary, metric)
    if metric == "rise_time" and value is not None and math.isnan(value):
        return run_end
    return math.nan if value is None else float(value)


def _resampled(curves: Curves, rows: np.ndarray) -> Curves:
    return Curves(
        curves.x,
        curves.performance[rows],
        curves.cumulative_falls[rows],
        tuple(curves.seeds[i] for i in rows),
        (),
        0.0,
        (),
        (),
        None,
        None,
    )


def bootstrap_difference(
    experiment: Experiment,
    ours: Curves,
    reference: Curves,
    metric: str,
    run_end: float,
    rng: np.random.Generator,
    n_resamples: int = N_RESAMPLES,
) -> tuple[float, float, float, int]:
    """(difference ours - reference on all seeds, its 2.5 and 97.5 bootstrap percentiles, the number of resamples in
    which the metric is undefined).

    The percentiles are NaN when the metric is undefined (an algorithm learns no gait on the resampled mean curve) in
    more than 5 % of the resamples: no interval is then stated, and the finding is inconclusive.

    :param experiment: the table's experiment (its metrics and units).
    :param ours: the curves of the algorithm judged.
    :param reference: Sarsa(λ)'s curves.
    :param metric: "rise_time", "end_performance" or "falls".
    :param run_end: the run's end in the table's rise-time unit (a rise time never reached counts as it).
    :param rng: the generator of the resamples.
    :param n_resamples: the number of bootstrap resamples (default :data:`N_RESAMPLES`).
    """
    difference = metric_value(experiment, ours, metric, run_end) - metric_value(experiment, reference, metric, run_end)
    samples = np.empty(n_resamples)
    for i in range(n_resamples):
        a = rng.integers(0, len(ours.seeds), len(ours.seeds))
        b = rng.integers(0, len(reference.seeds), len(reference.seeds))
        samples[i] = metric_value(experiment, _resampled(ours, a), metric, run_end) - metric_value(
            experiment, _resampled(reference, b), metric, run_end
        )
    undefined = int(np.count_nonzero(~np.isfinite(samples)))
    samples = samples[np.isfinite(samples)]
    if samples.size < 0.95 * n_resamples:  # the metric is undefined in too many resamples (no gait learned)
        return difference, math.nan, math.nan, undefined
    low, high = np.percentile(samples, [2.5, 97.5])
    return difference, float(low), float(high), undefined


def judge(sign: int, low: float, high: float) -> bool | None:
    """The rule of the module docstring: True (holds), False (does not hold) or None (inconclusive).

    :param sign: the sign of the thesis's difference (-1, 0 or +1).
    :param low: the 2.5 percentile of our difference.
    :param high: its 97.5 percentile.
    """
    if math.isnan(low) or math.isnan(high) or low <= 0.0 <= high:
        return None
    ours = 1 if low > 0.0 else -1
    return sign != 0 and ours == sign


def _claim(algo: str, metric: str, sign: int, thesis_entry, reference_entry) -> str:
    label, reference = ALGORITHM_LABELS.get(algo, algo), ALGORITHM_LABELS[REFERENCE]
    words = {-1: "lower", 0: "the same", 1: "higher"}[sign]
    better = "" if sign == 0 else (" (better)" if (sign < 0) == LOWER_IS_BETTER[metric] else " (worse)")
    base = row_algorithm(algo)[0]
    whose = "" if base == algo else f" for {ALGORITHM_LABELS[base]}"  # a stable row: the claim of its algorithm
    figures = f"{thesis_text(thesis_entry[0])} against {thesis_text(reference_entry[0])}, {thesis_entry[1]}"
    printed = f"thesis{whose}: {figures}"
    verb = "are" if metric == "falls" else "is"
    than = "as" if sign == 0 else "than"
    return f"{label}'s {METRICS[metric]} {verb} {words}{better} {than} {reference}'s ({printed})"


def no_gait_finding(
    experiment: Experiment, algo: str, ours: Curves | None, rng: np.random.Generator, n_resamples: int = N_RESAMPLES
) -> dict[str, Any]:
    """The finding "`algo` learns no gait" (the thesis prints NA as its end performance), judged on the share of
    bootstrap resamples of our seeds whose mean curve never reaches the success level (module docstring).

    :param experiment: the walking experiment (its success level).
    :param algo: the algorithm judged.
    :param ours: its curves (None or no seeds: inconclusive).
    :param rng: the generator of the resamples.
    :param n_resamples: the number of bootstrap resamples.
    """
    base = row_algorithm(algo)[0]
    whose = "its" if base == algo else f"{ALGORITHM_LABELS[base]}'s"
    claim = f"{ALGORITHM_LABELS.get(algo, algo)} learns no gait (thesis: NA as {whose} end performance)"
    entry = {"claim": claim, "algorithm": algo, "metric": "no_gait", "thesis_sign": None}
    if ours is None or not ours.seeds:
        return {**entry, "holds": None, "evidence": "no complete run"}
    too_few = _too_few(algo, ours)
    if too_few:
        return {**entry, "holds": None, "evidence": too_few}

    def no_gait(curves: Curves) -> bool:
        return math.isnan(metric_value(experiment, curves, "end_performance", math.nan))

    share = float(
        np.mean(
            [no_gait(_resampled(ours, rng.integers(0, len(ours.seeds), len(ours.seeds)))) for _ in range(n_resamples)]
        )
    )
    holds = True if share >= 0.975 else (False if share <= 0.025 else None)
    best = float(np.max(np.mean(ours.performance, axis=0)))
    evidence = (
        f"our mean curve's best {best:.3g} against the success level {experiment.success_threshold:g}; no "
        f"gait in {share:.1%} of {n_resamples} bootstrap resamples over {counted(len(ours.seeds), 'seed')}"
    )
    return {**entry, "holds": holds, "evidence": evidence, "no_gait_share": share}


def _nothing_averaged(algo: str, curves: Curves | None) -> str:
    """Why `algo` has no run to average ("" when it has one): no complete run, or every one left out."""
    if curves is not None and curves.seeds:
        return ""
    label = ALGORITHM_LABELS.get(algo, algo)
    left = len(curves.out_of_bounds_seeds) if curves is not None else 0
    diverged = len(curves.diverged_seeds) if curves is not None else 0
    if not left and not diverged:
        return f"{label} has no complete run. "
    return f"{label} has no run that stayed inside: {left} left the possible returns and {diverged} diverged. "


def _finite(value: float) -> float | None:
    """`value`, or None for NaN (findings.json is strict JSON: no NaN)."""
    return None if math.isnan(value) else float(value)


def _judged(
    experiment: Experiment,
    algo: str,
    metric: str,
    claim: str,
    ours: Curves | None,
    reference: Curves | None,
    run_end: float,
    rng: np.random.Generator,
    n_resamples: int,
    sources: tuple[Curves | None, Curves | None] = (None, None),
) -> dict[str, Any]:
    """One finding on the rows of `ours` and `reference` (module docstring's rule); `sources`: their curves as loaded,
    whose counts the evidence names (default: the curves judged)."""
    sign = thesis_sign(str(experiment.thesis_table[row_algorithm(algo)[0]][metric][1]))
    if reference is None or not reference.seeds or ours is None or not ours.seeds:
        evidence = (_nothing_averaged(algo, ours) + _nothing_averaged(REFERENCE, reference)).strip()
        return {"claim": claim, "holds": None, "evidence": evidence}
    difference, low, high, undefined = bootstrap_difference(
        experiment, ours, reference, metric, run_end, rng, n_resamples
    )
    unit = f" {experiment.rise_time_unit}" if metric == "rise_time" else ""
    if unit == " episodes" and abs(difference) == 1:
        unit = " episode"
    shown = [value for value in (difference, low, high) if not math.isnan(value)]
    scale, whole = max(map(abs, shown), default=0.0), all(float(value).is_integer() for value in shown)
    seeds = (
        f"over {len(ours.seeds)} and {counted(len(reference.seeds), 'seed')}"
        if len(ours.seeds) != 1 or len(reference.seeds) != 1
        else "over 1 seed each"
    )
    if math.isnan(low):
        interval = (
            f"no interval: the metric is undefined (no gait on the mean curve) in {undefined} of "
            f"{n_resamples} bootstrap resamples {seeds}"
        )
    else:
        ends = ", ".join(format_figure(end, scale, signed=True, whole=whole) for end in (low, high))
        interval = f"95 % bootstrap CI [{ends}] {seeds}"
    ours_text = (
        "undefined (no gait on the mean curve of all seeds)"
        if math.isnan(difference)
        else (f"{format_figure(difference, scale, signed=True, whole=whole)}{unit}")
    )
    evidence = f"ours {ours_text}, {interval}"
    too_few = "; ".join(
        reason for reason in (_too_few(algo, ours, sources[0]), _too_few(REFERENCE, reference, sources[1])) if reason
    )
    if too_few:
        evidence = f"{too_few} ({evidence})"
    return {
        "claim": claim,
        "holds": None if too_few else judge(sign, low, high),
        "evidence": evidence,
        "algorithm": algo,
        "metric": metric,
        "thesis_sign": sign,
        "difference": _finite(difference),
        "ci95": [_finite(low), _finite(high)],
    }


def _counted_runs(algo: str, curves: Curves | None) -> str:
    """How the runs that did not stay inside are counted in `algo`'s verdict on all runs ("" when every run stayed
    inside)."""
    if curves is None:
        return ""
    left, diverged = len(curves.out_of_bounds_seeds), len(curves.diverged_seeds)
    uncounted = len(curves.all_runs().diverged_seeds)
    parts = []
    if left:
        parts.append(f"{left} left the possible returns (counted with their own curves)")
    if diverged - uncounted:
        parts.append(f"{diverged - uncounted} diverged (counted as learning nothing)")
    if uncounted:
        parts.append(f"{uncounted} diverged (left out: no random policy's score)")
    return f"{ALGORITHM_LABELS.get(algo, algo)}: " + ", ".join(parts) if parts else ""


def _on_all_runs(curves: Curves | None) -> Curves | None:
    return None if curves is None else curves.all_runs()


def _with_inside_only(finding: dict[str, Any], inside: dict[str, Any], left_out: str) -> dict[str, Any]:
    """`finding` (judged on all runs) with the runs' counts in its evidence and the verdict on the runs that stayed
    inside beside it, when some run did not stay inside."""
    if not left_out:
        return finding
    kept = {key: inside[key] for key in ("holds", "evidence", "difference", "ci95", "no_gait_share") if key in inside}
    return {**finding, "evidence": f"{finding['evidence']}; every run counted ({left_out})", "inside_only": kept}


def table_findings(
    experiment: Experiment, curves: dict[str, Curves], budget: float, seed: int = 0, n_resamples: int = N_RESAMPLES
) -> list[dict[str, Any]]:
    """Every printed difference of the experiment's thesis table, judged on all of our runs, with the verdict on the
    runs that stayed inside the possible returns beside it (module docstring).

    :param experiment: the experiment (its metrics and thesis table).
    :param curves: the algorithms' learning curves by algorithm (rows: seeds).
    :param budget: the runs' length.
    :param seed: the seed of the bootstrap (default 0).
    :param n_resamples: bootstrap resamples (default 2000).
    """
    rng, inside_rng = np.random.default_rng(seed), np.random.default_rng([seed, 1])
    run_end = budget / experiment.rise_time_scale if experiment.protocol == "walking" else budget  # table units
    reference = curves.get(REFERENCE)
    table = experiment.thesis_table
    findings = []
    ordered = [algo for algo in ALGORITHM_LABELS if algo in curves] + [a for a in curves if a not in ALGORITHM_LABELS]
    for algo in (algo for algo in ordered if algo != REFERENCE and row_algorithm(algo)[0] in table):
        entries = table[row_algorithm(algo)[0]]  # a stable row is judged on the claims of its algorithm
        ours = curves[algo]
        left_out = "; ".join(text for text in (_counted_runs(algo, ours), _counted_runs(REFERENCE, reference)) if text)
        for metric, entry in entries.items():
            if metric == "end_performance" and entry[0] is None and experiment.success_threshold is not None:
                everything = no_gait_finding(experiment, algo, _on_all_runs(ours), rng, n_resamples)
                inside = no_gait_finding(experiment, algo, ours, inside_rng, n_resamples) if left_out else {}
                findings.append(_with_inside_only(everything, inside, left_out))
                continue
            sign = thesis_sign(str(entry[1]))
            if metric not in METRICS or sign is None:
                continue
            claim = _claim(algo, metric, sign, entry, table[REFERENCE][metric])
            everything = _judged(
                experiment,
                algo,
                metric,
                claim,
                _on_all_runs(ours),
                _on_all_runs(reference),
                run_end,
                rng,
                n_resamples,
                sources=(ours, reference),
            )
            inside = (
                _judged(experiment, algo, metric, claim, ours, reference, run_end, inside_rng, n_resamples)
                if left_out
                else {}
            )
            findings.append(_with_inside_only(everything, inside, left_out))
    return findings


def write_findings(out_dir: Path, thesis: str, findings: list[dict[str, Any]], regime: str = "") -> Path:
    """``<out_dir>/findings.json`` (the format the docs' verdict table reads), written atomically.

    :param out_dir: the results folder.
    :param thesis: what the folder reproduces, e.g. "Table 6.2".
    :param findings: the findings (``claim``, ``holds``, ``evidence``).
    :param regime: the reading's name, added to the file when given (default "").
    """
    data = {
        "thesis": thesis,
        "rule": "holds: our difference with Sarsa(λ) has the thesis's sign and its 95 % "
        "bootstrap CI over seeds excludes zero; does not hold (false) when the CI excludes zero with the other "
        "sign; inconclusive (null) when the CI includes zero or a side has fewer than "
        f"{MIN_AVERAGED_RUNS} averaged runs; where the thesis prints NA, 'learns no gait' holds when at least 97.5 % "
        "of the bootstrap resamples learn no gait. Every run is judged: a run whose values left the possible returns "
        "with its own curve, a diverged run as one that learned nothing (the random policy's score throughout, its "
        "falls going on at its last rate to the end of the budget); 'inside_only' gives the same rule on the runs "
        "that stayed inside, where some did not",
        "findings": findings,
    }
    if regime:
        data["sigma_regime"] = regime
    return files.write_json(Path(out_dir) / "findings.json", data)

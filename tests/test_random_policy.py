"""The random policy's score on the thesis's tasks (what a run that learned nothing is worth): measured with each
table's own metric, seeded, and the experiments' specs carry the committed means."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import sb3_er_envs  # noqa: F401  (registers the thesis's env ids)
from sb3_er.experiments.random_policy import random_policy_scores
from sb3_er.experiments.specs import EXPERIMENTS

SCORES = Path(__file__).resolve().parent.parent / "results" / "measured" / "random_policy" / "scores.json"


def test_the_pendulums_random_returns_are_sums_of_its_costs():
    """Every reward of the swing-up is a cost (<= 0), so an episode's return is at most 0; the same seed gives the
    same episodes, another seed others."""
    scores = random_policy_scores(EXPERIMENTS["pendulum"], 5, seed=3)
    assert np.all(scores <= 0.0) and np.all(np.isfinite(scores))
    assert np.array_equal(scores, random_policy_scores(EXPERIMENTS["pendulum"], 5, seed=3))
    assert not np.array_equal(scores, random_policy_scores(EXPERIMENTS["pendulum"], 5, seed=4))


def test_the_walkers_random_runs_fall_within_a_few_steps():
    """Random torques topple the simplest walker at once: a run ends far short of a learned gait's 10 m."""
    scores = random_policy_scores(EXPERIMENTS["walker"], 20, seed=0)
    assert np.all(np.isfinite(scores)) and scores.max() < EXPERIMENTS["walker"].success_threshold * 5
    assert scores.mean() < EXPERIMENTS["walker"].success_threshold


@pytest.mark.parametrize("n_runs", [0, -1, 2.5, None, True])
def test_a_bad_number_of_runs_is_refused(n_runs):
    with pytest.raises(ValueError, match="n_runs must be an integer of at least 1"):
        random_policy_scores(EXPERIMENTS["walker"], n_runs)


@pytest.mark.parametrize("name", ["pendulum", "walker", "leo"])
def test_the_specs_carry_the_committed_random_scores(name):
    committed = json.loads(SCORES.read_text())["tasks"][name]
    assert committed["runs"] == len(committed["scores"]) and committed["mean"] == pytest.approx(
        np.mean(committed["scores"]), rel=1e-12
    )
    spec = EXPERIMENTS[name].random_performance
    digits = 4 - 1 - math.floor(math.log10(abs(committed["mean"])))
    assert spec == round(committed["mean"], digits)

"""benchmarks/peers.py (issue 12) on a tiny budget: it runs every method side by side and prints its tables.

MushroomRL runs in its own venv, which the benchmark builds on first use (minutes of downloads); the test suite never
builds it: the MushroomRL test runs only where `python benchmarks/peers.py --build-mushroom` has been run.
"""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "peers.py"
TINY = [
    "--envs",
    "CartPole-v1",
    "--seeds",
    "1",
    "--budget",
    "1000",
    "--eval-freq",
    "500",
    "--eval-episodes",
    "1",
    "--final-episodes",
    "2",
    "--no-build",
]


def load_peers():
    spec = importlib.util.spec_from_file_location("peers", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(*methods):
    result = subprocess.run(
        [sys.executable, str(SCRIPT), *TINY, "--methods", *methods],
        check=False,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return result.stdout


def table_rows(out, env_id):
    return [line for line in out.splitlines() if line.startswith(f"| {env_id} |")]


def test_mushroom_tiles_come_closest_to_our_widths_by_hand():
    peers = load_peers()
    # MountainCar: 8 tilings of width 1.8 / 8 = 0.225 over [-1.2, 0.6]; MushroomRL's width is 1.8 / (n - 7/8):
    # n = round(8 + 0.875) = 9 tiles of 1.8 / 8.125 = 0.2215
    n_tiles = peers.mushroom_tiles(8, [0.225, 0.0175], [-1.2, -0.07], [0.6, 0.07])
    assert n_tiles == [9, 9]
    assert peers.mushroom_widths(8, n_tiles, [-1.2, -0.07], [0.6, 0.07]) == pytest.approx([1.8 / 8.125, 0.14 / 8.125])


def test_rl_zoo_dqn_settings_are_read_from_the_installed_package():
    n_timesteps, kwargs = load_peers().rl_zoo_dqn_hyperparameters("CartPole-v1")
    assert n_timesteps == 50_000  # rl-zoo's tuned CartPole-v1 entry
    assert kwargs["policy_kwargs"] == {"net_arch": [256, 256]}
    assert "policy" not in kwargs and "n_timesteps" not in kwargs


@pytest.mark.slow
def test_tiny_benchmark_prints_its_tables():
    out = run("sarsa_lambda", "er_sigma", "dqn")
    rows = table_rows(out, "CartPole-v1")
    for label in ("sb3-er SarsaLambda", "sb3-er ERSigma", "SB3 DQN (rl-zoo tuned)"):
        summary, per_seed = [row for row in rows if f"| {label} |" in row]
        assert "| 1,000 |" in summary  # the budget, for every method
        assert per_seed.split("|")[3].strip() == "0"  # seed 0
    assert "steps to threshold" in out and "peak RSS MB" in out


@pytest.mark.slow
def test_tiny_benchmark_with_mushroom_rl():
    peers = load_peers()
    ready, reason = peers.mushroom_ready(peers.DEFAULT_MUSHROOM_VENV)
    if not ready:
        pytest.skip(f"{reason}; the test suite does not build it")
    rows = table_rows(run("mushroom"), "CartPole-v1")
    assert any("| MushroomRL SARSA(λ) | 1,000 |" in row for row in rows)


@pytest.mark.slow
def test_json_resume_skips_finished_runs_and_tables_cover_them(tmp_path):
    results = tmp_path / "peers.json"
    first = subprocess.run(
        [sys.executable, str(SCRIPT), *TINY, "--methods", "sarsa_lambda", "--json", str(results)],
        check=True,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert "sarsa_lambda seed 0" in first.stderr
    second = subprocess.run(
        [sys.executable, str(SCRIPT), *TINY, "--methods", "sarsa_lambda", "er_sigma", "--json", str(results)],
        check=True,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert "sarsa_lambda seed 0" not in second.stderr  # finished: skipped
    assert "er_sigma seed 0" in second.stderr
    labels = [row.split("|")[2].strip() for row in table_rows(second.stdout, "CartPole-v1")]
    assert labels.count("sb3-er SarsaLambda") == 2 and labels.count("sb3-er ERSigma") == 2  # summary + per-seed rows
    assert [(r["method"], r["seed"]) for r in json.loads(results.read_text())] == [("sarsa_lambda", 0), ("er_sigma", 0)]


def test_rl_zoo_sac_settings_are_read_from_the_installed_package():
    peers = load_peers()
    n_timesteps, kwargs = peers.rl_zoo_hyperparameters("sac", "Pendulum-v1")
    assert n_timesteps == 20_000 and kwargs == {"learning_rate": 1e-3}  # rl-zoo's tuned Pendulum-v1 entry
    n_timesteps, kwargs = peers.rl_zoo_hyperparameters("sac", "MountainCarContinuous-v0")
    assert n_timesteps == 50_000 and kwargs["use_sde"] is True and kwargs["policy_kwargs"]["net_arch"] == [64, 64]


def test_methods_run_only_on_tasks_of_their_kind():
    peers = load_peers()
    assert set(peers.METHOD_ENVS["sac"]) == {"Pendulum-v1", "MountainCarContinuous-v0"}
    assert "Pendulum-v1" not in peers.METHOD_ENVS["dqn"] and "Pendulum-v1" not in peers.METHOD_ENVS["mushroom"]
    assert set(peers.ENVS) <= set(peers.METHOD_ENVS["sarsa_lambda"]) and set(peers.TARGETS) == set(peers.ENVS)


@pytest.mark.slow
def test_tiny_continuous_benchmark_with_sac():
    result = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            "--envs",
            "Pendulum-v1",
            "--seeds",
            "1",
            "--budget",
            "400",
            "--eval-freq",
            "200",
            "--eval-episodes",
            "1",
            "--final-episodes",
            "1",
            "--methods",
            "sarsa_lambda",
            "sac",
            "dqn",
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    rows = table_rows(result.stdout, "Pendulum-v1")
    assert any("| SB3 SAC (rl-zoo tuned) | 400 | no threshold |" in row for row in rows)
    assert any("| sb3-er SarsaLambda | 400 |" in row for row in rows)
    assert not any("DQN" in row for row in rows)  # DQN takes no Box actions

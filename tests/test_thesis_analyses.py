"""The thesis analyses of `sb3-er reproduce` with tiny budgets: replay orders (Appendix A), sigma definitions
(Appendix B) and pessimistic initialisation (Figure 5.5)."""

import hashlib
import json
import os

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import sb3_er_envs  # noqa: F401
from sb3_er import ER, SarsaLambda
from sb3_er.cli import main
from sb3_er.experiments import replay_order
from sb3_er.experiments.gridworld import CASES, PESSIMISTIC, PESSIMISTIC_VALUE, same_data_value_maps
from sb3_er.experiments.pessimistic import figure_variants, reproduce_pessimistic
from sb3_er.experiments.records import read_record
from sb3_er.experiments.replay_order import COLLECTOR_KWARGS, ORDERS, reproduce_replay_order
from sb3_er.experiments.runner import RunJob, artifact_path, run_csv_path
from sb3_er.experiments.sigma_study import DEFINITIONS, reproduce_sigma
from sb3_er.experiments.specs import ANALYSES
from sb3_er.zoo import model_kwargs

PNG = b"\x89PNG"
PENDULUM = "sb3_er/PendulumSwingup-v0"
TINY_REPLAY_ORDER = {
    "n_seeds": 2,
    "budget": 2000,
    "database_episodes": 2,
    "eval_every": 1000,
    "n_workers": 1,
    "show_progress": False,
}


def test_er_with_online_lambda_and_no_replay_learns_exactly_like_sarsa_lambda():
    """The replay-order database collector is Sarsa(lambda): bit-identical weights for a seed, every step stored."""
    collector = ER("TileQ", gym.make(PENDULUM), seed=7, **{**model_kwargs("er", PENDULUM), **COLLECTOR_KWARGS})
    sarsa = SarsaLambda("TileQ", gym.make(PENDULUM), seed=7, **model_kwargs("sarsa_lambda", PENDULUM))
    for name in ("learning_rate", "gamma", "exploration_rate", "trace_cutoff"):
        assert getattr(collector, name) == getattr(sarsa, name)
    assert collector.online_lambda == sarsa.trace_lambda == 0.92
    collector.learn(3200)  # two whole 15 s episodes and a part of a third
    sarsa.learn(3200)
    assert collector.policy.theta_array.any()
    np.testing.assert_array_equal(collector.policy.theta_array, sarsa.policy.theta_array)
    assert collector.replay_updates == 0
    assert collector.replay_buffer.n_transitions == collector.num_timesteps == 3200


def test_replaying_one_trajectory_at_a_time_equals_one_phase():
    """The checkpoints replay one trajectory per call; that is the same replay as one phase of as many."""
    collector = ER("TileQ", gym.make(PENDULUM), seed=1, **{**model_kwargs("er", PENDULUM), **COLLECTOR_KWARGS})
    collector.learn(2000)
    for order in ORDERS:
        one_call = ER("TileQ", gym.make(PENDULUM), seed=1, replay_order=order)
        one_by_one = ER("TileQ", gym.make(PENDULUM), seed=1, replay_order=order)
        for model in (one_call, one_by_one):
            model.replay_buffer = collector.replay_buffer
            model.seed_replay(5)
        one_call.replay(4)
        for _ in range(4):
            one_by_one.replay(1)
        assert one_call.replay_updates == one_by_one.replay_updates > 0
        np.testing.assert_array_equal(one_call.policy.theta_array, one_by_one.policy.theta_array)


def test_replay_order_command_writes_table_and_figure_and_replays_one_database_per_seed(tmp_path, capsys):
    main(
        [
            "reproduce",
            "replay-order",
            "--seeds",
            "2",
            "--budget",
            "2000",
            "--database-episodes",
            "2",
            "--eval-every",
            "1000",
            "--jobs",
            "1",
            "--no-progress",
            "--out",
            str(tmp_path),
        ]
    )
    assert "replay_orders.png" in capsys.readouterr().out
    assert (tmp_path / "replay_orders.png").read_bytes()[:4] == PNG
    markdown = (tmp_path / "summary.md").read_text()
    assert "| Replayed updates | reversed | forward | uniform |" in markdown
    assert "reversed trajectories are slightly better than uniformly drawn samples" in markdown
    assert "the same database from the same initial weights" in markdown
    assert "velocity_tile_width=0.33" in markdown and "inertia_about=" in markdown  # the reading at run time
    table = pd.read_csv(tmp_path / "summary.csv")
    assert list(table["checkpoint"]) == [0, 1000, 2000]
    assert set(table["reversed_n"]) == {2}

    n_weights = ER("TileQ", gym.make(PENDULUM)).policy.tile_coder.n_weights
    zero_weights = hashlib.sha256(np.zeros(n_weights).tobytes()).hexdigest()
    for seed in (0, 1):
        csv = run_csv_path(tmp_path, "replay_order", seed)
        frame = pd.read_csv(csv)
        assert sorted(frame["order"].unique()) == sorted(ORDERS)
        assert len(frame) == 3 * len(ORDERS)
        # every order replayed the same data, starting from fresh (zero) weights
        assert frame["database_sha256"].nunique() == 1
        assert set(frame["weights_at_start_sha256"]) == {zero_weights}
        # checkpoints are passed by less than one trajectory (at most one 1500-step episode)
        assert (
            (frame["replayed_updates"] >= frame["checkpoint"])
            & (frame["replayed_updates"] < frame["checkpoint"] + 1500)
        ).all()
        assert (frame[frame["checkpoint"] == 0]["return"].nunique()) == 1  # zero weights: one greedy policy
        assert (frame["database_episodes"] == 2).all() and (frame["return"] < 0).all()
        record = read_record(csv)
        assert record["run"] == f"replay_order/seed_{seed}"
        assert record["config"]["algorithm_kwargs"]["online_lambda"] == 0.92
        assert "database_episodes=2" in record["config"]["protocol"]["name"]
        assert record["config"]["budget_unit"] == "replayed updates"
        assert record["resolved"]["env"]["episode_seconds"] == 15.0  # the env's defaults, recorded
    # the database is the collector's: collecting it again with the same seed gives the same transitions
    job = RunJob(
        ANALYSES["replay-order"].with_settings(database_episodes=2),
        "er",
        1,
        2000,
        tmp_path / "x.csv",
        algo_kwargs=tuple(sorted(COLLECTOR_KWARGS.items())),
    )
    collector, _ = replay_order.collect_database(job, gym.make(PENDULUM))
    assert replay_order.database_digest(collector.replay_buffer) == frame["database_sha256"].iloc[0]

    resumed = reproduce_replay_order(out_dir=tmp_path, **TINY_REPLAY_ORDER)
    assert (resumed.runs_done, resumed.runs_skipped) == (0, 2)
    with pytest.raises(ValueError, match="resume with the same settings"):
        reproduce_replay_order(out_dir=tmp_path, **{**TINY_REPLAY_ORDER, "database_episodes": 3})


def test_sigma_command_runs_every_definition_under_its_own_name(tmp_path, capsys):
    main(
        [
            "reproduce",
            "sigma",
            "--seeds",
            "1",
            "--budget",
            "100",
            "--jobs",
            "1",
            "--no-progress",
            "--out",
            str(tmp_path),
        ]
    )
    assert "sigma_scores.png" in capsys.readouterr().out
    for figure in ("sigma_scores.png", "learning_curves.png"):
        assert (tmp_path / figure).read_bytes()[:4] == PNG
    table = pd.read_csv(tmp_path / "summary.csv")
    assert list(table["definition"]) == list(DEFINITIONS)  # from the worst case to the best case
    assert list(table["thesis_number"]) == [1, 4, 2, 5, 3]
    assert (table["runs"] == 1).all() and np.isfinite(table["score"]).all()
    markdown = (tmp_path / "summary.md").read_text()
    assert "| average_worst (4) |" in markdown and "best (the thesis's choice)" in markdown
    assert "Ours, best first:" in markdown and "reward='schuitema'" in markdown
    for definition in DEFINITIONS:
        csv = run_csv_path(tmp_path, f"er_sigma-{definition}", 0)
        frame = pd.read_csv(csv)
        assert list(frame["learning_time_s"]) == [0.0, 100.0]
        record = read_record(csv)
        assert record["run"] == f"er_sigma-{definition}/seed_0"
        assert record["config"]["algorithm_kwargs"]["sigma"] == definition
        assert record["resolved"]["algorithm"]["sigma"] == definition
        assert record["config"]["experiment"] == "sigma"
        assert record["config"]["protocol"]["eval_interval_s"] == 100.0
    with pytest.raises(ValueError, match="unknown sigma definitions \\['average_worse'\\]"):
        reproduce_sigma(n_seeds=1, budget=100, out_dir=tmp_path / "bad", sigmas=["average_worse"])
    with pytest.raises(ValueError, match="sets sigma itself"):
        reproduce_sigma(n_seeds=1, budget=100, out_dir=tmp_path / "bad", algo_kwargs={"sigma": "best"})


def test_pessimistic_command_starts_at_the_chosen_value_on_the_same_data_and_replays(tmp_path, capsys):
    main(
        [
            "reproduce",
            "pessimistic",
            "--seeds",
            "1",
            "--budget",
            "2",
            "--jobs",
            "1",
            "--no-progress",
            "--out",
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    names = ["value_maps_pessimistic_after_goal.png", "value_maps_pessimistic_long_replay.png", "positive_cells.png"]
    for name in names:
        assert name in out and (tmp_path / name).read_bytes()[:4] == PNG
    markdown = (tmp_path / "summary.md").read_text()
    assert "pessimistic Q₀ = -50" in markdown and "Why Q₀ = -50" in markdown
    table = pd.read_csv(tmp_path / "summary.csv")
    assert len(table) == 2 * 2 * 3  # (after one phase, after the long replay) x (tabular, tile coding) x 3 variants
    assert set(table["variant"]) == {"er", "er_sigma", "er_pessimistic"}

    csv = run_csv_path(tmp_path, "pessimistic", 0)
    frame = pd.read_csv(csv)
    start = frame[frame["phase"] == 0].set_index(["case", "variant"])
    for case in CASES:
        assert start.loc[(case, "er_pessimistic"), "q_min"] == start.loc[(case, "er_pessimistic"), "q_max"] == -50.0
        assert start.loc[(case, "er_sigma"), "q_min"] == start.loc[(case, "er_sigma"), "q_max"] == 0.0
        assert frame[frame["case"] == case]["database_sha256"].nunique() == 1  # one data set per case
    assert "initial_value=-50.0" in read_record(csv)["config"]["protocol"]["name"]

    # the first seed's maps are those of the value-map study given the same pessimistic value
    maps, _ = same_data_value_maps(0, long_phases=2, pessimistic_value=PESSIMISTIC_VALUE)
    stored = pd.read_csv(artifact_path(csv, "value_maps.csv"))
    for situation, phase in (("after goal", 1), ("long replay", 2)):
        for case in CASES:
            for variant in ("er", "er_sigma", PESSIMISTIC):
                cells = stored[(stored["case"] == case) & (stored["variant"] == variant) & (stored["phase"] == phase)]
                expected = maps[situation][case][variant]
                np.testing.assert_array_equal(cells["value"].to_numpy(), expected[cells["y"], cells["x"]])


def test_the_pessimistic_model_starts_at_the_chosen_value_for_every_cell_and_action():
    from sb3_er.experiments.gridworld import ENV_ID, _new_model

    env = gym.make(ENV_ID)
    algo, extra = figure_variants(-50.0)[PESSIMISTIC]
    cells = np.array([[x, y] for x in range(10) for y in range(7)], dtype=np.float64)
    for policy_kwargs in CASES.values():
        model = _new_model(algo, env, {**policy_kwargs, **extra}, seed=0)
        assert algo == "er" and model.sigma is None
        np.testing.assert_array_equal(model.policy.q_values(cells), -50.0)


def test_analysis_options_are_checked(tmp_path, capsys):
    for argv, message in (
        (["reproduce", "sigma", "--database-episodes", "3"], "--database-episodes does not apply to sigma"),
        (["reproduce", "replay-order", "--algos", "er"], "--algos does not apply to replay-order"),
        (["reproduce", "walker", "--sigmas", "best"], "--sigmas does not apply to walker"),
        (["reproduce", "pessimistic", "--algo-kwargs", "gamma:0.9"], "--algo-kwargs does not apply to pessimistic"),
        (
            ["reproduce", "sigma-regime", "--algos", "er_sigma_stable"],
            "--algos does not apply to sigma-regime (it chooses its learners with --learners)",
        ),
        (["reproduce", "pendulum", "--learners", "er_sigma"], "--learners does not apply to pendulum"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--out", str(tmp_path)])
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err
    with pytest.raises(ValueError, match="positive integer"):
        reproduce_pessimistic(n_seeds=0, out_dir=tmp_path)
    with pytest.raises(ValueError, match="whole number of replay phases"):
        reproduce_pessimistic(n_seeds=1, budget=2.5, out_dir=tmp_path)
    with pytest.raises(ValueError, match="address .* is for the Ray backend only"):
        reproduce_replay_order(address="auto", out_dir=tmp_path)
    assert not any(tmp_path.iterdir())  # nothing was written
    assert json.loads(json.dumps(ANALYSES["replay-order"].settings)) == [
        ["database_episodes", 200],
        ["eval_every", 75000],
    ]


@pytest.mark.slow
def test_replay_order_on_ray_equals_local(tmp_path):
    ray = pytest.importorskip("ray")
    from sb3_er.experiments.runner import RAY_ENV_VARS

    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    ray.init(address="local", num_cpus=1, include_dashboard=False, runtime_env={"env_vars": RAY_ENV_VARS})
    try:
        settings = {**TINY_REPLAY_ORDER, "n_seeds": 1}
        local = reproduce_replay_order(out_dir=tmp_path / "local", **settings)
        on_ray = reproduce_replay_order(out_dir=tmp_path / "ray", backend="ray", **{**settings, "n_workers": None})
    finally:
        ray.shutdown()
    assert on_ray.runs_done == 1
    pd.testing.assert_frame_equal(
        pd.read_csv(run_csv_path(on_ray.out_dir, "replay_order", 0)).drop(columns="wall_time_s"),
        pd.read_csv(run_csv_path(local.out_dir, "replay_order", 0)).drop(columns="wall_time_s"),
    )

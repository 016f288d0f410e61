"""rl-zoo integration: registration, the thesis hyperparameters in zoo_configs, train -> enjoy, and an optuna study."""

import importlib.resources
import inspect
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import rl_zoo3
from rl_zoo3 import hyperparams_opt

from sb3_er import ER, ERSigma, SarsaLambda, zoo
from sb3_er.experiments.specs import EXPERIMENTS

ENV_IDS = ["sb3_er/WindyCliff-v0", "sb3_er/PendulumSwingup-v0", "sb3_er/SimplestWalker-v0", "sb3_er/Leo-v0"]
# (alpha, gamma, epsilon) of thesis sections 5.1 and 4.2.1-4.2.3
THESIS_SETTINGS = {
    "sb3_er/WindyCliff-v0": (0.25, 0.98, 0.05),
    "sb3_er/PendulumSwingup-v0": (0.2, 0.98, 0.1),
    "sb3_er/SimplestWalker-v0": (0.2, 0.99, 0.05),
    "sb3_er/Leo-v0": (0.2, 0.996, 0.05),
}


def test_registration_adds_every_algorithm_to_rl_zoo():
    zoo.register_algorithms()
    assert rl_zoo3.ALGOS["er_sigma"] is ERSigma
    assert rl_zoo3.ALGOS["sarsa_lambda"] is SarsaLambda
    for name in zoo.ALGORITHM_NAMES:
        assert name in hyperparams_opt.HYPERPARAMS_SAMPLER
        assert hyperparams_opt.HYPERPARAMS_CONVERTER[name]({"sigma": "worst"}) == {"sigma": "worst"}


def test_each_zoo_name_is_its_class_name_in_snake_case():
    import re

    classes = zoo.algorithm_classes()
    assert list(classes) == list(zoo.ALL_ALGORITHM_NAMES)
    for name, cls in classes.items():  # SarsaLambda -> sarsa_lambda, ResidualERSigma -> residual_er_sigma, FQI -> fqi
        assert re.sub(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", cls.__name__).lower() == name


@pytest.mark.parametrize("algo", zoo.ALGORITHM_NAMES)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_zoo_configs_hold_the_thesis_hyperparameters(algo, env_id):
    kwargs = zoo.model_kwargs(algo, env_id)
    assert (kwargs["learning_rate"], kwargs["gamma"], kwargs["exploration_rate"]) == THESIS_SETTINGS[env_id]
    assert kwargs["policy_kwargs"]["n_tilings"] == 16
    assert "n_timesteps" not in kwargs and "policy" not in kwargs
    assert zoo.load_hyperparameters(algo, env_id)["policy"] == "TileQ"


@pytest.mark.parametrize("algo", ["er", "er_sigma", "residual_er", "residual_er_sigma"])
def test_the_thesis_entries_pass_the_thesis_preset_explicitly(algo):
    """A later class default (the "stable" preset) must not change the thesis's configs: each of their entries names
    its preset, and the users' classic-control entries, which take the class default, do not."""
    for env_id in ENV_IDS:
        assert zoo.model_kwargs(algo, env_id)["preset"] == "thesis", env_id
    assert "preset" not in zoo.model_kwargs(algo, "CartPole-v1")


def test_replay_schedules_of_thesis_section_4_2():
    assert zoo.model_kwargs("sarsa_lambda", "sb3_er/Leo-v0")["trace_lambda"] == 0.859
    assert zoo.model_kwargs("sarsa_lambda", "sb3_er/SimplestWalker-v0")["trace_lambda"] == 0.92
    walker = zoo.model_kwargs("er_sigma", "sb3_er/SimplestWalker-v0")
    assert (walker["replay_trigger"], walker["n_replays"]) == ("segment", 100)
    pendulum = zoo.model_kwargs("residual_er", "sb3_er/PendulumSwingup-v0")
    assert (pendulum["replay_trigger"], pendulum["replays_per_stored_trajectory"]) == ("episode", 10.0)
    leo = zoo.model_kwargs("er", "sb3_er/Leo-v0")
    assert (leo["replay_every"], leo["n_replays"], leo["online_lambda"]) == (100, 1500, 0.859)
    # the walker's run length: 5000 s of learning at 0.2 s per step
    assert zoo.load_hyperparameters("er", "sb3_er/SimplestWalker-v0")["n_timesteps"] * 0.2 == (
        EXPERIMENTS["walker"].default_budget
    )


def test_unknown_algorithm_or_env_is_named():
    with pytest.raises(ValueError, match="unknown algorithm 'ppo'"):
        zoo.config_path("ppo")
    with pytest.raises(KeyError, match="no entry for 'LunarLander-v3'"):
        zoo.load_hyperparameters("er", "LunarLander-v3")


def test_train_then_enjoy_round_trip(tmp_path, capsys):
    folder = str(tmp_path)
    zoo.train(
        [
            "--algo",
            "er",
            "--env",
            "sb3_er/WindyCliff-v0",
            "-n",
            "1500",
            "-f",
            folder,
            "--seed",
            "1",
            "--eval-freq",
            "-1",
            "--verbose",
            "0",
        ]
    )
    run_dir = tmp_path / "er" / "sb3_er-WindyCliff-v0_1"
    model = ER.load(run_dir / "sb3_er-WindyCliff-v0.zip")
    assert model.num_timesteps == 1500 and model.learning_rate(1.0) == 0.25  # rl-zoo passes a constant schedule
    assert any((tmp_path / "tensorboard").rglob("events.out.tfevents.*"))
    capsys.readouterr()
    zoo.enjoy(["--algo", "er", "--env", "sb3_er/WindyCliff-v0", "-f", folder, "--no-render", "-n", "300"])
    assert "Mean reward" in capsys.readouterr().out


@pytest.mark.parametrize("algo, vec_env", [("sarsa_lambda", "dummy"), ("er_sigma", "subproc")])
def test_train_honours_n_envs(tmp_path, algo, vec_env):
    """rl-zoo's n_envs (here from -params) reaches the model: n envs step together, so 1,600 steps are 400 of each."""
    zoo.train(
        ["--algo", algo, "--env", "CartPole-v1", "-n", "1600", "-f", str(tmp_path), "--seed", "1"]
        + ["--eval-freq", "-1", "--verbose", "0", "--vec-env", vec_env, "-params", "n_envs:4"]
    )
    run_dir = tmp_path / algo / "CartPole-v1_1"
    model = zoo.algorithm_classes()[algo].load(run_dir / "CartPole-v1.zip")
    assert model.n_envs == 4 and model.num_timesteps == 1600


GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "zoo.md"


def guide_commands() -> list[str]:
    """The command lines of the rl-zoo guide's first bash block, as written (comments kept)."""
    block = re.search(r"```bash\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.DOTALL).group(1)
    return [line for line in block.splitlines() if line.strip()]


def _command_line(line: str) -> list[str]:
    """A guide line as a subprocess argument list: the `sb3-er` console script of this environment, comment dropped."""
    arguments = shlex.split(line, comments=True)
    script = Path(sys.executable).parent / arguments[0]
    return [str(script) if script.is_file() else arguments[0], *arguments[1:]]


@pytest.mark.slow
def test_the_guides_train_then_enjoy_work_as_written(tmp_path):
    """The guide's `sb3-er train` then `sb3-er enjoy`, run in a fresh folder as a user types them: train (with a small
    -n added) writes where the guide's comment says, and enjoy finds that model with no -f and plays it."""
    lines = guide_commands()
    train_line = next(line for line in lines if line.startswith("sb3-er train"))
    enjoy_line = next(line for line in lines if line.startswith("sb3-er enjoy"))
    train = subprocess.run(
        [*_command_line(train_line), "-n", "300"], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert train.returncode == 0, train.stdout[-3000:] + train.stderr[-3000:]
    written = train_line.partition("# ->")[2].strip()
    assert (tmp_path / written / "sb3_er-SimplestWalker-v0.zip").is_file(), f"train did not write {written}"
    tensorboard = next(line for line in lines if line.startswith("tensorboard")).split("--logdir")[1].split()[0]
    assert any((tmp_path / tensorboard).rglob("events.out.tfevents.*")), f"no TensorBoard events in {tensorboard}"
    enjoy = subprocess.run(_command_line(enjoy_line), cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert enjoy.returncode == 0, enjoy.stdout[-3000:] + enjoy.stderr[-3000:]
    assert "Mean reward" in enjoy.stdout and "huggingface" not in enjoy.stdout.lower()


def _no_download(*args, **kwargs):
    raise AssertionError("sb3-er enjoy must not download from a model hub")


@pytest.mark.parametrize("folder", [[], ["-f", "rl-trained-agents"], ["--folder", "elsewhere"]])
def test_enjoy_without_a_model_says_where_it_looked_and_never_downloads(tmp_path, monkeypatch, folder):
    import rl_zoo3.enjoy

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(rl_zoo3.enjoy, "download_from_hub", _no_download)
    with pytest.raises(SystemExit) as stop:
        zoo.run_command("enjoy", ["--algo", "er_sigma", "--env", "sb3_er/SimplestWalker-v0", "--no-render", *folder])
    message = str(stop.value.code)
    looked_in = folder[1] if folder else "logs"  # the default is the folder train writes
    assert f"{looked_in}/er_sigma/sb3_er-SimplestWalker-v0_<N>/sb3_er-SimplestWalker-v0.zip" in message
    assert str(tmp_path / looked_in) in message
    train = "sb3-er train --algo er_sigma --env sb3_er/SimplestWalker-v0" + (f" -f {looked_in}" if folder else "")
    assert f"`{train}`" in message
    assert "TRUST_REMOTE_CODE" not in message and "hub" not in message


def test_enjoy_finds_the_latest_run_train_wrote_and_help_passes_through(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for run in (1, 2):
        (tmp_path / "logs" / "er" / f"sb3_er-WindyCliff-v0_{run}").mkdir(parents=True)
        (tmp_path / "logs" / "er" / f"sb3_er-WindyCliff-v0_{run}" / "sb3_er-WindyCliff-v0.zip").write_bytes(b"")
    arguments = zoo._with_defaults(["--algo", "er", "--env", "sb3_er/WindyCliff-v0"], "enjoy")
    assert arguments[-2:] == ["--folder", "logs"]
    assert zoo.find_trained_model(arguments) == Path("logs/er/sb3_er-WindyCliff-v0_2/sb3_er-WindyCliff-v0.zip")
    # train's spelling of the folder option is understood by enjoy too
    assert "--folder" in zoo._with_defaults(["--algo", "er", "--log-folder", "x"], "enjoy")
    for command in ("enjoy", "train"):  # `sb3-er enjoy -h` shows rl_zoo3's options, as the CLI's help promises
        with pytest.raises(SystemExit) as stop:
            zoo.run_command(command, ["-h"])
        assert stop.value.code == 0 and f"usage: sb3-er {command}" in capsys.readouterr().out


def test_optuna_study_with_two_trials(tmp_path):
    zoo.optimize(
        [
            "--algo",
            "er_sigma",
            "--env",
            "sb3_er/WindyCliff-v0",
            "-n",
            "300",
            "--n-trials",
            "2",
            "--n-evaluations",
            "1",
            "--eval-episodes",
            "2",
            "-f",
            str(tmp_path),
            "--no-optim-plots",
            "--sampler",
            "random",
            "--pruner",
            "none",
            "--seed",
            "0",
            "--verbose",
            "0",
        ]
    )
    (report,) = (tmp_path / "er_sigma").glob("report_*.csv")
    trials = pd.read_csv(report)
    assert len(trials) == 2
    assert set(trials["params_sigma"]) <= set(zoo.sigma_definitions())
    assert trials["params_learning_rate"].between(0.02, 0.6).all()


class _EveryChoiceTrial:
    """An optuna trial stand-in that records every categorical search space and returns its first choice."""

    def __init__(self):
        self.spaces = {}

    def suggest_categorical(self, name, choices):
        self.spaces[name] = list(choices)
        return choices[0]

    def suggest_float(self, name, low, high, log=False):
        return low

    def suggest_int(self, name, low, high, log=False):
        return low


@pytest.mark.parametrize("algo", zoo.ALL_ALGORITHM_NAMES)
def test_every_choice_of_the_search_space_builds_a_model(algo):
    import sb3_er_envs  # noqa: F401  (registers the environment ids)

    zoo.register_algorithms()
    trial = _EveryChoiceTrial()
    hyperparams_opt.HYPERPARAMS_SAMPLER[algo](trial, 3, 1, {})
    algorithm = zoo.algorithm_classes()[algo]
    for name, choices in trial.spaces.items():
        for choice in choices:
            algorithm("TileQ", "sb3_er/WindyCliff-v0", **{name: choice})
    if algo in ("er", "er_sigma", "residual_er", "residual_er_sigma"):  # the stabilizers, with every config's volume
        assert "preset" not in trial.spaces  # every stabilizer is sampled explicitly: the preset would decide nothing
        for name in ("truncate_targets", "target_copy", "step_size_bound", "project_weights"):
            assert trial.spaces[name] == [False, True]
        assert trial.spaces.get("averager") == (None if algo.startswith("residual") else [False, True])
        assert None in trial.spaces["replay_ratio"]
        for env_id in ENV_IDS:
            config = zoo.model_kwargs(algo, env_id)
            for ratio in trial.spaces["replay_ratio"]:
                ratio_trial = _EveryChoiceTrial()
                ratio_trial.suggest_categorical = lambda name, choices, ratio=ratio: (
                    ratio if name == "replay_ratio" else choices[-1]
                )
                sampled = hyperparams_opt.HYPERPARAMS_SAMPLER[algo](ratio_trial, 3, 1, {})
                algorithm("TileQ", env_id, **{**config, **sampled}, _init_setup_model=False)._setup_model()
    if algo == "er":  # every replay order ER has, prioritized sweeping included
        assert trial.spaces["replay_order"] == ["reversed", "forward", "uniform", "prioritized"]
    if algo in ("er_sigma", "residual_er_sigma"):
        assert sorted(trial.spaces["sigma"]) == sorted(["worst", "average_worst", "average", "average_best", "best"])


@pytest.mark.slow
def test_two_optimize_workers_share_one_sqlite_study(tmp_path):
    optuna = pytest.importorskip("optuna")
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    # the study exists before the workers start, as the README recommends (two first workers could race to create it)
    optuna.create_study(storage=storage, study_name="windy-er", direction="maximize")
    workers = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "sb3_er.cli",
                "optimize",
                "--algo",
                "er",
                "--env",
                "sb3_er/WindyCliff-v0",
                "--n-trials",
                "2",
                "--n-timesteps",
                "500",
                "--storage",
                storage,
                "--study-name",
                "windy-er",
                "-f",
                str(tmp_path / f"worker_{index}"),
                "--n-evaluations",
                "1",
                "--eval-episodes",
                "2",
                "--sampler",
                "random",
                "--pruner",
                "none",
                "--seed",
                str(index),
                "--no-optim-plots",
                "--verbose",
                "0",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for index in range(2)
    ]
    outputs = [worker.communicate(timeout=300)[0] for worker in workers]
    assert [worker.returncode for worker in workers] == [0, 0], "\n".join(outputs)
    trials = optuna.load_study(study_name="windy-er", storage=storage).get_trials()
    # each worker runs its own 2 trials into the shared study: 4 in all, with our sampler's parameters (ER's: the
    # common ones, the replay order and the stabilizers)
    assert len(trials) == 4, [trial.state for trial in trials]
    assert all(trial.state == optuna.trial.TrialState.COMPLETE for trial in trials), [t.state for t in trials]
    expected = {"learning_rate", "gamma", "exploration_rate", "replay_order"}
    expected |= {"truncate_targets", "target_copy", "step_size_bound", "averager", "project_weights", "replay_ratio"}
    assert all(set(trial.params) == expected for trial in trials), [sorted(trial.params) for trial in trials]
    # every worker's report lists the study's trials when it finished: the later one all 4
    reports = [pd.read_csv(next((tmp_path / f"worker_{index}" / "er").glob("report_*.csv"))) for index in range(2)]
    assert sorted(len(report) for report in reports)[-1] == 4


def test_plain_rl_zoo_trains_its_own_dqn_on_our_environments(tmp_path, monkeypatch):
    from rl_zoo3.train import train as zoo_train

    monkeypatch.setattr(
        "sys.argv",
        [
            "rl_zoo3.train",
            "--algo",
            "dqn",
            "--env",
            "sb3_er/SimplestWalker-v0",
            "--gym-packages",
            "sb3_er_envs",
            "-conf",
            str(importlib.resources.files(zoo.CONFIG_PACKAGE) / "dqn.yml"),
            "-n",
            "300",
            "-f",
            str(tmp_path),
            "--eval-freq",
            "-1",
            "--seed",
            "0",
            "--verbose",
            "0",
        ],
    )
    zoo_train()
    assert (tmp_path / "dqn" / "sb3_er-SimplestWalker-v0_1" / "sb3_er-SimplestWalker-v0.zip").is_file()


@pytest.mark.slow
def test_train_prints_a_table_every_few_episodes_not_every_episode(tmp_path):
    """`sb3-er train --algo er_sigma --env CartPole-v1 -n 20000` prints a table every log_interval (8) finished
    episodes, where it printed one per episode before; how many episodes 20,000 steps make depends on what the run
    learns, so the tables are checked against the episode counts they print. The walker's episodes (100 s of 0.2 s
    steps at most) still log at least once per 5,000 steps."""
    from sb3_er.common.base_class import TileQAlgorithm

    log_interval = inspect.signature(TileQAlgorithm.learn).parameters["log_interval"].default
    train = subprocess.run(
        _command_line("sb3-er train --algo er_sigma --env CartPole-v1 -n 20000 --seed 0"),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert train.returncode == 0, train.stderr[-2000:]
    tables = train.stdout.count("| time/")
    episodes = [int(count) for count in re.findall(r"\|\s*episodes\s*\|\s*(\d+)", train.stdout)]
    assert tables >= 5 and len(episodes) == tables, (tables, episodes)
    # one table per log_interval episodes: 8, 16, 24, ... and none in between
    assert episodes == [log_interval * (k + 1) for k in range(tables)], episodes
    longest_walker_episode = 100.0 / 0.2  # steps
    assert log_interval * longest_walker_episode <= 5_000

"""Keyword arguments for an env given on a command line (`reproduce --env-kwargs`, `train`'s and `enjoy`'s
`--env-kwargs`/`--eval-env-kwargs`) are checked against the env's constructor once, before any run starts: one clear
error, not one traceback per run."""

import gymnasium as gym
import pytest

from sb3_er import cli, zoo
from sb3_er.common.env_ids import check_env_kwargs


@pytest.mark.parametrize(
    "env_id, env_kwargs, message",
    [
        ("sb3_er/WindyCliff-v0", {"step_reward": "abc"}, r"WindyCliff-v0's step_reward must be a number, got 'abc'"),
        ("sb3_er/SimplestWalker-v0", {"step_reward": "abc"}, r"SimplestWalker-v0's step_reward must be a number"),
        ("sb3_er/SimplestWalker-v0", {"n_actions": 2.5}, r"n_actions must be an integer, got 2.5 \(float\)"),
        ("sb3_er/SimplestWalker-v0", {"step_reward_cap": "none"}, r"step_reward_cap must be a number or None"),
        ("CartPole-v1", {"sutton_barto_reward": 1}, r"sutton_barto_reward must be a bool"),
        (
            "sb3_er/WindyCliff-v0",
            {"step_rewrd": -1.0},
            r"takes no argument step_rewrd; its arguments are width, height, wind_rows, wind_probability, step_reward",
        ),
        ("sb3_er/WindyCliff-v0", {"width": 1}, r"WindyCliff-v0 refuses width=1: ValueError: width must be an integer"),
        ("sb3_er/SimplestWalker-v0", {"fall": "knee"}, r"refuses fall='knee': ValueError: fall must be one of"),
        ("sb3_er/NoSuchEnv-v0", {"a": 1}, r"the env sb3_er/NoSuchEnv-v0 cannot be found"),
    ],
)
def test_bad_env_kwargs_are_named_before_any_env_runs(env_id, env_kwargs, message):
    with pytest.raises(ValueError, match=message):
        check_env_kwargs(env_id, env_kwargs)


@pytest.mark.parametrize(
    "env_id, env_kwargs",
    [
        ("sb3_er/WindyCliff-v0", {"step_reward": -2, "width": 5}),  # an int where a float is annotated
        ("sb3_er/SimplestWalker-v0", {"step_reward_cap": None, "fall": "angles"}),
        ("sb3_er/WindyCliff-v0", {"max_episode_steps": 20}),  # gymnasium.make's own
        ("CartPole-v1", {"sutton_barto_reward": True}),
        ("sb3_er/WindyCliff-v0", {}),
    ],
)
def test_good_env_kwargs_pass(env_id, env_kwargs):
    check_env_kwargs(env_id, env_kwargs)


class _OpenEnv(gym.Env):
    """Takes any keyword (as a wrapper factory passing them on would)."""

    def __init__(self, **kwargs):
        self.observation_space = gym.spaces.Box(0.0, 1.0, (1,))
        self.action_space = gym.spaces.Discrete(2)
        if kwargs.get("size", 1) < 1:
            raise ValueError("size must be positive")


def test_an_env_taking_any_keyword_is_checked_by_making_it():
    gym.register("test_env_kwargs/Open-v0", entry_point=_OpenEnv)
    try:
        check_env_kwargs("test_env_kwargs/Open-v0", {"anything": 3})
        with pytest.raises(ValueError, match="refuses size=0: ValueError: size must be positive"):
            check_env_kwargs("test_env_kwargs/Open-v0", {"size": 0})
    finally:
        gym.registry.pop("test_env_kwargs/Open-v0")


@pytest.mark.parametrize(
    "experiment", ["gridworld", "pendulum", "walker", "leo", "replay-order", "sigma", "pessimistic"]
)
def test_every_reproduce_subcommand_checks_its_env_kwargs_before_a_run(experiment, tmp_path, capsys, monkeypatch):
    def no_run(*args, **kwargs):
        raise AssertionError("a run started")

    monkeypatch.setattr("sb3_er.experiments.runner.run_jobs", no_run)
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as stop:
        cli.reproduce_command([experiment, "--env-kwargs", "no_such_setting:3", "--seeds", "1", "--out", str(out)])
    assert stop.value.code == 2
    error = capsys.readouterr().err
    assert error.count("error:") == 1 and "takes no argument no_such_setting" in error
    assert "Traceback" not in error and not out.exists()


@pytest.mark.parametrize("analysis", ["framework", "sigma-regime"])
def test_analyses_of_several_envs_refuse_env_kwargs_as_a_usage_error(analysis, capsys):
    with pytest.raises(SystemExit) as stop:
        cli.reproduce_command([analysis, "--env-kwargs", "width:5"])
    assert stop.value.code == 2
    assert "--env-kwargs does not apply to" in capsys.readouterr().err


def test_the_library_functions_check_env_kwargs_too(tmp_path):
    from sb3_er.experiments.reproduce import reproduce

    with pytest.raises(ValueError, match="step_reward must be a number"):
        reproduce("gridworld", n_seeds=1, out_dir=tmp_path / "out", env_kwargs={"step_reward": "abc"})
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--env-kwargs", "step_reward:abc"], r"Python expression \(name 'abc' is not defined\)"),
        (["--env-kwargs", "step_reward:'abc'"], r"--env-kwargs: sb3_er/WindyCliff-v0's step_reward must be a number"),
        (["--eval-env-kwargs", "width:1"], r"--eval-env-kwargs: sb3_er/WindyCliff-v0 refuses width=1"),
        (["--env-kwargs", "stepreward:1"], r"takes no argument stepreward"),
    ],
)
@pytest.mark.parametrize("command", ["train", "optimize", "enjoy"])
def test_zoo_commands_check_env_kwargs_before_rl_zoo_starts(command, arguments, message, monkeypatch):
    pytest.importorskip("rl_zoo3")

    def no_run(*args, **kwargs):
        raise AssertionError("rl_zoo3 started")

    monkeypatch.setattr("rl_zoo3.train.train", no_run)
    monkeypatch.setattr("rl_zoo3.enjoy.enjoy", no_run)
    with pytest.raises(SystemExit, match=message) as stop:
        zoo.COMMANDS[command](["--algo", "sarsa_lambda", "--env", "sb3_er/WindyCliff-v0", *arguments])
    assert str(stop.value).startswith(f"sb3-er {command}: error: ")

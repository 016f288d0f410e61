"""A command whose optional package is missing names the extra that installs it (a wheel installed without extras)."""

import builtins
from unittest import mock

import pytest

from sb3_er import cli
from sb3_er.experiments.records import code_versions_line


def test_a_missing_extra_is_named():
    """rl_zoo3 is imported when `sb3-er train` runs: without it the message names the zoo extra."""
    real_import = builtins.__import__

    def without(name, *args, **kwargs):
        if name.partition(".")[0] == "rl_zoo3":
            raise ModuleNotFoundError("No module named 'rl_zoo3'", name="rl_zoo3")
        return real_import(name, *args, **kwargs)

    with mock.patch("builtins.__import__", without), pytest.raises(SystemExit) as stop:
        cli.main(["train", "--algo", "er", "--env", "sb3_er/WindyCliff-v0", "-n", "10"])
    assert "pip install 'sb3-er[zoo]'" in str(stop.value) and "rl_zoo3" in str(stop.value)


@pytest.mark.parametrize("missing, extra", [("pandas", "plots"), ("matplotlib", "plots"), ("ray", "ray")])
def test_every_optional_import_of_reproduce_names_its_extra(missing, extra):
    error = ModuleNotFoundError(f"No module named {missing!r}", name=missing)
    with mock.patch.object(cli, "reproduce_command", side_effect=error), pytest.raises(SystemExit) as stop:
        cli.main(["reproduce", "gridworld"])
    assert f"pip install 'sb3-er[{extra}]'" in str(stop.value)


def test_other_missing_modules_are_not_hidden():
    error = ModuleNotFoundError("No module named 'nowhere'", name="nowhere")
    with mock.patch.object(cli, "reproduce_command", side_effect=error), pytest.raises(ModuleNotFoundError):
        cli.main(["reproduce", "gridworld"])


def test_runs_outside_a_checkout_say_so():
    record = {"sb3_er_version": "0.1.0", "code_sha256": "ab" * 32, "git_commit": None}
    line = code_versions_line([record])
    assert line == "Code: sb3-er 0.1.0, code hash ababababab (1 run, not from a git checkout)."
    from_a_checkout = [dict(record, git_commit="c" * 40, git_dirty=dirty) for dirty in (False, True, False)]
    assert code_versions_line(from_a_checkout + [record]) == (
        "Code: sb3-er 0.1.0, code hash ababababab (4 runs from commit ccccccc with uncommitted changes and outside a "
        "git checkout)."
    )

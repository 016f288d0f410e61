"""Version records beside each run's CSV, and resumes that refuse (or, when allowed, warn about) mixed versions."""

import datetime
import json
import shutil
import subprocess
import warnings

import pandas as pd
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

import sb3_er
from sb3_er import zoo
from sb3_er.cli import main
from sb3_er.experiments import records
from sb3_er.experiments.records import MixedVersionsError, MixedVersionsWarning
from sb3_er.experiments.reproduce import reproduce
from sb3_er.experiments.runner import DamagedRunWarning, RunFailure, plan_jobs, run_csv_path, run_jobs
from sb3_er.experiments.specs import EXPERIMENTS

# The pendulum with one learning episode per run is the cheapest reproduction (about a second per run).
FAST = {"algos": ["er"], "budget": 1, "n_workers": 1, "show_progress": False}
RUN_LEVEL_KEYS = {"n_timesteps", "policy"}  # keys of zoo_configs/er.yml that are no constructor arguments
needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def _fake_commit(monkeypatch, commit, dirty=False, diff=None, code="from the commit"):
    """Pretend the code is at `commit`; its code hash is the commit's letter repeated, or `code` (None: unknown)."""
    state = {"git_commit": commit, "git_dirty": dirty, "git_diff_sha256": diff}
    monkeypatch.setattr(records, "git_state", lambda root=records.PACKAGE_ROOT, paths=(): dict(state))
    monkeypatch.setattr(records, "code_hash", lambda: commit[0] * 64 if code == "from the commit" else code)


def _git(cwd, *arguments):
    return subprocess.run(["git", *arguments], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


@needs_git
def test_git_state_of_a_checkout_a_dirty_tree_and_no_checkout(tmp_path):
    repository = tmp_path / "repository"
    (repository / "package").mkdir(parents=True)
    _git(repository, "init", "-q")
    (repository / "package" / "module.py").write_text("x = 1\n")
    _git(repository, "add", ".")
    _git(repository, "-c", "user.name=t", "-c", "user.email=t@example.org", "commit", "-qm", "first")
    commit = _git(repository, "rev-parse", "HEAD")
    assert records.git_state(repository) == {"git_commit": commit, "git_dirty": False, "git_diff_sha256": None}

    (repository / "package" / "module.py").write_text("x = 2\n")
    edited = records.git_state(repository)
    assert (edited["git_commit"], edited["git_dirty"]) == (commit, True) and len(edited["git_diff_sha256"]) == 64
    (repository / "package" / "new_module.py").write_text("y = 1\n")  # an untracked file changes the code too
    assert records.git_state(repository)["git_diff_sha256"] not in (None, edited["git_diff_sha256"])

    # only the given paths count: results written into the checkout leave its code clean
    _git(repository, "checkout", "-q", "--", "package")
    (repository / "package" / "new_module.py").unlink()
    (repository / "results").mkdir()
    (repository / "results" / "seed_0.csv").write_text("t,return\n")
    assert records.git_state(repository, ["package"]) == {
        "git_commit": commit,
        "git_dirty": False,
        "git_diff_sha256": None,
    }
    assert records.git_state(repository)["git_dirty"] is True  # the whole tree: the results are a change
    (repository / "package" / "module.py").write_text("x = 3\n")
    assert records.git_state(repository, ["package"])["git_dirty"] is True

    unknown = {"git_commit": None, "git_dirty": None, "git_diff_sha256": None}
    assert records.git_state(tmp_path / "not_a_checkout") == unknown
    # a package below a checkout's top level (a wheel in a virtual environment inside a repository) is no checkout
    assert records.git_state(repository / "package") == unknown


def test_record_holds_version_commit_and_resolved_configuration(tmp_path):
    result = reproduce("pendulum", n_seeds=1, first_seed=3, out_dir=tmp_path, **FAST)
    csv_path = run_csv_path(tmp_path, "er", 3)
    record = json.loads(csv_path.with_suffix(".json").read_text())

    assert record["run"] == "er/seed_3" and record["sb3_er_version"] == sb3_er.__version__
    top_level = records.PACKAGE_ROOT
    if shutil.which("git") and (top_level / ".git").exists():
        assert record["git_commit"] == _git(top_level, "rev-parse", "HEAD")
        # the code's folders of this repository (pyproject.toml's package-dir) and pyproject.toml itself
        assert records.checkout_code_paths() == ["envs", "pyproject.toml", "sb3_er", "zoo_configs"]
        changed = _git(top_level, "status", "--porcelain", "--", "envs", "pyproject.toml", "sb3_er", "zoo_configs")
        assert record["git_dirty"] == bool(changed) and (record["git_diff_sha256"] is None) == (not changed)
    else:  # an installed wheel: no commit to record
        assert record["git_commit"] is None and record["git_dirty"] is None

    entry = yaml.safe_load(zoo.config_path("er").read_text())["sb3_er/PendulumSwingup-v0"]
    config = record["config"]
    assert config["algorithm_kwargs"] == {
        "policy": "TileQ",
        "seed": 3,
        **{key: value for key, value in entry.items() if key not in RUN_LEVEL_KEYS},
    }
    assert (config["algorithm"], config["algorithm_class"]) == ("er", "sb3_er.er.ER")
    assert (config["env_id"], config["env_kwargs"]) == ("sb3_er/PendulumSwingup-v0", {})
    assert (config["budget"], config["budget_unit"], config["protocol"]["name"]) == (1.0, "episodes", "episodes")
    # what the model and the env held: the thesis's settings (4.2.1) and ER's own defaults
    resolved = record["resolved"]
    assert (resolved["algorithm"]["learning_rate"], resolved["algorithm"]["gamma"]) == (0.2, 0.98)
    assert resolved["algorithm"]["replay_order"] == "reversed" and resolved["algorithm"]["seed"] == 3
    assert (resolved["env"]["dt"], resolved["env"]["episode_seconds"]) == (0.01, 15.0)
    assert record["dependencies"]["stable-baselines3"] == __import__("stable_baselines3").__version__
    assert 0 < record["wall_time_s"] < 600
    assert datetime.datetime.fromisoformat(record["finished_at"]).tzinfo is not None
    assert len(pd.read_csv(csv_path)) == 1
    assert f"Code: sb3-er {sb3_er.__version__}" in result.table_markdown.read_text()


def test_resume_refuses_a_changed_configuration(tmp_path, monkeypatch):
    reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    original = zoo.load_hyperparameters

    def other_learning_rate(algo, env_id):
        return {**original(algo, env_id), "learning_rate": 0.3}

    monkeypatch.setattr(zoo, "load_hyperparameters", other_learning_rate)
    with pytest.raises(MixedVersionsError) as refusal:
        reproduce("pendulum", n_seeds=2, out_dir=tmp_path, **FAST)
    message = str(refusal.value)
    assert "er/seed_0: config.algorithm_kwargs.learning_rate 0.2 -> 0.3" in message
    assert "--allow-mixed-versions" in message
    assert not run_csv_path(tmp_path, "er", 1).exists()  # refused before running anything


def test_resume_refuses_a_changed_commit_unless_mixed_versions_are_allowed(tmp_path, monkeypatch, capsys):
    _fake_commit(monkeypatch, "a" * 40)
    reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    _fake_commit(monkeypatch, "b" * 40)  # same configuration, other code
    with pytest.raises(MixedVersionsError, match="er/seed_0: code_sha256 aaaaaaaaaa -> bbbbbbbbbb"):
        reproduce("pendulum", n_seeds=2, out_dir=tmp_path, **FAST)

    arguments = [
        "reproduce",
        "pendulum",
        "--seeds",
        "2",
        "--algos",
        "er",
        "--budget",
        "1",
        "--jobs",
        "1",
        "--no-progress",
        "--out",
        str(tmp_path),
    ]
    with pytest.raises(SystemExit) as exit_info:
        main(arguments)
    assert exit_info.value.code == 2
    assert "code_sha256 aaaaaaaaaa -> bbbbbbbbbb" in capsys.readouterr().err

    with pytest.warns(MixedVersionsWarning, match="kept because mixed versions are allowed"):
        main([*arguments, "--allow-mixed-versions"])
    assert "1 run done, 1 already finished" in capsys.readouterr().out
    assert records.read_record(run_csv_path(tmp_path, "er", 0))["git_commit"] == "a" * 40
    assert records.read_record(run_csv_path(tmp_path, "er", 1))["git_commit"] == "b" * 40
    summary = (tmp_path / "summary.md").read_text()
    assert "code hash aaaaaaaaaa (1 run from commit aaaaaaa)" in summary
    assert "code hash bbbbbbbbbb (1 run from commit bbbbbbb)" in summary
    assert "Mixed versions" in summary


def test_a_commit_that_leaves_the_code_alone_mixes_freely(tmp_path, monkeypatch):
    _fake_commit(monkeypatch, "a" * 40, code="c" * 64)
    reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    _fake_commit(monkeypatch, "b" * 40, code="c" * 64)  # e.g. a commit of the README during a long reproduction
    with warnings.catch_warnings():
        warnings.simplefilter("error", MixedVersionsWarning)
        resumed = reproduce("pendulum", n_seeds=2, out_dir=tmp_path, **FAST)
    assert (resumed.runs_done, resumed.runs_skipped) == (1, 1)
    summary = (tmp_path / "summary.md").read_text()  # one code version made both runs, whatever the commits
    assert "code hash cccccccccc (2 runs from commits aaaaaaa, bbbbbbb)" in summary
    assert "Mixed versions" not in summary


def test_without_a_code_hash_the_same_commit_warns_only_when_the_uncommitted_changes_differ(tmp_path, monkeypatch):
    _fake_commit(monkeypatch, "a" * 40, dirty=True, diff="1" * 64, code=None)
    reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MixedVersionsWarning)
        resumed = reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)  # the same changes: silent
    assert (resumed.runs_done, resumed.runs_skipped) == (0, 1)
    _fake_commit(monkeypatch, "a" * 40, dirty=True, diff="2" * 64, code=None)
    with pytest.warns(MixedVersionsWarning, match="er/seed_0: same commit, different uncommitted changes"):
        resumed = reproduce("pendulum", n_seeds=2, out_dir=tmp_path, **FAST)
    assert (resumed.runs_done, resumed.runs_skipped) == (1, 1)


def test_a_run_without_a_record_is_moved_aside_and_done_again(tmp_path):
    reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    csv_path = run_csv_path(tmp_path, "er", 0)
    written = csv_path.read_bytes()
    csv_path.with_suffix(".json").unlink()  # a driver stopped between the CSV and its record, or a pre-record run
    with pytest.warns(
        DamagedRunWarning,
        match=r"seed_0.csv has no version record .*moved aside as "
        r"seed_0.csv.damaged-\d{8}T\d{6}Z and done again",
    ):
        result = reproduce("pendulum", n_seeds=1, out_dir=tmp_path, **FAST)
    assert (result.runs_done, result.runs_skipped) == (1, 0)
    (kept,) = csv_path.parent.glob("seed_0.csv.damaged-*")
    assert kept.read_bytes() == written  # nothing is lost
    assert records.check_sealed(records.read_record(csv_path), csv_path) is None


def test_a_run_made_by_other_code_than_the_drivers_is_not_written(tmp_path, monkeypatch):
    # the driver reads the commit before it starts a run, the run when it starts: a node with other code
    codes = iter(["a" * 64, "b" * 64] * 2)
    monkeypatch.setattr(records, "code_hash", lambda: next(codes))
    jobs, _ = plan_jobs(EXPERIMENTS["pendulum"], ["er"], [0], 1, tmp_path)
    expected = r"er/seed_0:\nran on .* other code .*\(worker -> driver\): code_sha256 bbbbbbbbbb -> aaaaaaaaaa"
    with pytest.raises(RunFailure, match=expected):
        run_jobs(jobs, 1, show_progress=False)
    assert not run_csv_path(tmp_path, "er", 0).exists()
    with pytest.warns(MixedVersionsWarning, match="er/seed_0 ran with .*code_sha256 bbbbbbbbbb -> aaaaaaaaaa"):
        run_jobs(jobs, 1, show_progress=False, allow_mixed_versions=True)
    assert records.read_record(run_csv_path(tmp_path, "er", 0))["code_sha256"] == "b" * 64


def test_compare_records_names_each_differing_field():
    current = {
        "sb3_er_version": "0.2.0",
        "git_commit": "c" * 40,
        "config": {"budget": 5.0, "protocol": {"x": 1}},
        "dependencies": {"numpy": "2.1"},
        "python": "3.11.7",
    }
    recorded = {
        **current,
        "sb3_er_version": "0.1.0",
        "config": {"budget": 4.0, "protocol": {"x": 1, "y": 2}},
        "dependencies": {"numpy": "2.0"},
    }
    refusals, cautions = records.compare_records(recorded, current)
    assert refusals == [
        'sb3_er_version "0.1.0" -> "0.2.0"',
        "config.budget 4.0 -> 5.0",
        'config.protocol.y 2 -> "(absent)"',
    ]
    assert cautions == ['dependencies.numpy "2.0" -> "2.1"']
    assert records.compare_records(current, current) == ([], [])


@needs_git
@pytest.mark.parametrize(
    "out_dir",
    ["results/measured/walker", "results/measured/framework/pendulum", "results/measured/walker_screens/segments"],
)
def test_measured_runs_are_not_git_ignored(out_dir):
    """Committed measurements keep their per-run files: the CSV and version record a reproduction writes under
    results/measured/ at any depth must not match the repository's .gitignore (once, `runs/` two levels down did)."""
    root = records.PACKAGE_ROOT
    if subprocess.run(["git", "rev-parse", "--git-dir"], cwd=root, capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    csv = run_csv_path(root / out_dir, "er", 0)
    for path in (csv, csv.with_suffix(".json")):
        relative = str(path.relative_to(root))
        ignored = subprocess.run(["git", "check-ignore", "-q", "--no-index", relative], cwd=root).returncode == 0
        assert not ignored, f"{relative} is git-ignored"
    scratch = str(run_csv_path(root / "results/framework", "er", 0).relative_to(root))
    assert subprocess.run(["git", "check-ignore", "-q", "--no-index", scratch], cwd=root).returncode == 0


def test_compact_runs_joins_seeds_into_ranges():
    runs = [
        "pendulum/er/seed_0",
        "pendulum/er/seed_1",
        "pendulum/er/seed_2",
        "pendulum/er/seed_5",
        "lspi/seed_3",
        "pendulum/er/seed_6",
        "summary",
    ]
    assert records.compact_runs(runs) == "pendulum/er/seed_0-2, 5-6, lspi/seed_3, summary"
    assert records.grouped({"er/seed_0": ["a"], "er/seed_1": ["a"], "dyna/seed_0": ["b"], "fqi/seed_0": []}) == [
        "  er/seed_0-1: a",
        "  dyna/seed_0: b",
    ]


def _expand(compact):
    """The run keys a compact list names (the inverse of records.compact_runs, written independently)."""
    keys, prefix = set(), None
    for item in compact.split(", "):
        if "seed_" in item:
            prefix, item = item.rsplit("seed_", 1)
            prefix += "seed_"
        first, _, last = item.partition("-")
        keys.update(f"{prefix}{seed}" for seed in range(int(first), int(last or first) + 1))
    return keys


@given(
    st.lists(
        st.tuples(st.sampled_from(["er/", "pendulum/er_sigma/", "gridworld/lspi/"]), st.integers(0, 40)),
        min_size=1,
        max_size=60,
    )
)
def test_compact_runs_names_every_run_and_no_other(pairs):
    runs = [f"{prefix}seed_{seed}" for prefix, seed in pairs]
    compact = records.compact_runs(runs)
    assert _expand(compact) == set(runs)
    assert len(compact) <= len(", ".join(dict.fromkeys(runs)))

"""The wheel works outside the source tree: built from a copy of the package's files, installed into a fresh virtual
environment in a temporary folder, it runs the README's quickstart, ``sb3-er train`` and ``sb3-er reproduce`` there,
and reports the same code version as the checkout (the version records would refuse a mix otherwise).

The fresh environment gets the wheel and nothing of the checkout. Its dependencies (torch, SB3, rl_zoo3, ...) are the
ones this interpreter already has: a ``.pth`` line puts this interpreter's site-packages after the fresh ones, whose
own ``.pth`` files (the editable install of the checkout among them) Python does not run from there. Installing torch
again from the registry would take minutes and test pip, not sb3-er.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from sb3_er.experiments import records

ROOT = Path(__file__).resolve().parents[1]
# What a wheel is built from: the packaging files and the folders pyproject.toml maps into packages.
SOURCES = ("pyproject.toml", "README.md", "sb3_er", "envs", "zoo_configs")

pytestmark = pytest.mark.slow


def readme_quickstart() -> list[str]:
    """The Python blocks of the README's "Quickstart" section."""
    text = (ROOT / "README.md").read_text()
    section = re.search(r"^## Quickstart\n(.*?)(?=^## )", text, flags=re.MULTILINE | re.DOTALL)
    assert section, "the README has a '## Quickstart' section"
    return re.findall(r"^```python\n(.*?)^```", section.group(1), flags=re.MULTILINE | re.DOTALL)


@pytest.fixture(scope="module")
def venv(tmp_path_factory) -> Path:
    """A fresh virtual environment with the wheel built from this checkout installed, without its source tree."""
    work = tmp_path_factory.mktemp("wheel")
    source = work / "source"
    source.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(ROOT / name, source / name)
    dist = work / "dist"
    subprocess.run(
        [sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(dist), str(source)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    (wheel,) = dist.glob("sb3_er-*.whl")
    env = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(env)], check=True, capture_output=True, timeout=600)
    python = env / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    ours = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib"), *site.getsitepackages()}
    Path(purelib, "zz_dependencies_of_the_test_interpreter.pth").write_text("\n".join(sorted(ours)) + "\n")
    subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", str(wheel)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    shutil.rmtree(source)  # nothing of the checkout is left to import from
    return env


def run(venv: Path, arguments: list[str], cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    environment = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")}
    environment["PATH"] = f"{venv / 'bin'}{os.pathsep}{environment.get('PATH', '')}"
    result = subprocess.run(arguments, cwd=cwd, env=environment, capture_output=True, text=True, timeout=timeout)
    assert result.returncode == 0, f"{' '.join(arguments)} failed:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    return result


def test_the_wheel_imports_from_its_own_install_with_its_package_data(venv, tmp_path):
    probe = (
        "import json, sb3_er, sb3_er_envs, importlib.metadata\n"
        "from sb3_er import zoo\n"
        "from sb3_er.experiments import records\n"
        "print(json.dumps({'sb3_er': sb3_er.__file__, 'envs': sb3_er_envs.__file__,\n"
        "  'config': str(zoo.config_path('er_sigma')), 'metadata': importlib.metadata.version('sb3-er'),\n"
        "  'code': records.code_version(), 'files': sorted(records.code_files())}))\n"
    )
    seen = json.loads(run(venv, [str(venv / "bin" / "python"), "-c", probe], tmp_path).stdout)
    for key in ("sb3_er", "envs", "config"):
        assert Path(seen[key]).resolve().is_relative_to(venv.resolve()), (key, seen[key])
        assert not Path(seen[key]).resolve().is_relative_to(ROOT), (key, seen[key])
    import sb3_er

    assert seen["metadata"] == sb3_er.__version__  # one source for the version: pyproject reads sb3_er.__version__
    # The code version the records compare: the same files, the same hash and version as the checkout's.
    assert seen["files"] == sorted(records.code_files())
    assert seen["code"]["code_sha256"] == records.code_hash()
    assert seen["code"]["sb3_er_version"] == sb3_er.__version__
    assert seen["code"]["git_commit"] is None  # an installed wheel has no commit


def test_the_readme_quickstart_runs_from_the_wheel(venv, tmp_path):
    blocks = readme_quickstart()
    assert blocks
    for block in blocks:
        run(venv, [str(venv / "bin" / "python"), "-c", block], tmp_path)


def test_rl_zoo_training_runs_from_the_wheel(venv, tmp_path):
    run(
        venv,
        [
            "sb3-er",
            "train",
            "--algo",
            "er",
            "--env",
            "sb3_er/WindyCliff-v0",
            "-n",
            "500",
            "--seed",
            "0",
            "--eval-freq",
            "-1",
        ],
        tmp_path,
    )
    assert list((tmp_path / "logs" / "er").glob("sb3_er-WindyCliff-v0_*/sb3_er-WindyCliff-v0.zip"))


def test_reproduce_runs_from_the_wheel(venv, tmp_path):
    result = run(
        venv,
        ["sb3-er", "reproduce", "gridworld", "--seeds", "1", "--budget", "3", "--no-progress", "--jobs", "1"],
        tmp_path,
    )
    # the default rows, one seed each: the thesis's five algorithms and the stable learner's four
    assert re.search(r"^9 runs done", result.stdout, flags=re.MULTILINE)
    assert "(stable)" in result.stdout
    out = tmp_path / "results" / "gridworld"
    assert (out / "summary.md").is_file()
    record = json.loads(next((out / "runs").glob("*/seed_0.json")).read_text())
    assert record["code_sha256"] == records.code_hash() and record["git_commit"] is None

"""Fault injection with real signals and real files: killed workers and drivers, two drivers on one folder, damaged
run, record and settings files. Each case ends with the files of an uninterrupted reproduction (timings, host and
dates aside), and with no process of the command left.

The cheapest reproduction: the pendulum, two seeds of vanilla ER, two learning episodes per run (under a second each).
"""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from processes import alive, name, tree, wait_for

from sb3_er.cli import main
from sb3_er.experiments import files, records
from sb3_er.experiments.reproduce import reproduce
from sb3_er.experiments.runner import WORKER_NAME, DamagedRunWarning, RecordUpgradeWarning, read_run_csv, run_csv_path

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc (Linux)")

SETTINGS = {"n_seeds": 2, "algos": ["er"], "budget": 2, "show_progress": False}
COMMAND = ["reproduce", "pendulum", "--seeds", "2", "--algos", "er", "--budget", "2", "--no-progress"]
VOLATILE = {"host", "finished_at", "wall_time_s", "checksum"}  # differ between two runs of the same job


# --- what the files hold, without the volatile parts ---


def _comparable(folder: Path) -> dict[str, object]:
    """Every kept file under `folder` by relative path: CSVs without their wall times, records without host, times
    and checksums (the CSV's checksum covers its wall times), summary.md without its wall-time line, other files as
    bytes. Moved-aside files and the lock file are left out (the tests look at them on their own)."""
    content = {}
    for path in sorted(folder.rglob("*")):
        if not path.is_file() or path.name == files.LOCK_NAME or ".damaged-" in path.name:
            continue
        name = path.relative_to(folder).as_posix()
        if path.suffix == ".csv":
            frame = pd.read_csv(path)
            content[name] = frame.drop(columns=[c for c in frame.columns if c == "wall_time_s"]).to_csv(index=False)
        elif path.name.startswith("seed_") and path.suffix == ".json":
            record = json.loads(path.read_text())
            record["files"] = {file: entry.get("rows") for file, entry in record["files"].items()}
            content[name] = {key: value for key, value in record.items() if key not in VOLATILE}
        elif path.name == "summary.md":
            content[name] = [line for line in path.read_text().splitlines() if "wall time" not in line]
        else:
            content[name] = path.read_bytes()
    return content


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    """The folder of an uninterrupted reproduction, made once."""
    folder = tmp_path_factory.mktemp("uninterrupted")
    reproduce("pendulum", out_dir=folder, n_workers=1, **SETTINGS)
    return folder


@pytest.fixture()
def finished(uninterrupted, tmp_path) -> Path:
    """A copy of the uninterrupted reproduction to damage."""
    folder = tmp_path / "out"
    shutil.copytree(uninterrupted, folder)
    (folder / files.LOCK_NAME).unlink(missing_ok=True)
    return folder


def _assert_same_files(folder: Path, uninterrupted: Path) -> None:
    assert _comparable(folder) == _comparable(uninterrupted)
    assert not list(folder.rglob(f"*{files.PARTIAL_MARK}*"))  # no temporary file left


def _workers(driver: subprocess.Popen) -> list[int]:
    """The driver's worker processes that have started their loop (they name themselves then)."""
    return [pid for pid in tree(driver.pid) if name(pid) == WORKER_NAME]


def _start_driver(folder: Path, *options: str) -> subprocess.Popen:
    """`sb3-er reproduce` in a process of its own, its output in files beside `folder` (orphans that kept a pipe open
    would hold up the test)."""
    log = folder.parent / f"driver-{time.monotonic_ns()}"
    with open(f"{log}.out", "w") as out, open(f"{log}.err", "w") as err:
        driver = subprocess.Popen(
            [sys.executable, "-m", "sb3_er.cli", *COMMAND, "--out", str(folder), *options],
            stdout=out,
            stderr=err,
            text=True,
        )
    driver.log = log
    return driver


def _finish(driver: subprocess.Popen, timeout: float = 120) -> tuple[str, str]:
    """Wait for `driver` to end; its standard output and error."""
    driver.wait(timeout=timeout)
    return Path(f"{driver.log}.out").read_text(), Path(f"{driver.log}.err").read_text()


# --- killed processes ---


@pytest.mark.slow
def test_a_killed_worker_fails_no_run_and_the_others_go_on(tmp_path, uninterrupted):
    driver = _start_driver(tmp_path / "out", "--jobs", "2")
    seen = {}
    victim = wait_for(lambda: _workers(driver)[:1], "a worker process")[0]  # it has its job as soon as it starts
    seen.update(tree(driver.pid))
    os.kill(victim, signal.SIGKILL)  # what the OOM killer does
    while driver.poll() is None:
        seen.update(tree(driver.pid))
        time.sleep(0.1)
    out, err = _finish(driver)
    assert driver.returncode == 0, err
    assert "2 runs done, 0 already finished" in out
    assert re.search(r"er/seed_\d: its worker process died \(killed by SIGKILL\); the run is started again", err)
    assert "RunFailure" not in err and "BrokenProcessPool" not in err
    _assert_same_files(tmp_path / "out", uninterrupted)
    assert wait_for(lambda: not alive(seen) or None, "the command's processes to end", 10) is True


@pytest.mark.slow
def test_a_killed_driver_leaves_no_process_and_the_rerun_completes(tmp_path, uninterrupted):
    folder = tmp_path / "out"
    driver = _start_driver(folder, "--jobs", "2")
    workers = wait_for(lambda: len(_workers(driver)) == 2 and _workers(driver), "two worker processes")
    started = tree(driver.pid)  # the workers and multiprocessing's resource tracker
    for worker in workers:
        os.kill(worker, signal.SIGSTOP)  # blocked: no chance to notice anything themselves
    os.kill(driver.pid, signal.SIGKILL)  # a scheduler's hard limit: the driver alone, no chance to clean up
    _finish(driver)
    wait_for(lambda: not alive(started) or None, f"the orphans {alive(started)} to end", 10)

    resumed = reproduce("pendulum", out_dir=folder, n_workers=1, **SETTINGS)  # the lock died with its holder
    assert resumed.runs_done + resumed.runs_skipped == 2
    _assert_same_files(folder, uninterrupted)


@pytest.mark.slow
def test_sigterm_ends_the_driver_and_its_workers(tmp_path):
    driver = _start_driver(tmp_path / "out", "--jobs", "2")
    wait_for(lambda: len(_workers(driver)) == 2 or None, "two worker processes")
    started = tree(driver.pid)
    driver.send_signal(signal.SIGTERM)  # `timeout`, a scheduler's soft limit
    _finish(driver, timeout=30)
    assert driver.returncode == 128 + signal.SIGTERM
    wait_for(lambda: not alive(started) or None, f"the workers {alive(started)} to end", 15)


# --- two drivers on one folder ---


@pytest.mark.slow
def test_a_second_driver_is_refused_and_changes_nothing(tmp_path, uninterrupted, capsys):
    folder = tmp_path / "out"
    first = _start_driver(folder, "--jobs", "1")
    lock = folder / files.LOCK_NAME
    wait_for(lambda: lock.is_file() and f"pid {first.pid} " in lock.read_text(), "the first driver's lock")
    os.kill(first.pid, signal.SIGSTOP)  # hold the first driver still while the second one tries
    try:
        before = {path: (path.stat().st_mtime_ns, path.read_bytes()) for path in folder.rglob("*") if path.is_file()}
        with pytest.raises(SystemExit) as refusal:
            main([*COMMAND, "--out", str(folder), "--jobs", "1"])
        assert refusal.value.code == 2
        message = capsys.readouterr().err
        assert f"{folder} is being written by host " in message and f"pid {first.pid} " in message
        assert "Nothing was changed" in message
        after = {path: (path.stat().st_mtime_ns, path.read_bytes()) for path in folder.rglob("*") if path.is_file()}
        assert after == before
    finally:
        os.kill(first.pid, signal.SIGCONT)
    out, err = _finish(first)
    assert first.returncode == 0, err
    _assert_same_files(folder, uninterrupted)


def test_the_lock_names_its_holder_and_is_released_when_it_ends(tmp_path):
    with files.FolderLock(tmp_path):
        text = (tmp_path / files.LOCK_NAME).read_text()
        assert f"pid {os.getpid()} " in text and "host " in text
        # another process's flock on the same file (plain fcntl, not the package's) is refused while we hold it
        probe = [
            sys.executable,
            "-c",
            "import fcntl, os, sys; fcntl.flock(os.open(sys.argv[1], os.O_RDWR), fcntl.LOCK_EX | fcntl.LOCK_NB)",
            str(tmp_path / files.LOCK_NAME),
        ]
        assert "BlockingIOError" in subprocess.run(probe, capture_output=True, text=True).stderr
    assert subprocess.run(probe, capture_output=True).returncode == 0  # released
    with files.FolderLock(tmp_path):  # taken again at once
        pass


# --- damaged files ---


def _cut(path: Path, how: str) -> None:
    data = path.read_bytes()
    lines = data.splitlines(keepends=True)
    if how == "torn":  # a write cut in the middle of its last row
        path.write_bytes(data[: len(data) - len(lines[-1]) // 2])
    elif how == "short":  # whole rows missing (the 3 of 30 episodes)
        path.write_bytes(b"".join(lines[:-1]))
    else:
        path.write_bytes(b"")


@pytest.mark.parametrize("how", ["torn", "short", "empty"])
def test_a_damaged_csv_is_moved_aside_and_rerun(finished, uninterrupted, how):
    csv_path = run_csv_path(finished, "er", 1)
    _cut(csv_path, how)
    damaged = csv_path.read_bytes()
    with pytest.warns(DamagedRunWarning, match=re.escape(str(csv_path))):
        result = reproduce("pendulum", out_dir=finished, n_workers=1, **SETTINGS)
    assert (result.runs_done, result.runs_skipped) == (1, 1)
    _assert_same_files(finished, uninterrupted)
    (kept,) = csv_path.parent.glob("seed_1.csv.damaged-*")
    assert kept.read_bytes() == damaged  # kept for whoever wants to look
    assert len(list(csv_path.parent.glob("seed_1.json.damaged-*"))) == 1


@pytest.mark.parametrize("damage", ["edited", "empty", "garbled"])
def test_a_record_that_does_not_match_is_moved_aside_and_rerun(finished, uninterrupted, damage):
    csv_path = run_csv_path(finished, "er", 0)
    record_path = records.record_path(csv_path)
    if damage == "edited":
        record = json.loads(record_path.read_text())
        record["config"]["budget"] = 20.0  # its checksum no longer matches
        record_path.write_text(json.dumps(record))
    else:
        record_path.write_bytes(b"" if damage == "empty" else record_path.read_bytes()[:100])
    with pytest.warns(DamagedRunWarning, match=re.escape(str(record_path))):
        result = reproduce("pendulum", out_dir=finished, n_workers=1, **SETTINGS)
    assert (result.runs_done, result.runs_skipped) == (1, 1)
    _assert_same_files(finished, uninterrupted)


def test_an_empty_settings_file_is_moved_aside_and_written_anew(finished, uninterrupted):
    settings = finished / "settings.json"
    settings.write_bytes(b"")
    with pytest.warns(files.DamagedFileWarning, match=re.escape(f"{settings} is empty")):
        result = reproduce("pendulum", out_dir=finished, n_workers=1, **SETTINGS)
    assert (result.runs_done, result.runs_skipped) == (0, 2)
    _assert_same_files(finished, uninterrupted)
    assert len(list(finished.glob("settings.json.damaged-*"))) == 1


def _as_before_checksums(record_path: Path) -> dict:
    record = json.loads(record_path.read_text())
    old = {key: value for key, value in record.items() if key not in ("checksum", "files")}
    old["format"] = 1
    record_path.write_text(json.dumps(old, indent=2))
    return old


def test_records_from_before_checksums_are_checked_and_upgraded_once(finished, uninterrupted):
    csv_path = run_csv_path(finished, "er", 0)
    data = csv_path.read_bytes()
    old = _as_before_checksums(records.record_path(csv_path))
    with pytest.warns(RecordUpgradeWarning, match=r"1 finished run had a record without checksums \(er/seed_0\)"):
        result = reproduce("pendulum", out_dir=finished, n_workers=1, **SETTINGS)
    assert (result.runs_done, result.runs_skipped) == (0, 2)
    upgraded = records.read_record(csv_path)
    assert upgraded["upgraded_from_format"] == 1 and upgraded["format"] == records.RECORD_FORMAT
    assert {key: upgraded[key] for key in old if key != "format"} == {k: v for k, v in old.items() if k != "format"}
    assert records.check_sealed(upgraded, csv_path) is None and csv_path.read_bytes() == data
    upgraded.pop("upgraded_from_format")
    (finished / "runs/er/seed_0.json").write_text(json.dumps(upgraded))
    _assert_same_files(finished, uninterrupted)


def test_a_short_csv_beside_a_record_from_before_checksums_is_rerun(finished, uninterrupted):
    csv_path = run_csv_path(finished, "er", 1)
    _as_before_checksums(records.record_path(csv_path))
    _cut(csv_path, "short")  # 1 of 2 episodes, well-formed: only the protocol's length tells
    with pytest.warns(DamagedRunWarning, match=re.escape(f"{csv_path} has 1 rows, its run has 2")):
        result = reproduce("pendulum", out_dir=finished, n_workers=1, **SETTINGS)
    assert (result.runs_done, result.runs_skipped) == (1, 1)
    _assert_same_files(finished, uninterrupted)


def test_read_errors_name_the_file_and_what_to_do(tmp_path):
    empty = tmp_path / "seed_0.csv"
    empty.write_bytes(b"")
    with pytest.raises(files.DamagedFileError, match=re.escape(f"{empty} is empty") + ".*rerun the command"):
        read_run_csv(empty)
    empty.with_suffix(".json").write_bytes(b"{")
    with pytest.raises(files.DamagedFileError, match=re.escape(f"{empty.with_suffix('.json')} is not valid JSON")):
        records.read_record(empty)


# --- settings and the runner's own arguments ---


@pytest.mark.parametrize("name", ["seed", "env", "policy", "self", "verbose", "tensorboard_log"])
def test_algo_kwargs_that_the_runner_sets_are_refused_before_anything_is_written(tmp_path, capsys, name):
    with pytest.raises(SystemExit) as refusal:
        main([*COMMAND, "--out", str(tmp_path / "out"), "--algo-kwargs", f"{name}:5"])
    assert refusal.value.code == 2
    assert f"--algo-kwargs cannot set {name}: " in capsys.readouterr().err
    with pytest.raises(ValueError, match=f"--algo-kwargs cannot set {name}: "):
        reproduce("pendulum", out_dir=tmp_path / "out", algo_kwargs={name: 5}, **SETTINGS)
    assert not (tmp_path / "out").exists()


def test_a_folder_whose_runs_all_failed_takes_the_corrected_command(tmp_path, uninterrupted):
    folder = tmp_path / "out"
    folder.mkdir()
    # what a command whose every run failed left behind before settings waited for a finished run
    (folder / "settings.json").write_text(
        json.dumps(
            {
                "experiment": "pendulum",
                "env_id": "sb3_er/PendulumSwingup-v0",
                "budget": 2.0,
                "algo_kwargs": {"seed": 5},
                "env_kwargs": {},
            }
        )
    )
    reproduce("pendulum", out_dir=folder, n_workers=1, **SETTINGS)
    _assert_same_files(folder, uninterrupted)

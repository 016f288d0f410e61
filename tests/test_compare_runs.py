"""benchmarks/compare_runs.py: a rerun's per-run CSVs against the committed ones, wall times and the watch's count
aside (issue 39's check that the literal runs are unchanged)."""

import importlib.util
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "results" / "measured" / "table_6_2"


def load():
    spec = importlib.util.spec_from_file_location("compare_runs", ROOT / "benchmarks" / "compare_runs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def copy_runs(tmp_path: Path, algos=("er_sigma", "sarsa_lambda")) -> Path:
    rerun = tmp_path / "rerun"
    for algo in algos:
        shutil.copytree(COMMITTED / "runs" / algo, rerun / "runs" / algo, ignore=shutil.ignore_patterns("*.gif"))
    return rerun


def edit(path: Path, row: int, column: str, value: str) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def test_a_copy_with_other_wall_times_and_watch_counts_is_equal(tmp_path, capsys):
    compare_runs = load()
    rerun = copy_runs(tmp_path)
    edit(rerun / "runs" / "er_sigma" / "seed_0.csv", 2, "wall_time_s", "123.0")
    edit(rerun / "runs" / "er_sigma" / "seed_1.csv", 3, "values_out_of_range", "99")
    assert compare_runs.main([str(COMMITTED), str(rerun), "--algos", "er_sigma", "sarsa_lambda"]) == 0
    out = capsys.readouterr().out
    assert "er_sigma: 20 runs, 20 equal, 0 differing, 0 missing" in out


def test_a_changed_distance_a_missing_run_and_a_new_column_are_differences(tmp_path, capsys):
    compare_runs = load()
    rerun = copy_runs(tmp_path)
    edit(rerun / "runs" / "er_sigma" / "seed_3.csv", 5, "distance", "0.5")
    (rerun / "runs" / "sarsa_lambda" / "seed_7.csv").unlink()
    assert compare_runs.main([str(COMMITTED), str(rerun), "--algos", "er_sigma", "sarsa_lambda"]) == 1
    out = capsys.readouterr().out
    assert "seed_3: row 5, distance:" in out and "0.5 rerun" in out
    assert "sarsa_lambda: 20 runs, 19 equal, 0 differing, 1 missing" in out and "missing: seed_7" in out
    report = compare_runs.compare(COMMITTED, rerun, {"wall_time_s"}, ["sarsa_lambda"])
    assert report["sarsa_lambda"]["missing"] == ["seed_7"]
    path = rerun / "runs" / "sarsa_lambda" / "seed_0.csv"
    path.write_text(path.read_text().replace("diverged", "diverged,q_max", 1))
    assert "columns in one file only: q_max" in compare_runs.first_difference(
        COMMITTED / "runs" / "sarsa_lambda" / "seed_0.csv", path, {"wall_time_s"}
    )


def test_a_folder_without_runs_is_refused(tmp_path):
    with pytest.raises(SystemExit):
        load().main([str(COMMITTED), str(tmp_path)])

"""benchmarks/watch_counts.py: how far each row's runs left the possible returns, on hand-made runs whose figures are
computed by hand, and its refusal of runs whose files do not match their records."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from sb3_er.experiments import files, records

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "watch_counts.py"


def load_script():
    spec = importlib.util.spec_from_file_location("watch_counts_under_test", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


wc = load_script()
BOUNDS = {"low": -100.0, "high": 0.0, "margin": 0.5}


def write_run(folder: Path, row: str, seed: int, counts: list[int] | None, excursion=None, diverged=False) -> Path:
    """runs/<row>/seed_<seed>.csv with the watch's cumulative counts per row (None: a run from before the watch)
    and its sealed record."""
    path = folder / "runs" / row / f"seed_{seed}.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    header = "episode,return" + ("" if counts is None else ",values_out_of_range") + ",diverged"
    lines = [header]
    for index, count in enumerate(counts if counts is not None else [None, None]):
        last = diverged and index == len(counts or [None, None]) - 1
        lines.append(f"{index + 1},-5.0" + ("" if count is None else f",{count}") + f",{last}")
    data = ("\n".join(lines) + "\n").encode()
    path.write_bytes(data)
    record = records.sealed({"value_excursion": excursion}, path.name, data)
    files.write_json(records.record_path(path), record)
    return path


def test_rows_counted_as_by_hand(tmp_path):
    # vanilla ER: three runs; two left (10 and 4 values at their ends), the first values 2.5 and 0.75 above 0.
    write_run(tmp_path, "er", 0, [0, 3, 10], {**BOUNDS, "value": 2.5, "step": 300})
    write_run(tmp_path, "er", 1, [0, 0, 4], {**BOUNDS, "value": 0.75, "step": 100})
    write_run(tmp_path, "er", 2, [0, 0, 0])
    (tmp_path / "runs" / "er" / "seed_0_gait.csv").write_text("t,x\n0,0\n")  # a gait file is no run
    # Sarsa(lambda): one run, below the lower bound by 1.5, and diverged.
    write_run(tmp_path, "sarsa_lambda", 0, [0, 7], {**BOUNDS, "value": -101.5, "step": 50}, diverged=True)
    # residual ER: made before the watch.
    write_run(tmp_path, "residual_er", 0, None)
    text = wc.watch_counts(tmp_path, "python benchmarks/watch_counts.py X")
    lines = text.splitlines()
    table = [line for line in lines if line.startswith("| ") and not line.startswith("| row")]
    assert table == [  # the rows in the tables' order: Sarsa(lambda) first
        "| Sarsa(λ) | 1 | 1 | 1 | 7; 7 | 1.50 to 1.50 | 50 |",
        "| vanilla-ER | 3 | 2 | 0 | 4; 10 | 0.75 to 2.50 | 200 |",  # median of 0, 4, 10; of steps 100 and 300
        "| residual ER | 1 | not watched | 0 | — | — | — |",
    ]
    assert "Possible returns [-100, 0]; a value counts as outside beyond a margin of 0.5." in lines
    assert "Written by `python benchmarks/watch_counts.py X`" in text


def test_an_edited_run_is_refused_by_name(tmp_path):
    path = write_run(tmp_path, "er", 0, [0, 1], {**BOUNDS, "value": 2.5, "step": 300})
    path.write_text(path.read_text().replace(",1,", ",0,"))
    with pytest.raises(wc.RunsError, match="seed_0"):
        wc.watch_counts(tmp_path, "x")
    assert wc.main([str(tmp_path)]) == 2
    assert not (tmp_path / wc.OUTPUT).exists()


def test_the_command_writes_its_file(tmp_path, capsys):
    write_run(tmp_path, "er", 0, [0, 2], {**BOUNDS, "value": 1.0, "step": 10})
    assert wc.main([str(tmp_path)]) == 0
    written = (tmp_path / wc.OUTPUT).read_text(encoding="utf-8")
    assert written == capsys.readouterr().out.rstrip("\n") + "\n"
    assert "| vanilla-ER | 1 | 1 | 0 | 2; 2 | 1.00 to 1.00 | 10 |" in written
    json.loads((tmp_path / "runs" / "er" / "seed_0.json").read_text())  # untouched

"""How far each row of a table reproduction left the possible returns, from its committed runs: the value watch's
counts, not only whether a run left them.

    python benchmarks/watch_counts.py results/measured/table_6_1 [more folders ...]

A table's summary says how many runs of each row left the possible returns (``docs/value_watch.md``); a run that left
them once by a rounding's worth counts there as much as one that left them millions of times. Per row of each
folder (``runs/<row>/seed_<n>.csv`` with the version record beside, checked against its checksums when read), this
prints and writes (atomically) ``<folder>/watch_counts.md``:

- the runs, those whose values left the possible returns and those that diverged;
- the values the watch counted outside over a whole run (the ``values_out_of_range`` column at the run's last row,
  a count since the run began): the median over the row's runs and the largest;
- the first value counted outside (the record's ``value_excursion``): by how much it lay beyond the bound it crossed,
  least and most over the runs, and the median step (env steps since the run began) at which it came.

The bounds and the margin (5 % of the largest reward) are those the runs' records name. Runs made before the value
watch (no ``values_out_of_range`` column) are counted as not watched.
"""

from __future__ import annotations

import argparse
import csv
import re
import shlex
import statistics
import sys
from pathlib import Path

from sb3_er.common.atomic import write_atomically
from sb3_er.experiments import records
from sb3_er.experiments.summary import format_figure
from sb3_er.experiments.thesis import ALGORITHM_LABELS

OUTPUT = "watch_counts.md"


class RunsError(ValueError):
    """A run of a folder whose files do not match their record, or that cannot be read."""


def read_run(csv_path: Path) -> dict:
    """One run's watch figures: counted (None: not watched), diverged, the first excursion's distance and step."""
    record = records.read_record(csv_path)
    if record is None:
        raise RunsError(f"{csv_path}: no version record beside it")
    problem = records.check_sealed(record, csv_path)
    if problem:
        raise RunsError(problem)
    with csv_path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
        columns = reader.fieldnames or []
    if not rows:
        raise RunsError(f"{csv_path}: no rows")
    last = rows[-1]
    counted = int(last["values_out_of_range"]) if "values_out_of_range" in columns else None
    diverged = str(last.get("diverged", "False")).strip().lower() == "true"
    excursion = record.get("value_excursion")
    distance = step = bounds = None
    if isinstance(excursion, dict):
        value = float(excursion["value"])
        low = float("-inf") if excursion.get("low") is None else float(excursion["low"])  # LEO's: none below
        high = float("inf") if excursion.get("high") is None else float(excursion["high"])
        distance = value - high if value > high else low - value
        step = int(excursion["step"])
        margin = excursion.get("margin")  # records from before the margin of 5 % of the largest reward lack it
        bounds = (low, high, None if margin is None else float(margin))
    return {"counted": counted, "diverged": diverged, "distance": distance, "step": step, "bounds": bounds}


def _bound(value: float) -> str:
    """A bound to one decimal, digits grouped, without trailing zeros: -10,485.4, 0, 10.5; -inf and inf as such."""
    if value in (float("inf"), float("-inf")):
        return "-∞" if value < 0 else "∞"
    return f"{value:,.1f}".rstrip("0").rstrip(".")


def row_line(label: str, runs: list[dict]) -> str:
    """The table line of one row."""
    watched = [run for run in runs if run["counted"] is not None]
    left = sum(1 for run in watched if run["counted"] > 0)
    diverged = sum(run["diverged"] for run in runs)
    if not watched:
        return f"| {label} | {len(runs)} | not watched | {diverged} | — | — | — |"
    counts = [run["counted"] for run in watched]
    distances = [run["distance"] for run in watched if run["distance"] is not None]
    steps = [run["step"] for run in watched if run["step"] is not None]
    counted = f"{format_figure(statistics.median(counts), whole=True)}; {format_figure(max(counts), whole=True)}"
    beyond = (
        "—" if not distances else f"{format_figure(min(distances), max(distances))} to {format_figure(max(distances))}"
    )
    at = "—" if not steps else format_figure(statistics.median(steps), whole=True)
    return f"| {label} | {len(runs)} | {left} | {diverged} | {counted} | {beyond} | {at} |"


def watch_counts(folder: Path, command: str) -> str:
    """The Markdown of `folder`'s watch counts (module docstring)."""
    runs_folder = folder / "runs"
    if not runs_folder.is_dir():
        raise RunsError(f"{folder}: no runs/ folder (a results folder of sb3-er reproduce)")
    rows = sorted(
        (path for path in runs_folder.iterdir() if path.is_dir()),
        key=lambda path: (list(ALGORITHM_LABELS).index(path.name) if path.name in ALGORITHM_LABELS else 99, path.name),
    )
    lines = [
        f"# How far the runs left the possible returns: {folder.name}",
        "",
        f"Written by `{command}` from the runs' CSVs and version records.",
        "",
        "| row | runs | left the possible returns | diverged | values counted outside in a run (median; largest) "
        "| first value counted outside: beyond its bound by | its step (median) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    bounds = set()
    for row in rows:
        paths = sorted(
            (path for path in row.glob("seed_*.csv") if re.fullmatch(r"seed_\d+", path.stem)),  # not seed_0_gait.csv
            key=lambda path: int(path.stem.split("_")[1]),
        )
        if not paths:
            continue
        runs = [read_run(path) for path in paths]
        bounds.update(run["bounds"] for run in runs if run["bounds"] is not None)
        lines.append(row_line(ALGORITHM_LABELS.get(row.name, row.name), runs))
    lines.append("")
    for low, high, margin in sorted(bounds, key=lambda entry: (entry[0], entry[1], entry[2] or 0.0)):
        beyond = "" if margin is None else f"; a value counts as outside beyond a margin of {_bound(margin)}"
        lines.append(f"Possible returns [{_bound(low)}, {_bound(high)}]{beyond}.")
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="results folders of sb3-er reproduce")
    args = parser.parse_args(argv)
    for folder in args.folders:
        command = shlex.join(["python", "benchmarks/watch_counts.py", folder.as_posix()])
        try:
            text = watch_counts(folder, command)
        except (RunsError, ValueError, KeyError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        write_atomically(folder / OUTPUT, text)
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Whether the per-run CSVs of a rerun equal the committed ones, column by column, except the columns a rerun may
change (wall times, and the value watch's counts when the watch itself changed).

    python benchmarks/compare_runs.py COMMITTED RERUN [--ignore wall_time_s values_out_of_range ...] [--algos ...]

COMMITTED and RERUN are results folders of ``sb3-er reproduce`` (each with ``runs/<algo>/seed_<n>.csv``). Every run
of COMMITTED is looked up in RERUN; a run is *equal* when both CSVs have the same rows and the same value in every
column both have, ignored columns aside, compared exactly (the CSVs are read as text, so 0.1 and 0.10 differ only if
written so). A column one file has and the other lacks is a difference unless ignored. Printed: a line per algorithm
(runs compared, equal, differing, missing from the rerun) and, for each differing run, its first differing row and
column with both values. Exit status 1 when any run differs or is missing, so that a script can rely on it.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

#: Columns a rerun of the same code and seeds may change: wall-clock time, and the value watch's count.
DEFAULT_IGNORE = ("wall_time_s", "values_out_of_range")


def read_rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    """The header and rows of a CSV, every value as its text."""
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        return list(reader.fieldnames or []), list(reader)


def first_difference(committed: Path, rerun: Path, ignore: set[str]) -> str | None:
    """None when the two CSVs are equal outside `ignore`, else the first difference in words."""
    columns_a, rows_a = read_rows(committed)
    columns_b, rows_b = read_rows(rerun)
    only = sorted((set(columns_a) ^ set(columns_b)) - ignore)
    if only:
        return f"columns in one file only: {', '.join(only)}"
    if len(rows_a) != len(rows_b):
        return f"{len(rows_a)} rows committed, {len(rows_b)} rerun"
    compared = [column for column in columns_a if column in columns_b and column not in ignore]
    for index, (row_a, row_b) in enumerate(zip(rows_a, rows_b, strict=True)):
        for column in compared:
            if row_a[column] != row_b[column]:
                return f"row {index + 1}, {column}: {row_a[column]} committed, {row_b[column]} rerun"
    return None


def compare(committed: Path, rerun: Path, ignore: set[str], algos: list[str] | None = None) -> dict[str, dict]:
    """Per algorithm of `committed`: the runs compared, equal, differing (seed -> first difference) and missing."""
    report = {}
    for folder in sorted((committed / "runs").iterdir()):
        if not folder.is_dir() or (algos and folder.name not in algos):
            continue
        entry = {"compared": 0, "equal": 0, "differing": {}, "missing": []}
        for path in sorted(folder.glob("seed_*.csv")):
            if not path.stem.removeprefix("seed_").isdigit():
                continue  # seed_<n>_gait.csv and other per-run files
            entry["compared"] += 1
            other = rerun / "runs" / folder.name / path.name
            if not other.is_file():
                entry["missing"].append(path.stem)
                continue
            difference = first_difference(path, other, ignore)
            if difference is None:
                entry["equal"] += 1
            else:
                entry["differing"][path.stem] = difference
        report[folder.name] = entry
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("committed", type=Path)
    parser.add_argument("rerun", type=Path)
    parser.add_argument("--ignore", nargs="*", default=list(DEFAULT_IGNORE), help="columns a rerun may change")
    parser.add_argument("--algos", nargs="*", default=None, help="only these algorithms (default: every one)")
    args = parser.parse_args(argv)
    for folder in (args.committed, args.rerun):
        if not (folder / "runs").is_dir():
            parser.error(f"{folder}: no runs/ folder (not a results folder of sb3-er reproduce)")
    report = compare(args.committed, args.rerun, set(args.ignore), args.algos)
    print(f"{args.rerun} against {args.committed}, ignoring {', '.join(args.ignore) or 'nothing'}:")
    failed = False
    for algo, entry in report.items():
        print(
            f"  {algo}: {entry['compared']} runs, {entry['equal']} equal, {len(entry['differing'])} differing, "
            f"{len(entry['missing'])} missing from the rerun"
        )
        for seed, difference in entry["differing"].items():
            print(f"    {seed}: {difference}")
        if entry["missing"]:
            print(f"    missing: {', '.join(entry['missing'])}")
        failed |= bool(entry["differing"] or entry["missing"])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

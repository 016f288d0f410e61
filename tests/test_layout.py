"""Module boundaries: the version records describe jobs through the job module, not the runner (which uses the
records), and the default tilings live with the tile coder."""

from __future__ import annotations

import ast
from pathlib import Path

import sb3_er

PACKAGE = Path(sb3_er.__file__).resolve().parent


def imported_modules(path: Path) -> set[str]:
    """Every module `path` imports, at module level or inside functions."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def test_runner_and_records_do_not_import_each_other():
    """The runner writes records (it imports them); the records describe jobs without the runner: no cycle."""
    runner = imported_modules(PACKAGE / "experiments" / "runner.py")
    records = imported_modules(PACKAGE / "experiments" / "records.py")
    assert "sb3_er.experiments.runner" not in records
    assert "sb3_er.experiments.jobs" in records and "sb3_er.experiments.jobs" in runner


def test_the_default_tilings_live_in_the_tile_coding_module():
    from sb3_er.common import base_class, tile_coding

    for name in ("default_tile_widths", "default_tiles_per_dimension", "varying_dimensions", "package_tilings"):
        assert getattr(tile_coding, name).__module__ == "sb3_er.common.tile_coding"
    source = (PACKAGE / "common" / "base_class.py").read_text(encoding="utf-8")
    assert "def default_tile_widths" not in source and "yaml" not in source
    assert base_class.resolve_tiling is tile_coding.resolve_tiling  # what the algorithms use

"""The benchmark pages' generated parts: ``{sample-efficiency} tasks|methods|results``.

The sample-efficiency page (docs/benchmarks/sample_efficiency.md) states its method in prose; its tables come from the
benchmark itself, so that no figure is copied by hand:

- ``tasks``: the tasks, budgets, evaluation protocols, targets and where each came from (the TASKS table of
  benchmarks/sample_efficiency.py);
- ``methods``: the methods and how each is built (its METHODS table), and whether today's package runs each;
- ``results``: the committed ``results/measured/sample_efficiency/summary.md`` and its figure, or, while that folder
  holds no summary yet, a sentence saying how many runs of the benchmark in progress are committed (or that none is).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
SCRIPT = ROOT / "benchmarks" / "sample_efficiency.py"
RESULTS = ROOT / "results" / "measured" / "sample_efficiency"
PARTS = ("tasks", "methods", "results")


def load_benchmark():
    """benchmarks/sample_efficiency.py as a module (the benchmarks folder is no package)."""
    if "sample_efficiency" in sys.modules:
        return sys.modules["sample_efficiency"]
    spec = importlib.util.spec_from_file_location("sample_efficiency", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["sample_efficiency"] = module
    spec.loader.exec_module(module)
    return module


def results_markdown(results: Path = RESULTS, relative_to: Path = DOCS / "benchmarks") -> str:
    """The results part: summary.md (its own title left out, the page has one) and the figure, or the note that they
    are not committed yet.

    :param results: the results folder.
    :param relative_to: the folder of the page that shows them (image paths are relative to it).
    """
    summary = results / "summary.md"
    if not summary.is_file():
        runs = results / "runs.json"
        if runs.is_file():
            import json

            finished = len(json.loads(runs.read_text(encoding="utf-8"))["runs"])
            return (
                f"The benchmark is in progress: {finished:,} finished runs are committed so far "
                f"(`results/measured/{results.name}/runs.json`, whose README says how far it has come), and its "
                "summary is written when every run has finished. The first command below resumes it.\n"
            )
        return (
            f"The results are not committed yet: `results/measured/{results.name}/` holds no `summary.md`. The command "
            "below makes them.\n"
        )
    lines = summary.read_text(encoding="utf-8").splitlines()
    if lines and lines[0].startswith("# "):
        lines = lines[1:]
    load_benchmark()
    figure = results / sys.modules["sample_efficiency"].FIGURE
    if figure.is_file():
        import os

        where = Path(os.path.relpath(figure, relative_to)).as_posix()
        lines += [
            "",
            f"```{{figure}} {where}",
            ":alt: each method's median samples to the target over Sarsa(λ)'s, task by task",
            "",
            "Each method's median samples to the target divided by Sarsa(λ)'s, task by task (log scale; below the "
            "dashed line: at most half of Sarsa(λ)'s samples; open markers at the top: never reached, at the "
            "bottom: reached where Sarsa(λ) never did).",
            "```",
        ]
    return "\n".join(lines) + "\n"


def part_markdown(part: str) -> str:
    """The Markdown of one part of the page (PARTS)."""
    if part not in PARTS:
        raise ValueError(f"unknown part {part!r} of the sample-efficiency page; choose one of {', '.join(PARTS)}")
    if part == "results":
        return results_markdown()
    benchmark = load_benchmark()
    return benchmark.tasks_table() if part == "tasks" else benchmark.methods_table()


def _directive():
    from docutils import nodes
    from docutils.parsers.rst import Directive
    from docutils.statemachine import StringList

    class SampleEfficiency(Directive):
        required_arguments = 1
        has_content = False

        def run(self):
            environment = self.state.document.settings.env
            for path in (SCRIPT, RESULTS / "summary.md"):  # rebuild the page when either changes
                environment.note_dependency(str(path))
            container = nodes.container(classes=["sample-efficiency"])
            text = part_markdown(self.arguments[0])
            self.state.nested_parse(StringList(text.splitlines()), self.content_offset, container)
            return [container]

    return SampleEfficiency


def setup(app):
    app.add_directive("sample-efficiency", _directive())
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}

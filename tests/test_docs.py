"""The documentation: the Sphinx build passes with warnings as errors, every results folder is shown by a page, the
verdict table is generated from the findings files, and nothing a user reads cites commit hashes or files outside the
repository."""

from __future__ import annotations

import html
import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _load_generator():
    spec = importlib.util.spec_from_file_location("sb3er_docs", DOCS / "_ext" / "sb3er_docs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["sb3er_docs"] = module
    spec.loader.exec_module(module)
    return module


generator = _load_generator()
# A commit hash (7-40 hex digits with at least one letter and one digit) in prose.
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")


def hand_written_pages() -> list[Path]:
    """The documentation's own Markdown (the generated results pages and the build are left out)."""
    return sorted(p for p in DOCS.rglob("*.md") if not p.relative_to(DOCS).parts[0] in ("_build", "results"))


def page_text(path: Path) -> str:
    text = html.unescape(re.sub(r"<[^>]+>", " ", path.read_text(encoding="utf-8")))
    return text.translate(str.maketrans("\u2018\u2019\u201c\u201d", "''\"\""))  # Sphinx's smart quotes


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """The HTML site, built from scratch as `make docs` builds it (-W: any warning fails)."""
    out = tmp_path_factory.mktemp("html")
    result = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html",
                             str(DOCS), str(out)], capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert result.returncode == 0, f"the docs build has warnings or errors:\n{result.stderr[-6000:]}"
    return out


@pytest.mark.slow
def test_every_results_folder_is_shown_by_a_page(built):
    folders = generator.result_dirs()
    assert {"walker", "leo", "pendulum", "gridworld", "framework"} <= set(folders)
    pages = {path: page_text(path) for path in built.rglob("*.html")}
    for folder in folders:
        shown = [path for path, text in pages.items() if f"results/measured/{folder}/" in text]
        assert shown, f"no page shows results/measured/{folder}"
        summary = ROOT / "results" / "measured" / folder / "summary.md"
        if summary.is_file():  # its table is on the page, not only its name
            rows = summary.read_text().splitlines()
            first_row = next(line for line in rows if line.startswith("| ") and "---" not in line)
            cells = [cell.strip() for cell in first_row.strip("|").split("|") if cell.strip()]
            assert any(all(html.unescape(cell).replace("`", "") in text for cell in cells[:3]) for text in
                       (pages[path] for path in shown)), f"results/measured/{folder}/summary.md is not included"
        for figure in (ROOT / "results" / "measured" / folder).rglob("*.png"):
            if "runs" not in figure.relative_to(ROOT / "results" / "measured" / folder).parts:
                assert (built / "_images" / figure.name).is_file() or list((built / "_images").glob(
                    f"{figure.stem}*{figure.suffix}")), f"{figure} is not on any page"


@pytest.mark.slow
def test_the_cli_reference_is_generated_from_the_parser_tree(built):
    text = page_text(built / "cli.html")
    from sb3_er.cli import build_parser

    (commands,) = build_parser()._subparsers._group_actions  # the sub-command action of the tree
    assert set(commands.choices) == {"reproduce", "train", "enjoy", "optimize"}
    for command in commands.choices:
        assert re.search(rf"\b{command}\b", text), command
    for option in ("--seeds", "--allow-mixed-versions", "--backend", "--env-kwargs"):
        assert option in text


@pytest.mark.slow
def test_algorithm_pages_list_every_parameter(built):
    from sb3_er import ERSigma
    from sb3_er.common.docstrings import accepted_parameters

    text = page_text(built / "algorithms" / "er_sigma.html")
    for section in ("Notes", "Can I use?", "Example", "Results", "Parameters"):
        assert section in text
    for name in accepted_parameters(ERSigma):
        assert re.search(rf"\b{name}\b", text), name


def test_verdicts_say_not_judged_yet_without_findings_and_read_them_when_present(tmp_path):
    measured = tmp_path / "measured"
    (measured / "table_6_2").mkdir(parents=True)
    (measured / "leo").mkdir()
    (measured / "extra").mkdir()
    assert generator.verdict_rows(measured) == [("table_6_2", generator.THESIS_RESULTS["table_6_2"].thesis, "",
                                                 "not judged yet"),
                                                ("leo", generator.THESIS_RESULTS["leo"].thesis, "", "not judged yet")]
    (measured / "table_6_2" / "findings.json").write_text(json.dumps({"findings": [
        {"claim": "ER-sigma rises faster than Sarsa(lambda)", "holds": False, "evidence": "2400 s against 1800 s"},
        {"claim": "vanilla ER walks", "holds": True}]}))
    (measured / "extra" / "findings.json").write_text(json.dumps({"thesis": "Figure 7.1", "findings": [
        {"claim": "a | b", "holds": None}]}))
    rows = generator.verdict_rows(measured)
    assert rows[:2] == [("table_6_2", "Table 6.2, Figures 6.1b and 6.2a", "ER-sigma rises faster than Sarsa(lambda)",
                         "does not hold"),
                        ("table_6_2", "Table 6.2, Figures 6.1b and 6.2a", "vanilla ER walks", "holds")]
    assert rows[2][3] == "not judged yet" and rows[3] == ("extra", "Figure 7.1", "a | b", "inconclusive")
    table = generator.verdict_table(lambda name: f"{name}.md", measured)
    assert ("| [Simplest walker](table_6_2.md) | Table 6.2, Figures 6.1b and 6.2a | vanilla ER walks | holds | — |"
            in table)
    assert "a \\| b" in table  # a bar in a claim cannot break the table


def test_each_table_says_which_regime_er_sigma_was_in(tmp_path):
    """The sigma-regime summary names the table folder of each reading: its page and verdict rows say which way σ
    moved the targets there, from the committed figures."""
    measured = tmp_path / "measured"
    (measured / "table_6_1").mkdir(parents=True)
    (measured / "table_6_1" / "findings.json").write_text(json.dumps({"findings": [{"claim": "c", "holds": True}]}))
    (measured / "sigma_regime").mkdir()
    (measured / "sigma_regime" / "summary.csv").write_text(
        "reading,results,runs,phases,mean_shift,raised,lowered,left_bounds,diverged\n"
        "pendulum-0.33,table_6_1,4,400,-20.6,0.003,0.125,0,0\n"
        "walker-optimistic,,4,4275,1030000.0,0.23,0.072,3,0\n")
    sentence = generator.sigma_regime("table_6_1", measured)
    assert sentence.startswith("ER-σ's σ lowered its targets") and "-20.6 over 400 replay phases of 4 runs" in sentence
    assert "raised 0.3%, lowered 12.5%" in sentence and "in 0 of 4 runs" in sentence
    assert generator.sigma_regime("leo", measured) == ""
    table = generator.verdict_table(lambda name: f"{name}.md", measured)
    assert "| c | holds | lowered targets |" in table


@pytest.mark.parametrize("content, problem", [
    ("{", "not JSON"),
    ("[]", "a list 'findings'"),
    ('{"findings": [{"holds": true}]}', "'claim'"),
    ('{"findings": [{"claim": "x", "holds": "yes"}]}', "'holds': true, false or null"),
    ('{"findings": [{"claim": "x", "holds": true, "evidence": 3}]}', "'evidence'"),
])
def test_a_malformed_findings_file_is_an_error_naming_it(tmp_path, content, problem):
    (tmp_path / "walker").mkdir()
    (tmp_path / "walker" / "findings.json").write_text(content)
    with pytest.raises(generator.FindingsError, match=re.escape(problem)) as error:
        generator.read_findings("walker", tmp_path)
    assert "walker/findings.json" in str(error.value)


def test_the_readme_verdict_table_is_generated_and_current():
    assert generator.README_START in (ROOT / "README.md").read_text()
    assert generator.update_readme(check=True), "run: python docs/_ext/sb3er_docs.py readme"


def test_no_commit_hashes_or_history_in_the_prose_a_user_reads():
    for path in [ROOT / "README.md", *hand_written_pages()]:
        text = path.read_text(encoding="utf-8")
        text = re.sub(r"```.*?```", "", text, flags=re.DOTALL)  # commands and their output may show hashes
        assert not HASH.findall(text), f"{path.relative_to(ROOT)} cites commits: {HASH.findall(text)[:5]}"
        assert not re.search(r"\b[Ii]ssue \d+", text), f"{path.relative_to(ROOT)} speaks of the project's issues"


def test_nothing_in_the_package_cites_a_file_outside_the_repository():
    from sb3_er.experiments.records import code_files

    outside = ("DESIGN.md", "walker_readings.md", "leo_reference.md", "../shared", "/work/shared")
    for name, path in code_files().items():
        text = path.read_text(encoding="utf-8")
        for citation in outside:
            assert citation not in text, f"{name} cites {citation}"
def test_the_readme_table_holds_the_default_readings_only(tmp_path):
    measured = tmp_path / "measured"
    for name in ("table_6_1", "table_6_1_earlier_default", "extra"):
        (measured / name).mkdir(parents=True)
        (measured / name / "findings.json").write_text(json.dumps({"findings": [{"claim": name, "holds": True}]}))
    assert [row[0] for row in generator.verdict_rows(measured)] == ["table_6_1", "table_6_1_earlier_default", "extra"]
    assert [row[0] for row in generator.verdict_rows(measured, defaults_only=True)] == ["table_6_1"]

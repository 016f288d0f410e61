"""The documentation: the Sphinx build passes with warnings as errors, every results folder is shown by a page, the
verdict table is generated from the findings files, and nothing a user reads cites commit hashes or files outside the
repository."""

from __future__ import annotations

import html
import importlib.util
import inspect
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
    return sorted(p for p in DOCS.rglob("*.md") if p.relative_to(DOCS).parts[0] not in ("_build", "results"))


def page_text(path: Path) -> str:
    text = html.unescape(re.sub(r"<[^>]+>", " ", path.read_text(encoding="utf-8")))
    return text.translate(str.maketrans("\u2018\u2019\u201c\u201d", "''\"\""))  # Sphinx's smart quotes


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """The HTML site, built from scratch as `make docs` builds it (-W: any warning fails)."""
    out = tmp_path_factory.mktemp("html")
    result = subprocess.run(
        [sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(out)],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
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
            assert any(
                all(html.unescape(cell).replace("`", "") in text for cell in cells[:3])
                for text in (pages[path] for path in shown)
            ), f"results/measured/{folder}/summary.md is not included"
        for figure in (ROOT / "results" / "measured" / folder).rglob("*.png"):
            if "runs" not in figure.relative_to(ROOT / "results" / "measured" / folder).parts:
                assert (built / "_images" / figure.name).is_file() or list(
                    (built / "_images").glob(f"{figure.stem}*{figure.suffix}")
                ), f"{figure} is not on any page"


#: How a results folder names the command that made it: an ``sb3-er`` command, a script of benchmarks/ or a make
#: target (the suite's own time).
COMMAND = re.compile(
    r"\bsb3-er (?:reproduce|train|enjoy|optimize) "
    r"|\bpython (?:\S*/)?(benchmarks/[\w/]+\.py)"
    r"|\bmake (?:test|test-slow|demo)\b"
)


def test_results_folders_hold_data_and_name_the_command_that_made_them():
    """Scripts live in benchmarks/ or the package, not beside their data; each folder's Markdown (its README.md,
    READING.md, VERSIONS.md or generated summary) or its page's "Reproduce with" names the command, and every
    benchmarks/ script named exists."""
    measured = ROOT / "results" / "measured"
    code = sorted(p.relative_to(ROOT).as_posix() for p in measured.rglob("*") if p.suffix in (".py", ".sh", ".ipynb"))
    assert not code, f"scripts in the data folders (move them to benchmarks/ or sb3_er.experiments): {code}"
    for folder in generator.result_dirs():
        texts = [path.read_text(encoding="utf-8") for path in (measured / folder).glob("*.md")]
        if folder in generator.THESIS_RESULTS:
            texts.append(generator.THESIS_RESULTS[folder].command + " ")
        commands = [match for text in texts for match in COMMAND.finditer(text)]
        assert commands, f"results/measured/{folder} names no command that made it: give it a README.md saying which"
        for match in commands:
            if match.group(1):
                assert (ROOT / match.group(1)).is_file(), f"results/measured/{folder} names {match.group(1)}, missing"


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


@pytest.mark.slow
def test_each_algorithm_page_shows_the_whole_signature(built):
    """The class heading of every algorithm's page names each parameter with its default, as ``help()`` does."""
    from sb3_er.zoo import algorithm_classes

    for cls in algorithm_classes().values():
        pages = [p for p in (built / "algorithms").glob("*.html") if f'id="sb3_er.{cls.__name__}"' in p.read_text()]
        assert pages, f"no algorithm page documents sb3_er.{cls.__name__}"
        source = pages[0].read_text(encoding="utf-8")
        start = source.index(f'id="sb3_er.{cls.__name__}"')
        heading = page_text_of(source[start : source.index("</dt>", start)])
        for parameter in inspect.signature(cls).parameters.values():
            shown = f"{parameter.name}={parameter.default!r}"
            assert re.sub(r"\s+", "", shown) in re.sub(r"\s+", "", heading), f"{cls.__name__}'s heading lacks {shown}"


def page_text_of(markup: str) -> str:
    """The text of an HTML fragment, as :func:`page_text` reads a page."""
    text = html.unescape(re.sub(r"<[^>]+>", "", markup))
    return text.translate(str.maketrans("\u2018\u2019\u201c\u201d", "''\"\""))


def inventory_objects(objects_inv: Path, roles: tuple[str, ...]) -> list[str]:
    """The names of the objects of `roles` (e.g. ``"py:function"``) in a Sphinx ``objects.inv`` (version 2: four
    header lines, then zlib-compressed lines ``name domain:role priority uri display-name``)."""
    import zlib

    data = objects_inv.read_bytes()
    header_end = 0
    for _ in range(4):
        header_end = data.index(b"\n", header_end) + 1
    lines = zlib.decompress(data[header_end:]).decode("utf-8").splitlines()
    return [line.split(" ", 2)[0] for line in lines if len(line.split(" ", 2)) == 3 and line.split(" ", 2)[1] in roles]


def resolve(name: str):
    """The object of a dotted name such as ``sb3_er.common.tile_coding.TileCoder.slots`` (the longest importable
    module prefix, then attributes); a numba kernel as its Python function, a method as its function."""
    import importlib

    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
            break
        except ImportError:
            continue
    for part in parts[cut:]:
        obj = inspect.getattr_static(obj, part) if inspect.isclass(obj) else getattr(obj, part)
    obj = obj.__func__ if isinstance(obj, (staticmethod, classmethod)) else obj
    return getattr(obj, "py_func", obj)


@pytest.mark.slow
def test_every_function_the_site_shows_lists_its_parameters(built):
    """What autodoc put on the site (the build's inventory, private members included) documents every parameter: a
    page never shows a function whose parameters are described in prose only."""
    from sb3_er.common.docstrings import undocumented_parameters

    shown = inventory_objects(built / "objects.inv", ("py:function", "py:method", "py:classmethod", "py:staticmethod"))
    assert {"sb3_er.common.tile_coding.default_tile_widths", "sb3_er.TileQPolicy.q_values"} <= set(shown)
    for name in shown:
        obj = resolve(name)
        # a class's signature (autodoc shows ``__init__`` apart): the class's docstring documents its parameters
        doc = resolve(name.rsplit(".", 1)[0]).__doc__ if name.endswith((".__init__", ".__new__")) else obj.__doc__
        missing = undocumented_parameters(obj, doc)
        assert not missing, f"{name} does not document {missing}"


def test_verdicts_say_not_judged_yet_without_findings_and_read_them_when_present(tmp_path):
    measured = tmp_path / "measured"
    (measured / "table_6_2").mkdir(parents=True)
    (measured / "leo").mkdir()
    (measured / "extra").mkdir()
    assert generator.verdict_rows(measured) == [
        ("table_6_2", generator.THESIS_RESULTS["table_6_2"].thesis, "", "not judged yet", ""),
        ("leo", generator.THESIS_RESULTS["leo"].thesis, "", "not judged yet", ""),
    ]
    (measured / "table_6_2" / "findings.json").write_text(
        json.dumps(
            {
                "findings": [
                    {
                        "claim": "ER-sigma rises faster than Sarsa(lambda)",
                        "holds": False,
                        "evidence": "2400 s against 1800 s",
                    },
                    {"claim": "vanilla ER walks", "holds": True, "inside_only": {"holds": None, "evidence": "e"}},
                ]
            }
        )
    )
    (measured / "extra" / "findings.json").write_text(
        json.dumps({"thesis": "Figure 7.1", "findings": [{"claim": "a | b", "holds": None}]})
    )
    rows = generator.verdict_rows(measured)
    assert rows[:2] == [
        (
            "table_6_2",
            "Table 6.2, Figures 6.1b and 6.2a",
            "ER-sigma rises faster than Sarsa(lambda)",
            "does not hold",
            "",
        ),
        ("table_6_2", "Table 6.2, Figures 6.1b and 6.2a", "vanilla ER walks", "holds", "inconclusive"),
    ]
    assert rows[2][3] == "not judged yet" and rows[3] == ("extra", "Figure 7.1", "a | b", "inconclusive", "")
    table = generator.verdict_table(lambda name: f"{name}.md", measured)
    assert (
        "| [Simplest walker](table_6_2.md) | Table 6.2, Figures 6.1b and 6.2a | vanilla ER walks | holds "
        "| inconclusive | — |" in table
    )
    assert "| ER-sigma rises faster than Sarsa(lambda) | does not hold | — | — |" in table
    assert "a \\| b" in table  # a bar in a claim cannot break the table


def test_a_side_with_no_run_inside_is_not_judged_inside_only(tmp_path):
    """Where every run of a side left the possible returns, the verdict on the runs that stayed inside is none at all:
    the tables say so instead of "inconclusive", which a finding with too few or too spread runs inside gets; the
    words are those the findings module writes (its own function, so that a change of its wording fails here)."""
    import numpy as np

    from sb3_er.experiments.findings import _nothing_averaged
    from sb3_er.experiments.summary import Curves

    nothing = Curves(np.arange(2.0), np.zeros((0, 2)), np.zeros((0, 2)), (), (), 0.0, out_of_bounds_seeds=(0, 1, 2))
    measured = tmp_path / "measured"
    (measured / "table_6_1").mkdir(parents=True)
    (measured / "table_6_1" / "findings.json").write_text(
        json.dumps(
            {
                "findings": [
                    {
                        "claim": "none inside",
                        "holds": True,
                        "inside_only": {"holds": None, "evidence": _nothing_averaged("er", nothing)},
                    },
                    {"claim": "too few inside", "holds": True, "inside_only": {"holds": None, "evidence": "3 runs"}},
                ]
            }
        )
    )
    rows = generator.verdict_rows(measured)
    assert [row[4] for row in rows[:2]] == ["not judged: a side has no run inside", "inconclusive"]


def test_each_table_says_which_regime_er_sigma_was_in(tmp_path):
    """The sigma-regime summary names the table folder of each reading: its page and verdict rows say which way σ
    moved the targets there, from the committed figures."""
    measured = tmp_path / "measured"
    (measured / "table_6_1").mkdir(parents=True)
    (measured / "table_6_1" / "findings.json").write_text(json.dumps({"findings": [{"claim": "c", "holds": True}]}))
    (measured / "sigma_regime").mkdir()
    (measured / "sigma_regime" / "summary.csv").write_text(
        "reading,learner,results,runs,phases,mean_shift,raised,lowered,left_bounds,diverged\n"
        "pendulum-0.33,er_sigma_stable,table_6_1,4,400,+5.0,0.2,0.1,0,0\n"
        "pendulum-0.33,er_sigma,table_6_1,4,400,-20.6,0.003,0.125,0,0\n"
        "walker-optimistic,er_sigma,,4,4275,1030000.0,0.23,0.072,3,0\n"
    )
    sentence = generator.sigma_regime("table_6_1", measured)
    assert sentence.startswith("ER-σ's σ lowered its targets") and "-20.6 over 400 replay phases of 4 runs" in sentence
    assert "raised 0.3%, lowered 12.5%" in sentence and "in 0 of 4 runs" in sentence
    assert generator.sigma_regime("leo", measured) == ""
    table = generator.verdict_table(lambda name: f"{name}.md", measured)
    assert "| c | holds | — | lowered targets |" in table


@pytest.mark.parametrize(
    "content, problem",
    [
        ("{", "not JSON"),
        ("[]", "a list 'findings'"),
        ('{"findings": [{"holds": true}]}', "'claim'"),
        ('{"findings": [{"claim": "x", "holds": "yes"}]}', "'holds': true, false or null"),
        ('{"findings": [{"claim": "x", "holds": true, "evidence": 3}]}', "'evidence'"),
        ('{"findings": [{"claim": "x", "holds": true, "inside_only": true}]}', "['inside_only'] needs 'holds'"),
        ('{"findings": [{"claim": "x", "holds": true, "inside_only": {"holds": 1}}]}', "['inside_only'] needs"),
        ('{"findings": [{"claim": "x", "holds": 0}]}', "'holds': true, false or null"),
    ],
)
def test_a_malformed_findings_file_is_an_error_naming_it(tmp_path, content, problem):
    (tmp_path / "walker").mkdir()
    (tmp_path / "walker" / "findings.json").write_text(content)
    with pytest.raises(generator.FindingsError, match=re.escape(problem)) as error:
        generator.read_findings("walker", tmp_path)
    assert "walker/findings.json" in str(error.value)


def test_the_readme_verdict_table_is_generated_and_current():
    assert generator.README_START in (ROOT / "README.md").read_text()
    assert generator.update_readme(check=True), "run: python docs/_ext/sb3er_docs.py readme"


# --- measured figures come from the committed results files, never by hand ---

NUMBER = r"[-−+]?\d[\d,]*(?:\.\d+)?"
# A figure with one of these units, a decimal number or one of 4 or more digits looks measured.
UNIT = r"(?:%|×|s\b|ms\b|µs\b|min\b|h\b|m\b|MB\b|steps/s|updates/s)"
# What a number after these words is: a reference, a version or a year, not a figure.
REFERENCE = re.compile(
    r"(?:Tables?|Figures?|Fig\.|Eqs?\.|Alg\.|Algorithms?|Appendix|[Ss]ections?|[Cc]hapter|"
    r"Python|Ray|version|v)\s*[-–\d.,]*$"
)
# Numbers of the prose that are no measurement and appear in no file: each with what it is.
NOT_MEASURED = {
    "docs/benchmarks/performance.md": {"1.25": "a target ratio of whole-process wall times, not a measurement"},
    "docs/continuous_actions.md": {
        "-1.33": "a torque level, 2 * (k / 3 - 1)",
        "-0.67": "a torque level",
        "1.33": "a torque level",
        "1.71": "the outermost bin centre of 7 bins of [-2, 2]",
        "-1627.4": "Pendulum-v1's return bound, computed",
        "105": "MountainCarContinuous-v0's watch limit, 100 + 5 % of its largest reward (100), computed",
    },
    "docs/envs/dm_control.md": {"1801.00690": "the arXiv number of Tassa et al. 2018"},
    "docs/envs/leo.md": {"0.167": "the RX-28 motor's torque constant", "0.320": "its back-EMF constant"},
    "docs/guide/install.md": {"3.11": "the Python version tested"},
    "docs/guide/distributed.md": {"2.59": "a Ray release", "2.61": "a Ray release"},
    "docs/guide/zoo.md": {"5432": "PostgreSQL's port in an example URL"},
    "docs/readings.md": {
        "162000": "5 * 180^2, a cost in degrees",
        "8.04": "m l^2 of Table 4.1, computed",
        "3.77": "Table 4.1's J (3.773e-3), printed and rounded",
    },
    "docs/value_growth.md": {"0.265": "a closed-form factor", "0.60": "a closed-form overlap"},
    "docs/value_watch.md": {
        "-209.7": "a reward bound, computed",
        "-0.96": "a reward bound, computed",
        "-10485": "a return bound, computed",
        "65900": "a return bound, computed",
        "-16.27": "Pendulum-v1's worst reward, computed",
        "-1627": "its return bound, computed",
    },
}


def _plain(number: str) -> str:
    return number.rstrip(",").replace(",", "").replace("−", "-").lstrip("+")


def measured_looking_numbers(text: str) -> list[str]:
    """The figures of Markdown `text` that look measured (a decimal, 4 or more digits, or a unit such as s, %, ×),
    outside code (fenced blocks and inline code, where commands and their options live), link targets, references
    ("Table 6.2", "Eq. 5.7"), versions and years; each as a plain number ("-17400", "1.2")."""
    text = re.sub(r"```.*?```", "", text, flags=re.DOTALL)
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(r"\]\([^)]*\)", "]", text)
    text = re.sub(r"\b\d+\.\d+\.\d+\b", "", text)  # a release such as 1.10.1
    found = []
    for match in re.finditer(rf"(?<![\w.^]){NUMBER}(?:\s?{UNIT})?", text):
        number = _plain(re.match(NUMBER, match.group(0)).group(0))
        unit = match.group(0)[len(re.match(NUMBER, match.group(0)).group(0)) :].strip()
        if REFERENCE.search(text[max(0, match.start() - 14) : match.start()]):
            continue
        digits = number.lstrip("-")
        if re.fullmatch(r"(19|20)\d\d", digits) and not unit:
            continue
        if "." in digits or len(digits.split(".")[0]) >= 4 or unit:
            found.append(number + ("%" if unit == "%" else ""))
    return found


def source_numbers(folders: set[str] | None = None) -> list[float]:
    """Every number of the results files the pages show (of `folders` of results/measured only, when given), and of
    the package's code and configuration (parameters, the thesis's printed figures in sb3_er/experiments/thesis.py,
    the Makefile's commands), sorted."""
    shown = [
        path
        for path in generator.shown_results_files()
        if folders is None or path.relative_to(generator.MEASURED).parts[0] in folders
    ]
    paths = (
        shown
        + [ROOT / "Makefile"]
        + [
            path
            for folder in ("sb3_er", "envs", "zoo_configs")
            for path in (ROOT / folder).rglob("*")
            if path.suffix in (".py", ".yml")
        ]
    )
    numbers = set()
    for path in paths:
        numbers.update(re.findall(r"[-−]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?", path.read_text(encoding="utf-8")))
    return sorted({float(_plain(number)) for number in numbers})


def appears_in(number: str, sources: list[float]) -> bool:
    """Whether a figure as printed is one of `sources` at its printed precision (-17,400 stands for -1.74e+04 and
    -17,396; 12.0 for 12.04; 1,200,000 for 1.2e+06), so that a figure rounded from an included file is accepted; a
    percentage may also be a share (84 % for 0.844)."""
    import bisect

    if number.endswith("%"):
        share = number[:-1]
        digits = share.lstrip("-")
        places = len(digits.split(".")[1]) if "." in digits else 0
        as_share = f"{float(share) / 100:.{places + 2}f}"
        return appears_in(share, sources) or appears_in(as_share, sources)
    digits = number.lstrip("-")
    if "." in digits:
        step = 10.0 ** -len(digits.split(".")[1])
    else:
        significant = digits.rstrip("0") or "0"
        step = 10.0 ** (len(digits) - len(significant))
    value = float(number)
    index = bisect.bisect_left(sources, value - step / 2)
    return index < len(sources) and sources[index] <= value + step / 2


def test_appears_in_accepts_a_rounded_figure_and_refuses_another():
    sources = sorted([-17396.2, 1133961.0, 12.04, 0.39])
    assert appears_in("-17400", sources) and appears_in("1100000", sources) and appears_in("12.0", sources)
    assert not appears_in("-17500", sources) and not appears_in("1200000", sources) and not appears_in("12.1", sources)
    assert not appears_in("0.40", sources) and appears_in("0.4", sources)
    assert measured_looking_numbers(
        "Sarsa rises in 1,000 s (Table 6.2, Eq. 5.7): 12.0 m, +45 % and 20 seeds; "
        "`--budget 2500` [x](a/1.5.md) Python 3.11, 2013, MushroomRL 1.10.1"
    ) == ["1000", "12.0", "45%"]
    assert appears_in("84%", sorted([0.844])) and not appears_in("85%", sorted([0.844]))


def named_folders(text: str) -> set[str]:
    """The results folders a page names: ``results/measured/<dir>`` and links to a results page ``<dir>.md``."""
    names = set(re.findall(r"results/measured/(\w+)", text)) | set(re.findall(r"\]\((?:\.\./results/)?(\w+)\.md", text))
    return names & set(generator.result_dirs())


def test_every_measured_figure_in_the_prose_comes_from_a_committed_results_file():
    """A figure of a page must be in a results file of the folders that page names (``results/measured/<dir>`` or a
    link to its results page; a folder's analysis note also its own folder), so that a figure left over from an
    earlier run does not pass by matching some other folder's file: each figure is traceable from its page."""
    for path in [ROOT / "README.md", *hand_written_pages()]:
        name = path.relative_to(ROOT).as_posix()
        allowed = NOT_MEASURED.get(name, {})
        # the README's "Which algorithm?" block is generated from the results files (its own test keeps it current)
        text = re.sub(
            re.escape(generator.WHICH_START) + ".*?" + re.escape(generator.WHICH_END),
            "",
            path.read_text(encoding="utf-8"),
            flags=re.DOTALL,
        )
        folders = named_folders(text)
        if path.parent == DOCS / "_notes" and path.stem.startswith("results_"):
            folders.add(path.stem.removeprefix("results_"))
        own = source_numbers(folders)
        figures = [
            number for number in measured_looking_numbers(text) if number not in allowed and not appears_in(number, own)
        ]
        assert not figures, (
            f"{name} quotes figures that no results file of the folders it names "
            f"({', '.join(sorted(folders)) or 'none'}) holds: {figures[:12]}; name the folder the "
            "figure comes from, and include the file (or generate the table from it) instead of copying"
        )
    for name, numbers in NOT_MEASURED.items():  # the exceptions stay true to the pages
        text = (ROOT / name).read_text(encoding="utf-8")
        assert all(number in map(_plain, re.findall(NUMBER, text)) for number in numbers), name


def table_rows(text: str) -> list[tuple[str, ...]]:
    """The rows of the Markdown tables of `text` with two or more numeric cells, each as its stripped cells."""
    rows = []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("|") and line.endswith("|") and not re.fullmatch(r"[|\s:-]+", line):
            cells = tuple(cell.strip().replace("`", "") for cell in line.strip("|").split("|"))
            if sum(bool(re.search(r"\d", cell)) for cell in cells) >= 2:
                rows.append(cells)
    return rows


def test_the_analyses_of_the_results_pages_hold_no_tables_of_figures():
    """A results folder's analysis (docs/_notes/results_<dir>.md) is shown beneath the folder's own summary: a table
    of measured figures in it is a copy, or a compilation that belongs in a results file."""
    for path in sorted((DOCS / "_notes").glob("results_*.md")):
        text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.DOTALL)
        rows = [
            line
            for line in text.splitlines()
            if line.strip().startswith("|") and measured_looking_numbers(line.replace("|", " "))
        ]
        assert not rows, f"{path.relative_to(ROOT)} holds a table of figures: {rows[0][:100]}"


def test_no_page_copies_a_table_of_a_results_file():
    results = {
        row: path
        for path in generator.shown_results_files()
        if path.suffix == ".md"
        for row in table_rows(path.read_text(encoding="utf-8"))
    }
    for path in [ROOT / "README.md", *hand_written_pages()]:
        copied = [row for row in table_rows(path.read_text(encoding="utf-8")) if row in results]
        assert not copied, (
            f"{path.relative_to(ROOT)} copies rows of {results[copied[0]].relative_to(ROOT)} "
            f"(e.g. {' | '.join(copied[0][:4])}): include the file instead"
        )


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


# --- the "Can I use?" tables are made from what the code accepts ---


def table_cells(markdown: str) -> dict[tuple[str, str], str]:
    """{(row, column): cell} of the "Can I use?" tables in `markdown` (the spaces table's action and observation
    columns; the envs table's single column is called "use")."""
    cells, columns = {}, None
    for line in markdown.splitlines():
        if not line.startswith("|") or set(line) <= set("|-"):
            columns = None if not line.startswith("|") else columns
            continue
        row = [cell.strip() for cell in line.strip("|").split("|")]
        if columns is None:
            columns = ["use"] if row[0] == "env" else row[1:]
            continue
        cells.update({(row[0], column): cell for column, cell in zip(columns, row[1:], strict=True)})
    return cells


def test_each_algorithm_page_shows_the_generated_can_i_use_table():
    from sb3_er import zoo

    for name, algorithm in zoo.algorithm_classes().items():
        text = (DOCS / "algorithms" / f"{name}.md").read_text(encoding="utf-8")
        section = text.split("## Can I use?", 1)[1].split("\n## ", 1)[0]
        assert f"```{{can-i-use}} {algorithm.__name__}\n```" in section, f"{name}.md does not generate its table"
        assert not re.search(r"^\|", section, flags=re.MULTILINE), f"{name}.md has a hand-written table beside it"
    assert "```{can-i-use}\n```" in (DOCS / "guide" / "own_env.md").read_text(encoding="utf-8")


# What a refusal's message must name, per cell: the space's kind, or the set-up refused.
REFUSAL_NAMES = {
    "image (a Box of shape H × W × C)": "image",
    "several envs at once (a VecEnv with `n_envs` > 1)": "multiple envs",
    "a VecEnv of Dict observations": "FlattenObservation",
    "`VecNormalize(norm_obs=True)`, rl-zoo's `normalize: true`": "normalises observations",
}


@pytest.mark.parametrize(
    "name", ["sarsa_lambda", "er", "er_sigma", "residual_er", "residual_er_sigma", "dyna", "fqi", "lspi"]
)
def test_the_can_i_use_table_says_what_each_algorithm_does(name):
    """Every ✔️ of an algorithm's tables learns on an env of that kind and acts inside its action space; every ✘ is a
    ValueError naming the space or set-up (never a crash deep inside)."""
    import warnings

    from sb3_er import zoo

    algorithm = zoo.algorithm_classes()[name]
    cells = table_cells(generator.can_i_use_table([algorithm.__name__]))
    cases = generator.space_cases()
    assert {(case.row, case.column) for case in cases} <= set(cells)
    for case in cases:
        cell, env = cells[case.row, case.column], case.make()
        assert cell.startswith(("✔️", "✘")), cell
        if cell.startswith("✔️"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = algorithm("TileQ", env, policy_kwargs=generator.PROBE_POLICY_KWARGS, seed=0).learn(30)
            observations = model.get_env().reset()
            actions, _ = model.predict(observations, deterministic=True)
            assert len(actions) == model.get_env().num_envs
            assert all(model.action_space.contains(action) for action in actions), (case.row, case.column, actions)
        else:
            expected = REFUSAL_NAMES.get(case.row, case.row)
            with pytest.raises(ValueError, match=re.escape(expected)):
                algorithm("TileQ", env, policy_kwargs=generator.PROBE_POLICY_KWARGS)
        env.close()


# --- the built site's links: no link to nowhere, no missing page, file or anchor ---


def _links_and_ids(text: str) -> tuple[list[str], set[str]]:
    """(the href and src values, the ids and names) of an HTML text."""
    from html.parser import HTMLParser

    class Collector(HTMLParser):
        def __init__(self):
            super().__init__()
            self.links, self.ids = [], set()

        def handle_starttag(self, tag, attrs):
            for name, value in attrs:
                if name in ("href", "src") and value is not None and not (tag == "link" and name == "href"):
                    self.links.append(value)
                if name == "id" or (tag == "a" and name == "name"):
                    self.ids.add(value)

    collector = Collector()
    collector.feed(text)
    return collector.links, collector.ids


def dead_links(site: Path) -> list[str]:
    """Every link of the pages' text (the theme's navigation, which marks the current page with ``href="#"``, left
    out) that goes nowhere: ``href="#"``, a local file that is missing, or an anchor its page lacks."""
    from urllib.parse import unquote, urlsplit

    ids: dict[Path, set[str]] = {}

    def ids_of(page: Path) -> set[str]:
        if page not in ids:
            ids[page] = _links_and_ids(page.read_text(encoding="utf-8"))[1]
        return ids[page]

    problems = []
    for page in sorted(site.rglob("*.html")):
        text = page.read_text(encoding="utf-8")
        body = text.split('<div itemprop="articleBody">', 1)[-1].split("<footer", 1)[0]
        for link in _links_and_ids(body)[0]:
            where = f"{page.relative_to(site)}: {link!r}"
            parts = urlsplit(link)
            if parts.scheme or link.startswith("//"):
                continue  # an address on the web, not checked offline
            if link in ("#", ""):
                problems.append(f"{where} links to nothing")
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                problems.append(f"{where}: {target} does not exist")
            elif parts.fragment and target.suffix == ".html" and unquote(parts.fragment) not in ids_of(target):
                problems.append(f"{where}: {target.name} has no anchor #{parts.fragment}")
    return problems


def test_the_link_check_finds_each_kind_of_dead_link(tmp_path):
    nav = '<nav><a href="#">this page</a></nav>'
    body = (
        '<div itemprop="articleBody"><h1 id="top">T</h1><a href="#">self</a> <a href="b.html">b</a> '
        '<a href="missing.html">m</a> <a href="b.html#there">anchor</a> <a href="b.html#nowhere">lost</a> '
        '<a href="#top">top</a> <img src="_images/x.png"> <img src="_images/gone.png"> '
        '<a href="https://example.org/">web</a></div><footer><a href="#">up</a></footer>'
    )
    (tmp_path / "a.html").write_text(nav + body)
    (tmp_path / "b.html").write_text('<div itemprop="articleBody"><p id="there">b</p></div>')
    (tmp_path / "_images").mkdir()
    (tmp_path / "_images" / "x.png").write_bytes(b"")
    problems = dead_links(tmp_path)
    assert len(problems) == 4, problems
    assert "'#' links to nothing" in problems[0] and "missing.html does not exist" in problems[1]
    assert "no anchor #nowhere" in problems[2] and "gone.png does not exist" in problems[3]


@pytest.mark.slow
def test_the_built_site_has_no_dead_links(built):
    # wide tables wrap instead of hiding their last columns (the theme keeps cells on one line)
    assert "_static/sb3er.css" in (built / "results" / "table_6_2.html").read_text(encoding="utf-8")
    assert "white-space: normal" in (built / "_static" / "sb3er.css").read_text(encoding="utf-8")
    problems = dead_links(built)
    assert not problems, f"{len(problems)} dead links, e.g.:\n" + "\n".join(problems[:20])


# --- the results pages read as pages: titled sections, captioned figures in reading order, versions explained ---


def test_a_code_line_says_what_its_version_is_without_commits():
    line = "Code: sb3-er 0.1.0, code hash 2a9aefd586 (100 runs from commit a30c8a5 with uncommitted changes)."
    shown = generator.code_version_line(line)
    assert shown.startswith("Code: sb3-er 0.1.0, code hash `2a9aefd586` (100 runs).")
    assert "a30c8a5" not in shown and "uncommitted" not in shown and "checksum of the package's source" in shown
    older = (
        "Code: sb3-er 0.1.0, commit bdfcc619bb (9 runs); sb3-er 0.1.0, commit b002fa0dbe (dirty) (3 runs). "
        "**Mixed versions: the runs were made by different code.**"
    )
    shown = generator.code_version_line(older)
    assert "two earlier code versions" in shown and "(9 and 3 runs)" in shown and "**Mixed versions" in shown
    assert not HASH.findall(shown)
    assert generator.code_version_line("Code: sb3-er 0.1.0, code 78f3f2a6a9 (1 runs; commit b964b46 (dirty)).") == (
        f"Code: sb3-er 0.1.0, code hash `78f3f2a6a9` (1 run). {generator.CODE_VERSION_NOTE}"
    )


FIGURE = re.compile(r"```\{figure\} (\S+)\n:alt: [^\n]+\n\n([^\n]+)\n```")


def test_every_results_page_has_titled_sections_and_captioned_figures_in_reading_order():
    for name in generator.result_dirs():
        page = generator.results_page(name)
        headings = re.findall(r"^#+ (.+)$", page, flags=re.MULTILINE)
        assert not [h for h in headings if re.search(r"\.(md|csv|txt)$", h)], f"{name}: a file name as a heading"
        code_lines = [line for line in page.splitlines() if line.startswith("Code:")]
        assert not [line for line in code_lines if "commit" in line], f"{name}: a summary's code line cites commits"
        committed = next(line for line in page.splitlines() if line.startswith("Committed files:"))
        has_runs = any(path.name == "runs" and path.is_dir() for path in (generator.MEASURED / name).rglob("runs"))
        assert ("runs/" in committed) == has_runs, f"{name}: {committed!r} (a runs/ folder: {has_runs})"
        figures = FIGURE.findall(page)
        shown = [p for p in (generator.MEASURED / name).rglob("*") if p.suffix in generator.FIGURE_SUFFIXES]
        assert len(figures) == len([p for p in shown if "runs" not in p.relative_to(generator.MEASURED / name).parts])
        for target, caption in figures:
            words = caption.rsplit("(`", 1)[0]
            assert len(words.split()) >= 5, f"{name}: {target} is captioned {caption!r}"
        for folder in {Path(target).parent for target, _ in figures}:
            order = [Path(target).stem for target, _ in figures if Path(target).parent == folder]
            kinds = [
                0
                if stem == "learning_curves"
                else 2
                if stem.startswith("gait_")
                else 3
                if stem.startswith("walker_")
                else 1
                for stem in order
            ]
            assert kinds == sorted(kinds), f"{name}: figures out of reading order: {order}"


def test_the_typical_runs_caption_names_the_runs_whose_values_left_the_possible_returns():
    """Table 6.2's seed-0 figure shows all 5 algorithms (no run diverged): the caption names those whose seed-0 records
    hold a value that left the possible returns (read here from the records, not from the summary's code), and says
    they are averaged like every run."""
    folder = generator.MEASURED / "table_6_2"
    caption = generator.figure_caption(folder, folder / "typical_runs.png")
    labels = {"sarsa_lambda": "Sarsa(λ)", "er": "vanilla-ER", "er_sigma": "ER-σ", "residual_er": "residual ER"}
    labels["residual_er_sigma"] = "residual ER-σ"
    left_out = [
        algo for algo in labels if json.loads((folder / "runs" / algo / "seed_0.json").read_text())["value_excursion"]
    ]
    assert 0 < len(left_out) < len(labels)
    named_part = caption.split("left the possible returns")[0].split("The values of")[1]
    for algo, label in labels.items():
        named = re.search(rf"(?<![\w-]){re.escape(label)}(?![\w-])", named_part) is not None
        assert named == (algo in left_out), (algo, caption)
    assert "not shown" not in caption and "averages every run" in caption


def test_each_walker_animation_says_who_walks_after_how_long_and_how_far():
    folder = generator.MEASURED / "table_6_2"
    for algo, label in {"sarsa_lambda": "Sarsa(λ)", "er_sigma": "ER-σ"}.items():
        caption = generator.figure_caption(folder, folder / f"walker_{algo}.gif")
        rows = (folder / "runs" / algo / "seed_0.csv").read_text().splitlines()
        last = dict(zip(rows[0].split(","), rows[-1].split(","), strict=True))
        assert caption.startswith(f"{label} (seed 0) after {float(last['learning_time_s']):g} s of learning")
        assert f"{float(last['distance']):.2f} m in 100 s" in caption


def test_the_analyses_begin_with_a_sentence_and_link_elsewhere():
    for path in sorted((DOCS / "_notes").glob("results_*.md")):
        text = path.read_text(encoding="utf-8")
        assert re.match(r"[A-Z*`\[-]", text), f"{path.name} starts mid-sentence: {text[:40]!r}"
        own = path.stem.removeprefix("results_")
        assert f"]({own}.md)" not in text, f"{path.name} links to its own page"


# --- "Which algorithm?": generated from the committed benchmarks ---

SUMMARY_CSV = (
    "algorithm,metric,average,ci95,average_text,difference_with_sarsa_lambda,thesis_average,thesis_difference,seeds\n"
    "Sarsa(λ),Rise time [s],1500.0,,1500,-,1500,-,20\n"
    "Sarsa(λ),End performance,10.0,0.5,10.0 ± 0.50,-,11.7,-,20\n"
    "Sarsa(λ),Falls,58.5,17.1,58.5 ± 17.1,-,74,-,20\n"
    "Sarsa(λ),Runs whose values left the possible returns,0.0,,0 of 20,—,—,—,20\n"
    "vanilla-ER,Rise time [s],3300.0,,3300,+120 %,3400,+127 %,20\n"
    "vanilla-ER,End performance,8.9,0.4,8.90 ± 0.40,-11 %,11.7,+0 %,20\n"
    "vanilla-ER,Falls,151,55.7,151 ± 55.7,+158 %,150,+103 %,20\n"
    "vanilla-ER,Runs whose values left the possible returns,0.0,,0 of 20,—,—,—,20\n"
    "ER-σ,Rise time [s],900.0,,900,-40 %,500,-67 %,7\n"
    "ER-σ,End performance,12.0,0.2,12.0 ± 0.20,+20 %,11.5,-2 %,7\n"
    "ER-σ,Falls,40,5,40.0 ± 5.00,-31 %,44,-41 %,7\n"
    "ER-σ,Runs whose values left the possible returns,13.0,,13 of 20,—,—,—,7\n"
    "residual ER,Rise time [s],100.0,,100,-93 %,3400,+127 %,20\n"
    "residual ER,End performance,2.0,0.3,2.00 ± 0.30,-80 %,11.7,+0 %,20\n"
    "residual ER,Runs whose values left the possible returns,0.0,,0 of 20,—,—,—,20\n"
)


def test_which_algorithm_ranks_only_learners_with_enough_averaged_runs(tmp_path):
    """Sarsa(λ) ends best of the ranked (10.0 ± 0.5); vanilla-ER's [8.5, 9.3] misses Sarsa(λ)'s [9.5, 10.5]; ER-σ
    ends higher still but has 7 of 20 runs averaged (fewer than half), so it is not ranked, and the row says why."""
    (tmp_path / "table_6_2").mkdir()
    (tmp_path / "table_6_2" / "summary.csv").write_text(SUMMARY_CSV, encoding="utf-8")
    (benchmark,), source = generator.which_algorithm_benchmarks(tmp_path)
    assert "thesis's tables" in source
    assert [score.algorithm for score in generator.picks(benchmark)] == ["sarsa_lambda"]
    text = generator.which_algorithm(lambda folder, file: f"{folder}/{file}", tmp_path)
    row = next(line for line in text.splitlines() if "simplest walker" in line)
    assert "| Sarsa(λ) |" in row and "[summary](table_6_2/summary.md)" in row
    assert "ER-σ (values left the possible returns in 13 of 20 runs)" in row
    # ER-σ's 900 s is not ranked; residual ER's 100 s is its rise to its own low end, not a pick's
    assert "soonest (rise time, of the picks): Sarsa(λ), 1500 s" in row
    assert (
        "In short, the tasks on which each learner is the pick or one of the picks, of those it ran: Sarsa(λ) 1 of 1"
        in text
    )


def test_which_algorithm_reads_a_diverged_row_that_says_why_its_runs_are_left_out(tmp_path):
    """Where an experiment has no random policy's score (the grid world), diverged runs are left out and their row
    says so after the count: the runs made are read from the count, the note is not."""
    rows = SUMMARY_CSV + (
        "residual ER,Diverged runs,4.0,,4 of 20 (left out: this experiment has no random policy's score to count them"
        " by),,—,—,16\n"
    )
    (tmp_path / "table_6_2").mkdir()
    (tmp_path / "table_6_2" / "summary.csv").write_text(rows, encoding="utf-8")
    (benchmark,), _ = generator.which_algorithm_benchmarks(tmp_path)
    residual = next(score for score in benchmark.scores if score.algorithm == "residual_er")
    assert residual.runs == 20 and residual.left_out == "diverged in 4 of 20 runs"


def test_which_algorithm_reads_the_sample_efficiency_summary_when_it_is_committed(tmp_path):
    (tmp_path / "table_6_2").mkdir()
    (tmp_path / "table_6_2" / "summary.csv").write_text(SUMMARY_CSV, encoding="utf-8")
    (tmp_path / "sample_efficiency").mkdir()
    summary = {
        "benchmarks": [
            {
                "task": "balancing",
                "env_id": "sb3_er/SimplestWalker-v0",  # the env of table_6_2: the thesis's table gives way
                "metric": "steps to a return of 475",
                "higher_is_better": False,
                "files": ["summary.md", "cartpole.png"],
                "scores": [
                    {"algorithm": "sarsa_lambda", "mean": 30000, "ci95": 4000, "runs": 20, "text": "30,000"},
                    {"algorithm": "er_sigma", "mean": 20000, "ci95": 3000, "runs": 20, "text": "20,000"},
                    {"algorithm": "er", "mean": 25000, "ci95": 3000, "runs": 20, "text": "25,000"},
                    {"algorithm": "residual_er", "mean": 1000, "runs": 20, "averaged": 4, "left_out": "diverged"},
                ],
            }
        ]
    }
    (tmp_path / "sample_efficiency" / "summary.json").write_text(json.dumps(summary))
    (benchmark,), source = generator.which_algorithm_benchmarks(tmp_path)  # the thesis's table is not used
    assert "sample-efficiency" in source and benchmark.folder == "sample_efficiency"
    # lower is better: ER-σ's [17000, 23000] overlaps vanilla ER's [22000, 28000], not Sarsa(λ)'s [26000, 34000]
    assert [score.algorithm for score in generator.picks(benchmark)] == ["er_sigma", "er"]
    text = generator.which_algorithm(lambda folder, file: f"{folder}/{file}", tmp_path)
    assert "| ER-σ or vanilla-ER |" in text and "residual ER (diverged)" in text
    assert "[cartpole](sample_efficiency/cartpole.png)" in text
    assert 'marked "(stable)"' not in text  # no stable learner measured, nothing to explain
    # a summary of other envs: the thesis's table of an env it does not run comes back beside it
    summary["benchmarks"][0]["env_id"] = "CartPole-v1"
    summary["benchmarks"][0]["scores"].append({"algorithm": "er_sigma_stable", "mean": 26000, "runs": 20})
    (tmp_path / "sample_efficiency" / "summary.json").write_text(json.dumps(summary))
    benchmarks, source = generator.which_algorithm_benchmarks(tmp_path)
    assert [b.folder for b in benchmarks] == ["sample_efficiency", "table_6_2"]
    assert [b.env_id for b in benchmarks] == ["CartPole-v1", "sb3_er/SimplestWalker-v0"]
    assert "the thesis's tables for `sb3_er/SimplestWalker-v0`, which it does not run" in source
    text = generator.which_algorithm(lambda folder, file: f"{folder}/{file}", tmp_path, docs="../")
    assert '`preset="stable"`' in text and "[Stable replay](../stable_replay.md)" in text
    (tmp_path / "sample_efficiency" / "summary.json").write_text(json.dumps({"benchmarks": [{"task": "x"}]}))
    with pytest.raises(generator.FindingsError, match="sample_efficiency/summary.json: benchmarks\\[0\\]"):
        generator.which_algorithm_benchmarks(tmp_path)


def test_which_algorithm_names_every_learner_tied_at_the_top(tmp_path):
    """Two learners each picked on as many tasks: the short summary names both, in neither's favour, each counted
    against the tasks it ran."""
    (tmp_path / "sample_efficiency").mkdir()
    scores = [
        {"algorithm": "sarsa_lambda", "mean": 10.0, "ci95": 0.1, "runs": 10},
        {"algorithm": "er_sigma", "mean": 5.0, "ci95": 0.1, "runs": 10},
    ]
    summary = {
        "benchmarks": [
            {"task": "a", "env_id": "A-v0", "metric": "return", "scores": scores},
            {"task": "b", "env_id": "B-v0", "metric": "return", "scores": [{**scores[1], "mean": 20.0}, scores[0]]},
            {"task": "c", "env_id": "C-v0", "metric": "return", "scores": [scores[0], {**scores[1], "mean": 20.0}]},
            {"task": "d", "env_id": "D-v0", "metric": "return", "scores": [{**scores[0], "mean": 30.0}]},  # no ER-σ
        ]
    }
    (tmp_path / "sample_efficiency" / "summary.json").write_text(json.dumps(summary))
    text = generator.which_algorithm(lambda folder, file: None, tmp_path)
    assert "of those it ran: Sarsa(λ) 2 of 4, ER-σ 2 of 3. On a new task, try Sarsa(λ) or ER-σ first" in text
    summary["benchmarks"].pop()
    (tmp_path / "sample_efficiency" / "summary.json").write_text(json.dumps(summary))
    text = generator.which_algorithm(lambda folder, file: None, tmp_path)
    assert "of those it ran: ER-σ 2 of 3, Sarsa(λ) 1 of 3. On a new task, try ER-σ first" in text


def test_the_sample_efficiency_page_says_how_far_a_benchmark_in_progress_has_come(tmp_path):
    """Without summary.md the results part says the results are not committed; with a runs file and no summary yet,
    how many finished runs it holds; with a summary, the summary itself."""
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import sb3er_benchmarks
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    folder = tmp_path / "sample_efficiency"
    folder.mkdir()
    assert "not committed yet" in sb3er_benchmarks.results_markdown(folder, tmp_path)
    (folder / "runs.json").write_text(json.dumps({"format": 1, "commands": [], "runs": [{}] * 1234}))
    assert "in progress: 1,234 finished runs" in sb3er_benchmarks.results_markdown(folder, tmp_path)
    (folder / "summary.md").write_text("# Title\n\nthe summary's table\n")
    text = sb3er_benchmarks.results_markdown(folder, tmp_path)
    assert "the summary's table" in text and "# Title" not in text and "in progress" not in text

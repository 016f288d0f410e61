"""Version records of learning runs: which code and which configuration produced each per-run CSV.

Every finished run of ``sb3-er reproduce`` has a record ``runs/<algo>/seed_<n>.json`` beside its CSV. The record is
made where the run ran (a worker process or a Ray worker on another machine) and holds:

- ``sb3_er_version``: ``sb3_er.__version__``;
- ``code_sha256``: a hash of the code itself, every source file of the packages ``sb3_er`` (with its hyperparameters
  ``sb3_er.zoo_configs``) and ``sb3_er_envs`` as imported (see :func:`code_hash`; a checkout and the wheel built from
  it give the same hash);
- ``git_commit``, ``git_dirty`` and ``git_diff_sha256``: the commit of the checkout the package was imported from,
  whether the checkout's code (its package folders and ``pyproject.toml``; results and docs do not count) differed
  from that commit, and a hash of the differences (see :func:`git_state`; all three
  None when the package is not a git checkout, e.g. an installed wheel, or git is missing);
- ``config``: what the driver asked for, so that it can be recomputed before running anything: experiment, algorithm
  name, class and constructor keyword arguments (the zoo config entry without rl-zoo's run-level keys, plus policy and
  seed), env id and ``gymnasium.make`` keyword arguments, run length (``budget`` in ``budget_unit``) and the protocol
  (name, evaluation interval in seconds of learning time, greedy runs per evaluation, evaluation seed);
- ``resolved``: what the run's objects held after construction: every constructor parameter of the algorithm's class
  hierarchy within sb3_er read back from the model (e.g. ``policy_kwargs`` with the env's tiling filled in) and the
  environment's constructor arguments with their defaults;
- ``dependencies`` (versions of the numerical libraries) and ``python``; ``host``, ``finished_at`` (UTC, ISO 8601) and
  ``wall_time_s`` (seconds from the run's start to its end);
- ``format`` (RECORD_FORMAT), ``files`` and ``checksum``, added by the driver when it writes the record after the run's
  files (:func:`sealed`): each file's name with its SHA-256 and, for the CSV, its row count, and a SHA-256 of all the
  record's other fields. :func:`check_sealed` tells whether a record still matches its files. A field added to the
  record later (by the run or the driver) is covered by the checksum without further change. Records of format 1
  predate the checksums; the runner checks their CSVs (:func:`check_legacy_csv`) and seals them once
  (``upgraded_from_format``).

:func:`compare_records` decides what a resume may mix. A missing record, a different ``sb3_er_version``,
``code_sha256`` or any ``config`` field refuses. Runs of different commits with identical code (a commit that touched
only the README, say) mix freely, so a long reproduction survives commits that leave the code alone. Records without
``code_sha256`` fall back to the commit: a different or unknown commit refuses, the same commit with different
uncommitted changes warns. Different ``dependencies`` or Python versions warn. ``resolved``, ``host``, times and wall
time are never compared: the resolved values follow from the config and the code, which are compared already.
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import importlib.metadata
import inspect
import io
import json
import os
import platform
import socket
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from sb3_er.experiments import files

# 2: the record is written after the run's files and holds their checksums (`files`) and its own (`checksum`).
RECORD_FORMAT = 2
CHECKSUM_FIELD = "checksum"
# The directory that holds the sb3_er package: a checkout's top level, or site-packages for an installed wheel.
PACKAGE_ROOT = Path(__file__).resolve().parents[2]
DEPENDENCIES = ("stable-baselines3", "gymnasium", "numpy", "numba", "torch", "mujoco", "dm-control")
# Constructor parameters that are no settings of the run.
_NOT_CONSTRUCTOR = {"self", "policy", "env", "_init_setup_model"}


def git_state(root: str | Path = PACKAGE_ROOT, paths: Iterable[str] = ()) -> dict[str, Any]:
    """Commit, dirtiness and a hash of the uncommitted changes of the git checkout whose top level is `root`.

    Returns ``{"git_commit": str | None, "git_dirty": bool | None, "git_diff_sha256": str | None}``: the full commit
    hash of HEAD; whether the work tree differs from HEAD under `paths` (changed tracked files, or untracked files that
    are not ignored: a new module changes the code as much as an edited one); and the SHA-256 hex digest of ``git diff
    HEAD --binary -- <paths>`` followed by the path and content of every untracked, not ignored file under `paths`
    (name and size only above 1 MB), None when clean. All three are None when `root` is not the top level of a git
    work tree (so a wheel installed in a virtual environment inside some other repository gets None, not that
    repository's commit), when git is not installed, or when git fails (e.g. "dubious ownership").

    :param root: the checkout's top level (default: the folder holding the imported package).
    :param paths: the paths (relative to `root`) whose changes count; empty: the whole work tree. A run's record
        passes the code's folders (:func:`checkout_code_paths`), so the results a reproduction writes into the checkout
        do not make the next run's record "dirty".
    """
    unknown = {"git_commit": None, "git_dirty": None, "git_diff_sha256": None}
    root = Path(root).resolve()

    def git(*arguments: str) -> bytes:
        return subprocess.run(["git", "-C", str(root), *arguments], capture_output=True, check=True, timeout=60).stdout

    try:
        top_level = Path(git("rev-parse", "--show-toplevel").decode().strip()).resolve()
        if top_level != root:
            return unknown
        commit = git("rev-parse", "HEAD").decode().strip()
        pathspec = ["--", *paths] if paths else []
        digest = hashlib.sha256(git("diff", "HEAD", "--binary", *pathspec))
        untracked = sorted(
            name for name in git("ls-files", "--others", "--exclude-standard", "-z", *pathspec).split(b"\0") if name
        )
        changed = digest.digest() != hashlib.sha256(b"").digest() or bool(untracked)
        for name in untracked:
            path = root / os.fsdecode(name)
            digest.update(b"\0untracked\0" + name + b"\0")
            size = path.stat().st_size if path.is_file() else 0
            digest.update(path.read_bytes() if 0 < size <= 1 << 20 else str(size).encode())
    except (OSError, subprocess.SubprocessError, ValueError):
        return unknown
    return {
        "git_commit": commit,
        "git_dirty": changed,
        "git_diff_sha256": digest.hexdigest() if changed else None,
    }


CODE_SUFFIXES = (".py", ".xml", ".yml", ".yaml")
# The packages whose source is the code of a run, by import name. sb3_er.zoo_configs (the thesis's hyperparameters)
# lives in the checkout's top-level zoo_configs/ and inside sb3_er/ in an installed wheel: files are named by their
# import path, so both give the same names.
CODE_PACKAGES = ("sb3_er", "sb3_er.zoo_configs", "sb3_er_envs")


def code_files() -> dict[str, Path]:
    """The files :func:`code_hash` reads: ``{"<package path>/<relative path>": path}`` for every file with a suffix in
    CODE_SUFFIXES under the directories of CODE_PACKAGES (caches excluded), e.g. ``"sb3_er/zoo_configs/er.yml"``."""
    import importlib

    files: dict[str, Path] = {}
    for name in CODE_PACKAGES:
        root = Path(importlib.import_module(name).__file__).resolve().parent
        prefix = name.replace(".", "/")
        for path in root.rglob("*"):
            if path.suffix in CODE_SUFFIXES and "__pycache__" not in path.parts and path.is_file():
                files[f"{prefix}/{path.relative_to(root).as_posix()}"] = path
    return files


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """SHA-256 of the source of the imported packages (CODE_PACKAGES: ``sb3_er``, its hyperparameters
    ``sb3_er.zoo_configs`` and ``sb3_er_envs``): every file of :func:`code_files`, by name and content, in sorted
    order. A checkout and the wheel built from it give the same hash.

    Read once per process, the first time it is asked for (``execute_run`` and the driver ask before any run): the
    code a process runs is the code it imported, not what is on disk later. Editing the checkout during a long
    reproduction therefore neither changes the records of the runs already under way nor refuses them.
    """
    digest = hashlib.sha256()
    for name, path in sorted(code_files().items()):
        digest.update(f"\0{name}\0".encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def checkout_code_paths(root: str | Path = PACKAGE_ROOT) -> list[str]:
    """The paths of a checkout that hold the code, relative to `root`: the folders of CODE_PACKAGES that lie inside
    it (``sb3_er``, ``zoo_configs``, ``envs`` in this repository) and ``pyproject.toml`` (which maps them and pins the
    dependencies), sorted. Documentation, tests and results are not code: editing them leaves a run's record clean.

    :param root: the checkout's top level (default: the folder holding the imported package).
    """
    import importlib

    root = Path(root).resolve()
    paths = {"pyproject.toml"}
    for name in CODE_PACKAGES:
        folder = Path(importlib.import_module(name).__file__).resolve().parent
        if folder.is_relative_to(root):
            paths.add(folder.relative_to(root).as_posix())
    # a subpackage inside a listed folder is covered by it
    return sorted(path for path in paths if not any(path.startswith(other + "/") for other in paths))


def code_version() -> dict[str, Any]:
    """``sb3_er_version``, :func:`code_hash` and :func:`git_state` of the code's paths in the imported package's
    checkout (:func:`checkout_code_paths`)."""
    import sb3_er

    return {
        "sb3_er_version": sb3_er.__version__,
        "code_sha256": code_hash(),
        **git_state(PACKAGE_ROOT, checkout_code_paths()),
    }


def _jsonable(value: Any) -> Any:
    """`value` as plain JSON data: numpy scalars and arrays as numbers and lists, classes and functions as their
    qualified names, anything else as its str (e.g. a torch device as "cpu")."""
    import numpy as np

    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (np.ndarray, list, tuple)):
        return [_jsonable(item) for item in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, dict):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, type) or callable(value):
        return f"{getattr(value, '__module__', '?')}.{getattr(value, '__qualname__', repr(value))}"
    return str(value)


def normalized(record: dict[str, Any]) -> dict[str, Any]:
    """`record` as it reads back from its JSON file (tuples become lists, numpy numbers Python numbers).

    :param record: a run's version record (a dict as written to its JSON file).
    """
    return json.loads(json.dumps(_jsonable(record)))


def run_config(job) -> dict[str, Any]:
    """The configuration of `job` (a :class:`~sb3_er.experiments.jobs.RunJob`) as the driver plans it.

    Raises ValueError for an algorithm that has no class (the zoo lookup names the known ones) and KeyError when
    ``zoo_configs/<algo>.yml`` has no entry for the experiment's env.

    :param job: the run (a :class:`~sb3_er.experiments.jobs.RunJob`).
    """
    from sb3_er.experiments.jobs import job_model_kwargs
    from sb3_er.zoo import algorithm_classes

    experiment = job.experiment
    classes = algorithm_classes()
    if job.algo not in classes:
        raise ValueError(f"unknown algorithm {job.algo!r}; choose one of {', '.join(classes)}")
    algorithm_class = classes[job.algo]
    walking = experiment.protocol == "walking"
    return normalized(
        {
            "experiment": experiment.name,
            "algorithm": job.algo,
            "algorithm_class": f"{algorithm_class.__module__}.{algorithm_class.__qualname__}",
            "algorithm_kwargs": {"policy": "TileQ", "seed": job.seed, **job_model_kwargs(job)},
            "env_id": experiment.env_id,
            "env_kwargs": dict(getattr(job, "env_kwargs", ())),
            "budget": float(job.budget),
            "budget_unit": experiment.budget_unit,
            "protocol": {
                "name": experiment.protocol,
                "eval_interval_s": experiment.eval_interval if walking else None,
                "eval_runs": experiment.eval_runs if walking else None,
                "eval_seed": 10_000 + job.seed if walking else None,
            },
        }
    )


def resolved_settings(model, env) -> dict[str, Any]:
    """What `model` (a tile-coded sb3_er algorithm) and `env` (a Gymnasium env) hold after construction.

    ``algorithm``: each constructor parameter of the model's classes defined in sb3_er, read back from the model's
    attribute of that name when it has one (as given: None for a stabilizer its preset fills). ``stabilizers``: an ER
    class's stabilizers and replay volume as its preset resolved them (``model.stabilizers``; absent for the other
    classes). ``env``: the unwrapped env's constructor arguments, the ones given to ``gymnasium.make`` with the
    defaults of the rest.

    :param model: the constructed sb3-er algorithm.
    :param env: its Gymnasium env (wrapped or not).
    """
    names: list[str] = []
    for cls in type(model).__mro__:
        if not cls.__module__.startswith("sb3_er") or "__init__" not in vars(cls):
            continue
        for parameter in inspect.signature(cls.__init__).parameters.values():
            if parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY) and (
                parameter.name not in _NOT_CONSTRUCTOR and parameter.name not in names
            ):
                names.append(parameter.name)
    algorithm = {name: getattr(model, name) for name in sorted(names) if hasattr(model, name)}
    unwrapped = env.unwrapped
    given = dict(env.spec.kwargs) if env.spec is not None else {}
    try:
        bound = inspect.signature(type(unwrapped)).bind_partial(**given)
        bound.apply_defaults()
        env_arguments = dict(bound.arguments)
    except (TypeError, ValueError):
        env_arguments = given
    resolved = {"algorithm": algorithm, "env": env_arguments}
    if getattr(model, "stabilizers", None):
        resolved["stabilizers"] = dict(model.stabilizers)
    return normalized(resolved)


def dependency_versions(names: Iterable[str] = DEPENDENCIES) -> dict[str, str | None]:
    """Installed versions of `names` (distribution names), None for those not installed.

    :param names: distribution names (default: the packages a run's results depend on).
    """
    versions = {}
    for name in names:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def current_record(job, code: dict[str, Any] | None = None) -> dict[str, Any]:
    """The comparable part of the record that `job` would get from this process: code version, config, dependencies.

    `code` is a :func:`code_version` result to reuse (git is asked once per call otherwise).

    :param job: the run (a :class:`~sb3_er.experiments.jobs.RunJob`).
    :param code: a :func:`code_version` result (default None: read it now).
    """
    return normalized(
        {
            "format": RECORD_FORMAT,
            "run": job.key,
            **(code if code is not None else code_version()),
            "config": run_config(job),
            "dependencies": dependency_versions(),
            "python": platform.python_version(),
        }
    )


def finished_record(job, model, env, wall_time_s: float, code: dict[str, Any] | None = None) -> dict[str, Any]:
    """The full record of a finished run of `job`: :func:`current_record` plus resolved settings, host and times.

    `code` is the :func:`code_version` read when the run started (read now when None).

    :param job: the run (a :class:`~sb3_er.experiments.jobs.RunJob`).
    :param model: the trained model.
    :param env: its env.
    :param wall_time_s: the run's wall time [s].
    :param code: a :func:`code_version` result (default None: read it now).
    """
    return normalized(
        {
            **current_record(job, code),
            "resolved": resolved_settings(model, env),
            "host": socket.gethostname(),
            "finished_at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "wall_time_s": wall_time_s,
        }
    )


def record_path(csv_path: str | Path) -> Path:
    """Where the record of the run whose CSV is `csv_path` lives: the same name with ``.json``.

    :param csv_path: the run's CSV file.
    """
    return Path(csv_path).with_suffix(".json")


def write_json_atomically(path: Path, data: dict[str, Any]) -> None:
    """Write `data` as indented JSON to `path` atomically (see :func:`sb3_er.experiments.files.write_json`).

    :param path: the file.
    :param data: the JSON-able data.
    """
    files.write_json(path, data)


RECORD_REMEDY = (
    "rerun the command: it moves the run's files aside (renamed, kept) and runs it again; or delete the "
    "run's .csv and .json files"
)


def read_record(csv_path: str | Path) -> dict[str, Any] | None:
    """The record beside `csv_path`, or None when there is none. An empty file, a file that is not JSON or not a JSON
    object raises DamagedFileError (a ValueError) naming the file and what to do.

    :param csv_path: the run's CSV file.
    """
    path = record_path(csv_path)
    if not path.is_file():
        return None
    record = files.read_json(path, RECORD_REMEDY)
    if not isinstance(record, dict):
        raise files.DamagedFileError(f"{path} holds no version record (a JSON object); {RECORD_REMEDY}")
    return record


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def record_checksum(record: dict[str, Any]) -> str:
    """SHA-256 of every field of `record` but ``checksum`` itself, as key-sorted compact JSON: a field added to the
    record (by the run, the driver or a later version) is covered without any change here.

    :param record: a run's version record (a dict as written to its JSON file).
    """
    content = {key: value for key, value in record.items() if key != CHECKSUM_FIELD}
    return _sha256(json.dumps(content, sort_keys=True, separators=(",", ":")).encode())


def csv_rows(data: bytes) -> int:
    """The number of data rows of CSV text `data` (lines after the header; a quoted field may span lines).

    :param data: the CSV file's bytes.
    """
    import csv

    return max(0, sum(1 for _ in csv.reader(io.StringIO(data.decode(errors="replace")))) - 1)


def sealed(
    record: dict[str, Any], csv_name: str, csv_data: bytes, artifacts: dict[str, bytes] | None = None, **fields: Any
) -> dict[str, Any]:
    """`record` ready to be written after its files: ``format`` set to RECORD_FORMAT, ``files`` holding each file's
    name (beside the record) with its SHA-256 and, for the run's CSV `csv_name`, its row count; `fields` added; and
    ``checksum`` (see :func:`record_checksum`) over all of it. `artifacts` maps file names to their contents.

    :param record: a run's version record (a dict as written to its JSON file).
    :param csv_name: the file name of the run's CSV.
    :param csv_data: the CSV's bytes.
    :param artifacts: other files' contents by file name (default None: none).
    """
    record = {key: value for key, value in normalized(record).items() if key != CHECKSUM_FIELD}
    record.update(normalized(fields))
    record["format"] = RECORD_FORMAT
    record["files"] = {
        csv_name: {"rows": csv_rows(csv_data), "sha256": _sha256(csv_data)},
        **{name: {"sha256": _sha256(content)} for name, content in (artifacts or {}).items()},
    }
    record[CHECKSUM_FIELD] = record_checksum(record)
    return record


def check_sealed(record: dict[str, Any], csv_path: Path) -> str | None:
    """What is wrong with a sealed run (its record and the files it names, see :func:`sealed`), or None when the
    record's checksum matches its content and every file its checksum and row count.

    :param record: the sealed record read back.
    :param csv_path: the run's CSV file.
    """
    if record.get(CHECKSUM_FIELD) != record_checksum(record):
        return f"{record_path(csv_path)}: the record's checksum does not match its content (edited or damaged)"
    named = record.get("files")
    if not isinstance(named, dict) or csv_path.name not in named:
        return f"{record_path(csv_path)}: the record names no checksum of {csv_path.name}"
    for name, expected in named.items():
        path = csv_path.with_name(name)
        if not path.is_file():
            return f"{path} is missing (its record names it)"
        data = path.read_bytes()
        if "rows" in expected and csv_rows(data) != expected["rows"]:
            return f"{path} has {csv_rows(data)} rows, its record says {expected['rows']} (cut short or damaged)"
        if _sha256(data) != expected.get("sha256"):
            return f"{path}: the checksum differs from its record's (changed or damaged since the run was written)"
    return None


def check_legacy_csv(csv_path: Path, expected_rows: int | None) -> str | None:
    """What is wrong with the CSV of a run whose record predates checksums, or None: it must be well-formed CSV
    (a header, every line as many fields as the header, ending in a newline) with `expected_rows` rows, the length
    the protocol gives the run (when `expected_rows` is known), or fewer only when its ``diverged`` column says so.

    :param csv_path: the run's CSV file.
    :param expected_rows: the rows the protocol gives the run, or None when unknown.
    """
    import csv

    data = csv_path.read_bytes()
    if not data.strip():
        return f"{csv_path} is empty"
    lines = list(csv.reader(io.StringIO(data.decode(errors="replace"))))
    width = len(lines[0])
    if not data.endswith(b"\n") or any(len(line) != width for line in lines[1:]):
        return f"{csv_path} is cut short (its last row is incomplete)"
    rows = len(lines) - 1
    if expected_rows is None or rows == expected_rows:
        return None if rows else f"{csv_path} has no rows"
    header = lines[0]
    diverged = "diverged" in header and rows and all(line[header.index("diverged")] == "True" for line in lines[1:])
    if rows < expected_rows and diverged:
        return None  # a diverged run stops early
    return f"{csv_path} has {rows} rows, its run has {expected_rows} (cut short or damaged)"


SETTINGS_NAME = "settings.json"


def holds_runs(out_dir: str | Path) -> bool:
    """Whether results folder `out_dir` holds the CSV of any run (``runs/**/seed_<n>.csv``).

    :param out_dir: the results folder.
    """
    return any(path.is_file() for path in (Path(out_dir) / "runs").rglob("seed_*.csv"))


def check_settings(out_dir: str | Path, settings: dict[str, Any]) -> None:
    """Refuse (ValueError) to run `settings` in `out_dir` when its ``settings.json`` pins others and it holds runs.

    The settings are pinned by :func:`pin_settings` once a run has finished; a folder whose settings file pins other
    settings but holds no run (left by a command whose runs all failed) is not refused: its settings are replaced
    when the first run finishes. An empty or unreadable settings file is moved aside (renamed, kept) with a warning
    naming it and is pinned anew: the runs' records hold their settings too and are checked on their own.

    :param out_dir: the results folder.
    :param settings: the command's settings (seeds aside), as ``settings.json`` holds them.
    """
    import warnings

    path = Path(out_dir) / SETTINGS_NAME
    if not path.is_file():
        return
    try:
        existing = files.read_json(path, "it is moved aside and written anew")
    except files.DamagedFileError as error:
        moved = files.move_aside(path)
        warnings.warn(
            f"{error}: moved aside as {moved}; the runs' own records are checked instead",
            files.DamagedFileWarning,
            stacklevel=3,
        )
        return
    wanted = normalized(settings)
    if existing != wanted and holds_runs(out_dir):
        raise ValueError(
            f"{out_dir} holds runs made with {existing}, not {wanted}; resume with the same settings or choose "
            "another --out"
        )


def pin_settings(out_dir: str | Path, settings: dict[str, Any]) -> None:
    """Write `settings` to ``out_dir/settings.json`` (atomically) unless it holds them already. Call it once a run of
    `out_dir` has finished (see :func:`check_settings`).

    :param out_dir: the results folder.
    :param settings: the command's settings (seeds aside), as ``settings.json`` holds them.
    """
    path = Path(out_dir) / SETTINGS_NAME
    wanted = normalized(settings)
    try:
        if path.is_file() and files.read_json(path, "") == wanted:
            return
    except files.DamagedFileError:
        pass
    files.write_json(path, wanted)


def _leaves(value: Any, prefix: str) -> dict[str, Any]:
    if isinstance(value, dict) and value:
        leaves = {}
        for key, item in value.items():
            leaves.update(_leaves(item, f"{prefix}.{key}" if prefix else str(key)))
        return leaves
    return {prefix: value}


def _short(value: Any) -> str:
    if isinstance(value, str) and len(value) >= 40 and all(c in "0123456789abcdef" for c in value):
        return value[:10]  # a commit or SHA-256 hash
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _differences(recorded: Any, current: Any, prefix: str) -> list[str]:
    old, new = _leaves(recorded, prefix), _leaves(current, prefix)
    return [
        f"{key} {_short(old.get(key, '(absent)'))} -> {_short(new.get(key, '(absent)'))}"
        for key in sorted(set(old) | set(new))
        if old.get(key, "(absent)") != new.get(key, "(absent)")
    ]


def compare_records(recorded: dict[str, Any] | None, current: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(reasons to refuse, reasons to warn) when a run recorded as `recorded` meets the `current` record.

    Each reason is one line naming the field with its recorded and current values, e.g.
    ``"config.algorithm_kwargs.learning_rate 0.25 -> 0.3"``. `recorded` None (a run without a record) refuses as an
    unknown version.

    :param recorded: the run's record, or None when it has none.
    :param current: the record this process would write (:func:`current_record`).
    """
    if recorded is None:
        return ["no version record (a run made before records existed, or its .json was deleted): unknown version"], []
    refusals = _differences(recorded.get("sb3_er_version"), current.get("sb3_er_version"), "sb3_er_version")
    warnings = []
    if recorded.get("code_sha256") is not None and current.get("code_sha256") is not None:
        refusals += _differences(recorded.get("code_sha256"), current.get("code_sha256"), "code_sha256")
    else:  # an older record: the commit is all we know of the code
        refusals += _differences(recorded.get("git_commit"), current.get("git_commit"), "git_commit")
        same_commit = recorded.get("git_commit") == current.get("git_commit") and current.get("git_commit") is not None
        either_dirty = recorded.get("git_dirty") or current.get("git_dirty")
        if same_commit and either_dirty and recorded.get("git_diff_sha256") != current.get("git_diff_sha256"):
            warnings.append(
                "same commit, different uncommitted changes (git_diff_sha256 "
                f"{_short(recorded.get('git_diff_sha256'))} -> {_short(current.get('git_diff_sha256'))})"
            )
    refusals += _differences(recorded.get("config"), current.get("config"), "config")
    warnings += _differences(recorded.get("dependencies"), current.get("dependencies"), "dependencies")
    warnings += _differences(recorded.get("python"), current.get("python"), "python")
    return refusals, warnings


def compact_runs(runs: Iterable[str]) -> str:
    """Run keys as a short list: the seeds of one ``<prefix>seed_<n>`` joined into ranges, prefixes in first-seen order.

    e.g. ``["pendulum/er/seed_0", "pendulum/er/seed_1", "pendulum/er/seed_2", "pendulum/er/seed_5", "lspi/seed_3"]``
    -> ``"pendulum/er/seed_0-2, 5, lspi/seed_3"``; keys without a seed are kept as they are. A resume of hundreds of
    runs names them in a line or two instead of one name per run.

    :param runs: run keys such as ``"er/seed_3"``.
    """
    seeds_by_prefix: dict[str, list[int]] = {}
    for run in runs:
        prefix, separator, seed = run.rpartition("seed_")
        if separator and seed.isdigit():
            seeds_by_prefix.setdefault(prefix + separator, []).append(int(seed))
        else:
            seeds_by_prefix.setdefault(run, [])
    parts = []
    for prefix, seeds in seeds_by_prefix.items():
        ranges = []
        for seed in sorted(set(seeds)):
            if ranges and seed == ranges[-1][1] + 1:
                ranges[-1][1] = seed
            else:
                ranges.append([seed, seed])
        spans = ", ".join(str(first) if first == last else f"{first}-{last}" for first, last in ranges)
        parts.append(prefix + spans)
    return ", ".join(parts)


def grouped(reasons_by_run: dict[str, list[str]]) -> list[str]:
    """Lines ``"runs: reason; reason"``, one per distinct list of reasons, runs as :func:`compact_runs` writes them.

    :param reasons_by_run: reasons (one line each) by run key.
    """
    groups: dict[tuple[str, ...], list[str]] = {}
    for run, reasons in reasons_by_run.items():
        if reasons:
            groups.setdefault(tuple(reasons), []).append(run)
    return [f"  {compact_runs(runs)}: {'; '.join(reasons)}" for reasons, runs in groups.items()]


def counted(n: float, noun: str) -> str:
    """`n` and `noun`, the noun plural unless `n` is 1: ``counted(1, "run")`` -> ``"1 run"``, ``"20 runs"``,
    ``counted(2.5, "episode")`` -> ``"2.5 episodes"``.

    :param n: the count (a float is written with ``:g``).
    :param noun: the noun in the singular; the plural adds an "s".
    """
    return (f"{n:g}" if isinstance(n, float) else str(n)) + f" {noun}{'' if n == 1 else 's'}"


def code_versions_line(run_records: list[dict[str, Any] | None]) -> str:
    """The summary's line saying which code made the runs, grouped by the package's code hash (``code_sha256``),
    which is what decides whether runs may be mixed: commits that change only documentation or results share it.

    e.g. ``"Code: sb3-er 0.1.0, code hash 1f4d0e44dc (100 runs from commits dc32abd, 294af56 with uncommitted
    changes)."``: each commit once, marked when any of its runs was made with uncommitted changes to the code, the
    first four commits of a group named. Runs without a record count as their own version, and more than one version
    adds a bold warning.

    :param run_records: the records of the runs summarized (None for a run without one).
    """
    groups: dict[str, list[dict[str, Any] | None]] = {}
    for record in run_records:
        if record is None:
            key = "no record"
        elif record.get("code_sha256"):
            key = f"code hash {record['code_sha256'][:10]}"
        else:  # an older record without a code hash: its commit and uncommitted changes stand for the code
            diff = record.get("git_diff_sha256")
            key = f"code of commit {record['git_commit'][:10]}" if record.get("git_commit") else "code unknown"
            key += f" with changes {diff[:10]}" if diff else ""
        groups.setdefault(key, []).append(record)
    parts = []
    for key, members in groups.items():
        if key == "no record":
            parts.append(f"unknown version (no record): {counted(len(members), 'run')}")
            continue
        dirty_by_commit: dict[str, bool] = {}
        for record in members:
            if record.get("git_commit"):
                commit = record["git_commit"][:7]
                dirty_by_commit[commit] = dirty_by_commit.get(commit, False) or bool(record.get("git_dirty"))
        named = [commit + (" with uncommitted changes" if dirty else "") for commit, dirty in dirty_by_commit.items()]
        outside = any(not record.get("git_commit") for record in members)
        runs = counted(len(members), "run")
        if named:
            origin = (
                f" from {'commit' if len(named) == 1 else 'commits'} {', '.join(named[:4])}"
                + (", ..." if len(named) > 4 else "")
                + (" and outside a git checkout" if outside else "")
            )
        else:
            origin = ", not from a git checkout"
        parts.append(f"sb3-er {members[0].get('sb3_er_version')}, {key} ({runs}{origin})")
    mixed = " **Mixed versions: the runs were made by different code.**" if len(groups) > 1 else ""
    return f"Code: {'; '.join(parts)}.{mixed}"


class MixedVersionsError(ValueError):
    """Finished runs were made by other code or another configuration than the current one."""


class MixedVersionsWarning(UserWarning):
    """Finished runs share the commit and configuration but not the uncommitted changes or library versions."""


OVERRIDE_HINT = "--allow-mixed-versions (reproduce(..., allow_mixed_versions=True))"


def check_versions(
    recorded: dict[str, dict[str, Any] | None],
    current: dict[str, dict[str, Any]],
    allow_mixed_versions: bool,
    what: str,
) -> None:
    """Refuse (MixedVersionsError) or warn (MixedVersionsWarning) when `recorded` runs differ from `current`.

    `recorded` and `current` map run keys (``"er/seed_3"``) to records (None: no record); `what` names the runs in the
    message (e.g. ``"results/leo holds finished runs that"``). With `allow_mixed_versions` the reasons to refuse are
    warned about instead.

    :param recorded: records of the finished runs by run key (None: no record).
    :param current: the records this process would write, by run key.
    :param allow_mixed_versions: warn instead of refusing.
    :param what: names the runs in the message.
    """
    import warnings

    refusals, cautions = {}, {}
    for key, record in recorded.items():
        refusals[key], cautions[key] = compare_records(record, current[key])
    refused = grouped(refusals)
    if refused and not allow_mixed_versions:
        raise MixedVersionsError(
            f"{what} differ from the current code or configuration (recorded -> current):\n"
            + "\n".join(refused)
            + f"\nUse another --out, delete these runs' .csv and .json files to rerun them, or pass {OVERRIDE_HINT} "
            "to keep them beside runs of the current version."
        )
    if refused:
        warnings.warn(
            f"{what} differ from the current code or configuration, kept because mixed versions are allowed:\n"
            + "\n".join(refused),
            MixedVersionsWarning,
            stacklevel=4,
        )
    cautioned = grouped(cautions)
    if cautioned:
        warnings.warn(
            f"{what} differ in uncommitted changes or library versions (recorded -> current):\n"
            + "\n".join(cautioned)
            + "\nCommit your changes before a long reproduction so that its runs can be told apart.",
            MixedVersionsWarning,
            stacklevel=4,
        )


code_hash()  # the code this process imported, read now (see code_hash)

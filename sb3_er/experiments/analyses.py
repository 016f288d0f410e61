"""What the analyses of `sb3-er reproduce` share (``replay-order``, ``sigma``, ``pessimistic``; see
:data:`sb3_er.experiments.specs.ANALYSES`): checking the request, pinning an output folder to its settings, running
the jobs on the runner (parallel, resumable, versioned records, Ray) and the lines every summary ends with.

Each analysis module has a ``reproduce_<name>(...)`` function that returns a
:class:`~sb3_er.experiments.reproduce.Reproduction`; :data:`COMMANDS` maps the analysis names to them.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Any

from sb3_er.experiments import records
from sb3_er.experiments.runner import BACKENDS, RunJob, run_jobs, split_finished

COMMANDS = {
    "replay-order": "sb3_er.experiments.replay_order:reproduce_replay_order",
    "sigma": "sb3_er.experiments.sigma_study:reproduce_sigma",
    "pessimistic": "sb3_er.experiments.pessimistic:reproduce_pessimistic",
    "framework": "sb3_er.experiments.framework:reproduce_framework",
    "sigma-regime": "sb3_er.experiments.sigma_regime:reproduce_sigma_regime",
}


def command(name: str):
    """The ``reproduce_<name>`` function of analysis `name`; ValueError naming the analyses for another name.

    :param name: the analysis's name, e.g. "sigma".
    """
    if name not in COMMANDS:
        raise ValueError(f"unknown analysis {name!r}; choose one of {', '.join(COMMANDS)}")
    module, _, function = COMMANDS[name].partition(":")
    return getattr(importlib.import_module(module), function)


def check_request(n_seeds: int, budget: float, unit: str, backend: str, address: str | None) -> None:
    """ValueError naming the problem for a non-positive seed count or run length (in `unit`), an unknown backend or
    an address without the Ray backend.

    :param n_seeds: the number of seeds.
    :param budget: the run length.
    :param unit: the run length's unit, for the message.
    :param backend: "local" or "ray".
    :param address: the Ray cluster's address, or None.
    """
    if int(n_seeds) != n_seeds or n_seeds < 1:
        raise ValueError(f"the number of seeds must be a positive integer, got {n_seeds}")
    if not budget > 0:
        raise ValueError(f"the run length must be positive ({unit}), got {budget}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise ValueError(f"an address ({address!r}) is for the Ray backend only; add --backend ray")


def check_settings(out_dir: Path, settings: dict[str, Any]) -> None:
    """Refuse (ValueError) when `out_dir` holds runs made with other settings (see
    :func:`sb3_er.experiments.records.check_settings`); the settings are written once a run has finished.

    :param out_dir: the results folder.
    :param settings: the command's settings, as ``settings.json`` holds them.
    """
    records.check_settings(out_dir, settings)


def run_analysis_jobs(
    jobs: list[RunJob],
    out_dir: Path,
    n_workers: int | None,
    show_progress: bool,
    backend: str,
    address: str | None,
    allow_mixed_versions: bool,
    settings: dict[Path, dict[str, Any]] | None = None,
) -> tuple[int, int]:
    """Run the jobs that have not finished and return (runs done, runs already finished). Call it holding the lock
    of every folder the jobs write (:func:`sb3_er.experiments.files.lock_folders`).

    Finished runs are those whose record matches their files; damaged ones are moved aside and done again (see
    :func:`sb3_er.experiments.runner.split_finished`). Finished runs are first checked against the current code and
    configuration (MixedVersionsError naming the runs and fields unless `allow_mixed_versions`, see
    :mod:`sb3_er.experiments.records`). `settings` maps results folders (a run's folder holds ``runs/``) to the
    settings their ``settings.json`` pins, written once a run of the folder has finished. Failed runs raise RunFailure
    after the others are written.

    :param jobs: the analysis's runs.
    :param out_dir: the analysis's results folder.
    :param n_workers: worker processes (None: all CPUs).
    :param show_progress: show a progress bar.
    :param backend: "local" or "ray".
    :param address: the Ray cluster's address, or None.
    :param allow_mixed_versions: accept finished runs of other code or configuration.
    :param settings: the settings to pin per results folder (default None: none).
    """
    settings = {Path(folder): pinned for folder, pinned in (settings or {}).items()}

    def pin(job: RunJob) -> None:
        folder = job.csv_path.parents[2]  # <folder>/runs/<algo or label>/seed_<n>.csv
        if folder in settings:
            records.pin_settings(folder, settings[folder])

    to_run, finished = split_finished(jobs)
    if finished:
        code = records.code_version()
        records.check_versions(
            {job.key: records.read_record(job.csv_path) for job in finished},
            {job.key: records.current_record(job, code) for job in finished},
            allow_mixed_versions,
            f"{out_dir} holds finished runs that",
        )
        for job in finished:
            pin(job)
    if backend == "local":
        n_workers = n_workers or os.cpu_count() or 1
    run_jobs(
        to_run,
        n_workers,
        show_progress,
        backend=backend,
        address=address,
        allow_mixed_versions=allow_mixed_versions,
        on_written=pin,
    )
    return len(to_run), len(finished)


def code_line(jobs: list[RunJob]) -> str:
    """Which code made the finished runs of `jobs`, e.g. ``"Code: sb3-er 0.1.0, code hash 1f4d0e44dc (60
    runs from commit 91bd149)."`` (`records.code_versions_line`).

    :param jobs: the analysis's runs.
    """
    return records.code_versions_line([records.read_record(job.csv_path) for job in jobs if job.csv_path.is_file()])


def env_reading(jobs: list[RunJob]) -> str:
    """The env's constructor arguments as the first finished run of `jobs` resolved them (its defaults at run time,
    overridden by ``--env-kwargs``), e.g. ``"max_torque=0.6, n_torques=7, ..."``; "unknown" without a record.

    :param jobs: the analysis's runs.
    """
    for job in jobs:
        record = records.read_record(job.csv_path) if job.csv_path.is_file() else None
        if record is not None and "resolved" in record:
            env = {name: value for name, value in record["resolved"]["env"].items() if name != "render_mode"}
            return ", ".join(f"{name}={value!r}" for name, value in env.items())
    return "unknown"

"""How often the stable preset's projection binds: the share of replayed updates it changes, task by task.

    python benchmarks/projection_binding.py [--seeds 3] [--out results/measured/projection_binding]

The stable preset projects every weight a replayed update moved onto [V_min / N, V_max / N] (``project_weights``,
docs/stable_replay.md). Where it never binds, the stable learner is the thesis's; where it binds often, it fits
something else, and the sample-efficiency benchmark's differences between the two come from there. Per Gymnasium task
of ``benchmarks/sample_efficiency.py`` (its budget, the class defaults and nothing but the env id, as the benchmark
runs them) and per class (ER and ER-sigma under ``preset="stable"``), seeds 0 to ``--seeds`` - 1: the share of
replayed updates whose projection moved a weight back into the bounds, over the whole run and per quarter of it
(the kernels' count, ``train/projected_share`` in TensorBoard), the share of the weights learning moved that end at
a bound, and the CPU seconds. Printed as a table and written (atomically) to ``--out``/binding.json with the command
and the code version.
"""

import argparse
import shlex
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import sample_efficiency as se
from stable_baselines3.common.callbacks import BaseCallback

from sb3_er import ER, ERSigma, ValueBoundWarning
from sb3_er.common import kernels
from sb3_er.experiments import files, records

TASKS = ("CartPole-v1", "MountainCar-v0", "Acrobot-v1", "Pendulum-v1", "MountainCarContinuous-v0")
CLASSES = {"er_stable": ER, "er_sigma_stable": ERSigma}
QUARTERS = 4
OUT = Path(__file__).resolve().parent.parent / "results" / "measured" / "projection_binding"


class QuarterCounts(BaseCallback):
    """The kernels' running counts of replayed updates and of projected ones at each quarter of the run (no log dump
    happens in the run, so the watch's period counts run from its start)."""

    def __init__(self, total_timesteps: int):
        super().__init__()
        self.marks = [round(total_timesteps * (k + 1) / QUARTERS) for k in range(QUARTERS)]
        self.counts: list[tuple[float, float]] = []

    def _on_step(self) -> bool:
        if self.num_timesteps in self.marks:
            watch = self.model._watch.array
            self.counts.append((float(watch[kernels.WATCH_PERIOD_UPDATES]), float(watch[kernels.WATCH_PROJECTED])))
        return True


def measure(env_id: str, method: str, seed: int) -> dict:
    """One run: the projected shares (whole run and per quarter), the weights at a bound, CPU seconds."""
    budget = int(se.TASKS[env_id].budget)
    model = CLASSES[method]("TileQ", env_id, seed=seed, preset="stable")
    initial = model.policy.theta_array.copy()
    counter = QuarterCounts(budget)
    start = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ValueBoundWarning)
        model.learn(budget, callback=counter, log_interval=None)
    cpu = time.process_time() - start
    per_quarter, previous = [], (0.0, 0.0)
    for updates, projected in counter.counts:
        done = updates - previous[0]
        per_quarter.append((projected - previous[1]) / done if done else None)
        previous = (updates, projected)
    updates, projected = counter.counts[-1]
    theta = model.policy.theta_array
    moved = theta != initial
    low, high = model.value_bounds
    n = model.policy.tile_coder.n_tilings
    at_bound = np.isclose(theta[moved], low / n) | np.isclose(theta[moved], high / n)
    return {
        "task": env_id,
        "method": method,
        "seed": seed,
        "steps": budget,
        "replayed_updates": updates,
        "projected_share": projected / updates if updates else None,
        "projected_share_per_quarter": per_quarter,
        "weights_moved": int(moved.sum()),
        "weights_at_a_bound": float(at_bound.mean()) if moved.any() else None,
        "value_bounds": [low, high],
        "cpu_s": cpu,
    }


def _mean(values) -> float | None:
    values = [value for value in values if value is not None]
    return statistics.fmean(values) if values else None


def _share(value: float | None) -> str:
    return "—" if value is None else f"{100.0 * value:.1f} %"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds per task and class (default 3)")
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    parser.add_argument("--out", type=Path, default=OUT, help="where binding.json goes (default: the results folder)")
    args = parser.parse_args(argv)
    runs = [measure(env_id, method, seed) for env_id in args.tasks for method in CLASSES for seed in range(args.seeds)]
    print(
        "| task | method | projected share of replayed updates (mean over seeds) | per quarter of the run "
        "| moved weights at a bound | CPU s per run |"
    )
    print("|---|---|---:|---|---:|---:|")
    for env_id in args.tasks:
        for method in CLASSES:
            chosen = [run for run in runs if run["task"] == env_id and run["method"] == method]
            quarters = [_mean(run["projected_share_per_quarter"][k] for run in chosen) for k in range(QUARTERS)]
            print(
                f"| {env_id} | {se.label(method)} | {_share(_mean(run['projected_share'] for run in chosen))} "
                f"| {', '.join(_share(q) for q in quarters)} "
                f"| {_share(_mean(run['weights_at_a_bound'] for run in chosen))} "
                f"| {statistics.median(run['cpu_s'] for run in chosen):.1f} |"
            )
    command = shlex.join(["python", "benchmarks/projection_binding.py", *(sys.argv[1:] if argv is None else argv)])
    data = {"command": command, "code_version": records.code_version(), "runs": runs}
    args.out.mkdir(parents=True, exist_ok=True)
    path = files.write_json(args.out / "binding.json", data)
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

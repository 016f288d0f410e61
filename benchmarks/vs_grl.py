"""sb3-er against GRL's ``grld`` on GRL's compass-walker Sarsa(lambda) walk task, whole processes side by side.

Usage::

    python benchmarks/vs_grl.py --grld PATH/grl/build/grld --config PATH/runs/walker_B300.yaml [--pairs 5]

Each pair runs GRL's ``grld`` and then our learner as separate processes (alternating, so that a change of load hits
both), and the script prints per side: learning steps per second (GRL by its own clock, which excludes its
configuration and weight initialisation; ours over ``learn()`` alone), the whole process's wall time and peak memory
(``ru_maxrss`` of the child), then the medians and the ratios. Our run is
``SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", learning_rate=0.4, gamma=0.99, trace_lambda=0.92,
exploration_rate=0.05, policy_kwargs=dict(initial_value=(0.0, 1.0)), seed=1).learn(STEPS)`` with STEPS the learning
steps GRL made in the same trials (129,482 for 300 trials, seed 1), read from GRL's output. Start-up above the floor
is reported too: the same child's ``import stable_baselines3`` time and memory against the rest of its process.

Building ``grld`` (GRL, github.com/wcaarls/grl; measured at commit 9fda6a5), about 8 minutes on 2 cores, on
Debian/Ubuntu::

    apt-get install build-essential cmake pkg-config git libeigen3-dev zlib1g-dev libpython3-dev python3-distutils
    git clone https://github.com/wcaarls/grl.git && cd grl && git checkout 9fda6a5
    mkdir build && cd build
    cmake -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 .. && make grld -j2

(Without distutils, Python >= 3.12, delete the lines ``externals/pybind11`` and ``addons/python`` from MODULES in
``CMakeLists.txt`` first: grld does not use them.) The headless walker configuration is GRL's
``cfg/compass_walker/sarsa_walk.yaml`` with the visualizer keys (from ``visualizer:`` to the end) removed, ``runs: 1``,
``trials: 300``, ``test_interval: -1`` (every episode learns) and ``output:`` renamed (grld writes ``<output>.yaml``
and ``<output>-0.txt`` to its working directory)::

    sed -e '/^visualizer:/,$d' -e 's/^  runs: 5$/  runs: 1/' -e 's/^  trials: 2000$/  trials: 300/' \\
        -e 's/^  test_interval: 10$/  test_interval: -1/' -e 's/^  output: walker_sarsa_walk$/  output: walker_out/' \\
        cfg/compass_walker/sarsa_walk.yaml > walker_B300.yaml

Run on a quiet machine: both sides are single-threaded, and other jobs change both. The script prints the load
average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

OURS = r"""
import json, os, resource, sys, time
start = time.perf_counter()
import stable_baselines3
floor = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
import sb3_er_envs
from sb3_er import SarsaLambda
model = SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", learning_rate=0.4, gamma=0.99, trace_lambda=0.92,
                    exploration_rate=0.05, policy_kwargs=dict(initial_value=(0.0, 1.0)), seed=1)
ready = time.perf_counter() - start
learn_start = time.perf_counter()
model.learn(STEPS)
learn = time.perf_counter() - learn_start
print(json.dumps({"floor_s": floor[0], "floor_kib": floor[1], "ready_s": ready, "learn_s": learn,
                  "steps": model.num_timesteps, "episodes": model._episode_num}))
"""


def child_run(command: list[str], cwd: str) -> tuple[float, float, str]:
    """(wall s, peak memory MiB, stdout) of a child process; the peak is that child's own (``os.wait4``)."""
    with tempfile.TemporaryFile("w+") as out:
        start = time.perf_counter()
        process = subprocess.Popen(command, cwd=cwd, stdout=out, stderr=subprocess.DEVNULL, text=True)
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.perf_counter() - start
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode != 0:
            raise RuntimeError(f"{command[0]} failed with exit code {process.returncode}")
        out.seek(0)
        return wall, usage.ru_maxrss / 1024, out.read()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grld", required=True, type=Path, help="GRL's grld binary")
    parser.add_argument("--config", required=True, type=Path, help="the headless walker configuration (see above)")
    parser.add_argument("--pairs", type=int, default=5, help="alternating pairs of runs (at least 5)")
    parser.add_argument("--seed", type=int, default=1, help="grld's seed (-s)")
    args = parser.parse_args()
    if args.pairs < 5:
        parser.error("--pairs must be at least 5")
    print(f"load average before: {os.getloadavg()}")
    work = Path(tempfile.mkdtemp(prefix="vs_grl_"))
    config = work / args.config.name
    config.write_text(args.config.read_text())
    grl, ours = [], []
    for pair in range(args.pairs):
        wall, peak, stdout = child_run([str(args.grld.resolve()), "-s", str(args.seed), config.name], str(work))
        steps, seconds = parse_grld(stdout, work)
        grl.append({"wall": wall, "peak": peak, "steps": steps, "learn_s": seconds})
        code = OURS.replace("STEPS", str(steps))
        wall, peak, stdout = child_run([sys.executable, "-c", code], str(work))
        figures = json.loads(stdout.strip().splitlines()[-1])
        ours.append({"wall": wall, "peak": peak, **figures})
        print(
            f"pair {pair + 1}: GRL {steps / seconds:,.0f} steps/s, {grl[-1]['wall']:.2f} s, "
            f"{grl[-1]['peak']:.0f} MiB | "
            f"sb3-er {figures['steps'] / figures['learn_s']:,.0f} steps/s, {ours[-1]['wall']:.2f} s, "
            f"{ours[-1]['peak']:.0f} MiB",
            flush=True,
        )
    report(grl, ours)
    print(f"load average after: {os.getloadavg()}")


def parse_grld(stdout: str, work: Path) -> tuple[int, float]:
    """(learning steps, learning seconds by GRL's clock) of a grld run, from its ``<output>-0.txt``.

    GRL's online-learning experiment writes one row per trial: trial, learning steps so far, the episode's reward, its
    simulated time, reward per second, and the wall time since the run's learning began (its own clock, after the
    configuration and the weights' initialisation); agent and environment may append columns. The last row holds the
    totals.
    """
    files = sorted(work.glob("*-0.txt"), key=lambda f: f.stat().st_mtime)
    if not files:
        raise ValueError(f"grld wrote no <output>-0.txt in {work}")
    rows = [
        line.split() for line in files[-1].read_text().splitlines() if line.strip() and re.match(r"^\s*[-+0-9.]", line)
    ]
    if not rows:
        raise ValueError(f"{files[-1]}: no trial rows")
    return int(float(rows[-1][1])), float(rows[-1][5])


def report(grl: list[dict], ours: list[dict]) -> None:
    def median(rows, key):
        return statistics.median(r[key] for r in rows)

    grl_rate = statistics.median(r["steps"] / r["learn_s"] for r in grl)
    our_rate = statistics.median(r["steps"] / r["learn_s"] for r in ours)
    print(f"\nmedians of {len(grl)} pairs          sb3-er        GRL   ratio")
    print(f"learning steps per second     {our_rate:9,.0f}  {grl_rate:9,.0f}   {our_rate / grl_rate:.2f}x faster")
    print(
        f"whole process, wall (s)       {median(ours, 'wall'):9.2f}  {median(grl, 'wall'):9.2f}   "
        f"{median(ours, 'wall') / median(grl, 'wall'):.2f}x"
    )
    print(
        f"peak memory (MiB)             {median(ours, 'peak'):9.0f}  {median(grl, 'peak'):9.0f}   "
        f"{median(ours, 'peak') / median(grl, 'peak'):.2f}x"
    )
    floor_s = median(ours, "floor_s")
    print(
        f"\nsb3-er start-up: import stable_baselines3 {floor_s:.2f} s and {median(ours, 'floor_kib') / 1024:.0f} MiB "
        f"(the floor); import sb3_er and building the model {median(ours, 'ready_s') - floor_s:.2f} s above it; "
        f"peak memory {median(ours, 'peak') - median(ours, 'floor_kib') / 1024:.0f} MiB above it"
    )


if __name__ == "__main__":
    main()

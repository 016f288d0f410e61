"""Where a short run's start-up goes: the SB3 floor, numba's runtime, our modules, the model, the first steps.

Usage::

    python benchmarks/startup.py [--repeats 5]

A start-up is everything a process does before ``learn()`` learns, for the run of ``benchmarks/vs_grl.py``:
``SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", ..., policy_kwargs=dict(initial_value=(0.0, 1.0)), seed=1)`` and
10 steps. Each repeat is a fresh interpreter that times its phases in order with ``time.perf_counter`` and reads its
peak memory (``ru_maxrss``) after each; the phases add up to the whole:

1. ``import stable_baselines3`` (torch, and the TensorBoard writer SB3's logger imports): the floor;
2. ``import numba`` (and llvmlite);
3. numba's CPU target, which numba initialises the first time any kernel is compiled or loaded from its cache: it
   imports every numba implementation module, and ``numba.np.arraymath`` checks for a BLAS by importing
   ``scipy.linalg`` (shown apart, as 3a, by importing it first);
4. ``from sb3_er import SarsaLambda`` and ``import sb3_er_envs``;
5. building the model: the env, the tile coder, the kernels loaded from numba's cache, and the weights' fill
   (``n_weights`` float64 values, each its seeded initial value; shown apart as 5a, timed over a second fill);
6. ``learn(10)``.

Then the first and the second whole process of a fresh install: ``NUMBA_CACHE_DIR`` set to an empty folder, the
same run twice, so that the first compiles every kernel it calls and the second loads them (wall time of each).
Run on a quiet machine: the script prints the load average before and after.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

PHASED = r"""
import json, resource, time
marks = []
def mark(name):
    marks.append((name, time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
mark("start")
import stable_baselines3
mark("1 import stable_baselines3 (the floor)")
import numba
mark("2 import numba")
import scipy.linalg
mark("3a numba's BLAS check: import scipy.linalg")
from numba.core.registry import cpu_target
cpu_target.target_context.refresh()
mark("3 numba's CPU target (its implementation modules)")
from sb3_er import SarsaLambda
import sb3_er_envs
mark("4 import sb3_er's SarsaLambda and sb3_er_envs")
model = SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", learning_rate=0.4, gamma=0.99, trace_lambda=0.92,
                    exploration_rate=0.05, policy_kwargs=dict(initial_value=(0.0, 1.0)), seed=1)
mark("5 build the model")
model.learn(10)
mark("6 learn(10)")
from sb3_er.common import kernels
policy = model.policy
theta = policy.theta_array
fill = time.perf_counter()
kernels.fill_initial_weights(theta, *policy.initial_arguments)
fill = time.perf_counter() - fill
print(json.dumps({"marks": marks, "fill_s": fill, "n_weights": int(theta.size), "weights_mib": theta.nbytes / 2**20}))
"""

WHOLE = r"""
from sb3_er import SarsaLambda
SarsaLambda("TileQ", "sb3_er/CompassWalker-v0", learning_rate=0.4, gamma=0.99, trace_lambda=0.92,
            exploration_rate=0.05, policy_kwargs=dict(initial_value=(0.0, 1.0)), seed=1).learn(10)
"""


def run_python(code: str, env: dict | None = None) -> tuple[str, float]:
    """Run ``code`` in a fresh interpreter; its stdout and its wall time in seconds."""
    start = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env={**os.environ, **(env or {})}
    )
    return result.stdout, time.perf_counter() - start


def phases(repeats: int) -> None:
    rows: dict[str, list[tuple[float, float]]] = {}
    fills, sizes = [], None
    for _ in range(repeats):
        stdout, _ = run_python(PHASED)
        record = json.loads(stdout.strip().splitlines()[-1])
        marks = record["marks"]
        for (_, t0, _), (name, t1, rss) in itertools.pairwise(marks):
            rows.setdefault(name, []).append((t1 - t0, rss / 1024))
        fills.append(record["fill_s"])
        sizes = record["n_weights"], record["weights_mib"]
    names = list(rows)
    floor_rss = statistics.median(r for _, r in rows[names[0]])
    previous_rss = floor_rss
    print(
        f"phases of one start-up, medians of {repeats} fresh interpreters (each phase's time; peak memory after it, "
        f"and its growth)"
    )
    print(f"{'phase':55s} {'s':>6s} {'peak MiB':>9s} {'+MiB':>6s}")
    above_s = 0.0
    for name in names:
        seconds = statistics.median(t for t, _ in rows[name])
        rss = statistics.median(r for _, r in rows[name])
        grow = rss - previous_rss if name != names[0] else rss
        print(f"{name:55s} {seconds:6.2f} {rss:9.0f} {grow:6.0f}")
        previous_rss = rss
        if name != names[0]:
            above_s += seconds
    n_weights, weights_mib = sizes
    print(f"{'5a of 5: the weights fill (a second fill, timed)':55s} {statistics.median(fills):6.2f}")
    final_rss = statistics.median(r for _, r in rows[names[-1]])
    print(
        f"\nabove the floor: {above_s:.2f} s and {final_rss - floor_rss:.0f} MiB, of which the weights "
        f"(memory_size {n_weights:,} float64) are {weights_mib:.0f} MiB"
    )


def fresh_install(repeats: int) -> None:
    firsts, seconds = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as cache:
            firsts.append(run_python(WHOLE, {"NUMBA_CACHE_DIR": cache})[1])
            seconds.append(run_python(WHOLE, {"NUMBA_CACHE_DIR": cache})[1])
    first, second = statistics.median(firsts), statistics.median(seconds)
    print(
        f"\nwhole process, empty numba cache (a fresh install), medians of {repeats}: first run {first:.2f} s "
        f"(compiles the kernels it calls), second run {second:.2f} s (loads them): {first / second:.1f}x"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="fresh interpreters per figure (default 5)")
    args = parser.parse_args(argv)
    print(f"load average before: {os.getloadavg()}")
    run_python(WHOLE)  # numba's cache of this install warm
    phases(args.repeats)
    fresh_install(max(1, args.repeats // 2))
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()

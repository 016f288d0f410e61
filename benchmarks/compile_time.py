"""How long a new user waits the first time each algorithm learns: numba compiles its kernels on the first call and
keeps them in its cache, so the first process pays once per machine and every later one loads them.

    python benchmarks/compile_time.py [--repeats 1] [--algos SarsaLambda ERSigma ...]
    python benchmarks/compile_time.py --baseline-python OTHER/.venv/bin/python   # beside another checkout's

For each algorithm, two fresh interpreters in turn, both with ``NUMBA_CACHE_DIR`` set to the same new empty folder:
the first compiles every kernel its ``learn`` calls (a cold start, what a fresh install meets), the second loads them
(a warm start, every run after). Each times ``Algo("TileQ", "sb3_er/WindyCliff-v0", seed=0).learn(200)`` with
``time.perf_counter`` after the imports, and the figures printed are seconds of wall time and of this process's CPU
time (CPU time is what other load on the machine does not inflate). Prioritized sweeping is ER with
``replay_order="prioritized"``, whose phase kernel is a kernel of its own. Run on a quiet machine: the load average
is printed before and after. ``--baseline-python`` also times the same first learns under another Python
(another checkout's venv, which imports that checkout's package), alternating with this one's, and prints the cold
CPU seconds of both and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ALGOS = {
    "SarsaLambda": ("SarsaLambda", {}),
    "ER": ("ER", {}),
    "ERSigma": ("ERSigma", {}),
    "ResidualER": ("ResidualER", {}),
    "ResidualERSigma": ("ResidualERSigma", {}),
    "ER (prioritized sweeping)": ("ER", {"replay_order": "prioritized"}),
    "Dyna": ("Dyna", {}),
    "FQI": ("FQI", {"fit_every": 1}),
    "LSPI": ("LSPI", {"fit_every": 1}),
}

FIRST_LEARN = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
import sb3_er, sb3_er_envs
name, kwargs = sys.argv[1], json.loads(sys.argv[2])
wall, cpu = time.perf_counter(), time.process_time()
getattr(sb3_er, name)("TileQ", "sb3_er/WindyCliff-v0", seed=0, **kwargs).learn(200)
print(json.dumps({"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu}))
"""


def first_learn(name: str, kwargs: dict, cache: str, python: str = sys.executable) -> dict[str, float]:
    """Wall and CPU seconds of the first ``learn`` in a fresh interpreter whose numba cache is ``cache``."""
    environment = dict(os.environ, NUMBA_CACHE_DIR=cache)
    out = subprocess.run(
        [python, "-c", FIRST_LEARN, name, json.dumps(kwargs)],
        env=environment,
        cwd=cache,  # not the current folder: `python -c` puts it first on sys.path, where a checkout would win
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=1, help="cold and warm pairs per algorithm (median printed)")
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), choices=list(ALGOS), metavar="ALGO")
    parser.add_argument("--baseline-python", default=None, help="another checkout's Python, timed beside this one")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    header = f"{'algorithm':28s} {'cold wall s':>11s} {'cold CPU s':>10s} {'warm wall s':>11s} {'warm CPU s':>10s}"
    print(header + (f" {'baseline cold CPU s':>19s} {'vs baseline':>11s}" if args.baseline_python else ""))
    for label in args.algos:
        name, kwargs = ALGOS[label]
        cold, warm, baseline = [], [], []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory(prefix="numba_cache_") as cache:
                cold.append(first_learn(name, kwargs, cache))
                warm.append(first_learn(name, kwargs, cache))
            if args.baseline_python:
                with tempfile.TemporaryDirectory(prefix="numba_cache_") as cache:
                    baseline.append(first_learn(name, kwargs, cache, args.baseline_python))
        figures = [statistics.median(run[key] for run in runs) for runs in (cold, warm) for key in ("wall", "cpu")]
        line = f"{label:28s} {figures[0]:11.1f} {figures[1]:10.1f} {figures[2]:11.2f} {figures[3]:10.2f}"
        if baseline:
            before = statistics.median(run["cpu"] for run in baseline)
            line += f" {before:19.1f} {figures[1] / before:10.2f}x"
        print(line, flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

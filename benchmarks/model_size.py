"""How large a saved model is, and what its compression costs: sb3-er's ``save`` (SB3's zip, its members deflated)
against the same zip as SB3 writes it (members stored).

    python benchmarks/model_size.py [--repeats 5] [--out results/measured/model_size]

Per task, a model learns for a few steps (fresh: most weights still at their initial value) and for longer, then is
saved both ways. Printed per case: the weights' size in memory, each file's size and their ratio, and the median
seconds of ``save`` and of ``load`` over ``--repeats`` (sb3-er's ``save`` includes the deflation; ``load`` reads
every member whole either way). The stored file is the bytes SB3's own ``save`` writes for the model, taken before
sb3-er deflates them. Written (atomically) to ``--out``/summary.md with the command and the code version.
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import sb3_er_envs  # noqa: F401  (registers the thesis's env ids)
from sb3_er import ERSigma, SarsaLambda
from sb3_er.common.atomic import write_atomically
from sb3_er.experiments import records

OUT = Path(__file__).resolve().parent.parent / "results" / "measured" / "model_size"

#: (label, class, env id, learning steps)
CASES = (
    ("Sarsa(λ), simplest walker, fresh", SarsaLambda, "sb3_er/SimplestWalker-v0", 1_000),
    ("ER-σ, simplest walker, 100,000 steps", ERSigma, "sb3_er/SimplestWalker-v0", 100_000),
    ("ER-σ, pendulum swing-up, 30,000 steps", ERSigma, "sb3_er/PendulumSwingup-v0", 30_000),
    ("ER-σ, CartPole-v1, 20,000 steps", ERSigma, "CartPole-v1", 20_000),
)


def stored_bytes(model) -> bytes:
    """The zip SB3's own ``save`` writes for `model` (its members stored): what sb3-er's ``save`` deflates."""
    return model._sb3_zip()


def median_seconds(action, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def measure(label: str, algo, env_id: str, steps: int, repeats: int, folder: Path) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the value watch's warnings of the thesis's ER-sigma
        model = algo("TileQ", env_id, seed=0).learn(steps)
    ours, theirs = folder / "deflated.zip", folder / "stored.zip"
    save_s = median_seconds(lambda: model.save(ours), repeats)
    stored = stored_bytes(model)
    stored_s = median_seconds(lambda: theirs.write_bytes(stored_bytes(model)), repeats)
    load_ours = median_seconds(lambda: algo.load(ours), repeats)
    load_stored = median_seconds(lambda: algo.load(theirs), repeats)
    return {
        "case": label,
        "weights_mb": model.policy.theta_array.nbytes / 1e6,
        "stored_mb": len(stored) / 1e6,
        "deflated_mb": ours.stat().st_size / 1e6,
        "save_stored_s": stored_s,
        "save_s": save_s,
        "load_stored_s": load_stored,
        "load_s": load_ours,
    }


def table(results: list[dict]) -> str:
    lines = [
        "| model | weights in memory, MB | file stored (SB3), MB | file deflated (sb3-er), MB | stored / deflated | "
        "save, s: stored; deflated | load, s: stored; deflated |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(
            f"| {r['case']} | {r['weights_mb']:.1f} | {r['stored_mb']:.1f} | {r['deflated_mb']:.2f} | "
            f"{r['stored_mb'] / r['deflated_mb']:.0f} | {r['save_stored_s']:.2f}; {r['save_s']:.2f} | "
            f"{r['load_stored_s']:.2f}; {r['load_s']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="saves and loads per case, the median shown")
    parser.add_argument("--out", type=Path, default=OUT, help="where summary.md goes (default: the results folder)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be 1 or more, got {args.repeats}")
    with tempfile.TemporaryDirectory() as folder:
        results = [measure(*case, args.repeats, Path(folder)) for case in CASES]
    command = shlex.join(["python", "benchmarks/model_size.py", *(sys.argv[1:] if argv is None else argv)])
    version = records.code_version()
    text = (
        "# How large a saved model is\n\n"
        f"Printed by `{command}` (medians of {args.repeats} saves and loads; code hash "
        f"{str(version.get('code_sha256'))[:10]}).\n\n" + table(results)
    )
    print(text)
    write_atomically(args.out / "summary.md", text)
    print(f"wrote {args.out / 'summary.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

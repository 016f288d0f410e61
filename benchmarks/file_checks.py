"""What the checks on saved replay buffers cost: saving and loading a buffer of N transitions as a pickle and as an
.npz archive, and the share of the load spent checking (checksums, ranges, lengths, tiles against observations).

    python benchmarks/file_checks.py [--transitions 200000] [--tilings 16] [--repeats 3]

The buffer holds N transitions of a 4-dimensional random walk in 200-step trajectories, tiled with the given number
of tilings into 2^22 weights (the default memory). Printed: each operation's best wall-clock time over the repeats,
and the file sizes.
"""

import argparse
import copy
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

from sb3_er.common.buffers import TrajectoryReplayBuffer, check_state, load_buffer, save_buffer
from sb3_er.common.tile_coding import TileCoder

TRAJECTORY_LENGTH = 200


def filled_buffer(n: int, n_tilings: int) -> TrajectoryReplayBuffer:
    coder = TileCoder([0.25] * 4, [3], n_tilings=n_tilings)
    buffer = TrajectoryReplayBuffer(n, coder)
    rng = np.random.default_rng(0)
    observations = np.cumsum(rng.normal(0.0, 0.05, size=(n + 1, 4)), axis=0)
    for t in range(n):
        obs = observations[t]
        buffer.add(obs, coder.slots(obs), int(rng.integers(3)), -1.0, observations[t + 1])
        if (t + 1) % TRAJECTORY_LENGTH == 0:
            buffer.close_trajectory(observations[t + 1], terminated=False)
    return buffer


def best_of(repeats: int, operation) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        operation()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--transitions", type=int, default=200_000)
    parser.add_argument("--tilings", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    buffer = filled_buffer(args.transitions, args.tilings)
    coder = buffer.tile_coder
    state = buffer.__getstate__()
    print(f"{args.transitions} transitions, {args.tilings} tilings, {coder.n_weights} weights")
    print(f"  check_state (every field, once per load):  {best_of(args.repeats, lambda: check_state(state)):.3f} s")
    print(f"  __getstate__ with checksums:              {best_of(args.repeats, buffer.__getstate__):.3f} s")
    print(f"  deepcopy:                                  {best_of(args.repeats, lambda: copy.deepcopy(buffer)):.3f} s")
    with tempfile.TemporaryDirectory() as directory:
        for suffix in (".pkl", ".npz"):
            path = Path(directory) / f"buffer{suffix}"
            save = best_of(args.repeats, lambda path=path: save_buffer(buffer, path))
            load = best_of(args.repeats, lambda path=path: load_buffer(path, coder))
            print(
                f"  {suffix}: save {save:.3f} s, load {load:.3f} s (checks included), "
                f"{path.stat().st_size / 1e6:.1f} MB"
            )
        raw = pickle.dumps(state)
        print(f"  unpickling the state dict alone (no checks):{best_of(args.repeats, lambda: pickle.loads(raw)):.3f} s")


if __name__ == "__main__":
    main()

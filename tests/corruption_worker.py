"""Run by tests/test_corrupt_files.py in a subprocess: load bit-flipped and truncated replay buffers and models, then
use them (replay, learn), printing one JSON line per case. A crash (a segfault in a kernel) kills this process, not
the test run; the test then fails on the exit status and names the last case printed.

Usage: python corruption_worker.py DIRECTORY
"""

import json
import sys
import zipfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from conftest import LineWalkEnv  # noqa: E402

from sb3_er import ER  # noqa: E402

KWARGS = dict(policy_kwargs=dict(n_tilings=8, memory_size=2**15, tile_widths=[0.7]), exploration_rate=0.1, seed=0)
BIT = 5


def report(**case) -> None:
    print(json.dumps(case), flush=True)


def flipped(data: bytes, offset: int) -> bytes:
    out = bytearray(data)
    out[offset] ^= 1 << BIT
    return bytes(out)


def buffer_state(buffer) -> dict:
    state = buffer.__getstate__()
    state.pop("checksums")
    return state


def same_state(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray) else a[k] == b[k] for k in a
    )


def try_buffer(case: str, path: Path, data: bytes, original: dict, target, field=None) -> None:
    path.write_bytes(data)
    previous = target.replay_buffer
    try:
        target.load_replay_buffer(path, truncate_last_traj=False)
    except ValueError as error:
        report(
            kind="buffer",
            case=case,
            field=field,
            outcome="error",
            message=str(error),
            kept=target.replay_buffer is previous,
        )
        return
    intact = same_state(buffer_state(target.replay_buffer), original)
    target.replay(5)  # the kernels index with every loaded array
    report(kind="buffer", case=case, field=field, outcome="loaded", intact=intact)
    target.replay_buffer = previous


def buffer_cases(directory: Path) -> None:
    for prune in (None, "coverage"):
        source = ER("TileQ", LineWalkEnv(segment_every=7), replay_buffer_kwargs=dict(prune=prune), **KWARGS).learn(300)
        target = ER("TileQ", LineWalkEnv(), replay_buffer_kwargs=dict(prune=prune), **KWARGS).learn(50)
        original = buffer_state(source.replay_buffer)
        for suffix in (".pkl", ".npz"):
            path = directory / f"buffer_{prune}{suffix}"
            source.save_replay_buffer(path)
            data = path.read_bytes()
            located = []  # (field, offset) of each array's bytes where they occur once in the file
            if suffix == ".pkl":
                for name, value in original.items():
                    if isinstance(value, np.ndarray) and value.nbytes >= 8 and data.count(value.tobytes()) == 1:
                        located.append((name, data.find(value.tobytes()) + value.nbytes // 2))
            else:
                with zipfile.ZipFile(path) as archive:
                    for info in archive.infolist():  # a local header is 30 bytes plus the name and extra field
                        start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
                        located.append((info.filename[: -len(".npy")], start + info.compress_size // 2))
            for name, offset in located:
                try_buffer(f"{suffix} flip in {name}", path, flipped(data, offset), original, target, field=name)
                try_buffer(f"{suffix} truncated in {name}", path, data[:offset], original, target)
            for offset in range(0, len(data), max(1, len(data) // 150)):
                try_buffer(f"{suffix} flip at byte {offset}", path, flipped(data, offset), original, target)
            for offset in range(0, len(data), max(1, len(data) // 40)):
                try_buffer(f"{suffix} truncated at byte {offset}", path, data[:offset], original, target)


def members(data: bytes) -> dict[str, bytes]:
    """The decoded content of every member of the zip `data`."""
    import io

    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def try_model(case: str, path: Path, data: bytes, member=None, allow_pickle: bool = True, original=None) -> None:
    path.write_bytes(data)
    try:
        model = ER.load(path, env=LineWalkEnv(), allow_pickle=allow_pickle)
    except ValueError as error:
        report(kind="model", case=case, field=member, outcome="error", message=str(error))
        return
    model.learn(60, reset_num_timesteps=False)
    # a flip in a deflate stream's unused last bits changes no member: loading it is no wrong answer
    report(
        kind="model",
        case=case,
        field=member,
        outcome="loaded",
        intact=original is not None and members(data) == original,
    )


def model_cases(directory: Path) -> None:
    model = ER("TileQ", LineWalkEnv(segment_every=7), **KWARGS).learn(300)
    path = directory / "model.zip"
    model.save(path)
    data = path.read_bytes()
    original = members(data)
    with zipfile.ZipFile(path) as archive:
        spans = [
            (info.filename, info.header_offset + 30 + len(info.filename.encode()) + len(info.extra), info.compress_size)
            for info in archive.infolist()
        ]
    for allow_pickle in (True, False):
        for name, start, size in spans:
            for fraction in (0.1, 0.5, 0.9):
                offset = start + int(size * fraction)
                try_model(
                    f"flip in {name} at {fraction} (allow_pickle={allow_pickle})",
                    path,
                    flipped(data, offset),
                    member=name,
                    allow_pickle=allow_pickle,
                    original=original,
                )
            try_model(f"truncated in {name}", path, data[: start + size // 2], allow_pickle=allow_pickle)
        for offset in range(0, len(data), max(1, len(data) // 30)):
            try_model(f"truncated at byte {offset}", path, data[:offset], allow_pickle=allow_pickle)


if __name__ == "__main__":
    directory = Path(sys.argv[1])
    buffer_cases(directory)
    model_cases(directory)
    report(kind="done")

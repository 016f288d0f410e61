"""Atomic writes: the one way sb3-er writes a file it keeps (run files, records, summaries, figures, saved models
and replay buffers).

The content goes to a unique temporary name in the target's folder (``.<stem>.<token>.partial<suffix>``, so that two
writers never share one and libraries that read the format from the suffix still can), is flushed and fsynced, and is
renamed over the target; then the folder is fsynced. A reader sees the old file or the new one, never a torn one.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

PARTIAL_MARK = ".partial"


def partial_path(path: Path) -> Path:
    """A new, unique temporary name beside `path` that keeps its suffix (matplotlib and imageio read the format from
    it): ``.<stem>.<token>.partial<suffix>``.

    :param path: the file that will be written.
    """
    path = Path(path)
    return path.with_name(f".{path.stem}.{secrets.token_hex(6)}{PARTIAL_MARK}{path.suffix}")


def _fsync_folder(folder: Path) -> None:
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:  # a platform without directory descriptors
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)


@contextlib.contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path` to write to (by any library: ``savefig``, ``mimsave``, ...); when the
    block ends without an error, the file is fsynced and renamed to `path`. On an error it is removed.

    :param path: the file to write; replaced only when the block succeeds.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = partial_path(path)
    try:
        yield temporary
        with open(temporary, "rb+") as written:
            os.fsync(written.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


def write_atomically(path: str | Path, content: bytes | str) -> Path:
    """Write `content` (str as UTF-8) to `path` atomically: unique temporary name, flush, fsync, rename.

    :param path: the file to write.
    :param content: the file's content; a str is encoded as UTF-8.
    """
    data = content.encode() if isinstance(content, str) else bytes(content)
    with atomic_output(path) as temporary:
        with open(temporary, "xb") as stream:
            stream.write(data)
            stream.flush()
    return Path(path)

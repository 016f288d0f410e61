"""Files of a results folder: atomic writes, reads that name the file, and one writer per folder.

Every file a reproduction keeps (run CSVs and records, per-run artifacts, ``settings.json``, summaries, figures) is
written by :func:`write_atomically` or inside :func:`atomic_output` (from :mod:`sb3_er.common.atomic`): to a unique
temporary name in the same folder (``.<stem>.<token>.partial<suffix>``), flushed and fsynced, then renamed over the
final name, and the folder fsynced.
A reader therefore sees the old file or the new one, never a torn one, and two writers never share a temporary file.
Temporary files left by a killed writer are removed by :func:`remove_partial_files` when the next command takes the
folder's lock.

:func:`read_json` and :func:`read_csv` raise :class:`DamagedFileError` naming the file and what to do instead of a
bare parser error. :class:`FolderLock` (``fcntl.flock`` on ``<folder>/.sb3-er.lock``) lets one command write a results
folder at a time; the kernel releases the lock when its holder dies, however it dies.
"""

from __future__ import annotations

import contextlib
import datetime
import functools
import io
import json
import os
import socket
import sys
import threading
from pathlib import Path
from typing import Any

from sb3_er.common.atomic import PARTIAL_MARK, atomic_output, write_atomically  # noqa: F401  (re-exported)

LOCK_NAME = ".sb3-er.lock"


class DamagedFileError(ValueError):
    """A file of a results folder is empty, cut short or not what its name promises; the message names the file and
    what to do."""


class DamagedFileWarning(UserWarning):
    """A damaged file was moved aside (renamed, kept) and is written anew."""


class FolderLockedError(RuntimeError):
    """Another command holds the lock of a results folder; the message names its host and process."""


def json_bytes(data: Any) -> bytes:
    """`data` as the indented, key-sorted JSON text every record and settings file is written in.

    :param data: JSON-able data.
    """
    return (json.dumps(data, indent=2, sort_keys=True) + "\n").encode()


def write_json(path: str | Path, data: Any) -> Path:
    """Write `data` as indented JSON (keys sorted) to `path` atomically.

    :param path: the file.
    :param data: JSON-able data.
    """
    return write_atomically(path, json_bytes(data))


def csv_bytes(frame) -> bytes:
    """A pandas DataFrame as the CSV text (without the index) every table and run file is written in.

    :param frame: a pandas DataFrame.
    """
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False)
    return buffer.getvalue().encode()


def write_csv(path: str | Path, frame) -> Path:
    """Write a pandas DataFrame to `path` as CSV (without the index) atomically.

    :param path: the file.
    :param frame: a pandas DataFrame.
    """
    return write_atomically(path, csv_bytes(frame))


def read_json(path: str | Path, remedy: str) -> Any:
    """The JSON data in `path`; DamagedFileError naming the file, the fault and `remedy` (what to do) when the file
    is empty or not valid JSON.

    :param path: the file.
    :param remedy: what the reader should do about a damaged file, for the message.
    """
    path = Path(path)
    text = path.read_bytes()
    if not text.strip():
        raise DamagedFileError(f"{path} is empty (a write that was cut short); {remedy}")
    try:
        return json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise DamagedFileError(f"{path} is not valid JSON ({error}); {remedy}") from error


def read_csv(path: str | Path, remedy: str):
    """The pandas DataFrame in CSV file `path`; DamagedFileError naming the file, the fault and `remedy` when it is
    empty, has no header or rows of another width than the header.

    :param path: the file.
    :param remedy: what the reader should do about a damaged file, for the message.
    """
    import pandas as pd

    path = Path(path)
    try:
        return pd.read_csv(path)
    except pd.errors.EmptyDataError as error:
        raise DamagedFileError(f"{path} is empty (a write that was cut short); {remedy}") from error
    except (pd.errors.ParserError, UnicodeDecodeError) as error:
        raise DamagedFileError(f"{path} is not a well-formed CSV file ({error}); {remedy}") from error


def remove_partial_files(folder: str | Path) -> list[Path]:
    """Remove the temporary files that killed writers left under `folder` (see
    :func:`sb3_er.common.atomic.partial_path`, and the ``<name>.partial`` files of earlier versions); return them. Call
    it only while holding the folder's lock.

    :param folder: the folder to clean, searched recursively.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    removed = []
    for candidate in folder.rglob(f"*{PARTIAL_MARK}*"):
        name = candidate.name
        ours = name.startswith(".") and PARTIAL_MARK in name
        if candidate.is_file() and (ours or name.endswith(PARTIAL_MARK)):
            candidate.unlink(missing_ok=True)
            removed.append(candidate)
    return removed


class FolderLock:
    """The one-writer lock of results folder `folder`: an exclusive ``fcntl.flock`` on ``<folder>/.sb3-er.lock``.

    The holder writes its host, process id, command line and start time into the file, so that a second command can
    say who holds it: :meth:`acquire` raises FolderLockedError with that text, without waiting and without changing
    any file. The kernel drops the lock when the holding process dies (killed, crashed or ended), so a dead holder
    never blocks the next command; the file itself stays (deleting it would let two commands lock two different
    files). On a platform without ``fcntl`` the folder is not locked.

    Use it as a context manager, or call :meth:`acquire` and :meth:`release`.

    :param folder: the results folder to lock (``--out`` of ``sb3-er reproduce``).
    :param elsewhere: how the user of the locking command writes elsewhere instead, for the message (default
        "choose another --out": the option of ``sb3-er reproduce``).
    """

    def __init__(self, folder: str | Path, elsewhere: str = "choose another --out") -> None:
        self.folder = Path(folder)
        self.elsewhere = elsewhere
        self.path = self.folder / LOCK_NAME
        self._descriptor: int | None = None

    def acquire(self) -> FolderLock:
        try:
            import fcntl
        except ImportError:  # not a POSIX system
            return self
        self.folder.mkdir(parents=True, exist_ok=True)
        descriptor = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)  # not inherited by child processes
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(descriptor, 4096, 0).decode(errors="replace").strip() or "another command (starting)"
            os.close(descriptor)
            raise FolderLockedError(
                f"{self.folder} is being written by {holder}; wait until that command ends (or stop it) and run this "
                f"one again, or {self.elsewhere}. Nothing was changed."
            ) from None
        started = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        command = " ".join(sys.argv) or sys.executable
        text = f"host {socket.gethostname()}, pid {os.getpid()} (since {started}: {command})\n".encode()
        os.ftruncate(descriptor, 0)
        os.pwrite(descriptor, text, 0)
        self._descriptor = descriptor
        return self

    def release(self) -> None:
        if self._descriptor is not None:
            os.close(self._descriptor)  # closing the descriptor drops the flock
            self._descriptor = None

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc_info) -> None:
        self.release()


def move_aside(path: str | Path, reason: str = "damaged") -> Path | None:
    """Rename `path` to ``<name>.<reason>-<UTC time>`` (with ``-2``, ``-3``, ... if taken) beside it, so that no
    reader takes it for the file it was and nothing is lost; return the new path, None when `path` does not exist.

    :param path: the file (or folder) to move aside.
    :param reason: the word in the new name (default "damaged").
    """
    path = Path(path)
    if not path.exists():
        return None
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    target, number = path.with_name(f"{path.name}.{reason}-{stamp}"), 1
    while target.exists():
        number += 1
        target = path.with_name(f"{path.name}.{reason}-{stamp}-{number}")
    os.replace(path, target)
    return target


_held = threading.local()


def holds_folder_locks(function):
    """Decorate a command function (``reproduce``, ``reproduce_<analysis>``) so that the locks it takes with
    :func:`lock_folder` are held until it returns or raises, and released then.

    :param function: the command function to decorate.
    """

    @functools.wraps(function)
    def with_locks(*args, **kwargs):
        outer = getattr(_held, "stack", None)
        with contextlib.ExitStack() as stack:
            _held.stack = stack
            try:
                return function(*args, **kwargs)
            finally:
                _held.stack = outer

    return with_locks


def lock_folder(*folders: str | Path) -> None:
    """Take the :class:`FolderLock` of each of `folders` (a folder this process holds already is skipped), held until
    the function decorated with :func:`holds_folder_locks` that calls this returns, and remove the temporary files
    that killed writers left in it (:func:`remove_partial_files`); FolderLockedError, with the locks taken so far
    released by that function, when another command holds one."""
    stack = getattr(_held, "stack", None)
    if stack is None:
        raise RuntimeError("lock_folder is for functions decorated with holds_folder_locks")
    held = getattr(_held, "folders", set())
    for folder in dict.fromkeys(Path(folder).resolve() for folder in folders):
        if folder in held:
            continue
        stack.enter_context(FolderLock(folder))
        held.add(folder)
        stack.callback(held.discard, folder)
        remove_partial_files(folder)  # what a killed writer of this folder left
    _held.folders = held


def save_figure(figure, path: str | Path, **savefig_kwargs) -> Path:
    """``figure.savefig(path, **savefig_kwargs)`` (a matplotlib figure), atomically.

    :param figure: the matplotlib figure.
    :param path: the image file; its suffix gives the format.
    """
    with atomic_output(path) as temporary:
        figure.savefig(temporary, **savefig_kwargs)
    return Path(path)

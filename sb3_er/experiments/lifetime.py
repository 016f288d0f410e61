"""Processes that end with the command that started them, however it ends.

A worker process calls :func:`die_with_parent` first: on Linux the kernel sends it SIGKILL when its parent dies
(``prctl(PR_SET_PDEATHSIG)``), and on every platform a watchdog thread kills it once its parent process is gone (the
parent id changes when a process is orphaned). So a driver killed with SIGKILL, by a scheduler's time limit or the OOM
killer leaves no worker behind, where a worker of a ``concurrent.futures`` pool would stay blocked forever.

:class:`Reaper` is for processes the driver does not start itself (those a local Ray instance starts): a small
helper process, told the driver's descendants while the driver runs, that kills whatever of them is left when the
driver dies without saying goodbye. It only ever kills processes that descend from the driver and whose start time it
recorded, so a cluster the command joined (whose processes are no descendants) is never touched.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

PR_SET_PDEATHSIG = 1
PR_SET_NAME = 15
WATCH_INTERVAL_S = 0.5


def _prctl(option: int, argument) -> bool:
    """``prctl(option, argument)`` on Linux; False elsewhere or when it fails."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(option, argument, 0, 0, 0) == 0
    except (OSError, AttributeError):  # no prctl in this libc
        return False


def die_with_parent(parent_pid: int, name: str | None = None) -> None:
    """Make this process end when the process `parent_pid` (its parent) ends: SIGKILL from the kernel on Linux (also
    when this process is stopped or blocked), and a daemon thread that kills this process within WATCH_INTERVAL_S of
    being orphaned on any platform. `name` (at most 15 bytes) then becomes the process's name on Linux, as ``ps``,
    ``top`` and the OOM killer's log show it.

    :param parent_pid: the parent's process id.
    :param name: the process name to set (default None: keep it).
    """
    _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before the line above
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(WATCH_INTERVAL_S)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()
    if name is not None:
        import ctypes

        _prctl(PR_SET_NAME, ctypes.c_char_p(name.encode()[:15]))


def _proc_stat(pid: int) -> tuple[int, int] | None:
    """(parent pid, start time in clock ticks since boot) of `pid` from /proc, None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (command name) "
    return int(fields[1]), int(fields[19])


def descendants(pid: int | None = None) -> dict[int, int]:
    """The living descendants of `pid` (default this process), pid to start time; empty where /proc is missing.

    :param pid: the ancestor's process id (default None: this process).
    """
    pid = os.getpid() if pid is None else pid
    children: dict[int, list[int]] = {}
    started: dict[int, int] = {}
    try:
        entries = [int(name) for name in os.listdir("/proc") if name.isdigit()]
    except OSError:
        return {}
    for entry in entries:
        stat = _proc_stat(entry)
        if stat is not None:
            children.setdefault(stat[0], []).append(entry)
            started[entry] = stat[1]
    found: dict[int, int] = {}
    stack = list(children.get(pid, []))
    while stack:
        child = stack.pop()
        if child not in found:
            found[child] = started[child]
            stack.extend(children.get(child, []))
    return found


_REAPER_SOURCE = """
import os, signal, sys
def _proc_stat(pid):
    try:
        text = open(f"/proc/{pid}/stat").read()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()
    return int(fields[1]), int(fields[19])
known = {}
for line in sys.stdin:
    words = line.split()
    if words == ["bye"]:
        sys.exit(0)
    known = dict(zip(map(int, words[0::2]), map(int, words[1::2])))
for pid, start in known.items():  # the driver died: end what it started
    stat = _proc_stat(pid)
    if stat is not None and stat[1] == start:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
"""


class Reaper:
    """Kills the driver's descendants that outlive it (see the module docstring); a no-op where /proc is missing.

    Start it before starting the processes; a thread of the driver tells the helper the driver's descendants every
    WATCH_INTERVAL_S. Call :meth:`close` once they have been ended in order (e.g. after ``ray.shutdown()``).
    """

    def __init__(self) -> None:
        self._helper: subprocess.Popen | None = None
        self._lock = threading.Lock()
        if not Path("/proc/self/stat").exists():
            return
        self._helper = subprocess.Popen(
            [sys.executable, "-c", _REAPER_SOURCE],
            stdin=subprocess.PIPE,
            text=True,
            start_new_session=True,  # neither Ctrl-C to the group nor the driver's death stops it before its work
        )
        self._own_pid = self._helper.pid
        self._closed = threading.Event()
        threading.Thread(target=self._tell, name="reaper", daemon=True).start()

    def _tell(self) -> None:
        while not self._closed.wait(WATCH_INTERVAL_S):
            self.update()

    def update(self) -> None:
        """Tell the helper the driver's current descendants."""
        with self._lock:
            if self._helper is None:
                return
            known = {pid: start for pid, start in descendants().items() if pid != self._own_pid}
            try:
                self._helper.stdin.write(" ".join(f"{pid} {start}" for pid, start in known.items()) + "\n")
                self._helper.stdin.flush()
            except (OSError, ValueError):
                self._helper = None

    def close(self) -> None:
        """Tell the helper that the driver ended its processes itself, and wait for it to exit."""
        if self._helper is None:
            return
        self._closed.set()
        with self._lock:
            self._finish()

    def _finish(self) -> None:
        if self._helper is None:
            return
        try:
            self._helper.stdin.write("bye\n")
            self._helper.stdin.close()
        except (OSError, ValueError):
            pass
        self._helper.wait(timeout=10)
        self._helper = None

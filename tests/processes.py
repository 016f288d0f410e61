"""Processes read from /proc, independently of the package: for tests that a command's processes end with it."""

import os
import time
from pathlib import Path


def processes() -> dict[int, tuple[int, str, str]]:
    """pid -> (parent pid, state, command line) of every process."""
    table = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            command = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        table[int(entry)] = (int(fields[1]), fields[0], command)
    return table


def tree(pid: int) -> dict[int, str]:
    """The living descendants of `pid`: pid -> command line."""
    table = processes()
    found, stack = {}, [pid]
    while stack:
        parent = stack.pop()
        for child, (ppid, state, command) in table.items():
            if ppid == parent and child not in found and state != "Z":
                found[child] = command
                stack.append(child)
    return found


def name(pid: int) -> str:
    """The process's name (``/proc/<pid>/comm``), "" when it is gone."""
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


def alive(pids) -> list[int]:
    """Those of `pids` that still run."""
    table = processes()
    return [pid for pid in pids if pid in table and table[pid][1] != "Z"]  # a zombie has ended


def wait_for(condition, what: str, timeout: float = 120.0):
    """The first true value of `condition()`, asked every 50 ms; AssertionError naming `what` after `timeout` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")

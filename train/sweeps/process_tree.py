"""Every process a sweep starts ends with it: a local Ray instance is a dozen processes, and a signal while
ray.init is under way (before Ray can shut itself down) left `ray::DashboardAgent` and `ray::RuntimeEnvAgent`
running, orphaned to init and deaf to SIGTERM.

While a sweep owns Ray its driver is a child subreaper (Linux prctl PR_SET_CHILD_SUBREAPER): a process orphaned
below it is re-parented to it, not to init, so it stays in the driver's process tree. At the end, every process in
that tree that was not there before Ray started is asked to end (SIGTERM), then killed (SIGKILL) if it has not
within a grace period, and reaped. Where prctl is not available the tree is still ended, orphans aside.
"""

from __future__ import annotations

import ctypes
import os
import signal
import time
from pathlib import Path

PR_SET_CHILD_SUBREAPER = 36   # linux/prctl.h
GRACE_S = 2.0                 # Ray's processes end within a second of SIGTERM when they end at all; the agents never do
GIVE_UP_S = 5.0               # after SIGKILL: only a process stuck in the kernel outlives this


def _set_subreaper(on: bool) -> bool:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_CHILD_SUBREAPER, int(on), 0, 0, 0) == 0
    except (OSError, AttributeError):   # not Linux
        return False


def _table() -> dict[int, tuple[int, str]]:
    """{pid: (parent pid, state letter)} of every process /proc shows."""
    found = {}
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                fields = (p / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue   # ended meanwhile
            found[int(p.name)] = (int(fields[1]), fields[0])
    return found


def descendants(pid: int) -> set[int]:
    """The processes below `pid` (children, their children, ...), zombies included."""
    children: dict[int, list[int]] = {}
    for p, (ppid, _) in _table().items():
        children.setdefault(ppid, []).append(p)
    found, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), ()):
            if c not in found:
                found.add(c)
                todo.append(c)
    return found


class ProcessTree:
    """The processes this process starts from now on (Ray's), ended by end(): see the module's docstring."""

    def __init__(self):
        self.pid = os.getpid()
        self.before = descendants(self.pid)
        self.subreaper = _set_subreaper(True)

    def started(self) -> set[int]:
        return descendants(self.pid) - self.before

    def end(self, grace: float = GRACE_S) -> set[int]:
        """End every process started since __init__ (SIGTERM, then SIGKILL after `grace` seconds) and reap those
        that are this process's children; the subreaper flag off again. Returns the pids it had to signal."""
        signalled = set()
        deadline, sig = time.monotonic() + grace, signal.SIGTERM
        while True:
            live = {p for p in self.started() if _table().get(p, (0, "Z"))[1] not in "ZX"}
            self._reap()
            if not live or time.monotonic() > deadline + GIVE_UP_S:   # a process SIGKILL cannot end (stuck in the
                break                                                 # kernel): not waited for for ever
            if time.monotonic() > deadline:
                sig = signal.SIGKILL
            for p in live:
                try:
                    os.kill(p, sig)
                    signalled.add(p)
                except OSError:
                    pass
            time.sleep(0.05)
        self._reap()
        if self.subreaper:
            _set_subreaper(False)
        return signalled

    def _reap(self) -> None:
        """Collect the exit status of this process's ended children started since __init__ (no zombie stays)."""
        for p in self.started():
            try:
                os.waitpid(p, os.WNOHANG)
            except ChildProcessError:   # not our child (a grandchild not yet re-parented) or reaped already
                pass

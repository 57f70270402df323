"""Figure 2 drawn in a process of its own, started before the runner imports torch.

The runner's first second is torch's import, on one core, while the other core idles. A process started then imports
`train.figures` there (matplotlib, and torch through `aesop_torch.rules`' names: ~1.6 s on that core) and waits, so
Figure 2 at the end costs its drawing alone (~0.3 s, beside the goal trials) instead of an import and a drawing after
them. It holds no pybullet and no world. It ignores Ctrl-C (the runner owns it and ends the process) and lives until
`close`.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import threading

from train.physics import START_METHOD, by_name


def _init() -> None:
    import train.figures  # noqa: F401  the import this process exists to take off the runner's critical path


class Drawer:
    def __init__(self):
        main = threading.current_thread() is threading.main_thread()   # only it may set handlers
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None   # inherited by the process
        try:
            self._pool = mp.get_context(START_METHOD).Pool(1, initializer=_init)
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)

    def draw(self, target: str, *args):
        """target(*args) there, target given as "module:function": an object whose get() waits for the result."""
        return self._pool.apply_async(by_name, (target, args))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None

"""Figure 2 drawn in a process of its own, started before the runner imports torch.

The runner's first second is torch's import, on one core, while the other core idles. A process started then imports
`train.runner.figures` there (matplotlib, and torch through `aesop_torch.rules`' names: ~1.6 s on that core) and waits, so
Figure 2 at the end costs its drawing alone (~0.3 s, beside the goal trials) instead of an import and a drawing after
them. It holds no pybullet and no world. It ignores Ctrl-C (the runner owns it and ends the process) and lives until
`close`.
"""

from __future__ import annotations

from train.learning.sim_pool import by_name, end_pool, quiet_pool


def _init() -> None:
    import train.runner.figures  # noqa: F401  the import this process exists to take off the runner's critical path


class Drawer:
    def __init__(self):
        self._pool = quiet_pool(1, _init)

    def draw(self, target: str, *args):
        """target(*args) there, target given as "module:function": an object whose get() waits for the result."""
        return self._pool.apply_async(by_name, (target, args))

    def close(self) -> None:
        end_pool(self._pool)
        self._pool = None

"""Progress of the runner's long steps: a tqdm bar on a terminal, a few plain lines when the output is a file or pipe.

A bar on a terminal is redrawn in place, so it may update often; in a log every line stays, so there a step only
says when it starts and when it ends. Lines that tell the run's story (one per episode) go through `line`: above the
bar on a terminal, as they are in a log.
"""

from __future__ import annotations

import shutil
import sys
import time


class Step:
    """One long step: `update(n, postfix)` as work finishes, `close()` at the end (or use it as a context manager).
    announce=False: no start and end lines when plain (the step prints its own lines)."""

    def __init__(self, desc: str, total: int, unit: str = "it", stream=None, announce: bool = True):
        self.desc, self.total, self.unit, self.announce = desc, total, unit, announce
        self.stream = stream or sys.stdout
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.done, self.t0, self.bar = 0, time.perf_counter(), None
        if self.tty:
            from tqdm import tqdm
            sized = shutil.get_terminal_size((0, 0)).columns > 0   # a pty of unknown size reports 0 columns
            self.bar = tqdm(total=total, desc=desc, unit=unit, file=self.stream, dynamic_ncols=sized,
                            ncols=None if sized else 100, nrows=None if sized else 40, leave=True,
                            mininterval=0.2)
        elif announce:
            self._write(f"{desc}: {total} {unit}(s)...")

    def _write(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()

    def update(self, n: int = 1, postfix: str | None = None) -> None:
        self.done += n
        if self.bar is not None:
            if postfix is not None:
                self.bar.set_postfix_str(postfix, refresh=False)
            self.bar.update(n)

    def to(self, done: int, total: int | None = None) -> None:
        """For callbacks that report a running count (train.learning.population's progress(done, total))."""
        self.update(done - self.done)

    def line(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            self._write(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.announce and self.done >= self.total:
            self._write(f"{self.desc}: done in {time.perf_counter() - self.t0:.1f} s")

    def __enter__(self) -> "Step":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

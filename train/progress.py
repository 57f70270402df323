"""Progress on a terminal (one redrawn bar) or plain lines when the output is a file or a pipe."""

from __future__ import annotations

import sys


class Progress:
    def __init__(self, total: int, stream=None):
        self.total, self.stream = total, stream or sys.stdout
        self.tty = self.stream.isatty()

    def update(self, done: int, obj: str, rules: dict) -> None:
        fired = " ".join(f"{p}:{r}" for p, r in rules.items())
        if self.tty:
            width = 30
            fill = int(width * done / max(self.total, 1))
            self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{self.total} {obj:<24} {fired}\033[K")
            if done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(f"episode {done}/{self.total}: {obj} {fired}\n")
        self.stream.flush()

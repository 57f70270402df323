"""Silence pybullet's C-level chatter, which Python's own redirection cannot catch."""

import os
import sys
from contextlib import contextmanager


@contextmanager
def quiet_c_output():
    """Silence C-level stdout/stderr (pybullet's b3Warning / merge chatter) by pointing fds 1 and 2 at /dev/null."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)

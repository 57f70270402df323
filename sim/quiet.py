"""Silence pybullet's C-level chatter, which Python's own redirection cannot catch."""

import os
import sys
from contextlib import contextmanager, suppress


@contextmanager
def quiet_c_output():
    """Silence C-level stdout/stderr (pybullet's b3Warning / merge chatter) by pointing fds 1 and 2 at /dev/null.
    A stream that is None or whose fd is closed (a process started with `>&-`) has nothing to flush or restore."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            with suppress(OSError, ValueError):   # a full or closed stream: its owner reports that, not this
                stream.flush()
    saved = []
    for fd in (1, 2):
        try:
            saved.append(os.dup(fd))
        except OSError:   # closed: after the block it is closed again
            saved.append(None)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        for fd, old in zip((1, 2), saved):
            if old is None:
                os.close(fd)
            else:
                os.dup2(old, fd)
                os.close(old)
        if devnull not in (1, 2):
            os.close(devnull)

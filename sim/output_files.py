"""Writing an output file so that no reader ever sees half of it: one writer for the objects generator's --out,
the runner's checkpoints and summaries, and the sweeps' cells, records and reports.

The data goes to a temporary file in the target's directory, is fsynced, given the mode a plain open() would give
(mkstemp makes it private), and then put in place: renamed over the target, or, where the target must not be
overwritten, hard-linked to its name (which fails if the name was taken meanwhile; where hard links are not
supported, renamed after checking the name is free). The temporary file never stays, whatever ends the write.
Here, the lowest floor that writes such files (sim/make_objects.py), so that train/ imports it and sim imports
nothing from train.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

NO_LINKS = (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK)   # a file system without them


def _write(f, data: bytes) -> None:
    f.write(data)


def write_atomic(path: str | os.PathLike, data: bytes, *, replace: bool = True, hidden: bool = True,
                 write=None) -> None:
    """`data` to `path`, atomically (the module's docstring). replace=False: FileExistsError if `path` exists.
    hidden: the temporary file is `.<name>.<random>.tmp` (a directory listing skips it), else `<name>.<random>.tmp`
    (the runner's checkpoints, whose leftovers it recognises so). write(f, data): how the bytes are written (a test's
    stand-in for a full disk). OSError as the system gives it."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}." if hidden else f"{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            (write or _write)(f, data)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        if replace:
            os.replace(tmp, path)
            return
        try:
            os.link(tmp, path)
        except FileExistsError:
            raise
        except OSError as e:
            if e.errno not in NO_LINKS:
                raise
            if os.path.lexists(path):
                raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(path)) from None
            os.replace(tmp, path)
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)

"""The --out directory: whether this run may write it, its lock, the leftovers of a run killed before its first
checkpoint, and no symbolic link among what the run writes.

DIR belongs to one run at a time: an exclusive flock on DIR/.lock, which holds the pid, released by the kernel when
the run ends however it ends. A fresh run needs DIR empty or creatable; the leftovers of a run killed before its
first checkpoint (config.json, run.json, checkpoint temp files) count as empty and are removed. A resumed run writes
only inside DIR: a link among what it writes is refused. Torch-free: checked before the runner's first line.
"""

from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path

from train.common.exits import UsageError
from train.common.out_checks import link_inside, refuse_uncreatable, refuse_unusable, refuse_unwritable

LOCK_NAME = ".lock"
CONFIG_NAME = "config.json"   # the run's config, written when it starts (summary.json's `config`)
RUN_NAME = "run.json"         # the run's settings as given (objects, orders, physics, overrides): what --resume reads
WRITTEN = ("tb", "checkpoints", "frames", CONFIG_NAME, RUN_NAME, "summary.json", "figure2.png")   # what a run writes


def check_out(out: Path, resume: bool) -> None:
    """Refuse an --out that is not, or cannot become, a directory this run may write (nothing is created here): the
    checks every --out gets (train/common/out_checks.py), and the run's own."""
    refuse_unusable(out)
    if resume:
        if not out.is_dir():
            raise UsageError(f"--resume: no checkpoint at {out / 'checkpoints' / 'latest.pt'} ({out} does not exist): "
                             "nothing to continue; start the run without --resume")
    elif refuse_uncreatable(out) == out and holds_a_run(out):
        busy = lock_holder(out)
        raise UsageError(f"--out {out} is in use by another run (pid {busy})" if busy else
                         f"--out {out} already holds files; use --resume to continue it or another --out")
    refuse_unwritable(out)
    if resume and (link := link_inside(out, WRITTEN)):
        raise UsageError(f"--resume: {link} is a symbolic link; the run writes only inside --out {out}: remove it")


def _leftover(out: Path, entry) -> bool:
    """What a run killed before its first checkpoint leaves: its config.json, run.json and checkpoint temp files."""
    if entry.name == LOCK_NAME:   # whatever it is, lock_out judges it
        return True
    if entry.name in (CONFIG_NAME, RUN_NAME) and entry.is_file(follow_symlinks=False):
        return True
    if entry.name == "checkpoints" and entry.is_dir(follow_symlinks=False):
        return all(re.fullmatch(r"latest\.pt\..+\.tmp", e.name) and e.is_file(follow_symlinks=False)
                   for e in os.scandir(entry.path))
    return False


def holds_a_run(out: Path) -> bool:
    """Whether --out holds more than the lock and the leftovers of a run killed before its first checkpoint."""
    return not all(_leftover(out, e) for e in os.scandir(out))


def remove_leftovers(out: Path) -> None:
    """A fresh run into the --out of one killed before its first checkpoint: its leftovers go (the lock stays)."""
    for e in list(os.scandir(out)):
        if e.name == "checkpoints":
            for f in os.scandir(e.path):
                os.unlink(f.path)
            os.rmdir(e.path)
        elif e.name != LOCK_NAME:
            os.unlink(e.path)


def lock_holder(out: Path) -> str | None:
    """The pid written in DIR/.lock while a run holds it, else None. Only reads."""
    import fcntl

    try:
        fd = os.open(out / LOCK_NAME, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):   # not a lock of ours (a FIFO would block a read)
            return None
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except BlockingIOError:
        return os.read(fd, 32).decode(errors="replace").strip() or "unknown"
    finally:
        os.close(fd)   # closing drops the probe's shared lock, if it got one


def lock_out(out: Path) -> int:
    """Make --out this run's: an exclusive flock on DIR/.lock, held until the process ends (the kernel lets go
    even on SIGKILL). Refused (UsageError) while another run holds it."""
    import fcntl

    out.mkdir(parents=True, exist_ok=True)
    lock = out / LOCK_NAME
    # never through a link (it would write the pid into, or create, a file elsewhere) and never blocking (a FIFO)
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise UsageError(f"--out {out}: {lock} is a symbolic link, not a run's lock; remove it") from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise UsageError(f"--out {out}: {lock} is not a regular file, not a run's lock; remove it")
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 32).decode(errors="replace").strip()
        os.close(fd)
        raise UsageError(f"--out {out} is in use by another run" + (f" (pid {holder})" if holder else "")) from None
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


def unlock_created(out: Path, lock: int, created: list[Path]) -> None:
    """A run refused or interrupted after lock_out: the lock closed and, if lock_out created --out (`created`, the
    directories that did not exist, innermost first), nothing left behind (rmdir: only what is still empty)."""
    os.close(lock)
    if created:
        (out / LOCK_NAME).unlink(missing_ok=True)
        for d in created:
            try:
                d.rmdir()
            except OSError:
                pass

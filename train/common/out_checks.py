"""The checks every --out gets before anything is written, the runner's and the sweeps' alike: not a link to
nothing, a directory or creatable as one, writable, and no symbolic link among what a run writes there (a link would
send its writes elsewhere). Each refusal is one line, raised as the caller's own error class (`error`), worded the
same for both. What differs stays with each: the runner's lock and leftovers (train/runner/out_dir.py), the sweeps'
record (train/sweeps/store.py)."""

from __future__ import annotations

import os
from pathlib import Path

from train.common.exits import UsageError


def refuse_unusable(out: Path, error=UsageError) -> None:
    """An --out that is a symbolic link to nothing, or exists and is no directory."""
    if out.is_symlink() and not out.exists():
        raise error(f"--out {out} is a symbolic link to nothing ({os.readlink(out)})")
    if out.exists() and not out.is_dir():
        raise error(f"--out {out} exists and is not a directory")


def refuse_uncreatable(out: Path, error=UsageError) -> Path:
    """An --out that cannot be made: its nearest existing ancestor (returned) is a link to nothing, no directory,
    or not writable."""
    p = out
    while not p.exists():
        if p.is_symlink():
            raise error(f"--out {out}: {p} is a symbolic link to nothing")
        p = p.parent
    if not p.is_dir():
        raise error(f"--out {out}: {p} is not a directory")
    if not os.access(p, os.W_OK | os.X_OK):
        raise error(f"--out {out}: {p} is not writable")
    return p


def refuse_unwritable(out: Path, error=UsageError) -> None:
    """An --out directory this process cannot write."""
    if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
        raise error(f"--out {out} is not writable")


def link_inside(out: Path, written) -> Path | None:
    """The first symbolic link among what a run writes in --out (`written`: the names it writes there), walking
    the directories among them without following links."""
    for name in written:
        top = out / name
        if top.is_symlink():
            return top
        if top.is_dir():
            for root, dirs, files in os.walk(top):   # does not follow links
                for n in sorted(dirs + files):
                    if (Path(root) / n).is_symlink():
                        return Path(root) / n
    return None

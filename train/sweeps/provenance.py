"""Where a sweep's rows come from: the checkout's commit, the libraries' versions, the time (docs/sweeps.md "DIR").

The commit is `git describe --always --dirty --tags`, asked once per process: the code a process runs is the code
it imported when it started, whatever the tree holds later. `-dirty`: tracked files differ from the commit, so the
commit alone does not name the code.
"""

from __future__ import annotations

import functools
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LIBRARIES = ("torch", "numpy", "pybullet", "pyarrow", "ray")
UNKNOWN = "unknown"   # the commit outside git (or without git)


def utc_now() -> str:
    """The time now, UTC, ISO 8601 to the second (2026-12-06T14:03:59Z)."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


@functools.cache
def commit() -> str:
    """`git describe --always --dirty --tags` of this checkout, asked once per process; 'unknown' outside git."""
    try:
        r = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=ROOT, capture_output=True,
                           text=True, timeout=10, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return UNKNOWN
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else UNKNOWN


def names_its_code(c: str | None) -> bool:
    """Whether a commit string names the code exactly: a commit, not a dirty tree's, not unknown."""
    return bool(c) and c != UNKNOWN and not c.endswith("-dirty")


def versions() -> dict:
    """The installed versions of the libraries a cell's rows depend on, and Python's (None: not installed)."""
    from importlib import metadata
    found = {"python": sys.version.split()[0]}
    for name in LIBRARIES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found

"""Atomic checkpoints: write to a temporary file beside the target, fsync, then rename over it.

A run killed mid-write leaves the previous checkpoint intact; everything saved is plain tensors, dicts, lists,
strings and numbers, so `torch.load(path, weights_only=True)` reads it without executing any pickled code.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch


def _write_atomic(path: str | os.PathLike, write, mode: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; an output file is as readable as any other
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_atomic(obj, path: str | os.PathLike) -> None:
    _write_atomic(path, lambda f: torch.save(obj, f), "wb")


def write_text_atomic(text: str, path: str | os.PathLike) -> None:
    _write_atomic(path, lambda f: f.write(text), "w")


def load(path: str | os.PathLike) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)

"""Keep freed memory in the process: glibc's malloc tuned for many short-lived tensors of a few hundred kB.

torch allocates every CPU tensor with malloc. By default glibc maps a large block afresh (mmap) and gives memory freed
at the top of its heap back to the OS once more than twice the largest recent block is free; the next tensor then
touches new pages, one page fault per 4 kB. The memory's recall makes and drops tensors of 100 kB to 1 MB at every
step: 246 cues against 230 of the agent's episodes took ~20,000 page faults per recall, a fifth of its time, until
the recall spanned only the rows that differ between episodes; since then ~5,000, a tenth (getrusage around one
recall, 2026-12-02). `keep_freed_memory()` raises both thresholds, so freed blocks are reused.

It is process-wide (the C library's malloc, for numpy and everything else too), so the library never calls it by
itself: the runner (train/run.py) and the benchmarks do, before any work, and a user may. Where the C library has
no mallopt (not glibc) it does nothing and returns False.
"""

from __future__ import annotations

import ctypes

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3   # glibc's malloc.h


def keep_freed_memory(trim_mb: int = 128, mmap_mb: int = 32) -> bool:
    """Give memory back to the OS only when more than trim_mb MB is free at the heap's top, and map blocks of
    mmap_mb MB or more on their own (glibc's ceiling for its own adaptive threshold is 32 MB on 64-bit). Returns
    True if glibc took both settings."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_TRIM_THRESHOLD, trim_mb << 20)) & bool(mallopt(_M_MMAP_THRESHOLD, mmap_mb << 20))

"""The garbage collector while the runner starts: off during its imports, their objects frozen before it forks.

Importing torch, the simulator and matplotlib allocates millions of objects that live as long as the process and form
few cycles: the collector's passes over them took ~0.3 CPU-s of the runner's torch import (389 collections, 3 of them
full, on a busy machine) and ~0.1 s of the figure process's imports. This is the gc module's own recipe for a parent
that forks without exec (its docs, gc.freeze): collection off early in the parent, its objects frozen just before the
fork (a child's collections then neither walk them nor copy the pages they live on), collection on in the child.
Off or on, the collector changes no result: it frees unreachable cycles, nothing the run reads."""

from __future__ import annotations

import gc


def imports_begin() -> None:
    """The runner script's first line: collection off until imports_done (a caller of main() in-process keeps its
    collector as it is)."""
    gc.disable()


def imports_done() -> None:
    """Collection on again, what exists now frozen (never collected, never walked), if imports_begin turned it off;
    else nothing (a test's process keeps its own collector, its objects unfrozen)."""
    if not gc.isenabled():
        gc.freeze()
        gc.enable()

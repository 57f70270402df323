"""keep_freed_memory: freed tensors are reused instead of touching new pages (glibc only)."""

import subprocess
import sys

import pytest

# Each round makes three 1 MB tensors and drops them. With glibc's starting thresholds held fixed (128 kB: blocks
# above it mapped afresh, free memory above it at the heap's top given back) every round faults its 3 x 256 pages
# in again. (glibc's own default adapts both thresholds to the largest block freed so far, so whether it does the
# same depends on what the process freed before; in a 246-cue recall it did, ~20,000 faults.) With
# keep_freed_memory the blocks are reused.
ROUNDS = 40
WARM = 5   # rounds before counting: a fresh heap (torch alone, aesop_torch no longer importing the agent with it)
           # still grows over the first rounds (1,792 and 2,560 faults after 1 and 2 such rounds, 0 after 5)
SCRIPT = f"""
import ctypes, resource, sys, torch
from aesop_torch.malloc import keep_freed_memory
if sys.argv[1] == "tuned":
    ok = keep_freed_memory()
else:   # glibc's starting thresholds, held fixed
    mallopt = ctypes.CDLL(None).mallopt
    ok = bool(mallopt(-1, 128 << 10)) & bool(mallopt(-3, 128 << 10))
def round_():
    blocks = [torch.ones(1 << 18) for _ in range(3)]   # 1 MB each
    return sum(float(b[-1]) for b in blocks)
for _ in range({WARM}):   # the heap grown to hold a round (what the process allocated before decides how far)
    round_()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range({ROUNDS}):
    round_()
print(int(ok), resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def faults(mode: str) -> tuple[bool, int]:
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True)
    ok, n = out.stdout.split()
    return ok == "1", int(n)


def test_freed_tensors_are_reused_instead_of_faulted_in_again():
    tuned, kept = faults("tuned")
    if not tuned:
        pytest.skip("not glibc: mallopt is not there to tune")
    _, stingy = faults("stingy")
    pages = ROUNDS * 3 * (1 << 20) // 4096
    assert stingy > pages * 0.9          # every round's pages faulted in again
    assert kept < pages // 20            # reused (512 faults of 30,720 pages measured)

"""keep_freed_memory: freed tensors are reused instead of touching new pages (glibc only)."""

import subprocess
import sys

import pytest

# Each round makes three 1 MB tensors and drops them: 3 MB freed at the heap's top, more than glibc's adaptive trim
# threshold (twice the largest block), so by default it goes back to the OS and the next round faults its
# pages in again: of 40 x 768 pages, 19,387 faulted (2026-12-02). Kept, it is reused: 256.
ROUNDS = 40
SCRIPT = f"""
import resource, sys, torch
from aesop_torch.malloc import keep_freed_memory
tuned = sys.argv[1] == "tuned" and keep_freed_memory()
def round_():
    blocks = [torch.ones(1 << 18) for _ in range(3)]   # 1 MB each
    return sum(float(b[-1]) for b in blocks)
round_()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range({ROUNDS}):
    round_()
print(int(tuned), resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def faults(mode: str) -> tuple[bool, int]:
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True)
    tuned, n = out.stdout.split()
    return tuned == "1", int(n)


def test_freed_tensors_are_reused_instead_of_faulted_in_again():
    tuned, kept = faults("tuned")
    if not tuned:
        pytest.skip("not glibc: mallopt is not there to tune")
    _, default = faults("default")
    pages = ROUNDS * 3 * (1 << 20) // 4096
    assert default > pages // 4          # glibc's default: a large share of the rounds' pages fault in again
    assert kept < pages // 50            # kept: reused

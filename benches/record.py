"""Each benchmark's latest output, kept in BENCHMARKS.md by the benchmark itself.

A bench run inside `recorded(name)` prints as usual; when it finishes without error, its whole output replaces the
block between `<!-- bench:name -->` and `<!-- /bench:name -->` in BENCHMARKS.md (added at the end the first time),
headed by the command, the date, the core count and the torch version. So the file always holds the figures of the
last complete run of every bench, never a half-written one: a failed run leaves the file as it was, and the file
is replaced by rename. The curated table at the top of BENCHMARKS.md is written by hand from these blocks.

A bench records only when asked: `run_main(name, main)` runs main() inside `recorded(name)` when the command line
has `--record` (each bench's argparse accepts that flag; `make bench` passes it), and plainly otherwise, so trying a
bench never rewrites a tracked file. This module is imported by the benches, not run: `python benches/record.py`
does nothing.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import os
import sys
from pathlib import Path

BENCHMARKS_MD = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
SECTION = "## Latest output of each benchmark"


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, text: str) -> int:
        for s in self.streams:
            s.write(text)
        return len(text)

    def flush(self) -> None:
        for s in self.streams:
            s.flush()


def block(name: str, command: str, output: str, when: datetime.date, torch_version: str) -> str:
    from train.learning.sim_pool import cores   # here, not at the top: `python benches/record.py` has no root on sys.path
    return (f"<!-- bench:{name} -->\n`{command}` on {when.isoformat()}, {cores()} cores, torch {torch_version}:\n\n"
            f"```\n{output.rstrip()}\n```\n<!-- /bench:{name} -->")


def replace_block(text: str, name: str, new: str) -> str:
    """text with the block of `name` replaced by `new` (or `new` appended under SECTION when it has none)."""
    start, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    i = text.find(start)
    if i >= 0:
        j = text.find(end, i)
        if j < 0:
            raise ValueError(f"{BENCHMARKS_MD.name}: {start} has no closing {end}")
        return text[:i] + new + text[j + len(end):]
    if SECTION not in text:
        text = text.rstrip("\n") + f"\n\n{SECTION}\n\nWritten by the benchmarks themselves (`benches/record.py`).\n"
    return text.rstrip("\n") + "\n\n" + new + "\n"


@contextlib.contextmanager
def recorded(name: str, path: Path = BENCHMARKS_MD, enabled: bool = True):
    """Print as usual and, if the body finishes, record everything printed as bench `name`'s latest output.
    enabled=False (a partial run, e.g. a bench's skip option) prints without recording."""
    if not enabled:
        yield
        return
    buf = io.StringIO()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buf)):
        yield
    import torch

    command = " ".join(["python", f"benches/{name}.py", *sys.argv[1:]])
    text = path.read_text() if path.exists() else "# Benchmarks\n"
    new = replace_block(text, name, block(name, command, buf.getvalue(), datetime.date.today(), torch.__version__))
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(new)
    os.replace(tmp, path)
    print(f"(recorded in {path.name})", file=sys.stderr)   # stdout's last line stays the bench's name=value


def run_main(name: str, main, path: Path = BENCHMARKS_MD) -> None:
    """main() run plainly or, when the command line has `--record`, inside recorded(name, path). Parses nothing: the
    bench's own argparse, run in main(), accepts --record (store_true), answers --help and refuses a bad flag (or a
    partial run with --record) before anything is measured, so nothing is recorded then."""
    # argparse takes an unambiguous prefix (--rec) for --record (an ambiguous one fails in main() before anything)
    record = any(len(arg) > 2 and "--record".startswith(arg) for arg in sys.argv[1:])
    with recorded(name, path, enabled=record):
        main()


if __name__ == "__main__":
    import argparse
    argparse.ArgumentParser(description="The benches' record of their output in BENCHMARKS.md: a module they "
                                        "import, nothing to run.").parse_args()
